"""What the node and the bag tool put on TF and the pose topics (OutputPlan), without ROS."""

import os
import sys

from dq_fk_ros.description.loading import robot_from_urdf_text
from dq_fk_ros.description.schema import load_robot_description
from dq_fk_ros.description.shipped import shipped_robot_path
from dq_fk_ros.messages.frame_streams import FrameStream
from dq_fk_ros.messages.output_plan import OutputPlan
from dq_fk_ros.messages.outputs import POSE
from dq_fk_ros.ros.conversions import FrameMessages
from geometry_msgs.msg import PoseStamped
import numpy as np
import pytest
from rclpy.serialization import deserialize_message

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
import pinocchio_oracle as oracle  # noqa: E402, I100 (the tests' helpers)
from vendor_urdfs import UR5, vendor_path  # noqa: E402

# an arm on a base that a floating joint carries, a camera on a planar mount, and a second
# floating joint mid-arm with a wrist below it
ROBOT = """<robot name="carried">
  <link name="odom"/><link name="base"/><link name="l1"/><link name="l2"/><link name="cam"/>
  <link name="tool"/><link name="wrist"/><link name="flange"/>
  <joint name="carry" type="floating"><parent link="odom"/><child link="base"/>
    <origin xyz="1 2 3" rpy="0.1 0.2 0.3"/></joint>
  <joint name="j1" type="revolute"><parent link="base"/><child link="l1"/>
    <origin xyz="0 0 0.3"/><axis xyz="0 0 1"/>
    <limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
  <joint name="j2" type="revolute"><parent link="l1"/><child link="l2"/>
    <origin xyz="0 0.1 0.4" rpy="1.5707963 0 0"/><axis xyz="0 0 1"/>
    <limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
  <joint name="mount" type="planar"><parent link="base"/><child link="cam"/>
    <origin xyz="0.2 0 0.1"/><axis xyz="0 0 1"/></joint>
  <joint name="loose" type="floating"><parent link="l2"/><child link="tool"/>
    <origin xyz="0 0 0.2"/></joint>
  <joint name="j3" type="continuous"><parent link="tool"/><child link="wrist"/>
    <origin xyz="0.05 0 0.1" rpy="0 0.4 0"/><axis xyz="1 0 0"/></joint>
  <joint name="bolt" type="fixed"><parent link="wrist"/><child link="flange"/>
    <origin xyz="0 0 0.02"/></joint>
</robot>"""


def edges(plan, pairs):
    return {(plan.parent_ids[k], plan.frame_ids[k]) for k in pairs}


def test_a_urdf_plan_is_robot_state_publishers_tree_and_dh_frames_come_back_on_demand():
    model = robot_from_urdf_text(ROBOT, 'carried.urdf').model
    assert not model.publish_dh_frames  # the converted YAML's default
    plan = OutputPlan(model)
    assert edges(plan, [k for k, _ in plan.moving_edges]) == {
        ('base', 'l1'), ('l1', 'l2'), ('tool', 'wrist')}
    assert set(plan.static_edges) == {('base', 'cam'), ('wrist', 'flange')}
    assert plan.helpers.static == [] and plan.helpers.moving == []
    names = [model.frame_names[k] for k in plan.pose_frames]
    assert sorted(names) == ['cam', 'flange', 'l1', 'l2', 'wrist']
    assert {model.frame_names[k]: plan.pose_frame_ids[k] for k in plan.pose_frames} == {
        'l1': 'base', 'l2': 'base', 'cam': 'base', 'wrist': 'tool', 'flange': 'tool'}
    debug = OutputPlan(model, 'r/', dh_frames=True)
    assert {p for p, _ in debug.static_edges} >= {'r/odom'}  # the first chain's frame 0
    assert any(c.endswith('dh1') for _, c in debug.tf_edges(debug.moving_edges))
    assert ('r/odom', 'r/base') not in debug.static_edges  # never a floating edge


def test_a_dh_file_keeps_its_frames_on_tf():
    model = load_robot_description(shipped_robot_path('rl15'))
    plan = OutputPlan(model)
    assert plan.dh_frames and plan.tf_frames == tuple(range(len(model.frame_names)))
    off = OutputPlan(model, dh_frames=False)
    assert off.tf_frames == () and off.static_edges == [] and off.moving_edges == ()


def test_poses_below_a_floating_joint_are_in_its_child_as_pinocchio_has_them():
    model = robot_from_urdf_text(ROBOT, 'carried.urdf').model
    messages = FrameMessages(model)
    stream = FrameStream(POSE, messages.plan)
    assert not stream.uniform  # two roots: a layout each
    packed = FrameStream(POSE, messages.plan, compiled=False)
    pin_model = oracle.urdf_model(ROBOT)
    q = np.array([0.4, -0.7, 1.1])
    values = dict(zip(model.joint_names, q))
    placements = oracle.link_placements(pin_model, oracle.configuration(pin_model, values),
                                        list(model.frame_names[model.n_dh_frames:]))
    absolute, _ = model.frame_pose_arrays(q)
    frames = list(messages.plan.pose_frames)
    array, columns, _ = stream.values(q[None], None, absolute[None])
    every = list(range(len(frames)))
    serialized = stream.serialize(1, 2, array[0], columns, every)
    assert serialized == packed.serialize(1, 2, array[0], columns, every)  # C and packer
    for k, data in zip(frames, serialized):
        msg = deserialize_message(data, PoseStamped)
        name, root = model.frame_names[k], msg.header.frame_id
        expected = np.linalg.inv(placements[root]) @ placements[name]
        p, o = msg.pose.position, msg.pose.orientation
        x, y, z, w = o.x, o.y, o.z, o.w
        rotation = np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                             [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                             [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])
        np.testing.assert_allclose([p.x, p.y, p.z], expected[:3, 3], atol=1e-9, err_msg=name)
        np.testing.assert_allclose(rotation, expected[:3, :3], atol=1e-9, err_msg=name)
    # the message objects (the reference) say the same
    _, poses = messages.fill(None, absolute, model.frame_pose_arrays(q)[1])
    for k, data in zip(frames, serialized):
        msg = deserialize_message(data, PoseStamped)
        assert msg.header.frame_id == poses[k].header.frame_id
        assert msg.pose == poses[k].pose


@pytest.mark.parametrize('dh_frames', [None, True])
def test_the_ur5_twist_frame_is_on_tf(dh_frames):
    model = robot_from_urdf_text(open(vendor_path(UR5)).read(), 'ur5', tip=UR5[1]).model
    plan = OutputPlan(model, dh_frames=dh_frames)
    names = [model.frame_names[k] for k in plan.twist_frames]
    assert names == (['tool0'] if dh_frames is None else ['dh6', 'tool0'])


@pytest.mark.parametrize('given_plan', [False, True])
def test_the_message_objects_below_a_floating_joint_are_the_serialized_poses(given_plan):
    """FrameMessages.fill (the reference) puts rooted frames in their root, as the bytes do."""
    from builtin_interfaces.msg import Time
    model = robot_from_urdf_text(ROBOT, 'carried.urdf').model
    plan = OutputPlan(model, 'r/', dh_frames=True) if given_plan else None
    messages = FrameMessages(model, 'r/', plan=plan, dh_frames=True)
    assert messages.model is model and (messages.plan is plan or not given_plan)
    stream = FrameStream(POSE, messages.plan)
    q = np.array([0.4, -0.7, 1.1])
    absolute, relative = model.frame_poses(q)
    _, poses = messages.fill(Time(sec=1, nanosec=2), absolute, relative, q)
    frames = list(messages.plan.pose_frames)
    array, columns, _ = stream.values(q[None], None, np.array(absolute)[None])
    serialized = stream.serialize(1, 2, array[0], columns, list(range(len(frames))))
    assert len(poses) == len(model.frame_names) and len(serialized) == len(frames)
    roots = {poses[k].header.frame_id for k in frames}
    assert {'r/base', 'r/tool'} <= roots   # two floating joints: two roots besides the fixed
    for k, data in zip(frames, serialized):
        assert poses[k] == deserialize_message(data, PoseStamped), model.frame_names[k]


def test_the_dh_frames_choice_reaches_the_plan():
    model = robot_from_urdf_text(ROBOT, 'carried.urdf').model   # a URDF: none by default
    assert not FrameMessages(model).plan.dh_frames
    assert FrameMessages(model, dh_frames=True).plan.dh_frames
    assert not FrameMessages(model, dh_frames=False).plan.dh_frames
