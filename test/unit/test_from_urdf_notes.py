"""What ``from-urdf`` chooses and says: the default tip, each link's note, what it skipped."""

from dq_fk_ros.description.from_urdf import (load_urdf_description, longest_chain_tips,
                                             NODE_OPTIONS, urdf_to_description)
from dq_fk_ros.description.robot_model import MAX_NAME_CHARS
from dq_fk_ros.description.urdf_reader import parse_urdf
from dq_fk_ros.errors import RobotDescriptionError
import numpy as np
import pytest

LIMIT = '<limit lower="-1" upper="1" effort="1" velocity="1"/>'


def joint(name, parent, child, kind='revolute', extra=''):
    limit = LIMIT if kind in ('revolute', 'prismatic') else ''
    return (f'<joint name="{name}" type="{kind}"><parent link="{parent}"/>'
            f'<child link="{child}"/><origin xyz="0.1 0 0.2"/><axis xyz="0 1 0"/>{limit}'
            f'{extra}</joint>')


def urdf(links, joints):
    return ('<robot name="r">' + ''.join(f'<link name="{n}"/>' for n in links)
            + ''.join(joints) + '</robot>')


def tips(text, base='base'):
    return longest_chain_tips(parse_urdf(text, 'r.urdf'), base)


# two branches of one moving joint each, the URDF listing z_tip before a_tip
TWO = ['base', 'z_tip', 'a_tip', 'sensor']
TWO_JOINTS = [joint('jz', 'base', 'z_tip'), joint('ja', 'base', 'a_tip'),
              joint('js', 'base', 'sensor', 'fixed')]


def test_equally_long_chains_all_end_a_tip_in_the_urdfs_order_not_the_alphabets():
    assert tips(urdf(TWO, TWO_JOINTS)) == ['z_tip', 'a_tip']
    many = ['m', 'c', 'x', 'b', 'y', 'a']   # one order of 720: not a set's by chance
    assert tips(urdf(['base'] + many, [joint(f'j{n}', 'base', n) for n in many])) == many
    # a mimic joint does not make its chain longer
    mimic = joint('jz2', 'z_tip', 'z2', extra='<mimic joint="jz"/>')
    assert tips(urdf(TWO + ['z2'], TWO_JOINTS + [mimic])) == ['z_tip', 'a_tip']


def test_the_longest_chain_wins_whichever_branch_is_walked_first():
    for deeper in ('z_tip', 'a_tip'):
        more = [joint('j2', deeper, 'second'), joint('jf', 'second', 'flange', 'fixed')]
        text = urdf(TWO + ['second', 'flange'], TWO_JOINTS + more)
        assert tips(text) == ['second']   # the last moving joint's child, not the flange
        assert urdf_to_description(text, 'r.urdf').tip == 'second'


def test_no_moving_joint_below_the_base_has_no_tip_and_the_base_is_the_tip():
    text = urdf(['base', 'sensor'], [joint('js', 'base', 'sensor', 'fixed')])
    assert tips(text) == [None]
    assert urdf_to_description(text, 'r.urdf').tip == 'base'


def test_each_links_note_names_its_joint_its_kind_and_a_mimic():
    mimic = joint('jz2', 'z_tip', 'z2', extra='<mimic joint="jz"/>')
    text = urdf_to_description(urdf(TWO + ['z2'], TWO_JOINTS + [mimic]), 'r.urdf').text
    assert 'URDF link z2: child of jz2 (revolute, mimic) on z_tip' in text
    assert 'URDF link a_tip: child of ja (revolute) on base' in text
    assert 'URDF link sensor: child of js (fixed) on base' in text


def test_a_skipped_mimic_names_the_joint_it_follows():
    """A mimic of a joint above the base (not published) is skipped, and says which."""
    above = joint('jw', 'world', 'base')
    ghost = joint('jg', 'base', 'g', extra='<mimic joint="jw" multiplier="2" offset="3"/>')
    conversion = urdf_to_description(urdf(['world'] + TWO + ['g'],
                                          [above] + TWO_JOINTS + [ghost]), 'r.urdf', 'base')
    assert [j.name for j in conversion.skipped] == ['jg']
    assert 'skipped: side branch jg (revolute) -> g: mimics jw, which is not published' \
        in conversion.text


def test_a_joint_name_of_the_longest_length_is_taken_and_one_more_is_refused():
    for length, taken in ((MAX_NAME_CHARS, True), (MAX_NAME_CHARS + 1, False)):
        name = 'j' * length
        text = urdf(['base', 'tip'], [joint(name, 'base', 'tip')])
        if taken:
            model = urdf_to_description(text, 'r.urdf').model
            assert list(model.joint_names) == [name]
        else:
            with pytest.raises(RobotDescriptionError, match='joint name .* is not usable'):
                urdf_to_description(text, 'r.urdf')


def test_a_files_conversion_takes_the_base_and_names_the_callers_options(tmp_path):
    path = tmp_path / 'r.urdf'
    path.write_text(urdf(['world', 'base'] + TWO[1:],
                         [joint('jw', 'world', 'base', 'fixed')] + TWO_JOINTS))
    conversion, text = load_urdf_description(path, base='base', tip='a_tip')
    assert (conversion.base, conversion.tip) == ('base', 'a_tip') and '<robot' in text
    with pytest.raises(RobotDescriptionError,
                       match=f"^{path}: urdf_tip_link 'nowhere' is not a link"):
        load_urdf_description(path, tip='nowhere', options=NODE_OPTIONS)


def test_a_link_of_a_name_tf_cannot_carry_is_skipped_and_said_so():
    bad = joint('jb', 'base', 'bad name', 'fixed')
    conversion = urdf_to_description(urdf(TWO + ['bad name'], TWO_JOINTS + [bad]), 'r.urdf')
    assert [j.name for j in conversion.skipped] == ['jb']
    assert ': a name this package cannot publish' in conversion.text


def test_a_planar_and_a_floating_links_notes_say_how_they_are_published():
    text = urdf(TWO + ['puck', 'drone'],
                TWO_JOINTS + [joint('slide', 'base', 'puck', 'planar'),
                              joint('fly', 'base', 'drone', 'floating')])
    text = urdf_to_description(text, 'r.urdf').text
    assert ('URDF link puck: child of slide (planar) on base; fixed at its origin, as '
            'robot_state_publisher\n') in text
    assert ('URDF link drone: child of fly (floating) on base; at its origin, not on TF: it '
            'roots a TF tree\n') in text
    assert 'URDF link a_tip: child of ja (revolute) on base\n' in text


def test_a_link_fixed_before_the_first_moving_joint_moves_with_the_base():
    text = urdf(['base', 'mount', 'l1'], [joint('jm', 'base', 'mount', 'fixed'),
                                          joint('j1', 'mount', 'l1')])
    model = urdf_to_description(text, 'r.urdf').model
    assert [(link.frame, link.parent) for link in model.links] == [('mount', 'base'),
                                                                   ('l1', 'dh1')]


def test_a_side_chains_dh_frames_take_its_number_when_the_urdf_has_its_tips_names():
    taken = ['a_tip_dh0', 'a_tip_dh_0', 'a_tip_dq_fk_dh0']
    text = urdf(TWO + taken, TWO_JOINTS + [joint(f'x{k}', 'base', n, 'fixed')
                                           for k, n in enumerate(taken)])
    names = urdf_to_description(text, 'r.urdf').model.frame_names
    assert {'dh0', 'dh1', 'dq_fk_chain1_dh0', 'dq_fk_chain1_dh1'} <= set(names)


def test_a_continuous_joints_limit_element_gives_its_speed_and_no_position_limits():
    limited = ('<joint name="j1" type="continuous"><parent link="base"/><child link="l1"/>'
               '<axis xyz="0 0 1"/><limit lower="-1" upper="1" effort="1" velocity="2.5"/>'
               '</joint>')
    model = urdf_to_description(urdf(['base', 'l1'], [limited]), 'r.urdf').model
    assert np.isinf(model.chain.limits).all() and list(model.max_velocity) == [2.5]


def test_each_rows_note_names_its_urdf_joint_and_how_its_axis_meets_the_previous():
    more = [joint('j2', 'a_tip', 'second'), joint('jm', 'second', 'third',
                                                  extra='<mimic joint="j2"/>')]
    text = urdf_to_description(urdf(TWO + ['second', 'third'], TWO_JOINTS + more), 'r.urdf',
                               tip='third').text
    notes = [line.split('# ')[1] for line in text.splitlines() if '# URDF joint' in line]
    assert notes[0] == 'URDF joint ja (revolute): base -> a_tip; axis first'
    assert notes[1].startswith('URDF joint j2 (revolute): a_tip -> second; axis ')
    assert notes[1].endswith(' to the previous')
    assert notes[2].startswith('URDF joint jm (revolute, mimic): second -> third; axis ')


def test_a_tree_without_a_moving_joint_is_one_fixed_row_of_zeros():
    text = urdf(['base', 'sensor'], [joint('js', 'base', 'sensor', 'fixed')])
    conversion = urdf_to_description(text, 'r.urdf')
    assert '{frame: dh1, type: fixed, theta: 0.0, d: 0.0, a: 0.0, alpha: 0.0}' in \
        conversion.text.replace('"', '')
    assert '# no moving joint: a fixed row (every link is static)' in conversion.text


def test_the_header_counts_the_other_chains_and_says_how_their_dh_frames_are_named():
    three = TWO + ['third', 'q']
    joints = TWO_JOINTS + [joint('jt', 'z_tip', 'third'), joint('jq', 'a_tip', 'q')]
    text = urdf_to_description(urdf(three, joints), 'r.urdf').text
    lines = text.splitlines()
    assert lines[0] == '# Converted by `dq_fk from-urdf` from r.urdf: the chain base -> third ' \
        'and 1 more chains.'
    assert 'the DH frames are dh0..dh2 (<tip>_dh0... for the other chains); TF carries the ' \
        'URDF links under their URDF parents, as robot_state_publisher (publish_dh_frames: ' \
        'true adds the DH frames).' in lines[1]
    assert [line.strip() for line in lines if 'frame 0 in' in line] == [
        '# from base to third; frame 0 in base', '# from base to q; frame 0 in base']
    single = urdf_to_description(urdf(['base', 'a'], [joint('j', 'base', 'a')]), 'r.urdf')
    first, second = single.text.splitlines()[:2]
    assert first == '# Converted by `dq_fk from-urdf` from r.urdf: the chain base -> a.'
    assert 'dh0..dh1; TF carries' in second and 'other chains' not in second
    assert single.model.publish_dh_frames is False


def test_floating_planar_and_orphan_mimic_joints_are_said_once_five_by_name():
    floating = [f'f{k}_' + 'x' * 90 for k in range(7)]
    links = ['base', 'a'] + [f'd{k}' for k in range(7)]
    joints = [joint('j', 'base', 'a')] + [joint(n, 'base', f'd{k}', 'floating')
                                          for k, n in enumerate(floating)]
    (line,) = urdf_to_description(urdf(links, joints), 'r.urdf').warnings
    assert line.startswith('r.urdf: 7 floating joint(s) not published, as ')
    listed = line.split('published relative to it: ')[1]
    assert listed == ', '.join(f'{n[:80]} (base -> d{k}, 0 link(s) below)'
                               for k, n in enumerate(floating[:5])) + ' and 2 more'
    for count, more in ((5, ''), (6, ' and 1 more')):
        (line,) = urdf_to_description(urdf(links[:2 + count], joints[:1 + count]),
                                      'r.urdf').warnings
        assert line.endswith(f'{floating[4][:80]} (base -> d4, 0 link(s) below){more}')
    planar = [f'p{k}_' + 'y' * 90 for k in range(6)]
    joints = [joint('j', 'base', 'a')] + [joint(n, 'base', f'd{k}', 'planar')
                                          for k, n in enumerate(planar)]
    (line,) = urdf_to_description(urdf(links[:8], joints), 'r.urdf').warnings
    assert line.endswith(': ' + ', '.join(n[:80] for n in planar[:5]) + ' ... (1 more)')
    orphans = [joint(f'm{k}', 'base', f'd{k}', extra=f'<mimic joint="ghost{k}"/>')
               for k in range(6)]
    (line,) = urdf_to_description(urdf(links[:8], [joint('j', 'base', 'a')] + orphans),
                                  'r.urdf').warnings
    assert line.startswith('r.urdf: 6 mimic joint(s) of joints the URDF does not have')
    assert line.endswith('moves them: m0, m1, m2, m3, m4 ... (1 more)')


def test_a_floating_joints_parent_and_child_are_named_in_80_characters():
    parent, child = 'p' * 100, 'c' * 100
    text = urdf(['base', 'a', parent, child], [joint('j', 'base', 'a'),
                                               joint('jp', 'base', parent, 'fixed'),
                                               joint('fly', parent, child, 'floating')])
    (line,) = urdf_to_description(text, 'r.urdf').warnings
    assert line.endswith(f': fly ({parent[:80]} -> {child[:80]}, 0 link(s) below)')
