"""The node's serialized output equals the message objects it replaces, field by field."""

import os
import sys

from builtin_interfaces.msg import Time
from dq_fk_ros.description.schema import load_robot_description
from dq_fk_ros.description.shipped import shipped_robot_path, shipped_robots
from dq_fk_ros.messages.cdr import COMPILED
from dq_fk_ros.messages.cdr_templates import pose_stamped_template, tf_message_template
from dq_fk_ros.messages.frame_streams import FrameStream
from dq_fk_ros.messages.outputs import POSE, TWIST
from dq_fk_ros.ros.conversions import FrameBytes, FrameMessages
from geometry_msgs.msg import PoseStamped, TwistStamped
import numpy as np
import pytest
from rclpy.serialization import deserialize_message, serialize_message
from tf2_msgs.msg import TFMessage

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
from vendor_urdfs import PANDA, UR5, vendor_robot  # noqa: E402, I100 (the tests' helper)

STAMPS = [(0, 0), (1, 999_999_999), (1_800_000_000, 123_456_789), (2**31 - 1, 5)]


def same_outside_padding(ours, theirs, template):
    """Equal bytes except alignment padding, which rclpy leaves unset (ours is zero)."""
    assert len(ours) == len(theirs)
    padding = set(template.padding)
    assert all(ours[k] == 0 for k in padding)
    differ = [k for k in range(len(ours)) if ours[k] != theirs[k] and k not in padding]
    assert differ == [], differ[:10]


def robot_model(robot):
    """Load a shipped robot, or a vendor URDF converted (URDF links, a mimic finger)."""
    vendor = {'ur5.urdf': UR5, 'panda.urdf': PANDA}
    if robot in vendor:
        return vendor_robot(vendor[robot]).model
    return load_robot_description(shipped_robot_path(robot))


def every_frame_streams(plan, compiled=True):
    """Return the pose stream of every frame (as FrameMessages.poses) and the twist stream."""
    poses = FrameStream(POSE, plan, range(len(plan.frame_ids)), compiled)
    return poses, FrameStream(TWIST, plan, None, compiled)


@pytest.mark.parametrize('robot', shipped_robots() + ['ur5.urdf', 'panda.urdf'])
@pytest.mark.parametrize('prefix', ['', 'left/'])
def test_serialized_output_equals_the_message_objects(robot, prefix):
    model = robot_model(robot)
    objects = FrameMessages(model, prefix, model.optional_joints)  # every branch shown
    raw = FrameBytes(objects)
    pose_stream, twist_stream = every_frame_streams(objects.plan)
    rng = np.random.default_rng(len(robot) + len(prefix))
    for sec, nanosec in STAMPS:
        q = rng.uniform(-2, 2, model.dof)
        qdot = rng.normal(size=model.dof)
        absolute, relative = model.frame_poses(q)
        stamp = Time(sec=sec, nanosec=nanosec)
        tf, poses = objects.fill(stamp, absolute, relative, q)
        ours = raw.tf(sec, nanosec, relative, q)
        assert deserialize_message(ours, TFMessage) == tf  # every field
        same_outside_padding(ours, serialize_message(tf), raw.template)
        batch = np.array(absolute)[None]
        array, columns, rows = pose_stream.values(q[None], None, batch)
        every = list(range(len(absolute)))
        ours = pose_stream.serialize(sec, nanosec, array[0], columns, every)
        assert rows is None and len(ours) == len(poses)
        for data, msg, template in zip(ours, poses, pose_stream.templates):
            assert deserialize_message(data, PoseStamped) == msg
            same_outside_padding(data, serialize_message(msg), template)
        assert pose_stream.serialize(sec, nanosec, array[0], columns, every[1::2]) == ours[1::2]
        got = twist_stream.values(q[None], qdot[None], batch)
        if not twist_stream.frames:
            continue
        array, columns, rows = got
        picked = list(range(len(twist_stream.frames)))
        ours = twist_stream.serialize(sec, nanosec, array[0], columns, picked)
        twists = objects.fill_twists(stamp, [(t[:3], t[3:]) for t in array[0]])
        for data, msg, template in zip(ours, twists, twist_stream.templates):
            assert deserialize_message(data, TwistStamped) == msg
            same_outside_padding(data, serialize_message(msg), template)


@pytest.mark.skipif(COMPILED is None, reason='the struct packer alone is active')
@pytest.mark.parametrize('robot', shipped_robots() + ['ur5.urdf', 'panda.urdf'])
def test_the_c_writer_equals_the_packer_byte_for_byte(robot):
    model = robot_model(robot)
    raw = FrameBytes(FrameMessages(model, 'left/', model.optional_joints))
    assert raw._tf_c is not None
    compiled = every_frame_streams(raw.plan)
    packed = every_frame_streams(raw.plan, compiled=False)
    assert all(w[1] is not None for s in compiled for w in s._writers)
    rng = np.random.default_rng(len(robot))
    odd = [0.0, -0.0, np.nan, np.inf, -np.inf, 1e308, 5e-324]
    for sec, nanosec in STAMPS + [(-2**31, 2**32 - 1)]:
        q = rng.uniform(-2, 2, model.dof)
        absolute, relative = model.frame_pose_arrays(q)
        absolute[0, :len(odd)] = odd  # every bit pattern is copied as it is
        assert raw.tf(sec, nanosec, relative, q) == \
            raw.tf(sec, nanosec, relative.tolist(), q) == \
            raw.tf_writer()(sec, nanosec, relative, q)   # the node's
        for fast, reference in zip(compiled, packed):
            got = fast.values(q[None], rng.normal(size=(1, model.dof)), absolute[None])
            if got is None or not fast.frames:
                continue
            array, columns, _ = got
            every = list(range(len(fast.frames)))
            for picked in (every, every[::-2]):
                assert fast.serialize(sec, nanosec, array[0], columns, picked) == \
                    reference.serialize(sec, nanosec, array[0], columns, picked)
                direct = fast.direct_writer()   # the node's pose rows, straight to C
                if direct is not None:
                    assert direct(sec, nanosec, absolute, [fast.frames[i] for i in picked]) \
                        == reference.serialize(sec, nanosec, array[0], columns, picked)


@pytest.mark.skipif(COMPILED is None, reason='the struct packer alone is active')
def test_the_c_writer_refuses_what_it_cannot_write():
    from dq_fk_ros.messages import _cdr
    template = pose_stamped_template('world')
    writer = template.compiled(7)
    values = np.zeros((3, 7))
    assert len(writer.one(1, 2, values, [2])) == len(template.buf)
    for args in ((2**31, 0, values, [0]), (0, -1, values, [0]), (0, 2**32, values, [0]),
                 (0, 0, values, [3]), (0, 0, values, [-1]), (0, 0, values, [0, 1]),
                 (0, 0, values[:, :6].copy(), [0]), (0, 0, values.astype(np.float32), [0]),
                 (0, 0, np.zeros((3, 14))[:, ::2], [0]), (0, 0, values, ['x']),
                 (0, 0, values, 5), ('x', 0, values, [0])):
        with pytest.raises((ValueError, TypeError, IndexError, OverflowError)):
            writer.one(*args)
    with pytest.raises((ValueError, IndexError)):
        writer.each(0, 0, values, [0, 3])
    tf = tf_message_template([('a', 'b'), ('a', 'c')]).compiled(7)
    with pytest.raises(ValueError, match='one slot'):
        tf.each(0, 0, values, [0])
    assert template.compiled(6) is None  # runs of 7 floats: not a writer of 6
    buf = bytes(template.buf)
    for args in ((b'\x01\x00' + buf[2:], [4], [24], 7),       # big-endian CDR
                 (buf, [len(buf) - 4], [24], 7),             # a stamp past the end
                 (buf, [4], [len(buf) - 8], 7),              # a slot past the end
                 (buf, [0], [24], 7), (buf, [4], [24], 0), (buf, [4], ['x'], 7)):
        with pytest.raises((ValueError, TypeError)):
            _cdr.Template(*args)
    with pytest.raises(TypeError):
        _cdr.Template.__new__(_cdr.Template)  # nothing without arguments
    with pytest.raises(TypeError, match='set once'):
        writer.__init__(b'\x00\x01\x00\x00', [], [], 1)
    assert len(writer.one(1, 2, values, [2])) == len(template.buf)
