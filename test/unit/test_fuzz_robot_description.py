"""
Fuzzing the robot description loader: whatever a file holds, one clear error or a model.

Mutations of every shipped robot file (fields deleted, renamed, duplicated, given wrong
types, huge or non-finite numbers, control characters, deep nesting, long strings) must
give :class:`RobotDescriptionError` or a valid :class:`RobotModel`, never another exception.
"""

import copy
import math

from dq_fk_ros.description.robot_model import FRAME_ID, JOINT_NAME, pose_topic_name, TF_FRAME_ID
from dq_fk_ros.description.schema import load_robot_description, parse_robot_description
from dq_fk_ros.description.shipped import shipped_robot_path, shipped_robots
from dq_fk_ros.errors import RobotDescriptionError
from hypothesis import given, strategies as st
import numpy as np
import pytest
import yaml

ROBOTS = {name: yaml.safe_load(open(shipped_robot_path(name), encoding='utf-8'))
          for name in shipped_robots()}

NASTY_TEXT = st.one_of(
    st.text(max_size=20),
    st.sampled_from(['elbow\n', 'a b', '"q"', 'x --> <evil/> <!-- ', '/leading', 'trail/',
                     'a//b', 'a/1b', '1abc', 'tab\there', 'nul\x00', 'bell\x07', 'é',
                     'x' * 300, '']),
)
NASTY_NUMBER = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True),
    st.integers(min_value=-10**400, max_value=10**400),
    st.sampled_from([1e308, -1e308, 5e-324, 10**400, 0, -0.0]),
)
LEAF = st.one_of(NASTY_TEXT, NASTY_NUMBER, st.booleans(), st.none())
VALUE = st.recursive(LEAF, lambda inner: st.one_of(
    st.lists(inner, max_size=4), st.dictionaries(NASTY_TEXT, inner, max_size=3)),
    max_leaves=8)


def paths(data, prefix=()):
    """Every (path, value) in nested dicts and lists."""
    yield prefix, data
    if isinstance(data, dict):
        for key, value in data.items():
            yield from paths(value, prefix + (key,))
    elif isinstance(data, list):
        for k, value in enumerate(data):
            yield from paths(value, prefix + (k,))


def parent_of(data, path):
    for key in path[:-1]:
        data = data[key]
    return data


@st.composite
def mutated(draw):
    """Draw a shipped robot's data with 1-3 random mutations."""
    data = copy.deepcopy(ROBOTS[draw(st.sampled_from(sorted(ROBOTS)))])
    for _ in range(draw(st.integers(1, 3))):
        places = [p for p, _ in paths(data) if p]
        path = draw(st.sampled_from(places))
        parent = parent_of(data, path)
        kind = draw(st.sampled_from(['replace', 'delete', 'rename', 'duplicate']))
        if kind == 'replace':
            parent[path[-1]] = draw(VALUE)
        elif kind == 'delete':
            del parent[path[-1]]
        elif kind == 'rename' and isinstance(parent, dict):
            parent[draw(NASTY_TEXT)] = parent.pop(path[-1])
        elif isinstance(parent, list):
            parent.insert(path[-1], copy.deepcopy(parent[path[-1]]))
        if not places:
            break
    return data


def check(text):
    """Parse ``text``; a model must be valid, anything else a one-line error."""
    try:
        model = parse_robot_description(text, 'fuzz.yaml')
    except RobotDescriptionError as exc:
        message = str(exc)
        assert message.startswith('fuzz.yaml') and '\n' not in message, message
        assert len(message) < 600, message
        return None
    for name in model.frame_names + (model.fixed_frame,):
        assert TF_FRAME_ID.fullmatch(name), name
    for topic in model.topic_names:
        assert FRAME_ID.fullmatch(topic), topic
    for name in model.joint_names:
        assert JOINT_NAME.fullmatch(name), name
    assert model.name.isprintable()
    frames = model.chain.forward_all(np.zeros(model.chain.dof))
    assert np.isfinite(frames).all()
    return model


@given(mutated())
def test_mutated_robot_files_give_a_model_or_one_clear_error(data):
    check(yaml.safe_dump(data, allow_unicode=True))


@given(st.sampled_from(sorted(ROBOTS)), st.integers(0, 10_000), st.binary(max_size=8))
def test_text_damage_gives_a_model_or_one_clear_error(name, at, junk):
    text = open(shipped_robot_path(name), encoding='utf-8').read()
    at %= len(text)
    check(text[:at] + junk.decode('latin-1') + text[at:])


@pytest.mark.parametrize('text, words', [
    ('a: ' + '9' * 400, "field 'a' must be a finite number, got an integer of 400 digits"),
    ('a: ' + '9' * 5000, 'not valid YAML: Exceeds the limit'),
    ('a: ' + '[' * 5000 + ']' * 5000, 'nested too deeply'),
    ('a: {' * 3000 + '}' * 3000, 'nested too deeply'),
])
def test_the_classes_that_crashed_the_loader(text, words):
    """A 400-digit integer (OverflowError) and deep nesting (RecursionError) crashed it."""
    base = open(shipped_robot_path('rl15'), encoding='utf-8').read()
    with pytest.raises(RobotDescriptionError, match='^rl15.yaml: .*') as info:
        parse_robot_description(base.replace('a: 200', text, 1), 'rl15.yaml')
    assert words in str(info.value) and '\n' not in str(info.value)


def with_frame(name):
    base = open(shipped_robot_path('rl15'), encoding='utf-8').read()
    return base.replace('frame: shoulder_seg1', f'frame: {yaml.safe_dump(name).strip()}'
                        .replace('\n...', ''), 1)


@pytest.mark.parametrize('name', ['elbow\n', 'a b', '/world', 'tab\t', 'x' * 129, 'ü', ''])
def test_frame_names_follow_tf2(name):
    r"""``$`` used to match before a trailing newline: 'elbow\n' passed as a frame name."""
    with pytest.raises(RobotDescriptionError, match="field 'frame' must be a tf2 frame id"):
        parse_robot_description(with_frame(name), 'x.yaml')


@pytest.mark.parametrize('name, topic', [("it's", 'it_s'), ('a/1b', 'a/_1b'), ('x/', 'x/_'),
                                         ('a//b', 'a/_/b'), ('link_11.0', 'link_11_0'),
                                         ('finger-1', 'finger_1'), ('2nd', '_2nd')])
def test_frames_tf2_takes_are_published_with_a_valid_topic_name(name, topic):
    """The Allegro hand's link_11.0 was refused; its TF name stays, its topic is link_11_0."""
    model = parse_robot_description(with_frame(name), 'x.yaml')
    assert name in model.frame_names
    assert model.topic_names[model.frame_names.index(name)] == topic


def test_two_frames_with_one_topic_name_are_an_error_naming_both():
    text = with_frame('wrist.1').replace('frame: wrist_seg5', 'frame: wrist-1', 1)
    with pytest.raises(RobotDescriptionError, match="frames 'wrist.1' and 'wrist-1' would both "
                       'publish on ~/pose/wrist_1'):
        parse_robot_description(text, 'x.yaml')


def test_every_accepted_frame_name_is_a_valid_ros_topic_token():
    """The rule above is ROS's own: rclpy accepts ~/pose/<frame> for every accepted name."""
    from rclpy.validate_full_topic_name import validate_full_topic_name
    from rclpy.validate_topic_name import InvalidTopicNameException
    rng = np.random.default_rng(11)
    alphabet = list('abcXYZ_019/ .-\n')
    accepted = refused_by_ros = 0
    for _ in range(3000):
        name = ''.join(rng.choice(alphabet, size=rng.integers(1, 8)))
        if TF_FRAME_ID.fullmatch(name):  # its topic name is one ROS takes
            validate_full_topic_name(f'/dq_fk_node/pose/{pose_topic_name(name)}')
        if FRAME_ID.fullmatch(name):
            accepted += 1
            validate_full_topic_name(f'/dq_fk_node/pose/{name}')
        else:
            try:
                validate_full_topic_name(f'/dq_fk_node/pose/{name}')
            except InvalidTopicNameException:
                refused_by_ros += 1
    assert accepted > 100 and refused_by_ros > 100


@pytest.mark.parametrize('robot', ['x\n', 'bell\x07', '', ' ', 'x' * 129])
def test_robot_names_with_control_characters_are_refused(robot):
    base = open(shipped_robot_path('rl15'), encoding='utf-8').read()
    text = base.replace('robot: rl15', f'robot: {robot!r}'.replace("'", '"'))
    with pytest.raises(RobotDescriptionError, match="field 'robot' must be a non-empty name"):
        parse_robot_description(text, 'x.yaml')


def test_limits_of_size(tmp_path):
    base = open(shipped_robot_path('rl15'), encoding='utf-8').read()
    row = '  - {frame: f%d, joint: j%d, theta: 0, d: 0, a: 1, alpha: 0}\n'
    head = base[:base.index('chain:') + len('chain:\n')]
    many = head + ''.join(row % (k, k) for k in range(257))
    with pytest.raises(RobotDescriptionError, match='257 rows; a robot description has at '
                                                    'most 256'):
        parse_robot_description(many, 'x.yaml')
    big = tmp_path / 'big.yaml'
    big.write_text(base + '#' * (1 << 20))
    with pytest.raises(RobotDescriptionError, match='larger than 1024 KiB'):
        load_robot_description(big)


def test_a_huge_base_quaternion_is_normalised_without_overflow(recwarn):
    """A base quaternion of 1e308 printed a numpy overflow warning and blamed 'chain'."""
    base = open(shipped_robot_path('rl15'), encoding='utf-8').read()
    text = base.replace('rpy: [0, 0, 0]}', 'quaternion: [1.0e+308, 0, 0, 1.0e+308]}', 1)
    model = parse_robot_description(text, 'x.yaml')
    rotation = model.chain.base.rotation_wxyz
    np.testing.assert_allclose(rotation, [math.sqrt(0.5), math.sqrt(0.5), 0, 0], atol=1e-15)
    assert not [w for w in recwarn if 'overflow' in str(w.message)]
