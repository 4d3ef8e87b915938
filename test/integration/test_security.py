"""
Nothing a DDS peer, a file or a web page sends may run code, read files, freeze or crash.

The node runs as the robot's user (often root) and any peer on its domain may set its
parameters: every class of attack of the issue "nothing gets in" is here, each as a test
that failed before the fix (a marker file created, a secret in a reply, no answer for a
minute, SIGINT ignored).
"""

import os
import signal
import sys
import time

from dq_fk_ros.description.shipped import shipped_robot_path
from dq_fk_ros.ros.executables import executable
from geometry_msgs.msg import PoseStamped
from proc_table import proc_stat, processes as live
import pytest
from rcl_interfaces.srv import SetParameters
from rclpy.parameter import Parameter
from ros_harness import node_topic, start

sys.path.insert(0, os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))),
                                'unit'))
from test_from_urdf import chain_urdf  # noqa: E402, I100 (the unit tests' own)
from test_xacro_sandbox import escapes, macro_bomb  # noqa: E402, I100

RL15_JOINTS = [f'joint_{i}' for i in range(1, 7)]
SECRET = 'root:*:20228:0:99999:7::'


def set_parameter_async(listener, client, name, value):
    request = SetParameters.Request(parameters=[Parameter(name, value=value)
                                                .to_parameter_msg()])
    return client.call_async(request)


def set_parameter(listener, client, name, value, timeout_s=30):
    future = set_parameter_async(listener, client, name, value)
    assert listener.spin_until(future.done, timeout_s=timeout_s), f'no answer for {name}'
    return future.result().results[0]


def started_node(processes, listener, *params):
    """Start dq_fk_node with ``params``; return it, its /pose listener and a service client."""
    node = start(processes, 'dq_fk_node', *params, log_level='info')
    poses = listener.listen(PoseStamped, node_topic(node, 'pose/eeCarry_seg6'))
    zero = listener.joint_state(RL15_JOINTS, [0] * 6)
    assert listener.spin_until(lambda: poses, publish=zero, timeout_s=20)
    client = listener.probe.create_client(SetParameters, node_topic(node, 'set_parameters'))
    assert client.wait_for_service(timeout_sec=10)
    return node, poses, client


def stop(node, timeout_s=5.0):
    """SIGINT the node; return (seconds it took to exit, everything it printed)."""
    start_s = time.monotonic()
    os.killpg(node.pid, signal.SIGINT)
    output, _ = node.communicate(timeout=timeout_s + 5.0)
    return time.monotonic() - start_s, output


# -- code execution through xacro ---------------------------------------------------------
@pytest.mark.parametrize('name', ['comprehension', 'globals', 'computed names',
                                  'eval substitution'])
def test_xacro_escapes_run_nothing_in_the_cli_or_at_node_start(tmp_path, processes, name):
    marker = tmp_path / 'marker'
    path = tmp_path / 'evil.urdf.xacro'
    path.write_text(escapes(marker)[name])
    for argv in (executable('dq_fk') + ['validate', str(path)],
                 executable('dq_fk_node') + ['--ros-args', '-p',
                                             f'robot_description_file:={path}']):
        proc = processes.start(argv)
        output, _ = proc.communicate(timeout=60)
        assert proc.returncode == 1, output
        assert 'xacro failed' in output and 'Traceback' not in output, output
        assert not marker.exists(), argv
    assert len(output.strip().splitlines()) == 1, output


def test_xacro_set_at_run_time_runs_nothing(tmp_path, processes, listener):
    marker = tmp_path / 'marker'
    evil = {}
    for k, (name, text) in enumerate(escapes(marker).items()):
        evil[name] = tmp_path / f'evil{k}.urdf.xacro'
        evil[name].write_text(text)
    node, poses, client = started_node(processes, listener,
                                       f'robot_description_dirs:={tmp_path}')
    result = set_parameter(listener, client, 'robot_description_file',
                           str(evil['eval substitution']))
    assert not result.successful and 'a .xacro file is a program' in result.reason
    assert not marker.exists()
    stop(node)
    node, poses, client = started_node(processes, listener, f'robot_description_dirs:={tmp_path}',
                                       'allow_runtime_xacro:=true')
    for name, path in evil.items():
        result = set_parameter(listener, client, 'robot_description_file', str(path))
        assert not result.successful and result.reason == f'{path}: xacro failed', \
            (name, result.reason)
        assert not marker.exists(), name


# -- files disclosed to parameter clients -------------------------------------------------
def test_run_time_files_outside_the_folders_are_refused_and_nothing_is_quoted(
        tmp_path, processes, listener):
    robots, private = tmp_path / 'robots', tmp_path / 'private'
    robots.mkdir()
    private.mkdir()
    (private / 'shadow').write_text(SECRET + '\n')
    (robots / 'notes.txt').write_text(SECRET + '\n')             # in the folder, no robot
    (robots / 'env.yaml').write_text('API_KEY: hunter2\n')
    (robots / 'key.urdf').write_text(f'<notes>{SECRET}</notes>')
    (robots / 'shadow.yaml').symlink_to(private / 'shadow')
    secret_xacro = robots / 'leak.urdf.xacro'
    secret_xacro.write_text(
        '<?xml version="1.0"?><robot name="$(env HOME)${xacro.load_yaml(\'' +
        str(private / 'shadow') + '\')}" xmlns:xacro="http://www.ros.org/wiki/xacro">'
        '<link name="a"/></robot>')
    node, poses, client = started_node(processes, listener, f'robot_description_dirs:={robots}',
                                       'allow_runtime_xacro:=true')
    for path in (private / 'shadow', robots / 'shadow.yaml', '/etc/shadow', '/etc/passwd',
                 robots / 'notes.txt', robots / 'env.yaml', robots / 'key.urdf', secret_xacro):
        result = set_parameter(listener, client, 'robot_description_file', str(path))
        assert not result.successful, path
        for secret in ('root:', 'hunter2', 'API_KEY', '/root'):
            assert secret not in result.reason, (path, result.reason)
    zero = listener.joint_state(RL15_JOINTS, [0] * 6)
    poses.clear()
    assert listener.spin_until(lambda: poses, publish=zero, timeout_s=10)
    good = robots / 'puma.yaml'
    good.write_text(open(shipped_robot_path('puma560'), encoding='utf-8').read())
    assert set_parameter(listener, client, 'robot_description_file', str(good)).successful
    _, output = stop(node)
    assert 'root:' not in output and 'hunter2' not in output and 'API_KEY' not in output, output


# -- freezes: one parameter set may not stop the node ---------------------------------------
def test_a_huge_urdf_and_a_macro_bomb_are_answered_while_the_node_keeps_publishing(
        tmp_path, processes, listener):
    (tmp_path / 'big.urdf').write_text(chain_urdf(20_000))
    (tmp_path / 'bomb.urdf.xacro').write_text(macro_bomb())
    node, poses, client = started_node(processes, listener, f'robot_description_dirs:={tmp_path}',
                                       'allow_runtime_xacro:=true')
    zero = listener.joint_state(RL15_JOINTS, [0] * 6)
    for name, words in (('big.urdf', '20001 <link> elements'),
                        ('bomb.urdf.xacro', 'xacro failed')):
        poses.clear()
        arrivals, answered = [], []
        poses_seen = [0]

        def note():
            if len(poses) > poses_seen[0]:
                arrivals.append(time.monotonic())
                poses_seen[0] = len(poses)
            if future.done() and not answered:
                answered.append(time.monotonic())
            return bool(answered) and time.monotonic() > answered[0] + 1.0
        asked = time.monotonic()
        future = set_parameter_async(listener, client, 'robot_description_file',
                                     str(tmp_path / name))
        # the deadline of the wait: answered within 15 s (the xacro time limit is 3 s)
        assert listener.spin_until(note, publish=zero, timeout_s=15), f'no answer for {name}'
        result = future.result().results[0]
        assert not result.successful and words in result.reason, result.reason
        # the old robot was published all along, and after: poses (a joint state every
        # 50 ms, each answered) arrived while the bomb's answer was pending (its 3 s limit)
        # and in the second after each answer
        pending = sum(asked < t < answered[0] for t in arrivals)
        after = sum(t > answered[0] for t in arrivals)
        assert after >= 5 and (pending >= 5 or name == 'big.urdf'), \
            (name, pending, after, answered[0] - asked)
        assert node.poll() is None
    # and Ctrl-C works while a bomb is being expanded
    future = set_parameter_async(listener, client, 'robot_description_file',
                                 str(tmp_path / 'bomb.urdf.xacro'))
    # the expansion under way: the sandbox's child process (a session of its own)
    assert listener.spin_until(lambda: live(lambda pid: int(proc_stat(pid)[1]) == node.pid),
                               timeout_s=10)
    _, output = stop(node)   # its deadline: exited within 10 s of the SIGINT
    assert node.returncode is not None and 'Traceback' not in output, output[-500:]


# -- one line where one line is promised ----------------------------------------------------
def test_huge_numbers_are_one_line_in_every_tool(tmp_path, processes):
    """An axis of 1e200 gave a 39-line LinAlgError at node start (rc 1 in dq_fk_bag)."""
    offset = tmp_path / 'far.urdf'
    offset.write_text('<robot name="r"><link name="a"/><link name="b"/><joint name="j" '
                      'type="revolute"><parent link="a"/><child link="b"/><origin '
                      'xyz="1e200 0 0"/><axis xyz="0 0 1"/><limit lower="-1" upper="1" '
                      'effort="1" velocity="1"/></joint></robot>')
    words = "joint 'j': origin xyz is beyond 1e+06 m"
    for argv, code in ((executable('dq_fk') + ['fk', str(offset)], 1),
                       (executable('dq_fk_bag') + ['process', str(tmp_path), str(tmp_path / 'o'),
                                                   '--robot', str(offset)], 2),
                       (executable('dq_fk_node') + ['--ros-args', '-p',
                                                    f'robot_description_file:={offset}'], 1)):
        proc = processes.start(argv)
        output, _ = proc.communicate(timeout=60)
        assert proc.returncode == code and words in output, (argv, output)
        assert len(output.strip().splitlines()) == 1 and 'Warning' not in output, output
    axis = tmp_path / 'axis.urdf'
    axis.write_text(offset.read_text().replace('xyz="1e200 0 0"', 'xyz="0 0 1e200"')
                    .replace('<axis xyz="0 0 1"/>', '<axis xyz="1e200 0 0"/>'))
    proc = processes.start(executable('dq_fk') + ['fk', str(axis)])
    output, _ = proc.communicate(timeout=60)
    assert proc.returncode == 1 and 'beyond 1e+06 m' in output
    axis.write_text(offset.read_text().replace('xyz="1e200 0 0"', 'xyz="0 0 0.5"')
                    .replace('<axis xyz="0 0 1"/>', '<axis xyz="1e200 0 0"/>'))
    proc = processes.start(executable('dq_fk') + ['fk', str(axis)])
    output, _ = proc.communicate(timeout=60)
    assert proc.returncode == 0 and 'Warning' not in output, output


def test_joint_states_naming_too_many_joints_are_refused(processes, listener):
    """10 000-name JointStates held the node at 438 MB; more than 1024 names are refused."""
    from diagnostic_msgs.msg import DiagnosticArray
    node = start(processes, 'dq_fk_node')
    diagnostics = listener.listen(DiagnosticArray, '/diagnostics')
    poses = listener.listen(PoseStamped, node_topic(node, 'pose/eeCarry_seg6'))
    names = RL15_JOINTS + [f'extra_{k}' for k in range(1100)]
    huge = listener.joint_state(names, [0.0] * len(names))

    def refused():
        values = {v.key: v.value for d in diagnostics[-1:] for v in d.status[0].values}
        return int(values.get('rejected_malformed_cdr', 0)) > 0
    assert listener.spin_until(refused, publish=huge, timeout_s=20)
    assert not poses
    assert listener.spin_until(lambda: poses, publish=listener.joint_state(RL15_JOINTS, [0] * 6))
    assert node.poll() is None
