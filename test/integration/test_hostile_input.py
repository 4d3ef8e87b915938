"""
What a hostile or careless user sends to the running programs: they answer, they stay up.

dq_fk_node and fake_joint_publisher run as separate processes; the test talks to them over
DDS from its own rclpy context (parameter service, topics) on this run's private domain.
"""

import os
import time

from diagnostic_msgs.msg import DiagnosticArray
from dq_fk_ros.description.shipped import shipped_robot_path
from dq_fk_ros.ros.executables import executable
from geometry_msgs.msg import PoseStamped
import numpy as np
import pytest
from rcl_interfaces.srv import SetParameters
from rclpy.parameter import Parameter
from ros_harness import node_topic, start
from sensor_msgs.msg import JointState

pytestmark = pytest.mark.integration
RL15_JOINTS = [f'joint_{i}' for i in range(1, 7)]
RL15_TEXT = open(shipped_robot_path('rl15'), encoding='utf-8').read()


def bad_robot_files(folder):
    """One file per class of robot file that used to kill the running node."""
    rows = ''.join(f'  - {{frame: f{k}, joint: j{k}, theta: 0, d: 0, a: 1, alpha: 0}}\n'
                   for k in range(10_000))
    texts = {
        'huge_integer': (RL15_TEXT.replace('a: 200', 'a: ' + '9' * 400, 1),
                         "field 'a' must be a finite number"),
        'deep_nesting': (RL15_TEXT.replace('a: 200', 'a: ' + '[' * 5000 + ']' * 5000, 1),
                         'nested too deeply'),
        'newline_in_frame': (RL15_TEXT.replace('frame: shoulder_seg1',
                                               'frame: "shoulder_seg1\\n"', 1),
                             "field 'frame' must be a tf2 frame id"),
        'ten_thousand_rows': (RL15_TEXT[:RL15_TEXT.index('chain:') + 7] + rows,
                              'a robot description has at most 256'),
        'binary': ('\x00\x01\x02' * 100, 'not valid YAML'),
    }
    files = []
    for name, (text, words) in texts.items():
        path = folder / f'{name}.yaml'
        path.write_text(text, encoding='utf-8')
        files.append((path, words))
    files.append((folder / 'missing.yaml', 'no such file'))
    files.append((folder, 'is a directory'))
    return files


def set_parameter(listener, client, name, value):
    """Set one parameter of the node through its service; return the SetParametersResult."""
    request = SetParameters.Request(parameters=[Parameter(name, value=value)
                                                .to_parameter_msg()])
    future = client.call_async(request)
    assert listener.spin_until(future.done, timeout_s=30), f'no answer for {name}={value!r}'
    return future.result().results[0]


def ee_position(poses):
    p = poses[-1].pose.position
    return [p.x, p.y, p.z]


def test_the_running_node_refuses_every_bad_robot_file_and_keeps_its_robot(
        processes, listener, tmp_path):
    node = start(processes, 'dq_fk_node', f'robot_description_dirs:={tmp_path}')
    poses = listener.listen(PoseStamped, node_topic(node, 'pose/eeCarry_seg6'))
    zero = listener.joint_state(RL15_JOINTS, [0] * 6)
    assert listener.spin_until(lambda: poses, publish=zero, timeout_s=20)
    client = listener.probe.create_client(SetParameters, node_topic(node, 'set_parameters'))
    assert client.wait_for_service(timeout_sec=10)
    for path, words in bad_robot_files(tmp_path):
        result = set_parameter(listener, client, 'robot_description_file', str(path))
        assert not result.successful, path
        assert words in result.reason and '\n' not in result.reason, result.reason
        assert node.poll() is None, f'the node died on {path.name}'
        poses.clear()
        assert listener.spin_until(lambda: poses, publish=zero, timeout_s=10), path.name
        np.testing.assert_allclose(ee_position(poses), [1.025, 0, 1.445], atol=1e-9)
    rate = 'must be 0 (publish every update) or from 0.01 to 1e+06'
    for name, value, words in [('max_publish_rate_hz', float('nan'), rate),
                               ('max_publish_rate_hz', -1.0, rate),
                               ('max_publish_rate_hz', 5e-324, rate),
                               ('publish_frequency', 5e-324, rate),
                               ('urdf_tip_link', 'x' * 1_000_000, 'is not a link name'),
                               ('urdf_base_link', 'tool\n0', 'is not a link name'),
                               ('frame_prefix', 'a b', 'would not give valid frame ids'),
                               ('frame_prefix', '"quoted"/', 'would not give valid frame ids'),
                               ('out_of_limits', 'ignore', 'allowed: warn, clamp, reject')]:
        result = set_parameter(listener, client, name, value)
        assert not result.successful and words in result.reason, (name, result.reason)
    # and a good file still loads after all that
    good = set_parameter(listener, client, 'robot_description_file',
                         shipped_robot_path('puma560'))
    assert good.successful and node.poll() is None


def rss_mib(pid):
    with open(f'/proc/{pid}/status', encoding='ascii') as status:
        for line in status:
            if line.startswith('VmRSS:'):
                return int(line.split()[1]) / 1024.0
    raise AssertionError('no VmRSS')


def test_a_flood_of_unknown_joint_names_keeps_memory_and_diagnostics_small(
        processes, listener):
    """Every message names 20 new joints: memory, log and /diagnostics must stay bounded."""
    node = start(processes, 'dq_fk_node', 'joint_states_reliability:=reliable')
    diagnostics = listener.listen(DiagnosticArray, '/diagnostics')
    poses = listener.listen(PoseStamped, node_topic(node, 'pose/eeCarry_seg6'))
    zero = listener.joint_state(RL15_JOINTS, [0] * 6)
    assert listener.spin_until(lambda: poses and diagnostics, publish=zero, timeout_s=20)
    baseline = rss_mib(node.pid)
    pad = 'x' * 80
    sent = 0
    end = time.monotonic() + 4.0
    while time.monotonic() < end:
        names = RL15_JOINTS + [f'ghost_{sent}_{i}_{pad}' for i in range(20)]
        listener.joint_pub.publish(listener.joint_state(names, [0.0] * 26))
        sent += 1
        if sent % 50 == 0:
            listener.executor.spin_once(timeout_sec=0)

    def received():
        return int({v.key: v.value for v in diagnostics[-1].status[0].values}
                   ['updates_received'])
    counts = []

    def settled():  # the node has worked through its queue: two reports alike
        if diagnostics and (not counts or counts[-1][0] is not diagnostics[-1]):
            counts.append((diagnostics[-1], received()))
        return len(counts) >= 2 and counts[-1][1] == counts[-2][1]
    diagnostics.clear()
    assert listener.spin_until(settled, timeout_s=60), counts
    grown = rss_mib(node.pid) - baseline
    values = {v.key: v.value for v in diagnostics[-1].status[0].values}
    size = sum(len(v.key) + len(v.value) for v in diagnostics[-1].status[0].values)
    # enough names (20 a message, ~100 bytes each) reached the node to matter
    assert int(values['updates_received']) >= 2000, (sent, values['updates_received'])
    assert len(values['unknown_joints'].split(', ')) == 20
    count = int(values['updates_received'])
    assert int(values['unknown_names_unlisted']) >= 20 * (count - 1 - 20)
    assert size < 4000, size
    assert grown < 25.0, f'RSS grew by {grown:.1f} MiB ({baseline:.1f} MiB before)'
    assert node.poll() is None


@pytest.mark.parametrize('args, words', [
    (['-p', 'max_publish_rate_hz:=10'],
     "parameter 'max_publish_rate_hz' to '10' of type 'INTEGER', expecting type 'DOUBLE'"),
    (['-p', 'publish_tf:=1'], "expecting type 'BOOL'"),
    (['-p', 'max_publish_rate_hz:=.nan'], 'max_publish_rate_hz must be 0 (publish every'),
    (['-p', 'frame_prefix:=a b'], 'would not give valid frame ids'),
    (['-p', 'qos_depth:=0'], 'qos_depth must be an integer from 1 to 100000, got 0'),
    (['-p', 'qos_depth:=-1'], 'qos_depth must be an integer from 1 to 100000, got -1'),
    (['-p', 'qos_depth:=100001'], 'qos_depth must be an integer from 1 to 100000, got 100001'),
    (['-p', 'input_batch_ms:=-1.0'], 'input_batch_ms must be a number from 0 to 100'),
    (['-p', 'input_batch_ms:=.nan'], 'input_batch_ms must be a number from 0 to 100'),
    (['-p', 'input_batch_ms:=100.5'], 'input_batch_ms must be a number from 0 to 100'),
    (['--params-file', '/nonexistent/params.yaml'], '/nonexistent/params.yaml: no such file'),
])
def test_bad_start_up_arguments_are_one_line_and_exit_1(processes, args, words):
    proc = processes.start(executable('dq_fk_node') + ['--ros-args'] + args)
    output, _ = proc.communicate(timeout=30)
    assert proc.returncode == 1, output
    assert 'Traceback' not in output and len(output.strip().splitlines()) == 1, output
    assert output.startswith('dq_fk_node: ') and words in output, output


def test_fake_publisher_with_max_messages_exits_by_itself(processes, listener):
    joints = listener.listen(JointState, '/joint_states', 100)
    proc = start(processes, 'fake_joint_publisher', 'max_messages:=25', 'rate_hz:=100.0',
                 'wait_for_subscribers:=1')
    deadline = time.monotonic() + 30
    while proc.poll() is None and time.monotonic() < deadline:
        listener.executor.spin_once(timeout_sec=0.05)
    assert proc.returncode == 0, proc.stdout.read()
    listener.spin_until(lambda: len(joints) == 25, timeout_s=2)
    assert len(joints) == 25
    assert not os.path.exists(f'/proc/{proc.pid}')
