"""``links:``: named frames fixed to the chain (or moving with one of its joints)."""

import math
import os
import sys

from builtin_interfaces.msg import Time
from dq_fk_ros.description.schema import parse_robot_description
from dq_fk_ros.description.to_urdf import link_poses, urdf_joints
from dq_fk_ros.errors import RobotDescriptionError
from dq_fk_ros.kinematics.dh import homogeneous_from_dq
from dq_fk_ros.ros.conversions import FrameMessages
import homogeneous as hm
import numpy as np
import pytest

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
from vendor_urdfs import PANDA, UR5, vendor_robot, Z1  # noqa: E402, I100 (the tests' helper)

ARM = """
robot: two_link
units: {length: mm, angle: deg}
base: {frame: base0, xyz: [0, 0, 100]}
chain:
  - {frame: upper, joint: j1, theta: 0, d: 0, a: 300, alpha: 90}
  - {frame: lower, joint: j2, theta: 0, d: 0, a: 200, alpha: 0}
tool: {frame: tcp, xyz: [0, 0, 50]}
links:
  - {frame: flange, parent: tcp, xyz: [0, 0, 10], rpy: [0, 90, 0]}
  - {frame: camera, parent: flange, xyz: [30, 0, 0], quaternion: [0, 0, 1, 1]}
  - {frame: upper_link, parent: upper, tf_parent: base0, xyz: [-150, 0, 0]}
  - {frame: plate, parent: base0, xyz: [0, 0, -50], rpy: [90, 0, 0]}
  - {frame: finger, parent: flange, type: prismatic, axis: [1, 2, 2],
     mimic: {joint: j2, multiplier: 0.01, offset: 5}, xyz: [0, 0, 20]}
  - {frame: pad, parent: finger, xyz: [0, 0, 5]}
  - {frame: knuckle, parent: camera, type: revolute, axis: [1, 0, 0],
     mimic: {joint: j1, multiplier: -2}}
  - {frame: jaw, parent: flange, type: revolute, axis: [0, 1, 0], joint: grip,
     limits: [-30, 60], max_velocity: 90, xyz: [0, 10, 0]}
  - {frame: jaw_tip, parent: jaw, xyz: [0, 0, 40]}
  - {frame: jaw2, parent: flange, type: prismatic, mimic: {joint: grip, multiplier: 2}}
end_effector: flange
"""


def expected_frames(q):
    """Every frame of ARM at ``q``, by 4x4 matrices written from the file's numbers."""
    base = hm.trans(z=0.1)
    upper, lower = hm.chain_frames([(q[0], 0, 0.3, math.pi / 2), (q[1], 0, 0.2, 0)],
                                   'standard', base)[1:]
    tcp = lower @ hm.trans(z=0.05)
    flange = tcp @ hm.trans(z=0.01) @ hm.rot_y(math.pi / 2)
    camera = flange @ hm.trans(x=0.03) @ hm.rot_z(math.pi / 2)
    stroke = 0.01 * q[1] + 0.005    # along the unit axis (1, 2, 2) / 3
    finger = flange @ hm.trans(z=0.02) @ hm.trans(stroke / 3, 2 * stroke / 3, 2 * stroke / 3)
    pad = finger @ hm.trans(z=0.005)
    knuckle = camera @ hm.rot_x(-2 * q[0])
    jaw = flange @ hm.trans(y=0.01) @ hm.rot_y(q[2])
    return {'base0': base, 'upper': upper, 'lower': lower, 'tcp': tcp, 'flange': flange,
            'camera': camera, 'upper_link': upper @ hm.trans(x=-0.15),
            'plate': base @ hm.trans(z=-0.05) @ hm.rot_x(math.pi / 2), 'finger': finger,
            'pad': pad, 'knuckle': knuckle, 'jaw': jaw, 'jaw_tip': jaw @ hm.trans(z=0.04),
            'jaw2': flange @ hm.trans(z=2 * q[2])}


def test_links_follow_the_chain_frames_they_are_fixed_to():
    model = parse_robot_description(ARM, 'arm.yaml')
    assert model.frame_names == ('base0', 'upper', 'lower', 'tcp', 'flange', 'camera',
                                 'upper_link', 'plate', 'finger', 'pad', 'knuckle', 'jaw',
                                 'jaw_tip', 'jaw2')
    assert model.parent_frames == ('world', 'base0', 'upper', 'lower', 'tcp', 'flange',
                                   'base0', 'base0', 'flange', 'finger', 'camera', 'flange',
                                   'jaw', 'flange')
    # static: fixed to their TF parent; moving: another body (upper_link under base0) or a
    # motion (finger, knuckle, jaw2: mimics; jaw: its own joint)
    assert model.moving == (False, True, True, False, False, False, True, False, True, False,
                            True, True, False, True)
    assert model.end_effector == 'flange' and model.end_effector_index == 4
    # the jaw's joint: optional, after the chain's, in degrees in the file
    assert model.joint_names == ('j1', 'j2', 'grip') and model.optional_joints == ('grip',)
    assert model.chain.dof == 2 and model.dof == 3
    np.testing.assert_allclose(model.limits[2], np.radians([-30, 60]))
    assert model.max_velocity[2] == pytest.approx(math.radians(90))
    assert model.angular.tolist() == [True, True, True]
    needs = dict(zip(model.frame_names, model.frame_needs))
    assert needs['jaw'] == needs['jaw_tip'] == needs['jaw2'] == {'grip'}
    assert needs['knuckle'] == needs['flange'] == frozenset()
    rng = np.random.default_rng(5)
    qs = rng.uniform(-3, 3, size=(40, 3))
    batch = homogeneous_from_dq(model.forward_all_batch(qs))
    for q, frames in zip(qs, batch):
        expected = expected_frames(q)
        single = homogeneous_from_dq(model.forward_all(q))
        for k, name in enumerate(model.frame_names):
            np.testing.assert_allclose(frames[k], expected[name], atol=1e-12, err_msg=name)
            np.testing.assert_allclose(single[k], expected[name], atol=1e-12, err_msg=name)


def test_tf_transforms_are_relative_to_the_tf_parent():
    model = parse_robot_description(ARM, 'arm.yaml')
    q = np.array([0.7, -1.1, 0.4])
    expected = expected_frames(q)
    absolute, relative = model.frame_poses(q)
    assert len(absolute) == len(model.frame_names)
    assert len(relative) == len(model.chain.joints) + len(model.links)
    rows = len(model.chain.joints)
    for j, link in enumerate(model.links):
        ours = hm.matrix_of_pose(relative[rows + j][:3], relative[rows + j][3:])
        want = np.linalg.inv(expected[link.tf_parent]) @ expected[link.frame]
        np.testing.assert_allclose(ours, want, atol=1e-12, err_msg=link.frame)
    assert model.transform_poses(q) == relative  # the node's /tf-only path
    batch = model.relative_batch(q[None, :])[0]
    for k, pose in enumerate(relative):
        np.testing.assert_allclose(hm.matrix_of_pose(pose[:3], pose[3:]),
                                   homogeneous_from_dq(batch[k]), atol=1e-12)
    # the moving transforms are exactly the moving frames' (rows first, then links)
    names = [model.frame_names[k] for k, _ in model.moving_edges]
    assert names == ['upper', 'lower', 'upper_link', 'finger', 'knuckle', 'jaw', 'jaw2']


def test_static_links_go_to_tf_static_under_their_parent():
    model = parse_robot_description(ARM, 'arm.yaml')
    messages = FrameMessages(model, 'r1/')
    static = {t.child_frame_id: t for t in messages.static_tf(Time()).transforms}
    assert set(static) == {'r1/base0', 'r1/tcp', 'r1/flange', 'r1/camera', 'r1/plate',
                           'r1/pad', 'r1/jaw_tip', 'r1/upper_dh_z', 'r1/lower_dh_z'}
    # every static transform is the child's pose in its parent, from the file's numbers
    expected = expected_frames(np.zeros(3))
    expected['world'] = np.eye(4)
    for child, t in static.items():
        if child.endswith('_dh_z'):  # the URDF's helper links: test_urdf.py
            continue
        parent = t.header.frame_id.replace('r1/', '')
        ours = hm.matrix_of_pose(
            [t.transform.translation.x, t.transform.translation.y, t.transform.translation.z],
            [t.transform.rotation.x, t.transform.rotation.y, t.transform.rotation.z,
             t.transform.rotation.w])
        np.testing.assert_allclose(
            ours, np.linalg.inv(expected[parent]) @ expected[child.replace('r1/', '')],
            atol=1e-12, err_msg=child)
    assert static['r1/base0'].header.frame_id == 'world'  # the fixed frame: no prefix
    assert static['r1/camera'].header.frame_id == 'r1/flange'
    t = static['r1/camera'].transform
    assert (t.translation.x, t.rotation.z, t.rotation.w) == pytest.approx(
        (0.03, math.sqrt(0.5), math.sqrt(0.5)))
    moving = [(t.header.frame_id, t.child_frame_id) for t in messages.tf.transforms]
    # the jaw's joint was never named: its links are left out until it is
    assert moving == [('r1/base0', 'r1/upper'), ('r1/upper', 'r1/lower'),
                      ('r1/base0', 'r1/upper_link'), ('r1/flange', 'r1/finger'),
                      ('r1/camera', 'r1/knuckle')]
    assert sorted(model.frame_names[k] for k in messages.hidden) == ['jaw', 'jaw2', 'jaw_tip']
    shown = FrameMessages(model, 'r1/', shown_optional=('grip',))
    assert shown.hidden == frozenset()
    assert [t.child_frame_id for t in shown.tf.transforms][-2:] == ['r1/jaw', 'r1/jaw2']
    # the end effector's twist is published too when it is a link
    assert [model.frame_names[k] for k in messages.twist_frames] == ['lower', 'tcp', 'flange']


def test_the_urdf_of_a_robot_with_links_poses_them_alike():
    model = parse_robot_description(ARM, 'arm.yaml')
    joints = {j.child: j for j in urdf_joints(model)}
    assert joints['finger'].kind == 'prismatic' and joints['finger'].mimic == ('j2', 0.01,
                                                                               0.005)
    assert joints['knuckle'].kind == 'continuous'
    assert joints['jaw'].name == 'grip' and joints['jaw'].mimic is None
    assert joints['jaw'].limits == pytest.approx(
        (math.radians(-30), math.radians(60), math.radians(90), 1e9))
    assert joints['jaw2'].mimic == ('grip', 2.0, 0.0)
    q = np.array([0.3, 0.9, -0.2])
    poses = link_poses(model, q)
    expected = expected_frames(q)
    for name in model.frame_names:
        np.testing.assert_allclose(poses[name].to_matrix(), expected[name], atol=1e-12)


BAD = {
    'unknown parent': ('parent: tcp, xyz: [0, 0, 10]', 'parent: nowhere, xyz: [0, 0, 10]',
                       "links[0] (frame 'flange'): field 'parent' names 'nowhere', which is "
                       'not an earlier frame; frames so far: world, base0, upper, lower, tcp'),
    'a later frame as parent': ('parent: tcp, xyz: [0, 0, 10]', 'parent: camera, xyz: [0, 0, 10]',
                                "field 'parent' names 'camera', which is not an earlier frame"),
    'a frame used twice': ('frame: camera, parent', 'frame: upper, parent',
                           "links[1] (frame 'upper'): frame 'upper' is already used by chain[0]"),
    'a motion without mimic': ('mimic: {joint: j1, multiplier: -2}}', 'xyz: [0, 0, 0]}',
                               "links[6] (frame 'knuckle'): a revolute link takes either "
                               "'joint' (a joint of its own) or 'mimic' (moving with another "
                               'joint), not neither'),
    'joint and mimic': ('joint: grip,', 'joint: grip, mimic: {joint: j1},',
                        "links[7] (frame 'jaw'): a revolute link takes either 'joint'"),
    'mimic of no joint': ('joint: j1, multiplier: -2', 'joint: j9, multiplier: -2',
                          "links[6] (frame 'knuckle') mimic: field 'joint' names 'j9', "
                          'which no row or link has; joints: j1, j2, grip'),
    'a link joint named as a chain joint': ('joint: grip,', 'joint: j2,',
                                            "links[7] (frame 'jaw'): joint 'j2' is already a "
                                            'joint of the robot'),
    'limits with mimic': ('multiplier: 2}}', 'multiplier: 2}, limits: [0, 1]}',
                          "links[9] (frame 'jaw2'): field 'limits' does not go with 'mimic'"),
    'limits upside down': ('limits: [-30, 60]', 'limits: [60, -30]',
                           "links[7] (frame 'jaw'): field 'limits' has lower 60 above upper"),
    'a zero axis': ('axis: [1, 0, 0]', 'axis: [0, 0, 0]', "field 'axis' must not be all zeros"),
    'axis on a fixed link': ('quaternion: [0, 0, 1, 1]}',
                             'quaternion: [0, 0, 1, 1], axis: [1, 0, 0]}',
                             "field 'axis' applies only to a link of type revolute or "
                             'prismatic'),
    'an unknown type': ('type: revolute', 'type: planar', "field 'type' is 'planar'; allowed: "
                        'fixed, revolute, prismatic'),
    'an unknown end effector': ('end_effector: flange', 'end_effector: hand',
                                "field 'end_effector' names 'hand', which is not a frame of "
                                'the robot'),
    'links not a list': ('links:\n', 'links: 3\nx:\n', "unknown field 'x'"),
}


@pytest.mark.parametrize('case', sorted(BAD))
def test_bad_links_are_one_line_errors(case):
    old, new, expected = BAD[case]
    assert old in ARM
    with pytest.raises(RobotDescriptionError) as caught:
        parse_robot_description(ARM.replace(old, new, 1), 'arm.yaml')
    assert str(caught.value).startswith('arm.yaml: ') and '\n' not in str(caught.value)
    assert expected in str(caught.value) and not str(caught.value).endswith(': ')


def test_links_must_be_a_list():
    text = ARM[:ARM.index('links:')] + 'links: {frame: x}\n'
    with pytest.raises(RobotDescriptionError, match='links: expected a list of'):
        parse_robot_description(text, 'arm.yaml')


def test_a_long_list_of_frames_is_cut_in_messages():
    links = ''.join(f'  - {{frame: extra{k}, parent: tcp}}\n' for k in range(25))
    text = ARM[:ARM.index('links:\n') + len('links:\n')] + links + \
        '  - {frame: lost, parent: nowhere}\n'
    with pytest.raises(RobotDescriptionError) as caught:
        parse_robot_description(text, 'arm.yaml')
    assert str(caught.value).endswith(
        'frames so far: world, base0, upper, lower, tcp, extra0, extra1, extra2, extra3, '
        'extra4, extra5, extra6, extra7, extra8, extra9, extra10, extra11, extra12, extra13, '
        'extra14 ... (10 more)')


@pytest.mark.parametrize('robot', ['arm.yaml', 'ur5', 'panda', 'z1'])
def test_the_unrolled_frame_poses_with_links_are_the_general_path(robot):
    """Chain and links as straight-line code: the looping path's floats (== on each)."""
    arms = {'ur5': UR5, 'panda': PANDA, 'z1': Z1}
    model = vendor_robot(arms[robot]).model if robot in arms else \
        parse_robot_description(ARM, 'arm.yaml')
    assert model.links
    for q in np.random.default_rng(12).uniform(-2.5, 2.5, size=(300, model.dof)):
        assert model.frame_poses(q) == model.frame_poses_general(q)
    assert model.frame_poses(q.tolist()) == model.frame_poses_general(q)
    assert 'u0, u1, u2' in model.kinematics.unrolled.source  # constant offsets multiplied inline
    with pytest.raises(ValueError, match=f'expected {model.dof} joint values'):
        model.frame_poses(np.zeros(model.dof + 1))


def test_batches_of_a_model_with_links_keep_w_non_negative():
    model = parse_robot_description(ARM, 'arm.yaml')
    qs = np.random.default_rng(14).uniform(-3, 3, size=(200, model.dof))
    batch = model.forward_all_batch(qs)
    assert (batch[..., 0] >= 0.0).all()
    for q, frames in zip(qs[:20], batch[:20]):
        for k, pose in enumerate(model.frame_poses(q)[0]):
            np.testing.assert_allclose(frames[k][1:4], pose[3:6], atol=1e-12)
