"""The compiled kernel is optional: without a C compiler the package installs and runs numpy."""

import os
import shutil
import subprocess
import sys
import zipfile

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
LEFT_OUT = shutil.ignore_patterns('.venv*', 'build', 'install', 'log', '*.so', '__pycache__',
                                  '*.egg-info', 'node_modules', '.git', '.hypothesis',
                                  '.pytest_cache', '.stamps', '.logs')


def test_without_a_compiler_the_wheel_has_no_kernel_and_fk_runs_on_numpy(tmp_path):
    source = tmp_path / 'src'
    shutil.copytree(ROOT, source, ignore=LEFT_OUT)
    env = dict(os.environ, CC='/bin/false')  # every compile fails, as with no compiler
    subprocess.run([sys.executable, '-m', 'pip', 'wheel', '--no-deps', '--no-build-isolation',
                    '-q', '-w', str(tmp_path / 'wheel'), str(source)], env=env, check=True,
                   capture_output=True)
    wheel = next((tmp_path / 'wheel').glob('dq_fk_ros-*.whl'))
    with zipfile.ZipFile(wheel) as archive:
        names = archive.namelist()
    assert 'dq_fk_ros/kinematics/kernel.py' in names
    assert not [n for n in names if '_kernel' in n or '_cdr' in n or '_mcap' in n or
                '_rcl_publish' in n or 'transforms/_tf.' in n]
    with zipfile.ZipFile(wheel) as archive:
        archive.extractall(tmp_path / 'site')
    code = ('import numpy as np, dq_fk_ros\n'
            'print(dq_fk_ros.kernel_info()["active"])\n'
            f'chain = dq_fk_ros.load_robot({str(source / "config" / "rl15.yaml")!r}).model.chain\n'
            'print((np.round(chain.forward(np.zeros(6)).translation, 6) + 0.0).tolist())\n'
            'from dq_fk_ros.messages.cdr import COMPILED\n'
            'from dq_fk_ros.messages.cdr_templates import pose_stamped_template\n'
            'print(COMPILED is None, pose_stamped_template("w").compiled(7))\n'
            'from dq_fk_ros.transforms.buffer_core import BufferCore, COMPILED\n'
            'core = BufferCore()\n'
            'core.set_transform("a", "b", 5, (1.0, 0, 0, 0, 0, 0, 1))\n'
            'print(COMPILED is None, core.lookup("a", "b", 5)[0][0])\n'
            'from dq_fk_ros.ros.publisher_group import COMPILED, WHY\n'
            'print(COMPILED, WHY.split(":")[0])\n')
    run = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True,
                         cwd=tmp_path, env=dict(os.environ, PYTHONPATH=str(tmp_path / 'site')))
    assert run.returncode == 0, run.stderr
    active, position, writer, tf, publish = run.stdout.splitlines()
    assert active == 'numpy'
    assert position == '[1.025, 0.0, 1.445]'  # the paper's Fig. 4 pose at q = 0
    assert writer == 'True None'  # the node's messages: the struct packer
    assert tf == 'True 1.0'       # TF lookups: the Python walk
    assert publish == 'False publish_raw'  # the node publishes by rclpy's publish_raw
