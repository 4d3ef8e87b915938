"""The ``links:`` entries of a robot file: each mistake said in one line, where and what."""

from dq_fk_ros.description.schema import parse_robot_description
from dq_fk_ros.errors import RobotDescriptionError
import numpy as np
import pytest

ROBOT = """
robot: r
units: {length: m, angle: rad}
base: {frame: b0}
chain:
  - {frame: l1, joint: j1, theta: 0, d: 0.1, a: 0, alpha: 0}
links:
"""
AT = "r.yaml: links[0] (frame 'cam')"   # then ': ' and the field, or ' mimic: ' and its field


def refusal(entry):
    with pytest.raises(RobotDescriptionError) as caught:
        parse_robot_description(ROBOT + f'  - {entry}\n', 'r.yaml')
    return str(caught.value)


def link(entry):
    model = parse_robot_description(ROBOT + f'  - {entry}\n', 'r.yaml')
    return next(k for k in model.links if k.frame == 'cam')


@pytest.mark.parametrize('entry, said', [
    ('{frame: cam}', ": missing field 'parent' (required: frame, parent)"),
    ('{frame: cam, parent: nowhere}',
     ": field 'parent' names 'nowhere', which is not an earlier frame; frames so far: "),
    ('{frame: cam, parent: l1, tf_parent: nowhere}',
     ": field 'tf_parent' names 'nowhere', which is not an earlier frame; frames so far: "),
    ("{frame: cam, parent: l1, tf_parent: 'a b'}", ": field 'tf_parent' must be a tf2 frame id"),
    ('{frame: cam, parent: l1, type: spinning}',
     ": field 'type' is 'spinning'; allowed: fixed, revolute, prismatic, floating"),
    ('{frame: cam, parent: l1, type: revolute, joint: g, mimic: {joint: j1}}',
     ": a revolute link takes either 'joint' (a joint of its own) or 'mimic' (moving with "
     'another joint), not both'),
    ('{frame: cam, parent: l1, type: prismatic}',
     ": a prismatic link takes either 'joint' (a joint of its own) or 'mimic' (moving with "
     'another joint), not neither'),
    ('{frame: cam, parent: l1, type: revolute, joint: g, axis: [0, 0, 0]}',
     ": field 'axis' must not be all zeros"),
    ('{frame: cam, parent: l1, type: revolute, joint: g, axis: [1.0e-9, 0, 0]}',
     ": field 'axis' must not be all zeros"),   # 1e-9 long: not more than the bound
    ('{frame: cam, parent: l1, type: revolute, joint: g, axis: [5.0e-10, 5.0e-10, 5.0e-10]}',
     ": field 'axis' must not be all zeros"),
    ('{frame: cam, parent: l1, type: revolute, joint: g, axis: [1, 2]}',
     ": field 'axis' must be a list of 3 numbers"),
    ("{frame: cam, parent: l1, type: revolute, joint: 'a b'}", ": field 'joint' must be a joint "
     'name'),
    ('{frame: cam, parent: l1, type: revolute, joint: g, max_velocity: -1}',
     ": field 'max_velocity' "),
    ('{frame: cam, parent: l1, type: revolute, mimic: {joint: j1}, limits: [0, 1]}',
     ": field 'limits' does not go with 'mimic' (the link moves with its source joint)"),
    ('{frame: cam, parent: l1, type: revolute, mimic: {joint: j1}, max_velocity: 1}',
     ": field 'max_velocity' does not go with 'mimic' (the link moves with its source joint)"),
    ('{frame: cam, parent: l1, type: revolute, mimic: {multiplier: 2}}',
     " mimic: missing field 'joint' (required: joint)"),
    ("{frame: cam, parent: l1, type: revolute, mimic: {joint: 'a b'}}",
     " mimic: field 'joint' must be a joint name"),
    ('{frame: cam, parent: l1, type: revolute, mimic: {joint: j1, multiplier: x}}',
     " mimic: field 'multiplier' "),
    ('{frame: cam, parent: l1, type: revolute, mimic: {joint: j1, offset: x}}',
     " mimic: field 'offset' "),
])
def test_each_mistake_in_a_link_says_where_and_what(entry, said):
    assert refusal(entry).startswith(AT + said)


@pytest.mark.parametrize('kind', ['fixed', 'floating'])
@pytest.mark.parametrize('field, value', [('axis', '[0, 0, 1]'), ('joint', 'g'),
                                          ('limits', '[0, 1]'), ('max_velocity', '1'),
                                          ('mimic', '{joint: j1}')])
def test_a_fixed_link_takes_no_motion_field(kind, field, value):
    assert refusal(f'{{frame: cam, parent: l1, type: {kind}, {field}: {value}}}') == \
        AT + f': field {field!r} applies only to a link of type revolute or prismatic'


def test_an_entry_that_is_not_a_mapping_is_placed_by_its_index():
    assert refusal('7').startswith('r.yaml: links[0]: expected a mapping with fields frame, ')
    assert refusal('{frame: 7, parent: l1}').startswith("r.yaml: links[0]: field 'frame' ")


def test_an_axis_is_made_a_unit_vector_however_large_or_small():
    for axis, unit in (('[1.0e+200, 0, 0]', [1, 0, 0]), ('[0, 3.0e-9, 4.0e-9]', [0, 0.6, 0.8]),
                       ('[0, 0, -2]', [0, 0, -1])):
        got = link(f'{{frame: cam, parent: l1, type: revolute, joint: g, axis: {axis}}}')
        np.testing.assert_allclose(got.motion[1], unit, atol=1e-15)
    assert link('{frame: cam, parent: l1, type: revolute, joint: g}').motion[1] == (0, 0, 1.0)


def test_a_link_of_its_own_joint_without_limits_is_unbounded_and_a_mimic_follows_one_to_one():
    own = link('{frame: cam, parent: l1, type: revolute, joint: g}')
    assert own.limits == (-np.inf, np.inf) and own.max_velocity == np.inf
    follower = link('{frame: cam, parent: l1, type: prismatic, mimic: {joint: j1}}')
    assert follower.motion == ('prismatic', (0, 0, 1.0), 'j1', 1.0, 0.0)


@pytest.mark.parametrize('fields, said', [
    ('limits: [0]', "field 'limits' must be a list of 2 numbers"),
    ('max_velocity: 0', "field 'max_velocity' must be a positive speed (per second), got 0"),
    ('max_velocity: x', "field 'max_velocity' must be a number"),
])
def test_a_rows_limits_and_speed_are_said_where_and_what(fields, said):
    text = ROBOT.replace('alpha: 0}', f'alpha: 0, {fields}}}').replace('links:\n', '')
    with pytest.raises(RobotDescriptionError) as caught:
        parse_robot_description(text, 'r.yaml')
    assert str(caught.value).startswith("r.yaml: chain[0] (frame 'l1'): " + said)
