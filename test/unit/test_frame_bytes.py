"""The node's serialized output equals the message objects it replaces, field by field."""

import os
import sys

from builtin_interfaces.msg import Time
from dq_fk_ros.description.schema import load_robot_description
from dq_fk_ros.description.shipped import shipped_robot_path, shipped_robots
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
