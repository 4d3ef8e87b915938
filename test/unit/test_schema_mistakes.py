"""
Each mistake in a robot file says where it is and what is wrong, in one line.

The robot below is valid; each case changes one thing and names the place (``f.yaml: WHERE:``)
and the words the message must hold. Written from docs/robot_description.md's fields.
"""

import copy
import math

from dq_fk_ros.description.robot_model import MAX_NAME_CHARS, MAX_ROWS
from dq_fk_ros.description.schema import parse_robot_description
from dq_fk_ros.errors import RobotDescriptionError
import pytest
import yaml

ROBOT = {'robot': 'arm', 'base': {'frame': 'b0'}, 'tool': {'frame': 'tcp'}, 'chain': [
    {'frame': 'l1', 'joint': 'j1', 'theta': 0, 'd': 0.1, 'a': 0.2, 'alpha': 0},
    {'frame': 'l2', 'joint': 'j2', 'theta': 0, 'd': 0, 'a': 0.2, 'alpha': 0}]}


def changed(*edits):
    data = copy.deepcopy(ROBOT)
    for edit in edits:
        edit(data)
    return data


def row(k, **fields):
    """Return an edit setting (or, for None, removing) fields of row ``k``."""
    def edit(data):
        for key, value in fields.items():
            if value is None:
                data['chain'][k].pop(key, None)
            else:
                data['chain'][k][key] = value
    return edit


def top(**fields):
    def edit(data):
        data.update(fields)
    return edit


FIXED = {'type': 'fixed', 'joint': None}
CYLINDRICAL = {'type': 'cylindrical', 'd_joint': 'j1d'}
MIMIC = {'joint': None, 'mimic': {'joint': 'j1'}}

L1, L2 = "chain[0] (frame 'l1')", "chain[1] (frame 'l2')"   # a row: its index and frame
CASES = [
    # the row's numbers and names: the place is the row, the message names the field
    (row(0, theta='x'), L1, "'theta'"),
    (row(0, d='x'), L1, "'d'"),
    (row(0, alpha='x'), L1, "'alpha'"),
    (row(0, scale='x'), L1, "'scale'"),
    (row(0, scale=0), L1, "field 'scale' must not be 0 (it multiplies the joint "
                          'value)'),
    (row(0, frame=5), 'chain[0]', "field 'frame' must be a tf2 frame id"),
    (row(0, joint=5), L1, "field 'joint' must be a joint name"),
    # a fixed row takes no joint fields
] + [(row(1, **FIXED, **{field: value}), L2,
      f"field '{field}' does not apply to a fixed row")
     for field, value in (('limits', [0, 1]), ('max_velocity', 1), ('mimic', {'joint': 'j1'}),
                          ('d_joint', 'x'), ('d_limits', [0, 1]), ('d_max_velocity', 1),
                          ('scale', 2))] + [
    # only a cylindrical row reads d from a joint of its own
    (row(1, **{field: value}), L2, f"field '{field}' applies only to a cylindrical row")
    for field, value in (('d_joint', 'x'), ('d_limits', [0, 1]), ('d_max_velocity', 1))] + [
    (row(1, **CYLINDRICAL, mimic={'joint': 'j1'}), L2,
     "field 'mimic' does not apply to a cylindrical row"),
    (row(1, type='cylindrical'), L2, "missing field 'd_joint' (a cylindrical row "
                                     "reads two joints: 'joint' for theta, 'd_joint' "
                                     'for d)'),
    (row(1, type='cylindrical', d_joint=5), L2, "field 'd_joint' must be a joint name"),
    (row(1, **CYLINDRICAL, d_limits='x'), L2, "'d_limits'"),
    (row(1, **CYLINDRICAL, d_max_velocity='x'), L2, "'d_max_velocity'"),
] + [
    # a mimic row moves with its source: none of the joint's own fields
    (row(1, **MIMIC, **{field: value}), L2,
     f"field '{field}' does not go with 'mimic' (the row moves with its source joint)")
    for field, value in (('limits', [0, 1]), ('max_velocity', 1), ('scale', 2))] + [
    (row(1, joint='j2', mimic={'joint': 'j1'}), L2,
     "field 'joint' does not go with 'mimic' (the row moves with its source joint)"),
    (row(1, **{**MIMIC, 'mimic': 5}), L2 + ' mimic', 'expected a mapping'),
    (row(1, **{**MIMIC, 'mimic': {'multiplier': 2}}), L2 + ' mimic', "'joint'"),
    (row(1, **{**MIMIC, 'mimic': {'joint': 'j1', 'multiplier': 'x'}}), L2 + ' mimic',
     "'multiplier'"),
    (row(1, **{**MIMIC, 'mimic': {'joint': 'j1', 'offset': 'x'}}), L2 + ' mimic',
     "'offset'"),
    # the base and the tool
    (top(base=5), 'base', 'expected a mapping'),
    (top(base={'xyz': [0, 0, 0]}), 'base', "'frame'"),
    (top(base={'frame': 'b0', 'xyz': [0, 'x', 0]}), 'base', "field 'xyz[1]' must be a number"),
    (top(base={'frame': 'b0', 'xyz': [0, 1e300, 0]}), 'base',
     "field 'xyz[1]' is 1e+300 m; offsets are at most"),
    (top(base={'frame': 'b0', 'rpy': [0, 0]}), 'base', "'rpy'"),
    (top(base={'frame': 'b0', 'quaternion': [0, 0, 1]}), 'base', "'quaternion'"),
    (top(base={'frame': 'b0', 'quaternion': [0, 0, 0, 0]}), 'base',
     "field 'quaternion' (x, y, z, w) must not be all zeros"),
    (top(base={'frame': 'b0', 'quaternion': [1e-10, 0, 0, 0]}), 'base',
     "field 'quaternion' (x, y, z, w) must not be all zeros"),
    (top(base={'frame': 'b0', 'rpy': [0, 0, 0], 'quaternion': [0, 0, 0, 1]}), 'base',
     "give either 'rpy' or 'quaternion', not both"),
    (top(tool={'frame': 'l1'}), 'tool', "frame 'l1' is already used by chain[0]"),
    (top(base={'frame': 'l2'}), L2, "frame 'l2' is already used by base"),
    # the file's own fields: no place but the file
    (top(units=5), 'units', 'expected a mapping'),
    (top(units={'angle': 'gon'}), 'units', "'angle'"),
    (top(links=5), 'links', 'expected a list of {frame, parent, xyz, rpy | quaternion}, got 5 '
                            '(int)'),
    (top(chain=5), 'chain', 'expected a non-empty list of DH rows, got 5 (int)'),
    (top(links=[{'frame': f'k{k}', 'parent': 'tcp'} for k in range(MAX_ROWS + 1)]), 'links',
     f'{MAX_ROWS + 1} links; a robot description has at most'),
    (top(chain=[ROBOT['chain'][0]] * (MAX_ROWS + 1)), 'chain',
     f'{MAX_ROWS + 1} rows; a robot description has at most {MAX_ROWS}'),
]

TOP_CASES = [
    (top(robot=''), "field 'robot' must be a non-empty name of printable characters"),
    (top(robot='r' * (MAX_NAME_CHARS + 1)), "field 'robot' must be a non-empty name"),
    (top(description='bell \x07'),
     "field 'description' must be text of printable characters (at most 4096), got "
     "'bell \\x07' (str)"),
    (top(convention='modern'), "field 'convention' is 'modern'; allowed: standard, modified"),
    (top(fixed_frame=5), "field 'fixed_frame' must be a tf2 frame id"),
    (lambda data: data.pop('base'), "missing field 'base' (required: robot, base, chain; or "
                                    'robot, chains)'),
]


def said(data):
    with pytest.raises(RobotDescriptionError) as caught:
        parse_robot_description(yaml.safe_dump(data), 'f.yaml')
    message = str(caught.value)
    assert '\n' not in message
    return message


@pytest.mark.parametrize('edit, where, words', CASES)
def test_a_mistake_says_its_place_and_what(edit, where, words):
    message = said(changed(edit))
    assert message.startswith(f'f.yaml: {where}: '), message
    assert words in message, message
    if words.endswith(('row', 'value)', 'for d)', 'zeros', 'not both', 'joint)')):
        assert message == f'f.yaml: {where}: {words}'   # the whole message


def test_a_chains_parent_that_is_no_frame_id_says_which_chain():
    second = {'parent': 5, 'base': {'frame': 'b1'},
              'chain': [dict(ROBOT['chain'][0], frame='z', joint='jz')]}
    data = {'robot': 'arm', 'chains': [{'parent': 'world', 'base': {'frame': 'b0'},
                                        'chain': ROBOT['chain']}, second]}
    assert said(data).startswith("f.yaml: chains[1]: field 'parent' must be a tf2 frame id")


@pytest.mark.parametrize('edit, words', TOP_CASES)
def test_a_mistake_of_the_file_itself_names_only_the_file(edit, words):
    assert said(changed(edit)).startswith(f'f.yaml: {words}')


def test_what_is_allowed_at_the_bounds_loads():
    """A name of the longest length, tabs and newlines in a description, a tiny quaternion."""
    data = changed(top(robot='r' * MAX_NAME_CHARS, description='a\tb\nc',
                       base={'frame': 'b0', 'quaternion': [1e-9, 0, 0, 0]}))
    model = parse_robot_description(yaml.safe_dump(data), 'f.yaml')
    assert model.name == 'r' * MAX_NAME_CHARS


def test_rows_are_counted_over_every_chain():
    rows = [ROBOT['chain'][0]]
    half = MAX_ROWS // 2 + 1
    chains = [{'parent': 'world', 'base': {'frame': 'b0'},
               'chain': [dict(rows[0], frame=f'a{k}', joint=f'ja{k}') for k in range(half)]},
              {'parent': 'a0', 'base': {'frame': 'b1'},
               'chain': [dict(rows[0], frame=f'c{k}', joint=f'jc{k}') for k in range(half)]}]
    message = said({'robot': 'arm', 'chains': chains})
    assert message.startswith('f.yaml: chains[1].chain: ') and \
        f'{2 * half} rows; a robot description has at most {MAX_ROWS}' in message


def test_a_prismatic_mimic_offset_moves_d_a_revolute_one_theta():
    for kind, moved in (('prismatic', 'd'), ('revolute', 'theta')):
        data = changed(row(0, type=kind),
                       row(1, type=kind, joint=None, mimic={'joint': 'j1', 'offset': 0.5}))
        data['units'] = {'angle': 'rad', 'length': 'm'}
        model = parse_robot_description(yaml.safe_dump(data), 'f.yaml')
        row_1 = model.chain.joints[1]
        assert math.isclose(getattr(row_1, moved), 0.5), (kind, row_1)


def test_a_file_that_is_no_mapping_says_so_in_its_own_words():
    """Not a robot file: public says only that; the message for the log names what it got."""
    with pytest.raises(RobotDescriptionError) as caught:
        parse_robot_description('[1, 2]', 'f.yaml')
    assert str(caught.value).startswith('f.yaml: expected a mapping with fields robot, ')
    assert str(caught.value).endswith(', got a list of 2')
    assert 'list of 2' not in caught.value.public


def test_a_link_moves_on_tf_only_where_its_tf_parent_is_another_rigid_body():
    """A fixed row, the base and the tool ride with the body before them; a moving row not."""
    data = changed(row(1, type='fixed', joint=None))   # l2 fixed to l1; the tool to l2
    data['links'] = [
        {'frame': 'cam', 'parent': 'tcp', 'tf_parent': 'l1'},      # l1's body: still
        {'frame': 'plate', 'parent': 'b0', 'tf_parent': 'world'},  # the base is the world's
        {'frame': 'mark', 'parent': 'l2', 'tf_parent': 'l1'},      # a fixed row: l1's body
        {'frame': 'flag', 'parent': 'l1', 'tf_parent': 'b0'},      # l1 turns about j1: moves
    ]
    model = parse_robot_description(yaml.safe_dump(data), 'f.yaml')
    moving = dict(zip(model.frame_names, model.moving))
    assert [moving[f] for f in ('cam', 'plate', 'mark', 'flag')] == [False, False, False, True]


def test_the_files_own_fields_each_say_what_is_wrong():
    for edit, message in (
            (top(end_effector=5), "f.yaml: field 'end_effector' must be a tf2 frame id"),
            (top(end_effector='nowhere'), "f.yaml: field 'end_effector' names 'nowhere', "
                                          'which is not a frame of the robot; frames: '),
            (top(publish_dh_frames='yes'), "f.yaml: field 'publish_dh_frames' must be true or "
                                           "false, got 'yes' (str)"),
            (top(links=[{'frame': 'cam', 'parent': 'tcp'}, {'frame': 'cam', 'parent': 'b0'}]),
             "f.yaml: links[1] (frame 'cam'): frame 'cam' is already used by links[0]"),
            (top(links=[{'frame': 'l_1', 'parent': 'tcp'}], chain=[
                dict(ROBOT['chain'][0], frame='l.1')]),
             "f.yaml: frames 'l.1' and 'l_1' would both publish on ~/pose/l_1")):
        assert said(changed(edit)).startswith(message)


def test_yaml_that_does_not_parse_says_where_and_the_source_defaults_to_string():
    with pytest.raises(RobotDescriptionError) as caught:
        parse_robot_description('robot: [unclosed')
    assert str(caught.value) == ("<string>: not valid YAML at line 1, column 17: expected ',' "
                                 "or ']', but got '<stream end>'")   # the problem, not context
    assert caught.value.public == '<string>: not valid YAML at line 1, column 17'
    with pytest.raises(RobotDescriptionError) as caught:   # a reader's error has no place
        parse_robot_description('robot: a\x01b', 'f.yaml')
    assert str(caught.value) == ('f.yaml: not valid YAML: unacceptable character #x0001: '
                                 'special characters are not allowed')


def test_a_number_python_refuses_and_a_file_of_no_robot_say_so_in_public_words():
    with pytest.raises(RobotDescriptionError) as caught:
        parse_robot_description('robot: ' + '9' * 5000, 'f.yaml')
    assert str(caught.value).startswith('f.yaml: not valid YAML: Exceeds the limit (4300 '
                                        'digits) for integer string conversion')
    assert caught.value.public == 'f.yaml: not valid YAML'
    with pytest.raises(RobotDescriptionError) as caught:
        parse_robot_description('x: 1', 'f.yaml')
    assert caught.value.public == (
        'f.yaml: not a robot description (a YAML mapping with the fields robot, base and '
        'chain (or chains), and no others than robot, description, convention, units, '
        'fixed_frame, base, chain, tool, chains, links, end_effector, publish_dh_frames)')
