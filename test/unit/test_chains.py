"""A robot as a tree of DH chains: ``chains:`` in the YAML, the whole tree's poses and TF."""

import math
import os
import sys

from dq_fk_ros.description.from_urdf import urdf_to_description
from dq_fk_ros.description.schema import load_robot_description, parse_robot_description
from dq_fk_ros.description.shipped import shipped_robot_path
from dq_fk_ros.description.to_urdf import robot_to_urdf
from dq_fk_ros.errors import RobotDescriptionError
from dq_fk_ros.kinematics.dh import homogeneous_from_dq
from dq_fk_ros.ros.conversions import FrameMessages
import homogeneous as hm
import numpy as np
import pytest
from same_frames import assert_same_frames

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
import pinocchio_oracle  # noqa: E402, I100 (the tests' helper)

DEG = math.pi / 180.0


def dual_arm():
    return load_robot_description(shipped_robot_path('dual_arm'))


def expected_dual_arm(q):
    """
    Every frame of config/dual_arm.yaml at ``q``, from its numbers by 4x4 matrices.

    Written from the file's rows with the textbook standard DH matrix, independently of
    the package's dual quaternions.
    """
    waist, l1, l2, l3, r1, r2, r3, grip = q
    f = {'world': np.eye(4)}
    f['pedestal'] = hm.trans(z=0.8)
    f['torso'] = f['pedestal'] @ hm.dh_standard(waist, 0.4, 0.0, 0.0)
    for side, sign, (j1, j2, j3) in (('left', 1.0, (l1, l2, l3)),
                                     ('right', -1.0, (r1, r2, r3))):
        f[f'{side}_shoulder'] = f['torso'] @ hm.trans(y=0.25 * sign) @ hm.rot_x(-sign * 90 * DEG)
        f[f'{side}_upper_arm'] = f[f'{side}_shoulder'] @ hm.dh_standard(j1, 0, 0.3, 0)
        f[f'{side}_forearm'] = f[f'{side}_upper_arm'] @ hm.dh_standard(
            j2, 0, 0.25, sign * 90 * DEG)
        f[f'{side}_wrist'] = f[f'{side}_forearm'] @ hm.dh_standard(j3, 0.08, 0, 0)
        f[f'{side}_tcp'] = f[f'{side}_wrist'] @ hm.trans(z=0.05)
    f['left_finger_base'] = f['left_tcp'] @ hm.rot_y(90 * DEG)
    f['left_finger_a'] = f['left_finger_base'] @ hm.dh_standard(0, 0.01 + grip, 0, 0)
    f['left_finger_b_base'] = f['left_tcp'] @ hm.rot_y(-90 * DEG)
    f['left_finger_b'] = f['left_finger_b_base'] @ hm.dh_standard(0, 0.01 + grip, 0, 0)
    f['head_camera'] = f['torso'] @ hm.trans(0.1, 0, 0.3) @ hm.rot_y(20 * DEG)
    return f


def configurations(model, count, seed=0):
    rng = np.random.default_rng(seed)
    limits = np.where(np.isfinite(model.limits), model.limits,
                      np.sign(model.limits) * math.pi)
    return rng.uniform(limits[:, 0], limits[:, 1], size=(count, model.dof))


def test_the_two_arm_example_is_a_tree_posed_as_its_numbers_say():
    model = dual_arm()
    assert model.joint_names == ('waist', 'left_shoulder_pitch', 'left_elbow',
                                 'left_wrist_roll', 'right_shoulder_pitch', 'right_elbow',
                                 'right_wrist_roll', 'left_gripper')
    assert [b.parent for b in model.branches] == ['torso', 'torso', 'left_tcp', 'left_tcp']
    assert model.branches[3].external == ('left_gripper',)  # the mimic finger
    assert model.required_joints == () and model.optional_joints == model.joint_names
    qs = configurations(model, 200)
    batch = homogeneous_from_dq(model.forward_all_batch(qs))
    for q, frames in zip(qs, batch):
        want = expected_dual_arm(q)
        absolute, relative = model.frame_poses(q)
        for k, name in enumerate(model.frame_names):
            np.testing.assert_allclose(frames[k], want[name], atol=1e-12, err_msg=name)
            np.testing.assert_allclose(hm.matrix_of_pose(absolute[k][:3], absolute[k][3:]),
                                       want[name], atol=1e-12, err_msg=name)
        # every TF transform is the child in its TF parent
        for k, r in model.moving_edges:
            parent = model.parent_frames[k]
            np.testing.assert_allclose(
                hm.matrix_of_pose(relative[r][:3], relative[r][3:]),
                np.linalg.inv(want[parent]) @ want[model.frame_names[k]], atol=1e-12)
    for k, pose in model.static_transforms():
        name, parent = model.frame_names[k], model.parent_frames[k]
        np.testing.assert_allclose(hm.matrix_of_pose(pose[:3], pose[3:]),
                                   np.linalg.inv(want[parent]) @ want[name], atol=1e-12)


def test_the_straight_line_code_of_a_tree_is_the_general_path_to_the_bit():
    model = dual_arm()
    for q in configurations(model, 50, seed=1):
        assert model.frame_poses(q) == model.frame_poses_general(q)
        assert model.transform_poses(q) == model.frame_poses_general(q)[1]
    relative = model.relative_batch(configurations(model, 5, seed=2))
    assert relative.shape == (5, 9 + 1, 8)  # the rows, then the link


def test_each_transform_needs_only_the_joints_between_its_frames():
    model = dual_arm()
    needs = dict(zip(model.frame_names, model.edge_needs))
    assert needs['torso'] == {'waist'} and needs['left_forearm'] == {'left_elbow'}
    assert needs['left_finger_b'] == {'left_gripper'} and needs['left_shoulder'] == set()
    poses = dict(zip(model.frame_names, model.frame_needs))
    assert poses['left_finger_b'] == {'waist', 'left_shoulder_pitch', 'left_elbow',
                                      'left_wrist_roll', 'left_gripper'}
    # an arm's joints alone: its rows on TF, nothing of the torso, the other arm, the gripper
    shown = FrameMessages(model, '', ('left_shoulder_pitch', 'left_elbow', 'left_wrist_roll'))
    assert [t.child_frame_id for t in shown.tf.transforms] == [
        'left_upper_arm', 'left_forearm', 'left_wrist']
    assert 'left_tcp' in [model.frame_names[k] for k in shown.hidden]  # its pose needs waist


def test_a_tree_goes_to_urdf_and_back_to_1e_12_and_agrees_with_pinocchio():
    model = dual_arm()
    urdf = robot_to_urdf(model)
    again = parse_robot_description(urdf_to_description(urdf, 'dual_arm.urdf').text)
    qs = configurations(model, 200, seed=3)
    before = assert_same_frames(model, again, qs, atol=1e-12)
    # pinocchio reads the URDF written from the tree (the mimic finger given its value)
    oracle = pinocchio_oracle.urdf_model(urdf, mimic=False)
    for q, frames in zip(qs[:20], before):
        values = dict(zip(model.joint_names, q.tolist()))
        values['left_finger_b_joint'] = values['left_gripper']
        placements = pinocchio_oracle.link_placements(
            oracle, pinocchio_oracle.configuration(oracle, values), list(model.frame_names))
        for k, name in enumerate(model.frame_names):
            np.testing.assert_allclose(frames[k], placements[name], atol=1e-12, err_msg=name)


TREE = """
robot: t
chains:
  - parent: world
    base: {frame: b0}
    chain:
      - {frame: f1, joint: j1, theta: 0, d: 0.1, a: 0.2, alpha: 0}
  - parent: f1
    base: {frame: c0}
    chain:
      - {frame: c1, joint: k1, theta: 0, d: 0, a: 0.1, alpha: 0}
"""


@pytest.mark.parametrize('change, message', [
    (('parent: f1', 'parent: nowhere'),
     "t.yaml: chains[1]: field 'parent' names 'nowhere', which is not the fixed frame or a "
     'frame of an earlier chain; frames so far: world, b0, f1'),
    (('parent: world', 'parent: f1'),
     "t.yaml: chains[0]: field 'parent' of the first chain must be the fixed frame 'world', "
     "got 'f1'"),
    (('robot: t', 'robot: t\nbase: {frame: x}'),
     "t.yaml: field 'base' goes inside an entry of 'chains' when the file has 'chains' (give "
     'either chains, or base and chain)'),
    (('frame: c1', 'frame: f1'),
     "t.yaml: chains[1].chain[0] (frame 'f1'): frame 'f1' is already used by chains[0].chain[0] "
     "(frame 'f1'); frame names must be unique"),
    (('joint: k1', 'joint: j1'),
     "t.yaml: chains[1].chain[0] (frame 'c1'): joint 'j1' is already read by chains[0].chain[0] "
     "(frame 'f1'); joint names must be unique"),
    (('joint: j1,', 'mimic: {joint: k1},'),
     "t.yaml: chains[0].chain[0] (frame 'f1') mimic: field 'joint' names 'k1', a joint of "
     "another chain; the first chain's rows mimic its own joints"),
    (('chains:', 'chains: []\nx:'), None),
])
def test_mistakes_in_chains_are_one_line(change, message):
    text = TREE.replace(*change)
    with pytest.raises(RobotDescriptionError) as caught:
        parse_robot_description(text, 't.yaml')
    assert '\n' not in str(caught.value)
    if message is not None:
        assert str(caught.value) == message


def test_one_chain_written_as_chains_means_the_same_as_base_and_chain():
    flat = load_robot_description(shipped_robot_path('rl15'))
    text = open(shipped_robot_path('rl15')).read()
    nested = text.replace('base:', 'chains:\n  - parent: world\n    base:').replace(
        '\nchain:', '\n    chain:').replace('\n  - {frame', '\n      - {frame').replace(
        '\ntool:', '\n    tool:')
    model = parse_robot_description(nested, 'nested.yaml')
    assert model.frame_names == flat.frame_names and model.required_joints == flat.joint_names
    q = configurations(flat, 1)[0]
    assert model.frame_poses(q) == flat.frame_poses(q)
