"""FrameMessages: what the node would publish, checked without DDS."""

from types import SimpleNamespace

from builtin_interfaces.msg import Time
from dq_fk_ros.description.schema import load_robot_description, parse_robot_description
from dq_fk_ros.description.shipped import shipped_robot_path
from dq_fk_ros.kinematics.dh import homogeneous_from_dq
from dq_fk_ros.ros.conversions import (FrameBytes, FrameMessages, joint_state_fields,
                                       ns_to_stamp, qos_profile, stamp_to_ns)
import homogeneous as hm
import numpy as np
from rclpy.serialization import deserialize_message
from sensor_msgs.msg import JointState
from tf2_msgs.msg import TFMessage


def as_matrix(translation, rotation):
    return hm.matrix_of_pose([translation.x, translation.y, translation.z],
                             [rotation.x, rotation.y, rotation.z, rotation.w])


def compose_tf(transforms, root, frame):
    """Walk a list of TransformStamped from ``frame`` up to ``root``."""
    by_child = {t.child_frame_id: t for t in transforms}
    m = np.eye(4)
    while frame != root:
        t = by_child[frame]
        m = as_matrix(t.transform.translation, t.transform.rotation) @ m
        frame = t.header.frame_id
    return m


def test_stamps_round_trip():
    assert stamp_to_ns(ns_to_stamp(1_234_567_890_123)) == 1_234_567_890_123
    stamp = ns_to_stamp(1_234_567_890_123)
    assert (stamp.sec, stamp.nanosec) == (1234, 567_890_123)


def test_rl15_messages_at_zero_are_fig4_and_tf_composes_to_the_pose():
    model = load_robot_description(shipped_robot_path('rl15'))
    messages = FrameMessages(model)
    stamp = Time(sec=5, nanosec=7)
    absolute, relative = model.chain.frame_poses(np.zeros(6))
    tf, poses = messages.fill(stamp, absolute, relative)
    static = messages.static_tf(stamp)
    ee = poses[-1]
    assert ee.header.frame_id == 'world' and ee.header.stamp == stamp
    p, o = ee.pose.position, ee.pose.orientation
    np.testing.assert_allclose([p.x, p.y, p.z], [1.025, 0, 1.445], atol=1e-12)
    np.testing.assert_allclose([o.x, o.y, o.z, o.w], [0.707107, 0, 0.707107, 0], atol=5e-7)
    pairs = [(t.header.frame_id, t.child_frame_id) for t in static.transforms]
    assert pairs == [('world', 'base_seg0')] + [
        (f, f + '_dh_z') for f in ('shoulder_seg1', 'upperarm_seg2', 'elbow_seg3',
                                   'forearm_seg4', 'wrist_seg5')]  # the URDF's helper links
    assert tf.transforms[-1].header.frame_id == 'wrist_seg5'
    assert tf.transforms[-1].child_frame_id == 'eeCarry_seg6'
    assert len(tf.transforms) == 6 and all(t.header.stamp == stamp for t in tf.transforms)
    np.testing.assert_allclose(compose_tf(static.transforms + tf.transforms, 'world',
                                          'eeCarry_seg6'),
                               as_matrix(p, o), atol=1e-12)


def test_random_configurations_tf_tree_equals_absolute_poses():
    model = load_robot_description(shipped_robot_path('panda'))
    messages = FrameMessages(model, 'left/')
    static = messages.static_tf(Time())
    for q in np.random.default_rng(2).uniform(-2, 2, size=(20, 7)):
        absolute, relative = model.chain.frame_poses(q)
        tf, poses = messages.fill(Time(), absolute, relative)
        expected = homogeneous_from_dq(model.chain.forward_all(q))
        for k, frame_id in enumerate(messages.frame_ids):
            np.testing.assert_allclose(
                compose_tf(static.transforms + tf.transforms, 'world', frame_id), expected[k],
                atol=1e-12)
            np.testing.assert_allclose(as_matrix(poses[k].pose.position,
                                                 poses[k].pose.orientation), expected[k],
                                       atol=1e-12)


def test_frame_prefix_applies_to_every_frame_id_but_the_fixed_frame():
    model = load_robot_description(shipped_robot_path('panda'))
    messages = FrameMessages(model, 'left/')
    tf, _ = messages.fill(Time(), *model.chain.frame_poses(np.zeros(7)))
    static = messages.static_tf(Time())
    ids = {t.child_frame_id for t in tf.transforms + static.transforms}
    ids |= {t.header.frame_id for t in tf.transforms + static.transforms}
    assert ids == {'world'} | {'left/' + n for n in model.frame_names}
    assert [(t.header.frame_id, t.child_frame_id) for t in static.transforms] == [
        ('world', 'left/panda_link0'), ('left/panda_link7', 'left/panda_link8')]


def test_fixed_rows_go_to_tf_static_and_mimic_rows_to_tf():
    model = parse_robot_description(
        'robot: r\nbase: {frame: b}\nchain:\n'
        '  - {frame: l1, joint: j1, theta: 0, d: 0, a: 0.3, alpha: 0}\n'
        '  - {frame: l2, type: fixed, theta: 0.5, d: 0.1, a: 0.2, alpha: 0}\n'
        '  - {frame: l3, theta: 0, d: 0, a: 0.2, alpha: 0, mimic: {joint: j1}}\n')
    messages = FrameMessages(model)
    tf, _ = messages.fill(Time(), *model.chain.frame_poses([0.4]))
    assert [t.child_frame_id for t in tf.transforms] == ['l1', 'l3']
    stamp = Time(sec=7, nanosec=9)
    static = messages.static_tf(stamp).transforms
    assert [(t.header.frame_id, t.child_frame_id) for t in static] == [
        ('world', 'b'), ('l1', 'l2'), ('l1', 'l1_dh_z'), ('l3', 'l3_dh_z')]
    assert all(t.header.stamp == stamp for t in static)


def test_a_cylindrical_rows_moving_helper_goes_on_tf_under_its_dh_frame():
    model = load_robot_description(shipped_robot_path('rrc'))
    messages = FrameMessages(model, 'r/')
    last = messages.tf.transforms[-1]
    assert (last.header.frame_id, last.child_frame_id) == ('r/rrc_link3', 'r/rrc_link3_dh_z0')


def test_an_outputs_qos_is_reliable_its_depth_and_latched_as_transient_local():
    from rclpy.qos import DurabilityPolicy, ReliabilityPolicy
    for latched, durability in ((True, DurabilityPolicy.TRANSIENT_LOCAL),
                                (False, DurabilityPolicy.VOLATILE)):
        qos = qos_profile(SimpleNamespace(latched=latched, depth=3))
        assert (qos.depth, qos.reliability, qos.durability) == \
            (3, ReliabilityPolicy.RELIABLE, durability)


def test_joint_state_fields_are_its_names_positions_velocities_and_stamp_in_ns():
    msg = JointState(name=['a', 'b'], position=[0.5, 1.5], velocity=[2.0, 3.0])
    msg.header.stamp = Time(sec=3, nanosec=5)
    names, positions, velocities, ns = joint_state_fields(msg)
    assert (list(names), list(positions), list(velocities), ns) == \
        (['a', 'b'], [0.5, 1.5], [2.0, 3.0], 3_000_000_005)


TWO_CYLINDRICAL = (
    'robot: cc\nconvention: standard\nbase: {frame: b}\nchain:\n'
    '  - {frame: c1, type: cylindrical, joint: t1, d_joint: d1, theta: 0, d: 0, a: 0.2,'
    ' alpha: 0.3}\n'
    '  - {frame: r2, joint: t2, theta: 0, d: 0.1, a: 0.3, alpha: 0}\n'
    '  - {frame: c3, type: cylindrical, joint: t3, d_joint: d3, theta: 0, d: 0, a: 0.1,'
    ' alpha: -0.4}\n')


def test_two_moving_helpers_are_written_alike_by_every_path():
    """Two cylindrical rows: two helper frames on /tf, as the message objects have them."""
    model = parse_robot_description(TWO_CYLINDRICAL)
    messages = FrameMessages(model, 'p/')
    raw = FrameBytes(messages)
    assert raw.sends_tf is True and len(messages.helpers.moving) == 2
    for q in ([0.3, 0.1, -0.7, 0.5, 0.05], [1, 0, 2, -1, 0]):   # plain ints too
        absolute, relative = model.frame_pose_arrays(np.asarray(q, dtype=float))
        tf, _ = messages.fill(Time(sec=4, nanosec=2), absolute.tolist(), relative.tolist(), q)
        children = [t.child_frame_id for t in tf.transforms]
        assert children[-2:] == ['p/c1_dh_z0', 'p/c3_dh_z0']
        for ours in (raw.tf(4, 2, relative, q), raw.tf(4, 2, relative.tolist(), q),
                     raw.tf_writer()(4, 2, relative, q)):
            assert deserialize_message(ours, TFMessage) == tf


def test_a_robot_with_nothing_moving_sends_no_tf():
    model = parse_robot_description(
        'robot: still\nbase: {frame: b}\nchain:\n'
        '  - {frame: l1, type: fixed, theta: 0.5, d: 0.1, a: 0.2, alpha: 0}\n')
    assert FrameBytes(FrameMessages(model)).sends_tf is False
    rl15 = load_robot_description(shipped_robot_path('rl15'))
    assert FrameBytes(FrameMessages(rl15)).sends_tf is True
