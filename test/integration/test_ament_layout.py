"""
The ament layout works: colcon builds the package and ``ros2 run`` finds its node.

There is no ros2cli on PyPI; ``ros2 run dq_fk_ros dq_fk_node`` runs
``<install>/dq_fk_ros/lib/dq_fk_ros/dq_fk_node`` after ``. install/setup.sh``, which is
exactly what this test does.
"""

import os
import shutil
import signal
import subprocess
import sys
import time

import pytest
import rclpy

PACKAGE_ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
COLCON = os.path.join(os.path.dirname(sys.executable), 'colcon')
NOT_SOURCES = shutil.ignore_patterns('.venv*', '.git', 'build', 'install', 'log', '__pycache__',
                                     '*.egg-info', '.pytest_cache')

pytestmark = pytest.mark.integration


@pytest.fixture(scope='module', params=['copied', 'symlink-install'])
def colcon_workspace(request, tmp_path_factory):
    """
    Copy the package into ``src/`` of a fresh workspace and ``colcon build`` it.

    Both ways ROS 2 developers build: plain (files copied into install/) and
    ``--symlink-install`` (colcon runs a link to setup.py from build/dq_fk_ros and installs
    in develop mode, links into src/).
    """
    ws = tmp_path_factory.mktemp('ws')
    shutil.copytree(PACKAGE_ROOT, ws / 'src' / 'dq_fk_ros', ignore=NOT_SOURCES)
    listed = subprocess.run([COLCON, 'list', '--names-only'], cwd=ws, capture_output=True,
                            text=True, check=True)
    extra = ['--symlink-install'] if request.param == 'symlink-install' else []
    build = subprocess.run([COLCON, 'build', *extra], cwd=ws, capture_output=True, text=True)
    assert build.returncode == 0, build.stdout + build.stderr
    return ws, listed.stdout.split()


def test_colcon_sees_only_dq_fk_ros(colcon_workspace):
    """The vendored tf2_msgs stays invisible to colcon (vendor/COLCON_IGNORE)."""
    _, packages = colcon_workspace
    assert packages == ['dq_fk_ros']


def test_install_layout(colcon_workspace):
    ws, _ = colcon_workspace
    share = ws / 'install' / 'dq_fk_ros' / 'share'
    assert (share / 'ament_index' / 'resource_index' / 'packages' / 'dq_fk_ros').is_file()
    assert (share / 'dq_fk_ros' / 'package.xml').is_file()
    executable = ws / 'install' / 'dq_fk_ros' / 'lib' / 'dq_fk_ros' / 'dq_fk_node'
    assert os.access(executable, os.X_OK)
    # setup.py's direct_script: the function imported, not looked up in importlib.metadata
    text = executable.read_text(encoding='utf-8')
    assert 'from dq_fk_ros.ros.executables import run_dq_fk_node' in text, text
    assert 'importlib' not in text, text


def _wait_for_node(name, timeout_s):
    """Return True once a node called ``name`` is visible over DDS in this domain."""
    context = rclpy.Context()
    rclpy.init(context=context)
    probe = rclpy.create_node('ament_layout_probe', context=context)
    try:
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            # seen, and started: its joint_states subscription is the last thing it makes (a
            # SIGINT in the middle of rclpy's own start-up is rclpy's business, not this test's)
            if name in probe.get_node_names() and probe.count_subscribers('/joint_states'):
                return True
            time.sleep(0.1)
        return False
    finally:
        probe.destroy_node()
        rclpy.shutdown(context=context)


def test_ros2_run_starts_node_and_exits_cleanly_on_sigint(colcon_workspace, processes):
    ws, _ = colcon_workspace
    proc = processes.start(
        ['bash', '-c', '. install/setup.sh && exec install/dq_fk_ros/lib/dq_fk_ros/dq_fk_node'],
        cwd=ws)
    assert _wait_for_node('dq_fk_node', timeout_s=20.0), 'dq_fk_node never appeared over DDS'
    proc.send_signal(signal.SIGINT)
    output, _ = proc.communicate(timeout=10)
    assert proc.returncode == 0, output
    assert 'Traceback' not in output, output
