"""dq_fk_node in-process with rclpy: a real publisher and subscribers over DDS (loopback)."""

import math
import os
import sys
import xml.etree.ElementTree as ET

from dq_fk_ros.description.schema import load_robot_description
from dq_fk_ros.description.shipped import shipped_robot_path
from dq_fk_ros.description.to_urdf import robot_to_urdf
from dq_fk_ros.messages.outputs import POSE
from geometry_msgs.msg import PoseStamped, TwistStamped
import homogeneous_tf as htf
import numpy as np
import pytest
from rclpy.exceptions import ParameterUninitializedException
from rclpy.parameter import Parameter
from rclpy.serialization import serialize_message
from ros_harness import Harness, TF_STATIC_QOS
from tf2_msgs.msg import TFMessage

pytestmark = pytest.mark.integration
RL15_JOINTS = [f'joint_{i}' for i in range(1, 7)]


@pytest.fixture
def ros(ros_domain_id):
    harness = Harness()
    try:
        yield harness
    finally:
        harness.close()


def position_of(msg):
    p = msg.pose.position
    return [p.x, p.y, p.z]


def test_rl15_zero_pose_is_fig4_on_the_pose_topic_and_through_tf(ros):
    ros.start_node()
    poses = ros.listen(PoseStamped, ros.topic('pose/eeCarry_seg6'))
    tf = ros.listen(TFMessage, '/tf')
    zero = ros.joint_state(RL15_JOINTS, [0] * 6)
    assert ros.spin_until(lambda: poses and tf, publish=zero)
    static = ros.listen(TFMessage, '/tf_static', TF_STATIC_QOS)  # a late joiner
    assert ros.spin_until(lambda: static)
    ee = poses[-1]
    assert ee.header.frame_id == 'world' and ee.header.stamp == zero.header.stamp
    np.testing.assert_allclose(position_of(ee), [1.025, 0, 1.445], atol=1e-9)
    o = ee.pose.orientation
    np.testing.assert_allclose([o.x, o.y, o.z, o.w], [0.707107, 0, 0.707107, 0], atol=5e-7)
    transforms = static[-1].transforms + tf[-1].transforms
    composed = htf.compose(transforms, 'world', 'eeCarry_seg6')
    np.testing.assert_allclose(composed, htf.pose_matrix(ee.pose), atol=1e-9)
    assert htf.parent_of(transforms, 'eeCarry_seg6') == 'wrist_seg5'


BAD_MESSAGES = [
    ('names and positions differ in length', RL15_JOINTS, [0.0] * 5),
    ('NaN', RL15_JOINTS, [0.0, math.nan, 0, 0, 0, 0]),
    ('infinity', RL15_JOINTS, [0.0, 0, 0, math.inf, 0, 0]),
    ('empty', [], []),
    ('only unknown joints', ['gripper'], [0.02]),
    ('duplicate names', RL15_JOINTS + ['joint_1'], [0.0] * 7),
]


def test_every_bad_input_leaves_the_node_alive_and_publishing(ros):
    node = ros.start_node()
    poses = ros.listen(PoseStamped, ros.topic('pose/eeCarry_seg6'))
    chain = load_robot_description(shipped_robot_path('rl15')).chain
    assert ros.spin_until(lambda: poses, publish=ros.joint_state(RL15_JOINTS, [0] * 6))
    for k, (what, names, positions) in enumerate(BAD_MESSAGES):
        before = node.diagnostics()
        ros.joint_pub.publish(ros.joint_state(names, positions))
        q = np.full(6, 0.1 * (k + 1))
        poses.clear()
        valid = ros.joint_state(RL15_JOINTS, q)
        assert ros.spin_until(lambda: poses, publish=valid), what
        np.testing.assert_allclose(position_of(poses[-1]), chain.forward(q).translation,
                                   atol=1e-9, err_msg=what)
        assert _value(node.diagnostics(), 'updates_rejected') > \
            _value(before, 'updates_rejected'), what
    status = node.diagnostics()
    assert _value(status, 'rejected_length_mismatch') >= 1
    assert _value(status, 'rejected_non_finite') >= 2
    assert 'gripper' in {v.key: v.value for v in status.values}['unknown_joints']


def test_an_exception_in_the_input_thread_is_counted_and_the_node_goes_on(ros):
    """The input thread ended silently when its callback raised: no /tf ever after."""
    node = ros.start_node()
    poses = ros.listen(PoseStamped, ros.topic('pose/eeCarry_seg6'))
    zero = ros.joint_state(RL15_JOINTS, [0] * 6)
    assert ros.spin_until(lambda: poses, publish=zero)
    note = node._gaps.note

    def broken(number):
        raise RuntimeError('broken on purpose')
    node._gaps.note = broken
    assert ros.spin_until(lambda: _value(node.diagnostics(), 'input_errors') >= 3,
                          publish=zero)
    node._gaps.note = note
    poses.clear()
    assert ros.spin_until(lambda: poses, publish=zero)


def test_missing_joints_hold_publishing_back(ros):
    node = ros.start_node()
    poses = ros.listen(PoseStamped, ros.topic('pose/eeCarry_seg6'))
    partial = ros.joint_state(RL15_JOINTS[:4], [0] * 4)
    assert not ros.spin_until(lambda: poses, timeout_s=1.0, publish=partial)
    status = {v.key: v.value for v in node.diagnostics().values}
    assert status['joints_never_seen'] == 'joint_5, joint_6'
    rest = ros.joint_state(RL15_JOINTS[4:], [0, 0])
    assert ros.spin_until(lambda: poses, publish=rest)


def test_a_side_branch_pose_topic_is_published_from_the_message_that_first_names_it(ros):
    """Not from the next look at who reads the pose topics (twice a second): at once."""
    node = ros.start_node(robot_description_file='dual_arm', publish_unread_topics=True)
    outputs = node._outputs
    (poses,) = [s for s, stream in enumerate(outputs.streams) if stream.output is POSE]
    hidden = [k for k in outputs.streams[poses].frames if k in outputs.messages.hidden]
    assert hidden and len(outputs.groups[poses]) == len(outputs.publishers[poses]) - len(hidden)
    model = node._model
    every_joint = ros.joint_state(model.joint_names, [0.1] * len(model.joint_names))
    # handed to the node as its input thread does (no timer can run in between)
    node._on_joint_state(serialize_message(every_joint), {'publication_sequence_number': None})
    assert not outputs.messages.hidden
    assert len(outputs.groups[poses]) == len(outputs.publishers[poses])


def test_a_tree_publishes_each_chain_when_its_joints_arrive_and_a_mimic_with_its_source(ros):
    """config/dual_arm.yaml: an arm, then the gripper (one joint, the other finger a mimic)."""
    node = ros.start_node(robot_description_file='dual_arm')
    tf = ros.listen(TFMessage, '/tf', 100)
    static = ros.listen(TFMessage, '/tf_static', TF_STATIC_QOS)

    def children():
        return [t.child_frame_id for t in tf[-1].transforms] if tf else []
    arm = ros.joint_state(['left_shoulder_pitch', 'left_elbow', 'left_wrist_roll'],
                          [0.1, 0.2, 0.3])
    assert ros.spin_until(lambda: 'left_wrist' in children(), publish=arm)
    assert children() == ['left_upper_arm', 'left_forearm', 'left_wrist']
    status = {v.key: v.value for v in node.diagnostics().values}
    assert status['joints_never_seen'] == ('waist, right_shoulder_pitch, right_elbow, '
                                           'right_wrist_roll, left_gripper')
    grip = ros.joint_state(['left_gripper'], [0.03])
    assert ros.spin_until(lambda: 'left_finger_b' in children(), publish=grip)
    assert children() == ['left_upper_arm', 'left_forearm', 'left_wrist', 'left_finger_a',
                          'left_finger_b']
    transforms = {t.child_frame_id: t for t in tf[-1].transforms}
    for finger in ('left_finger_a', 'left_finger_b'):  # d = 0.01 m + the gripper's 0.03 m
        t = transforms[finger].transform
        assert (t.translation.x, t.translation.y, t.translation.z) == pytest.approx(
            (0.0, 0.0, 0.04), abs=1e-12)
    assert 'waist' in {v.value for v in node.diagnostics().values
                       if v.key == 'joints_never_seen'}.pop()
    assert ros.spin_until(lambda: static)  # transient local: may come after /tf
    assert {t.child_frame_id for t in static[-1].transforms} >= {
        'pedestal', 'left_shoulder', 'right_shoulder', 'left_tcp', 'head_camera'}


def test_reload_with_a_bad_file_keeps_the_old_model(ros, tmp_path):
    node = ros.start_node(robot_description_dirs=str(tmp_path))
    bad = tmp_path / 'bad.yaml'
    bad.write_text('robot: x\nbase: {frame: b}\nchain: []\n')
    result = node.set_parameters([Parameter('robot_description_file', value=str(bad))])[0]
    assert not result.successful and 'expected a non-empty list' in result.reason
    poses = ros.listen(PoseStamped, ros.topic('pose/eeCarry_seg6'))
    assert ros.spin_until(lambda: poses, publish=ros.joint_state(RL15_JOINTS, [0] * 6))
    # a good file is taken: the Panda's flange topic appears
    good = shipped_robot_path('panda')
    assert node.set_parameters([Parameter('robot_description_file', value=good)])[0].successful
    flange = ros.listen(PoseStamped, ros.topic('pose/panda_link8'))
    panda = ros.joint_state([f'panda_joint{i}' for i in range(1, 8)], [0] * 7)
    assert ros.spin_until(lambda: flange, publish=panda)
    np.testing.assert_allclose(position_of(flange[-1]), [0.088, 0, 0.926], atol=1e-9)


def test_frame_prefix_applies_to_every_frame_id(ros):
    ros.start_node(frame_prefix='left/')
    tf = ros.listen(TFMessage, '/tf')
    assert ros.spin_until(lambda: tf, publish=ros.joint_state(RL15_JOINTS, [0] * 6))
    static = ros.listen(TFMessage, '/tf_static', TF_STATIC_QOS)
    assert ros.spin_until(lambda: static)
    transforms = tf[-1].transforms + static[-1].transforms
    ids = {t.child_frame_id for t in transforms} | {t.header.frame_id for t in transforms}
    model = load_robot_description(shipped_robot_path('rl15'))
    links = {link.get('name') for link in ET.fromstring(robot_to_urdf(model)).iter('link')}
    assert ids == {'world'} | {'left/' + n for n in links - {'world'}}
    assert {'left/' + n for n in model.frame_names} < ids  # and the URDF's helper links


def test_twist_from_joint_velocities(ros):
    ros.start_node()
    twists = ros.listen(TwistStamped, ros.topic('twist/eeCarry_seg6'))
    chain = load_robot_description(shipped_robot_path('rl15')).chain
    q, qdot = np.linspace(-0.5, 0.5, 6), np.linspace(0.2, 1.2, 6)
    assert ros.spin_until(lambda: twists, publish=ros.joint_state(RL15_JOINTS, q, qdot))
    v, w = chain.twist(q, qdot)
    t = twists[-1].twist
    np.testing.assert_allclose([t.linear.x, t.linear.y, t.linear.z], v, atol=1e-9)
    np.testing.assert_allclose([t.angular.x, t.angular.y, t.angular.z], w, atol=1e-9)
    assert twists[-1].header.frame_id == 'world'


def test_a_zero_stamp_is_never_published(ros):
    from builtin_interfaces.msg import Time
    ros.start_node()
    poses = ros.listen(PoseStamped, ros.topic('pose/eeCarry_seg6'))
    zero = ros.joint_state(RL15_JOINTS, [0] * 6, stamp=Time())
    assert ros.spin_until(lambda: poses, publish=zero)
    assert poses[-1].header.stamp.sec > 0


def test_invalid_robot_file_at_start_exits_with_the_message(processes, tmp_path):
    bad = tmp_path / 'bad.yaml'
    bad.write_text('robot: x\nbase: {frame: b}\nchain:\n  - {frame: l, joint: j, theta: 0, '
                   'd: 0, a: 0, alfa: 0}\n')
    proc = processes.start([sys.executable, '-m', 'dq_fk_ros.ros.node', '--ros-args', '-p',
                            f'robot_description_file:={bad}'])
    output, _ = proc.communicate(timeout=30)
    assert proc.returncode == 1
    assert f"dq_fk_node: {bad}: chain[0] (frame 'l'): unknown field 'alfa'" in output
    assert 'Traceback' not in output


def _value(status, key):
    return int({v.key: v.value for v in status.values}.get(key, 0))


def test_use_sim_time_stamps_from_clock(ros):
    """With use_sim_time, a zero JointState stamp is replaced by the /clock time."""
    from builtin_interfaces.msg import Time
    from rosgraph_msgs.msg import Clock
    ros.start_node(use_sim_time=True)
    clock_pub = ros.probe.create_publisher(Clock, '/clock', 10)
    poses = ros.listen(PoseStamped, ros.topic('pose/eeCarry_seg6'))
    sim = Time(sec=1234, nanosec=500)
    zero = ros.joint_state(RL15_JOINTS, [0] * 6, stamp=Time())

    def tick():
        clock_pub.publish(Clock(clock=sim))
        return bool(poses) and poses[-1].header.stamp == sim
    assert ros.spin_until(tick, publish=zero)


def test_a_flood_of_messages_leaves_the_node_alive_with_the_latest_state(ros):
    """Thousands of messages at once: some may be dropped by the queue, never the last one."""
    node = ros.start_node()
    poses = ros.listen(PoseStamped, ros.topic('pose/eeCarry_seg6'), 1000)
    chain = load_robot_description(shipped_robot_path('rl15')).chain
    assert ros.spin_until(lambda: poses, publish=ros.joint_state(RL15_JOINTS, [0] * 6))
    qs = np.random.default_rng(9).uniform(-1, 1, size=(3000, 6))
    for q in qs:
        ros.joint_pub.publish(ros.joint_state(RL15_JOINTS, q))
    last = chain.forward(qs[-1]).translation

    def caught_up():
        return np.allclose(position_of(poses[-1]), last, atol=1e-9)
    assert ros.spin_until(caught_up, timeout_s=30)
    assert _value(node.diagnostics(), 'updates_rejected') == 0


@pytest.mark.parametrize('input_thread', [True, False])
def test_joint_states_lost_in_a_full_queue_are_counted(ros, input_thread):
    """One publisher, a queue of 1, a burst: every message is either taken or counted lost."""
    from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
    node = ros.start_node(qos_depth=1, joint_states_reliability='reliable',
                          input_thread=input_thread)
    reports = ros.listen(DiagnosticArray, '/diagnostics')
    counts = node._merger.counts
    first = ros.joint_state(RL15_JOINTS, [0] * 6)
    # counting starts once the node has seen one publisher matched (the harness's), from
    # the first message it takes then
    assert ros.spin_until(lambda: node._gaps._last is not None, publish=first)
    ros.spin_until(lambda: False, timeout_s=0.3)  # what was sent so far is taken
    received, lost = counts['received'], node._gaps.lost
    burst = [ros.joint_state(RL15_JOINTS, q) for q in
             np.random.default_rng(3).uniform(-1, 1, size=(3000, 6))]
    for msg in burst:
        ros.joint_pub.publish(msg)
    ros.spin_until(lambda: False, timeout_s=0.2)
    ros.joint_pub.publish(first)  # one more after a pause: the burst's tail is not "lost"

    def accounted():
        return counts['received'] - received + node._gaps.lost - lost == len(burst) + 1
    assert ros.spin_until(accounted, timeout_s=20), \
        (counts['received'] - received, node._gaps.lost - lost)
    assert node._gaps.lost > lost  # a queue of one cannot have kept up with the burst
    lost_now = node._gaps.lost
    assert _value(node.diagnostics(), 'updates_lost') == lost_now

    def warned():  # the report of the second the losses happened in says so
        return any(m.status[0].level == DiagnosticStatus.WARN and 'lost' in m.status[0].message
                   and _value(m.status[0], 'updates_lost') == lost_now for m in reports)
    assert ros.spin_until(warned, timeout_s=5)
    reports.clear()  # and the next report, with nothing lost since, is OK again
    assert ros.spin_until(lambda: reports, timeout_s=5)
    assert reports[0].status[0].level == DiagnosticStatus.OK


def readme_parameter_rows(heading='### Parameters'):
    """Return the README's parameter table under ``heading``: {name: (type, default)}."""
    readme = open(os.path.join(os.path.dirname(__file__), '..', '..', 'README.md')).read()
    table = readme.split(heading, 1)[1].split('\n\n', 2)[1]
    rows = {}
    for line in table.splitlines()[2:]:
        name, kind, default = (cell.strip() for cell in line.strip('|').split('|')[:3])
        rows[name.strip('`')] = (kind, default.split('`')[1])
    return rows


def test_the_readme_lists_every_parameter_with_its_type_and_default(ros):
    """README "Parameters" is the node's: the same names, types and default values."""
    node = ros.start_node(publish_frequency=None)  # every default the node's own
    rows = readme_parameter_rows()
    rclpys_own = set(ros.probe.list_parameters([], 0).names)  # use_sim_time and the like
    declared = {}
    for name in node.list_parameters([], 0).names:
        if name not in rclpys_own:
            try:
                param = node.get_parameter(name)
                declared[name] = (param.type_, param.value)
            except ParameterUninitializedException:  # typed, no value: its declared type
                kind = Parameter.Type(node.describe_parameter(name).type)
                declared[name] = (kind, [] if kind == Parameter.Type.STRING_ARRAY else None)
    assert sorted(rows) == sorted(declared)
    types = {Parameter.Type.STRING: 'string', Parameter.Type.DOUBLE: 'double',
             Parameter.Type.BOOL: 'bool', Parameter.Type.INTEGER: 'int',
             Parameter.Type.STRING_ARRAY: 'string[]'}
    for name, (type_, value) in declared.items():
        kind, default = rows[name]
        assert kind == types[type_], name
        if type_ == Parameter.Type.STRING_ARRAY:
            shown = str(list(value))
        elif value is None:
            shown = 'unset'  # the robot's default (publish_dh_frames)
        elif type_ == Parameter.Type.BOOL:
            shown = 'true' if value else 'false'
        else:
            shown = str(value) if value != '' else "''"
        assert default == shown, name


@pytest.mark.parametrize('batch_ms, batch_s', [(None, 0.002), (0.0, 0.0), (5.0, 0.005)])
def test_input_batch_ms_is_the_input_threads_window(ros, batch_ms, batch_s):
    params = {} if batch_ms is None else {'input_batch_ms': batch_ms}
    node = ros.start_node(**params)
    assert node._input._batch_s == pytest.approx(batch_s)


@pytest.mark.parametrize('input_thread', [True, False])
@pytest.mark.parametrize('depth', [None, 7])
def test_qos_depth_is_the_joint_state_subscriptions_depth(ros, input_thread, depth):
    params = {'input_thread': input_thread, **({} if depth is None else {'qos_depth': depth})}
    node = ros.start_node(**params)
    assert node._joint_state_sub.qos_profile.depth == (1000 if depth is None else depth)


def test_the_node_publishes_the_output_table_as_written(ros):
    """Every row of messages/outputs.py: the node's publisher has its name, type and QoS."""
    from dq_fk_ros.messages.outputs import OUTPUTS
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, ReliabilityPolicy
    node = ros.start_node()
    names = {'pose': ros.topic('pose/eeCarry_seg6'), 'twist': ros.topic('twist/eeCarry_seg6')}
    for output in OUTPUTS:
        if output.topic.startswith('~/'):
            topic = names[output.topic.split('/')[1]]
        else:
            topic = output.topic if output.topic.startswith('/') else '/' + output.topic
        ros.spin_until(lambda: ros.probe.get_publishers_info_by_topic(topic), timeout_s=10)
        infos = [i for i in ros.probe.get_publishers_info_by_topic(topic)
                 if i.node_name == node.get_name()]
        assert len(infos) == 1, (topic, infos)
        qos = infos[0].qos_profile
        assert infos[0].topic_type == output.msgtype, topic
        assert qos.reliability == ReliabilityPolicy.RELIABLE, topic
        assert qos.durability == (DurabilityPolicy.TRANSIENT_LOCAL if output.latched
                                  else DurabilityPolicy.VOLATILE), topic
        assert qos.history in (HistoryPolicy.KEEP_LAST, HistoryPolicy.UNKNOWN), topic
