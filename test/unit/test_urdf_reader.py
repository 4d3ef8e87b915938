"""Reading a URDF or xacro file: its bounds, what is passed to xacro, and each refusal."""

import sys
import xml.etree.ElementTree as ElementTree

from dq_fk_ros.description import urdf_reader
from dq_fk_ros.description.robot_model import MAX_LENGTH_M
from dq_fk_ros.description.urdf_reader import (
    MAX_URDF_BYTES, MAX_URDF_ELEMENTS, parse_urdf, parse_xml, read_urdf_text)
from dq_fk_ros.errors import RobotDescriptionError
import numpy as np
import pytest


def refusal(path, **kwargs):
    with pytest.raises(RobotDescriptionError) as caught:
        read_urdf_text(path, **kwargs)
    return str(caught.value)


def test_a_file_of_exactly_the_bound_is_read_whole_and_one_byte_more_is_refused(tmp_path):
    path = tmp_path / 'r.urdf'
    path.write_bytes(b'x' * MAX_URDF_BYTES)
    assert len(read_urdf_text(path)) == MAX_URDF_BYTES
    path.write_bytes(b'x' * (MAX_URDF_BYTES + 1))
    assert refusal(path) == (f'{path}: larger than {MAX_URDF_BYTES // 1024} KiB; a URDF is '
                             f'at most that big')


def test_a_file_that_grows_after_its_size_was_read_is_read_to_the_bound_only(
        tmp_path, monkeypatch):
    path = tmp_path / 'r.urdf'
    path.write_bytes(b'x' * (MAX_URDF_BYTES + 100))
    monkeypatch.setattr(urdf_reader.os.path, 'getsize', lambda _: 10)   # small when asked
    asked = []
    real_open = open

    class Recorder:
        """The file, its ``read(n)`` recording ``n``."""

        def __init__(self, name, mode):
            self.stream = real_open(name, mode)

        def __enter__(self):
            return self

        def __exit__(self, *exc):
            self.stream.close()

        def read(self, size=-1):
            asked.append(size)
            return self.stream.read(size)
    monkeypatch.setattr(urdf_reader, 'open', Recorder, raising=False)
    assert refusal(path) == (f'{path}: larger than {MAX_URDF_BYTES // 1024} KiB; a URDF is '
                             f'at most that big')
    assert asked == [MAX_URDF_BYTES + 1]


def test_each_unreadable_file_is_said_in_one_line(tmp_path, monkeypatch):
    path = tmp_path / 'r.urdf'
    path.write_bytes(b'<robot name="\xff"/>')
    assert refusal(path) == f'{path}: not UTF-8 text'

    def denied(*args, **kwargs):
        raise PermissionError(13, 'Permission denied')
    monkeypatch.setattr(urdf_reader, 'open', denied, raising=False)
    assert refusal(path) == f'{path}: cannot be read (Permission denied)'


def test_a_xacro_file_without_xacro_installed_says_how_to_get_it(tmp_path, monkeypatch):
    path = tmp_path / 'r.urdf.xacro'
    path.write_text('<robot name="r"/>')
    monkeypatch.setitem(sys.modules, 'xacro', None)   # import xacro: ImportError
    assert refusal(path) == f'{path}: a .xacro file needs the xacro package (pip install xacro)'


def test_the_xacro_expansion_gets_the_time_limit_roots_and_packages_given(
        tmp_path, monkeypatch):
    path = tmp_path / 'r.urdf.xacro'
    path.write_text('<robot name="r"/>')
    calls = []

    def expand(*args, **kwargs):
        calls.append((args, kwargs))
        return '<robot name="expanded"/>'
    monkeypatch.setattr(urdf_reader, 'expand_xacro', expand)
    stop = object()
    assert read_urdf_text(path, ['/a'], 2.5, stop, {'p': '/p'}, ['/w']) == \
        '<robot name="expanded"/>'
    keywords = {'should_stop': stop, 'packages': {'p': '/p'}, 'within': ['/w']}
    assert calls == [((str(path), ['/a'], 2.5), keywords)]


def one_joint(joint_xml):
    """Return the URDF text of links a, b and one joint between them (``{}``: its body)."""
    return ('<robot name="r"><link name="a"/><link name="b"/>' + joint_xml.format(
        '<parent link="a"/><child link="b"/>') + '</robot>')


def joint_refusal(joint_xml):
    with pytest.raises(RobotDescriptionError) as caught:
        parse_urdf(one_joint(joint_xml), 'r.urdf')
    return str(caught.value)


def test_each_malformed_joint_is_said_in_one_line():
    assert joint_refusal('<joint type="fixed">{}</joint>') == 'r.urdf: a <joint> without a name'
    assert joint_refusal('<joint name="j">{}</joint>') == (
        "r.urdf: joint 'j': type ''; allowed: revolute, continuous, prismatic, fixed, "
        'floating, planar')
    assert joint_refusal('<joint name="j" type="fixed">{}<origin rpy="a b"/></joint>') == \
        "r.urdf: joint 'j': origin rpy: 'a b' is not 3 numbers"
    assert joint_refusal('<joint name="j" type="revolute">{}<axis xyz="1 0"/></joint>') == \
        "r.urdf: joint 'j': axis xyz: '1 0' is not 3 finite numbers"
    over = f'{MAX_LENGTH_M * 1.0000001:.9g}'
    assert joint_refusal(f'<joint name="j" type="fixed">{{}}<origin xyz="{over} 0 0"/></joint>') \
        == f"r.urdf: joint 'j': origin xyz is beyond {MAX_LENGTH_M:g} m"


def test_a_joints_defaults_and_bounds_are_urdfs():
    tree = parse_urdf(one_joint('<joint name="j" type="fixed">{}<origin rpy="0 0 1"/></joint>'))
    np.testing.assert_allclose(tree.joints['b'].origin[:3, 3], [0, 0, 0], atol=0)
    np.testing.assert_allclose(tree.joints['b'].axis, [1, 0, 0], atol=0)   # no <axis>
    tree = parse_urdf(one_joint('<joint name="j" type="revolute">{}<axis/></joint>'))
    np.testing.assert_allclose(tree.joints['b'].axis, [1, 0, 0], atol=0)   # <axis> no xyz
    tree = parse_urdf(one_joint(f'<joint name="j" type="fixed">{{}}<origin '
                                f'xyz="{MAX_LENGTH_M:.17g} 0 0"/></joint>'))   # at the bound
    assert tree.joints['b'].origin[0, 3] == MAX_LENGTH_M
    # a tiny axis is still a direction: more than 1e-12 long
    tree = parse_urdf(one_joint('<joint name="j" type="revolute">{}<axis xyz="1e-12 1e-12 '
                                '1e-12"/></joint>'))
    np.testing.assert_allclose(tree.joints['b'].axis, np.full(3, 1 / np.sqrt(3)), atol=1e-15)
    assert joint_refusal('<joint name="j" type="revolute">{}<axis xyz="5e-13 0 0"/></joint>') \
        == "r.urdf: joint 'j': axis xyz is all zeros"


def tree_refusal(text, source='r.urdf'):
    with pytest.raises(RobotDescriptionError) as caught:
        parse_urdf(text, source) if source is not None else parse_urdf(text)
    return caught.value


def test_each_malformed_urdf_is_said_in_one_line():
    assert str(tree_refusal('<robot/>', None)) == '<string>: no <link> elements'
    assert str(tree_refusal('<!DOCTYPE r [<!ENTITY x "y">]><robot/>')) == \
        'r.urdf: XML entity declarations are not accepted in a URDF'
    assert str(tree_refusal('<!DOCTYPE r [<!entity x "y">]><robot/>')).startswith(
        'r.urdf: not valid XML: ')   # (expat's words: no entity in lower case either)
    error = tree_refusal('<' + 's' * 50 + '/>')
    assert str(error) == f'r.urdf: the root element is <{"s" * 40}>, not <robot>; is this a URDF?'
    assert error.public == 'r.urdf: the root element is not <robot>; not a URDF'
    assert str(tree_refusal('<robot><link/></robot>')) == 'r.urdf: a <link> without a name'
    long = 'l' * 80
    assert str(tree_refusal(f'<robot><link name="{long}"/><link name="{long}"/></robot>')) == \
        f"r.urdf: link '{long[:70]}' is defined twice"
    joint = '<joint name="{}" type="fixed"><parent link="a"/><child link="{}"/></joint>'
    links = '<link name="a"/><link name="b"/><link name="c"/>'
    assert str(tree_refusal('<robot>' + links + joint.format(long, 'b') + joint.format(long, 'c')
                            + '</robot>')) == f"r.urdf: joint '{long[:70]}' is defined twice"
    links += f'<link name="{long}"/>'
    assert str(tree_refusal('<robot>' + links + joint.format(long, long) +
                            joint.format(long + 'x', long) + '</robot>')) == (
        f"r.urdf: link '{long[:70]}' is the child of two joints ('{long[:70]}' and "
        f"'{long[:70]}'); a URDF is a tree")


def test_a_urdf_without_a_robot_name_is_robot():
    assert parse_urdf('<robot><link name="a"/></robot>').name == 'robot'
    assert parse_urdf('<robot name=""><link name="a"/></robot>').name == 'robot'


def test_the_element_bound_holds_at_its_edge_for_links_and_joints():
    links = ''.join(f'<link name="l{k}"/>' for k in range(MAX_URDF_ELEMENTS))
    assert len(parse_urdf(f'<robot>{links}</robot>').links) == MAX_URDF_ELEMENTS
    assert str(tree_refusal(f'<robot>{links}<link name="x"/></robot>')) == \
        f'r.urdf: {MAX_URDF_ELEMENTS + 1} <link> elements; a URDF has at most {MAX_URDF_ELEMENTS}'
    joints = ''.join(f'<joint name="j{k}" type="fixed"><parent link="l0"/><child link="l{k}"/>'
                     '</joint>' for k in range(1, MAX_URDF_ELEMENTS + 2))
    assert str(tree_refusal(f'<robot>{links}{joints}</robot>')) == \
        f'r.urdf: {MAX_URDF_ELEMENTS + 1} <joint> elements; a URDF has at most ' \
        f'{MAX_URDF_ELEMENTS}'


def test_each_malformed_limit_and_mimic_is_said_in_one_line():
    assert joint_refusal('<joint name="j" type="revolute">{}<limit lower="x"/></joint>') == \
        "r.urdf: joint 'j': limit lower: 'x' is not 1 numbers"
    assert joint_refusal('<joint name="j" type="revolute">{}<limit upper="x"/></joint>') == \
        "r.urdf: joint 'j': limit upper: 'x' is not 1 numbers"
    assert joint_refusal('<joint name="j" type="revolute">{}<limit lower="1" upper="0.5"/>'
                         '</joint>') == "r.urdf: joint 'j': limit lower 1 is above upper 0.5"
    assert joint_refusal('<joint name="j" type="revolute">{}<mimic/></joint>') == \
        "r.urdf: joint 'j': <mimic> without a joint"
    for field in ('multiplier', 'offset'):
        assert joint_refusal(f'<joint name="j" type="revolute">{{}}<mimic joint="k" '
                             f'{field}="nan"/></joint>') == \
            f"r.urdf: joint 'j': mimic {field}: 'nan' is not 1 finite numbers"


def test_xml_is_read_with_its_text_and_expat_says_where_it_broke():
    assert parse_xml('<name> arm_description </name>').text == ' arm_description '
    with pytest.raises(ElementTree.ParseError) as caught:
        parse_xml('<robot>')
    assert str(caught.value) == 'no element found: line 1, column 7'
    assert caught.value.position == (1, 7)
    assert str(tree_refusal('<robot>')) == \
        'r.urdf: not valid XML: no element found: line 1, column 7'


def test_a_cycle_below_the_root_names_a_link_of_it():
    long = 'c' * 80
    joint = '<joint name="{}" type="fixed"><parent link="{}"/><child link="{}"/></joint>'
    text = (f'<robot><link name="root"/><link name="{long}"/><link name="d"/>' +
            joint.format('j1', long, 'd') + joint.format('j2', 'd', long) + '</robot>')
    assert str(tree_refusal(text)) == \
        f"r.urdf: the joints form a cycle through link '{long[:70]}'"
