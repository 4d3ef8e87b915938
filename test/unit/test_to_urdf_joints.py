"""The URDF joints a DH robot is written as: names, kinds, limits, helpers, one by one."""

import math
import xml.etree.ElementTree as ElementTree

from dq_fk_ros.description.schema import parse_robot_description
from dq_fk_ros.description.to_urdf import (
    HelperFrames, link_poses, link_segments, matrix_to_rpy, NO_LIMIT_SPEED, NO_LIMIT_STROKE_M,
    robot_to_urdf, UrdfJoint)
from dq_fk_ros.kinematics.dual_quaternion import DualQuaternion
import numpy as np
import pytest

ROBOT = """
robot: r
convention: standard
units: {length: m, angle: rad}
fixed_frame: world
base: {frame: b0, xyz: [0, 0, 0.1]}
chain:
  - {frame: l1, joint: j1, type: revolute, theta: 0, d: 0.2, a: 0.3, alpha: 0, limits: [-1, 2]}
  - {frame: l2, joint: j2, type: revolute, theta: 0, d: 0, a: 1e-10, alpha: 0}
  - {frame: l3, joint: j3, type: revolute, theta: 0, d: 0, a: 0, alpha: 0}
tool: {frame: tcp, xyz: [0, 0, 0.05]}
links:
  - {frame: grip, parent: l3, type: revolute, joint: g, limits: [-1, 2]}
  - {frame: free, parent: l3, type: revolute, joint: f}
  - {frame: slide, parent: l3, type: prismatic, mimic: {joint: j1}}
  - {frame: spin, parent: l3, type: revolute, mimic: {joint: j1}}
"""


@pytest.fixture(scope='module')
def robot():
    model = parse_robot_description(ROBOT, 'r.yaml')
    return model, robot_to_urdf(model)


def joints_of(text):
    """Return ``{name: (type, parent, child, limit attributes or None)}`` of a URDF text."""
    out = {}
    for j in ElementTree.fromstring(text).findall('joint'):
        limit = j.find('limit')
        out[j.get('name')] = (j.get('type'), j.find('parent').get('link'),
                              j.find('child').get('link'),
                              None if limit is None else {k: float(v)
                                                          for k, v in limit.attrib.items()})
    return out


def test_each_joint_is_named_and_typed_as_its_row_or_link(robot):
    speed = NO_LIMIT_SPEED
    bounded = {'lower': -1.0, 'upper': 2.0, 'effort': speed, 'velocity': speed}
    assert joints_of(robot[1]) == {
        'b0_fixed': ('fixed', 'world', 'b0', None),   # the base: its frame's name
        'j1': ('revolute', 'b0', 'l1_dh_z', bounded),
        'l1_dh_x': ('fixed', 'l1_dh_z', 'l1', None),   # a (0.3 m) after the motion
        'j2': ('continuous', 'l1', 'l2_dh_z', None),   # no limits: continuous
        'l2_dh_x': ('fixed', 'l2_dh_z', 'l2', None),   # a of 1e-10 m is an offset too
        'j3': ('continuous', 'l2', 'l3', None),
        'tcp_fixed': ('fixed', 'l3', 'tcp', None),   # the tool: its frame's name
        'g': ('revolute', 'l3', 'grip', bounded),   # no max_velocity: "none given"
        'f': ('continuous', 'l3', 'free', None),
        'slide_joint': ('prismatic', 'l3', 'slide', {'lower': -NO_LIMIT_STROKE_M,
                                                     'upper': NO_LIMIT_STROKE_M,
                                                     'effort': speed, 'velocity': speed}),
        'spin_joint': ('continuous', 'l3', 'spin', None),
    }
    assert robot[1].count('<!--') == 1   # the header's; no note on a joint that needs none


def test_a_bounded_rows_helper_link_is_a_static_frame_under_its_dh_frame(robot):
    helpers = HelperFrames(robot[0])
    assert [(name, robot[0].frame_names[k]) for name, k, _ in helpers.static] == [
        ('l1_dh_z', 'l1'), ('l2_dh_z', 'l2')]
    pose = {name: offset for name, _, offset in helpers.static}['l1_dh_z']
    assert pose.isclose(DualQuaternion.from_translation([-0.3, 0.0, 0.0]), atol=1e-12)


def test_poses_and_segments_follow_the_joints_given(robot):
    model = robot[0]
    joints = [UrdfJoint('near', 'fixed', 'world', 'a', DualQuaternion.from_translation(
                  [1e-9, 0.0, 0.0])),   # at the bound: no segment drawn
              UrdfJoint('far', 'fixed', 'a', 'b', DualQuaternion.from_translation(
                  [0.0, 2.0, 0.0]))]
    poses = link_poses(model, np.zeros(model.dof), joints)
    assert sorted(poses) == ['a', 'b', 'world']
    np.testing.assert_allclose(poses['b'].translation, [1e-9, 2.0, 0.0], atol=1e-15)
    segments = link_segments(model, np.zeros(model.dof), joints)
    assert len(segments) == 1
    np.testing.assert_allclose(np.array(segments[0]), [[1e-9, 0, 0], [1e-9, 2.0, 0]],
                               atol=1e-15)


def test_roll_is_kept_when_yaw_makes_the_first_column_point_along_y():
    yaw, roll = math.pi / 2, 0.3
    rz = np.array([[math.cos(yaw), -math.sin(yaw), 0], [math.sin(yaw), math.cos(yaw), 0],
                   [0, 0, 1]])
    rx = np.array([[1, 0, 0], [0, math.cos(roll), -math.sin(roll)],
                   [0, math.sin(roll), math.cos(roll)]])
    np.testing.assert_allclose(matrix_to_rpy(rz @ rx), (roll, 0.0, yaw), atol=1e-12)
