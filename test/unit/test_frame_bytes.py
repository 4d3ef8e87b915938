"""The node's serialized output equals the message objects it replaces, field by field."""

import os
import sys

from builtin_interfaces.msg import Time
from dq_fk_ros.description.schema import load_robot_description
from dq_fk_ros.description.shipped import shipped_robot_path, shipped_robots
from dq_fk_ros.messages.cdr import COMPILED
from dq_fk_ros.messages.cdr_templates import pose_stamped_template, tf_message_template
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


@pytest.mark.parametrize('robot', shipped_robots() + ['ur5.urdf', 'panda.urdf'])
@pytest.mark.parametrize('prefix', ['', 'left/'])
def test_serialized_output_equals_the_message_objects(robot, prefix):
    model = robot_model(robot)
    objects = FrameMessages(model, prefix, model.optional_joints)  # every branch shown
    raw = FrameBytes(objects)
    rng = np.random.default_rng(len(robot) + len(prefix))
    for sec, nanosec in STAMPS:
        q = rng.uniform(-2, 2, model.dof)
        absolute, relative = model.frame_poses(q)
        stamp = Time(sec=sec, nanosec=nanosec)
        tf, poses = objects.fill(stamp, absolute, relative, q)
        ours = raw.tf(sec, nanosec, relative, q)
        assert deserialize_message(ours, TFMessage) == tf  # every field
        same_outside_padding(ours, serialize_message(tf), raw.templates['tf'])
        every = list(range(len(absolute)))
        assert raw.poses(sec, nanosec, absolute, every) == \
            [raw.pose(sec, nanosec, pose) for pose in absolute]
        assert raw.poses(sec, nanosec, absolute, every[1::2]) == \
            [raw.pose(sec, nanosec, pose) for pose in absolute[1::2]]
        for msg, pose in zip(poses, absolute):
            ours = raw.pose(sec, nanosec, pose)
            assert deserialize_message(ours, PoseStamped) == msg
            same_outside_padding(ours, serialize_message(msg), raw.templates['pose'])
        v, w = rng.normal(size=3), rng.normal(size=3)
        (twist,) = objects.fill_twists(stamp, [(v, w)])[:1]
        ours = raw.twist(sec, nanosec, v.tolist(), w.tolist())
        assert deserialize_message(ours, TwistStamped) == twist
        same_outside_padding(ours, serialize_message(twist), raw.templates['twist'])


@pytest.mark.skipif(COMPILED is None, reason='the struct packer alone is active')
@pytest.mark.parametrize('robot', shipped_robots() + ['ur5.urdf', 'panda.urdf'])
def test_the_c_writer_equals_the_packer_byte_for_byte(robot):
    model = robot_model(robot)
    raw = FrameBytes(FrameMessages(model, 'left/', model.optional_joints))
    assert raw._tf_c is not None and raw._pose_c is not None
    rng = np.random.default_rng(len(robot))
    odd = [0.0, -0.0, np.nan, np.inf, -np.inf, 1e308, 5e-324]
    every = list(range(len(model.frame_names)))
    for sec, nanosec in STAMPS + [(-2**31, 2**32 - 1)]:
        q = rng.uniform(-2, 2, model.dof)
        absolute, relative = model.frame_pose_arrays(q)
        absolute[0, :len(odd)] = odd  # every bit pattern is copied as it is
        assert raw.tf(sec, nanosec, relative, q) == \
            raw.tf(sec, nanosec, relative.tolist(), q)
        assert raw.poses(sec, nanosec, absolute, every) == \
            raw.poses(sec, nanosec, absolute.tolist(), every)
        assert raw.poses(sec, nanosec, absolute, every[::-2]) == \
            [raw.pose(sec, nanosec, pose) for pose in absolute.tolist()[::-2]]


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
