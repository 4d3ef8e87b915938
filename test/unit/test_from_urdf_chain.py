"""The chain ``dq_fk from-urdf`` cuts from a URDF and the names of its DH frames."""

from dq_fk_ros.description.from_urdf import (_check_frame, _dh_frame_names, chain_joints,
                                             urdf_to_description)
from dq_fk_ros.description.robot_model import MAX_NAME_CHARS, MAX_ROWS
from dq_fk_ros.description.urdf_reader import parse_urdf
from dq_fk_ros.errors import RobotDescriptionError
import pytest


def urdf(*joints):
    """Return a URDF tree of ``(name, type, parent, child)`` joints (z axes, no origins)."""
    links = sorted({end for j in joints for end in j[2:]})
    return parse_urdf('<robot name="r">' + ''.join(f'<link name="{k}"/>' for k in links) +
                      ''.join(f'<joint name="{n}" type="{t}"><parent link="{p}"/><child '
                              f'link="{c}"/><axis xyz="0 0 1"/><limit lower="-1" upper="1" '
                              f'effort="1" velocity="1"/></joint>' for n, t, p, c in joints) +
                      '</robot>', 'r.urdf')


def test_base_and_tip_may_be_named_as_tf_names_with_a_slash():
    tree = urdf(('j1', 'revolute', 'a', 'b'), ('j2', 'revolute', 'b', 'c'))
    base, tip, joints = chain_joints(tree, '/b', '/c')
    assert (base, tip, [j.name for j in joints]) == ('b', 'c', ['j2'])
    assert chain_joints(tree)[:2] == ('a', 'c')   # the root, the end of the longest chain


def test_a_floating_joint_on_the_chain_is_refused_with_the_options_to_avoid_it():
    tree = urdf(('fly', 'floating', 'a', 'b'), ('j', 'revolute', 'b', 'c'))
    with pytest.raises(RobotDescriptionError) as caught:
        chain_joints(tree, 'a', 'c', ('urdf_base_link', 'urdf_tip_link'))
    assert str(caught.value) == (
        "r.urdf: joint 'fly' on the chain is floating; a DH chain takes revolute, continuous, "
        'prismatic, fixed and planar (as fixed) joints: choose a urdf_base_link below it or a '
        'urdf_tip_link above it')
    assert [j.name for j in chain_joints(tree, 'b', 'c')[2]] == ['j']


def test_dh_frame_names_take_the_next_pattern_while_the_urdf_holds_a_name():
    assert _dh_frame_names(2, set()) == ['dh0', 'dh1']
    assert _dh_frame_names(2, {'dh1'}) == ['dh_0', 'dh_1']
    assert _dh_frame_names(2, {'dh0', 'dh_1'}) == ['dq_fk_dh0', 'dq_fk_dh1']
    with pytest.raises(RobotDescriptionError) as caught:
        _dh_frame_names(2, {'dh0', 'dh_0', 'dq_fk_dh1'})
    assert str(caught.value) == 'the URDF uses every DH frame name dq_fk would give (dh0...)'
    tip = 't' * (MAX_NAME_CHARS - 4)   # tip_dh0: exactly the longest name
    assert _dh_frame_names(1, set(), tip) == [tip + '_dh0']
    assert _dh_frame_names(1, set(), tip + 't', 7) == ['dq_fk_chain7_dh0']   # one too long
    tip = 'x' * 100
    with pytest.raises(RobotDescriptionError) as caught:   # the first name shown in 80
        _dh_frame_names(1, {tip + '_dh0', tip + '_dh_0', tip + '_dq_fk_dh0',
                            'dq_fk_chain3_dh0'}, tip, 3)
    assert str(caught.value) == \
        f'the URDF uses every DH frame name dq_fk would give ({"x" * 80}...)'


def test_a_link_name_of_the_longest_length_is_a_frame():
    _check_frame('l' * MAX_NAME_CHARS, 'r.urdf')
    with pytest.raises(RobotDescriptionError, match='at most'):
        _check_frame('l' * (MAX_NAME_CHARS + 1), 'r.urdf')


def test_the_conversion_refuses_in_one_line_naming_its_source():
    text = '<robot name="r"><link name="a"/></robot>'
    with pytest.raises(RobotDescriptionError) as caught:
        urdf_to_description(text, convention='craig')
    assert str(caught.value) == "convention 'craig'; allowed: standard, modified"
    with pytest.raises(RobotDescriptionError) as caught:
        urdf_to_description('<robot name="r"/>')
    assert str(caught.value).startswith('<string>: ')   # no file: the text's default name
    assert urdf_to_description(text, 'r.urdf').model.source == 'r.urdf (converted)'


def urdf_text(*joints, links=()):
    """Return URDF text of ``(name, type, parent, child[, mimic])`` joints."""
    names = list(links) + sorted({end for j in joints for end in j[2:4]} - set(links))
    return ('<robot name="r">' + ''.join(f'<link name="{k}"/>' for k in names) +
            ''.join(f'<joint name="{j[0]}" type="{j[1]}"><parent link="{j[2]}"/><child '
                    f'link="{j[3]}"/><axis xyz="0 0 1"/><limit lower="-1" upper="1" effort="1" '
                    f'velocity="1"/>' + (f'<mimic joint="{j[4]}"/>' if len(j) > 4 else '') +
                    '</joint>' for j in joints) + '</robot>')


def test_a_chain_joint_mimicking_a_joint_off_the_chain_is_refused():
    text = urdf_text(('j1', 'revolute', 'a', 'b'), ('side', 'revolute', 'a', 's'),
                     ('j2', 'revolute', 'b', 'c', 'side'))
    with pytest.raises(RobotDescriptionError) as caught:
        urdf_to_description(text, 'r.urdf', 'a', 'c')
    assert str(caught.value) == ("r.urdf: joint 'j2' on the chain mimics 'side', which is not "
                                 "a moving joint of the chain 'a' -> 'c'")
    text = urdf_text(('j1', 'revolute', 'a', 'b'), ('j2', 'revolute', 'b', 'c', 'j1'))
    assert urdf_to_description(text, 'r.urdf', 'a', 'c').model.joint_names == ('j1',)


def test_side_branches_count_towards_the_rows_bound():
    branches = [(f's{k}', 'revolute', 'a', f'l{k}') for k in range(MAX_ROWS - 1)]
    text = urdf_text(('j1', 'revolute', 'a', 'b'), *branches)
    assert len(urdf_to_description(text, 'r.urdf', 'a', 'b').model.joint_names) == MAX_ROWS
    text = urdf_text(('j1', 'revolute', 'a', 'b'), *branches, ('one_more', 'revolute', 'a', 'm'))
    with pytest.raises(RobotDescriptionError) as caught:
        urdf_to_description(text, 'r.urdf', 'a', 'b')
    assert str(caught.value) == (f'r.urdf: {MAX_ROWS + 1} moving joints; a robot description '
                                 f'has at most {MAX_ROWS} rows')


@pytest.mark.parametrize('count, more', [(5, ''), (6, ' and 1 more'), (7, ' and 2 more')])
def test_link_names_with_a_slash_are_said_five_by_name(count, more):
    long = 'n' * 100
    slashed = [long] + [f'k{k}' for k in range(count - 1)]
    parents = ['root'] + ['/' + name for name in slashed]
    text = urdf_text(*[(f'j{k}', 'fixed', parents[k], parents[k + 1]) for k in range(count)],
                     ('slide', 'planar', 'root', 'puck'), links=parents)
    warnings = urdf_to_description(text, 'r.urdf').warnings
    assert len(warnings) == 2 and 'planar' in warnings[0]   # added to the others
    shown = ', '.join([('/' + long)[:80]] + ['/' + name for name in slashed[1:5]])
    assert warnings[-1] == ('r.urdf: link names with a leading slash are published without it, '
                            f'as tf2 strips it: {shown}{more}')
