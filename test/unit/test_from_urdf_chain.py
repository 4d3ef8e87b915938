"""The chain ``dq_fk from-urdf`` cuts from a URDF and the names of its DH frames."""

from dq_fk_ros.description.from_urdf import _check_frame, _dh_frame_names, chain_joints
from dq_fk_ros.description.robot_model import MAX_NAME_CHARS
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
