"""The URDF export: well-formed, a tree over the published frames, and the same kinematics."""

import json
import math
import re
import xml.etree.ElementTree as ET

from dq_fk_ros.description import to_urdf
from dq_fk_ros.description.schema import load_robot_description, parse_robot_description
from dq_fk_ros.description.shipped import shipped_robot_path, shipped_robots
from dq_fk_ros.description.to_urdf import (
    description_urdf, HelperFrames, link_poses, link_segments, NO_LIMIT_SPEED, robot_to_urdf)
from dq_fk_ros.kinematics.dh import homogeneous_from_dq
import homogeneous as hm
from hypothesis import given, strategies as st
import numpy as np
import pytest


def urdf_origin(element):
    """4x4 of a URDF <origin xyz rpy>: Trans(xyz) Rz(yaw) Ry(pitch) Rx(roll)."""
    if element is None:
        return np.eye(4)
    x, y, z = (float(v) for v in element.get('xyz', '0 0 0').split())
    roll, pitch, yaw = (float(v) for v in element.get('rpy', '0 0 0').split())
    return hm.trans(x, y, z) @ hm.rot_z(yaw) @ hm.rot_y(pitch) @ hm.rot_x(roll)


def urdf_link_poses(text, joint_values):
    """Compose every link's pose from the URDF's joints, as a URDF consumer would."""
    root = ET.fromstring(text)
    joints = {j.get('name'): j for j in root.findall('joint')}
    children = {j.find('child').get('link') for j in joints.values()}
    links = [link.get('name') for link in root.findall('link')]
    roots = [name for name in links if name not in children]
    assert len(roots) == 1, roots
    poses = {roots[0]: np.eye(4)}
    pending = list(joints.values())
    while pending:
        progressed = False
        for joint in list(pending):
            parent = joint.find('parent').get('link')
            if parent not in poses:
                continue
            kind = joint.get('type')
            motion = np.eye(4)
            if kind != 'fixed':
                mimic = joint.find('mimic')
                if mimic is not None:
                    value = (float(mimic.get('multiplier', 1)) * joint_values[mimic.get('joint')]
                             + float(mimic.get('offset', 0)))
                else:
                    value = joint_values[joint.get('name')]
                axis = np.array([float(v) for v in joint.find('axis').get('xyz').split()])
                if kind in ('revolute', 'continuous'):
                    motion = hm.rodrigues(axis, value)
                else:
                    motion = hm.trans(*(value * axis))
            poses[joint.find('child').get('link')] = (
                poses[parent] @ urdf_origin(joint.find('origin')) @ motion)
            pending.remove(joint)
            progressed = True
        assert progressed, 'URDF joints do not form a tree'
    return poses, roots[0]


@pytest.mark.parametrize('name', shipped_robots())
def test_urdf_kinematics_equal_the_dh_chain(name):
    model = load_robot_description(shipped_robot_path(name))
    text = robot_to_urdf(model)
    rng = np.random.default_rng(8)
    for q in rng.uniform(-2, 2, size=(30, model.dof)):
        poses, root = urdf_link_poses(text, dict(zip(model.joint_names, q)))
        assert root == model.fixed_frame
        expected = homogeneous_from_dq(model.forward_all(q))  # every chain, every link
        for frame, m in zip(model.frame_names, expected):
            np.testing.assert_allclose(poses[frame], m, atol=1e-12)


def test_urdf_is_well_formed_with_limits_and_visuals():
    model = load_robot_description(shipped_robot_path('puma560'))
    root = ET.fromstring(robot_to_urdf(model))
    assert root.tag == 'robot' and root.get('name') == 'puma560'
    q2 = [j for j in root.findall('joint') if j.get('name') == 'q2'][0]
    assert q2.get('type') == 'revolute'
    limit = q2.find('limit')
    assert float(limit.get('lower')) == pytest.approx(math.radians(-45))
    assert float(limit.get('upper')) == pytest.approx(math.radians(225))
    assert root.findall('link/visual'), 'segments should be drawn'


def test_mimic_and_negative_scale_rows():
    model = parse_robot_description(
        'robot: r\nbase: {frame: b}\nchain:\n'
        '  - {frame: l1, joint: j1, theta: 0.2, d: 0.1, a: 0.3, alpha: 0.4, scale: -1}\n'
        '  - {frame: l2, theta: 0.1, d: 0, a: 0.2, alpha: 0, mimic: {joint: j1, '
        'multiplier: 0.5}}\n'
        '  - {frame: l3, type: prismatic, joint: j3, theta: 0.3, d: 0.2, a: 0.1, alpha: 1}\n',
        'inline.yaml')
    text = robot_to_urdf(model)
    for axis in ET.fromstring(text).iter('axis'):  # unit axes, as URDF readers expect
        assert np.linalg.norm([float(v) for v in axis.get('xyz').split()]) == 1.0
    for q in np.random.default_rng(1).uniform(-1, 1, size=(20, 2)):
        poses, _ = urdf_link_poses(text, dict(zip(model.joint_names, q)))
        for frame, m in zip(model.frame_names, homogeneous_from_dq(model.chain.forward_all(q))):
            np.testing.assert_allclose(poses[frame], m, atol=1e-12)


def test_scale_other_than_one_is_refused_clearly():
    model = parse_robot_description(
        'robot: r\nbase: {frame: b}\nchain:\n'
        '  - {frame: l1, joint: j1, theta: 0, d: 0, a: 0.3, alpha: 0, scale: 2}\n', 'x.yaml')
    with pytest.raises(ValueError, match="frame 'l1'.*scale 2.0"):
        robot_to_urdf(model)


@pytest.mark.parametrize('name', ['x --> <evil/> <!-- ', 'a & b "c" \'d\'', '--', 'ends-',
                                  ']]> <![CDATA[', 'ü ✓'])
def test_hostile_robot_names_leave_the_urdf_well_formed(name):
    """A robot name used to be written raw into an XML comment: '-->' broke the URDF."""
    text = open(shipped_robot_path('rl15'), encoding='utf-8').read()
    model = parse_robot_description(text.replace('robot: rl15', f'robot: {json.dumps(name)}'))
    root = ET.fromstring(robot_to_urdf(model))  # expat, a real XML parser
    assert root.tag == 'robot' and root.attrib['name'] == name
    assert {link.attrib['name'] for link in root.iter('link')} >= set(model.frame_names)


# every character XML 1.0 allows (its Char production), the ones markup uses most often
XML_TEXT = st.text(st.sampled_from('&<>"\'\t\n\r ;#') | st.characters(
    blacklist_categories=('Cs',), blacklist_characters='\ufffe\uffff').filter(
    lambda c: c in '\t\n\r' or ord(c) >= 0x20))


@given(XML_TEXT)
def test_an_attribute_value_reads_back_as_written(text):
    """The URDF's attribute quoting, read back by expat (tabs and newlines kept, not spaces)."""
    element = ET.fromstring(f'<a b={to_urdf._xml_attribute(text)}/>')
    assert element.attrib['b'] == text


MIMIC_ROBOT = (
    'robot: gripper_arm\nbase: {frame: b}\nchain:\n'
    '  - {frame: l1, joint: j1, theta: 0, d: 0.1, a: 0.3, alpha: 0.4, limits: [-2, 2],'
    ' max_velocity: 1.5}\n'
    '  - {frame: l2, theta: 0.1, d: 0, a: 0.2, alpha: 0, mimic: {joint: j1,'
    ' multiplier: -0.5}}\n'
    '  - {frame: l3, type: prismatic, joint: j3, theta: 0.3, d: 0.2, a: 0.1, alpha: 1}\n')


def test_a_mimic_row_loads_in_pinocchio_with_mimic_support():
    """A mimic row was written 'continuous' after a limited joint: pinocchio refused it."""
    from pinocchio_oracle import configuration, link_placements, urdf_model
    model = parse_robot_description(MIMIC_ROBOT, 'mimic.yaml')
    text = robot_to_urdf(model)
    joints = {j.get('name'): j for j in ET.fromstring(text).iter('joint')}
    mimic = joints['l2_joint']
    assert mimic.get('type') == joints['j1'].get('type') == 'revolute'
    assert [float(mimic.find('limit').get(k)) for k in ('lower', 'upper')] == [-1.0, 1.0]
    pin_model = urdf_model(text, mimic=True)
    assert pin_model.nq == 2  # the mimic joint adds no configuration variable
    for q in np.random.default_rng(3).uniform(-1, 1, size=(10, 2)):
        placements = link_placements(pin_model, configuration(
            pin_model, dict(zip(model.joint_names, q))), model.frame_names)
        for frame, m in zip(model.frame_names, homogeneous_from_dq(model.chain.forward_all(q))):
            np.testing.assert_allclose(placements[frame], m, atol=1e-12)


def test_limits_never_say_a_joint_cannot_move():
    """velocity="0" effort="0" read as a joint that cannot move (MoveIt, ros2_control)."""
    model = parse_robot_description(MIMIC_ROBOT, 'mimic.yaml')
    root = ET.fromstring(robot_to_urdf(model))
    limits = {j.get('name'): j.find('limit') for j in root.iter('joint')}
    assert float(limits['j1'].get('velocity')) == 1.5  # the description's max_velocity
    for name in ('j1', 'l2_joint', 'j3'):
        assert float(limits[name].get('velocity')) > 0 and float(limits[name].get('effort')) > 0
    assert float(limits['j3'].get('velocity')) == NO_LIMIT_SPEED  # none given
    # a prismatic joint without limits: +-1000 m, said in a comment next to the joint
    assert [float(limits['j3'].get(k)) for k in ('lower', 'upper')] == [-1000.0, 1000.0]
    text = robot_to_urdf(model)
    note = text.index('<!-- no limits in the description: +-1000 m stands for none')
    assert text.index('<joint name="j3"') > note  # the comment comes right before its joint
    assert '<joint' not in text[note:text.index('<joint name="j3"')]


def test_a_fixed_row_is_a_fixed_joint_from_its_parent_frame():
    model = parse_robot_description(
        'robot: r\nbase: {frame: b}\nchain:\n'
        '  - {frame: l1, joint: j1, theta: 0, d: 0.1, a: 0.3, alpha: 0.2}\n'
        '  - {frame: l2, type: fixed, theta: 0.5, d: 0.1, a: 0.2, alpha: 0.3}\n', 'fixed.yaml')
    root = ET.fromstring(robot_to_urdf(model))
    joints = {j.get('name'): j for j in root.iter('joint')}
    fixed = joints['l2_fixed']
    assert fixed.get('type') == 'fixed'
    assert (fixed.find('parent').get('link'), fixed.find('child').get('link')) == ('l1', 'l2')
    m = homogeneous_from_dq(model.chain.relative_all([0.0])[1])
    np.testing.assert_allclose(urdf_origin(fixed.find('origin')), m, atol=1e-12)
    # every link the joints name is declared, leaves included
    links = {link.get('name') for link in root.iter('link')}
    named = {j.find(k).get('link') for j in joints.values() for k in ('parent', 'child')}
    assert named == links and 'l2' in links


def test_the_visual_cylinders_lie_along_each_offset():
    """Each cylinder's length is its joint origin's offset, centred halfway, along it."""
    model = load_robot_description(shipped_robot_path('rl15'))
    root = ET.fromstring(robot_to_urdf(model))
    offsets = {}
    for j in root.iter('joint'):
        m = urdf_origin(j.find('origin'))
        if np.linalg.norm(m[:3, 3]) > 1e-9:
            offsets.setdefault(j.find('parent').get('link'), []).append(m[:3, 3])
    assert offsets
    for link in root.iter('link'):
        visuals = link.findall('visual')
        expected = offsets.get(link.get('name'), [])
        assert len(visuals) == len(expected)
        for visual, t in zip(visuals, expected):
            length = float(visual.find('geometry/cylinder').get('length'))
            assert length == pytest.approx(np.linalg.norm(t), abs=1e-12)
            m = urdf_origin(visual.find('origin'))
            np.testing.assert_allclose(m[:3, 3], t / 2, atol=1e-12)
            np.testing.assert_allclose(m[:3, 2], t / np.linalg.norm(t), atol=1e-9)


@pytest.mark.parametrize('pitch', [math.pi / 2, -math.pi / 2])
def test_rpy_at_gimbal_lock_still_gives_the_rotation(pitch):
    from dq_fk_ros.description.to_urdf import matrix_to_rpy
    m = hm.rot_z(0.7) @ hm.rot_y(pitch) @ hm.rot_x(0.3)
    roll, p, yaw = matrix_to_rpy(m[:3, :3])
    assert p == pytest.approx(pitch) and roll == 0.0
    np.testing.assert_allclose(hm.rot_z(yaw) @ hm.rot_y(p) @ hm.rot_x(roll), m, atol=1e-12)


def test_helper_frames_are_children_of_their_dh_frames():
    """Each helper's offset from its DH frame is the URDF's, constant or at the joints."""
    for name, q in (('rl15', [0.3, -0.2, 0.5, 0.1, -0.7, 0.9]), ('rrc', [0.2, -0.4, 1.1, 0.05])):
        model = load_robot_description(shipped_robot_path(name))
        helpers = HelperFrames(model)
        poses = link_poses(model, q)
        frames = model.frame_names
        for helper, anchor, offset in helpers.static:
            assert helper == frames[anchor] + '_dh_z'
            for at in (np.zeros(model.dof), np.asarray(q)):
                at_poses = link_poses(model, at)
                np.testing.assert_allclose(
                    (at_poses[frames[anchor]].inverse() * at_poses[helper]).to_matrix(),
                    offset.to_matrix(), atol=1e-12)
        assert len(helpers.moving_poses(q)) == len(helpers.moving)
        for (helper, anchor), pose in zip(helpers.moving, helpers.moving_poses(q)):
            assert helper == frames[anchor] + '_dh_z0'
            expected = (poses[frames[anchor]].inverse() * poses[helper]).to_matrix()
            np.testing.assert_allclose(hm.matrix_of_pose(pose[:3], pose[3:]), expected,
                                       atol=1e-12)
        every = {j.get('name') for j in ET.fromstring(robot_to_urdf(model)).iter('link')}
        named = {h for h, _, _ in helpers.static} | {h for h, _ in helpers.moving}
        assert named == {link for link in every if '_dh_z' in link}
        assert bool(helpers.moving) == (name == 'rrc')
    rl15 = HelperFrames(load_robot_description(shipped_robot_path('rl15')))
    assert len(rl15.static) == 5 and rl15.moving == [] and rl15.moving_poses([0] * 6) == []


def test_description_urdf_is_the_source_urdf_when_there_is_one():
    import dataclasses
    model = load_robot_description(shipped_robot_path('rl15'))
    assert description_urdf(model) == robot_to_urdf(model)
    assert description_urdf(dataclasses.replace(model, urdf='<robot name="x"/>')) == \
        '<robot name="x"/>'


def test_link_segments_run_between_link_origins():
    model = load_robot_description(shipped_robot_path('puma560'))
    q = [0.1, -0.5, 0.3, 0.2, 0.4, -0.3]
    poses = link_poses(model, q)
    segments = link_segments(model, q)
    assert segments
    origins = [p.translation for p in poses.values()]
    for start, end in segments:
        assert min(np.linalg.norm(start - o) for o in origins) < 1e-12
        assert np.linalg.norm(end - start) > 1e-9


def test_a_mimic_link_with_an_offset_keeps_it_in_the_urdf():
    model = parse_robot_description(
        'robot: r\nbase: {frame: b}\nchain:\n'
        '  - {frame: l1, joint: j1, theta: 0, d: 0.1, a: 0.3, alpha: 0.2}\n'
        'links:\n  - {frame: f, parent: l1, type: prismatic, mimic: {joint: j1, multiplier: 2, '
        'offset: 0.25}}\n', 'm.yaml')
    mimic = [j for j in ET.fromstring(robot_to_urdf(model)).iter('joint')
             if j.get('name') == 'f_joint'][0].find('mimic')
    assert (mimic.get('joint'), mimic.get('multiplier'), mimic.get('offset')) == \
        ('j1', '2.0', '0.25')


def test_link_poses_follow_mimic_rows_and_joints_are_frozen():
    import dataclasses
    from dq_fk_ros.description.to_urdf import urdf_joints
    model = parse_robot_description(
        'robot: r\nbase: {frame: b}\nchain:\n'
        '  - {frame: l1, joint: j1, theta: 0.2, d: 0.1, a: 0.3, alpha: 0.4}\n'
        '  - {frame: l2, theta: 0.1, d: 0, a: 0.2, alpha: 0.3, mimic: {joint: j1, '
        'multiplier: 0.5}}\n', 'mimic.yaml')
    q = [0.7]
    poses = link_poses(model, q)
    for frame, m in zip(model.frame_names, homogeneous_from_dq(model.chain.forward_all(q))):
        np.testing.assert_allclose(poses[frame].to_matrix(), m, atol=1e-12)
    joint = urdf_joints(model)[0]
    with pytest.raises(dataclasses.FrozenInstanceError):
        joint.name = 'x'


@pytest.mark.parametrize('offset', [(0.3, 0.0, 0.0), (-2.5, 0.0, 0.0), (0.0, 0.7, 0.0),
                                    (0.0, 0.0, 0.4), (0.0, 0.0, -0.4), (0.2, -0.3, 0.6),
                                    (1e-3, 0.0, -2.0)])
def test_a_link_segment_is_a_cylinder_from_the_joint_to_the_next(offset):
    """The visual of a joint offset: a cylinder of that length whose axis points along it."""
    from dq_fk_ros.description.to_urdf import _segment
    from dq_fk_ros.kinematics.dual_quaternion import DualQuaternion
    t = np.array(offset)
    visual = ET.fromstring(_segment(DualQuaternion.from_pose([1.0, 0.0, 0.0, 0.0], t)))
    origin, cylinder = visual.find('origin'), visual.find('geometry/cylinder')
    np.testing.assert_allclose([float(v) for v in origin.get('xyz').split()], t / 2,
                               atol=1e-12)
    roll, pitch, yaw = (float(v) for v in origin.get('rpy').split())
    rotation = hm.rot_z(yaw) @ hm.rot_y(pitch) @ hm.rot_x(roll)   # URDF's fixed-axis rpy
    np.testing.assert_allclose(rotation[:3, :3] @ [0.0, 0.0, 1.0], t / np.linalg.norm(t),
                               atol=1e-12)
    assert float(cylinder.get('length')) == pytest.approx(np.linalg.norm(t), abs=1e-12)
    assert visual.find('material').get('name') == 'dq_fk_grey'


def test_zeros_are_written_as_0_and_the_material_is_defined_once():
    text = robot_to_urdf(load_robot_description(shipped_robot_path('rl15')))
    numbers = re.findall(r'(?<=["\s])-?[0-9.e+-]+(?=["\s])', text)
    assert numbers and not {'0.0', '-0.0'} & set(numbers) and '0' in numbers
    robot = ET.fromstring(text)
    materials = robot.findall('material')
    assert [(m.get('name'), m.find('color').get('rgba')) for m in materials] == \
        [('dq_fk_grey', '0.6 0.6 0.65 1')]
