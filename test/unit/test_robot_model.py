"""The robot description file: units, structure, and one clear line for every mistake."""

import dataclasses
import math

from dq_fk_ros.description.robot_model import MAX_ROWS
from dq_fk_ros.description.schema import load_robot_description, parse_robot_description
from dq_fk_ros.description.shipped import shipped_robot_path
from dq_fk_ros.description.yaml_fields import yaml_number
from dq_fk_ros.errors import RobotDescriptionError
import homogeneous as hm
from hypothesis import given, strategies as st
import numpy as np
import pytest

GOOD = """
robot: demo
convention: standard
units: {length: mm, angle: deg}
fixed_frame: world
base: {frame: base0, xyz: [0, 0, 500], rpy: [0, 0, 90]}
chain:
  - {frame: link1, joint: j1, theta: 0, d: 100, a: 200, alpha: 90, limits: [-90, 90]}
  - {frame: link2, joint: j2, type: prismatic, theta: 30, d: 50, a: 0, alpha: 0,
     limits: [0, 300], max_velocity: 250}
  - {frame: link3, type: fixed, theta: 0, d: 0, a: 100, alpha: 0}
  - {frame: link4, theta: 10, d: 0, a: 0, alpha: 0, mimic: {joint: j1, multiplier: -2,
     offset: 5}}
tool: {frame: tcp, xyz: [0, 0, 20], quaternion: [0, 0, 0, 1]}
"""


def test_a_good_file_in_mm_and_deg_becomes_metres_and_radians():
    model = parse_robot_description(GOOD, 'good.yaml')
    assert model.frame_names == ('base0', 'link1', 'link2', 'link3', 'link4', 'tcp')
    assert model.parent_frames == ('world', 'base0', 'link1', 'link2', 'link3', 'link4')
    assert model.moving == (False, True, True, False, True, False)
    assert model.joint_names == ('j1', 'j2')
    np.testing.assert_allclose(model.limits, [[-math.pi / 2, math.pi / 2], [0, 0.3]])
    np.testing.assert_allclose(model.max_velocity, [math.inf, 0.25])
    q = np.array([0.3, 0.1])
    deg = math.pi / 180
    expected = hm.chain_frames(
        [(0.3, 0.1, 0.2, 90 * deg), (30 * deg, 0.05 + 0.1, 0, 0), (0, 0, 0.1, 0),
         (10 * deg - 2 * 0.3 + 5 * deg, 0, 0, 0)], 'standard',
        base=hm.trans(z=0.5) @ hm.rot_z(90 * deg), tool=hm.trans(z=0.02))
    from dq_fk_ros.kinematics.dh import homogeneous_from_dq
    np.testing.assert_allclose(homogeneous_from_dq(model.chain.forward_all(q)), expected,
                               atol=1e-12)


def test_defaults_are_metres_radians_standard_world():
    model = parse_robot_description(
        'robot: r\nbase: {frame: b}\nchain:\n  - {frame: l1, joint: j, theta: 0, d: 1, '
        'a: 0, alpha: 0}\n')
    assert model.fixed_frame == 'world' and model.chain.convention == 'standard'
    np.testing.assert_allclose(model.chain.forward([0.0]).translation, [0, 0, 1])


def test_rpy_is_urdf_fixed_axis_order():
    model = parse_robot_description(
        'robot: r\nbase: {frame: b, rpy: [0.1, 0.2, 0.3]}\nchain:\n'
        '  - {frame: l1, type: fixed, theta: 0, d: 0, a: 0, alpha: 0}\n')
    expected = hm.rot_z(0.3) @ hm.rot_y(0.2) @ hm.rot_x(0.1)
    np.testing.assert_allclose(model.chain.base.to_matrix(), expected, atol=1e-12)


def edit(text, old, new):
    assert old in text, old
    return text.replace(old, new, 1)


ROW1 = '{frame: link1, joint: j1, theta: 0, d: 100, a: 200, alpha: 90, limits: [-90, 90]}'

BAD_CASES = [
    # (what, edited text, words the one-line message must contain)
    ('missing field', edit(GOOD, 'alpha: 90, limits', 'limits'),
     ["chain[0] (frame 'link1')", "missing field 'alpha'"]),
    ('typo in a field name', edit(GOOD, 'alpha: 90, limits', 'alfa: 90, limits'),
     ["chain[0] (frame 'link1')", "unknown field 'alfa'", 'allowed fields: frame, joint']),
    ('unknown top-level field', GOOD + 'colour: red\n', ["unknown field 'colour'"]),
    ('wrong type', edit(GOOD, 'a: 200', 'a: two hundred'),
     ["chain[0] (frame 'link1')", "field 'a' must be a number", "'two hundred'"]),
    ('boolean is not a number', edit(GOOD, 'd: 100', 'd: true'), ["field 'd' must be a number"]),
    ('NaN', edit(GOOD, 'd: 100', 'd: .nan'), ["field 'd' must be a finite number", 'nan']),
    ('infinity', edit(GOOD, 'a: 200', 'a: .inf'), ["field 'a' must be a finite number"]),
    ('unknown convention', edit(GOOD, 'convention: standard', 'convention: craig'),
     ["field 'convention' is 'craig'", 'allowed: standard, modified']),
    ('unknown joint type', edit(GOOD, 'type: prismatic', 'type: spherical'),
     ["chain[1] (frame 'link2')", "field 'type' is 'spherical'",
      'allowed: revolute, prismatic, cylindrical, fixed']),
    ('unknown length unit', edit(GOOD, 'length: mm', 'length: inch'),
     ['units', "field 'length' is 'inch'", 'allowed: m, cm, mm']),
    ('unknown angle unit', edit(GOOD, 'angle: deg', 'angle: grad'),
     ["field 'angle' is 'grad'", 'allowed: rad, deg']),
    ('duplicate frame', edit(GOOD, 'frame: link2', 'frame: link1'),
     ["frame 'link1' is already used by chain[0]", 'unique']),
    ('frame clashes with the fixed frame', edit(GOOD, 'frame: link2', 'frame: world'),
     ["frame 'world' is already used by fixed_frame"]),
    ('duplicate joint', edit(GOOD, 'joint: j2', 'joint: j1'),
     ["chain[1] (frame 'link2')", "joint 'j1' is already read by chain[0]"]),
    ('leading slash in a frame id', edit(GOOD, 'frame: link1', 'frame: /link1'),
     ["field 'frame' must be a tf2 frame id", "'/link1'"]),
    ('negative speed', edit(GOOD, 'max_velocity: 250', 'max_velocity: -1'),
     ["chain[1] (frame 'link2'): field 'max_velocity' must be a positive speed (per second), "
      'got -1']),
    ('d_joint on a revolute row', edit(GOOD, 'joint: j1,', 'joint: j1, d_joint: j1d,'),
     ["chain[0] (frame 'link1'): field 'd_joint' applies only to a cylindrical row"]),
    ('limits upside down', edit(GOOD, 'limits: [0, 300]', 'limits: [300, 0]'),
     ["field 'limits' has lower 300 above upper 0"]),
    ('zero scale', edit(GOOD, ROW1, ROW1[:-1] + ', scale: 0}'), ["field 'scale' must not be 0"]),
    ('mimic of an unknown joint', edit(GOOD, 'mimic: {joint: j1', 'mimic: {joint: j9'),
     ["chain[3] (frame 'link4') mimic", "names 'j9', which no row reads; joints: j1, j2"]),
    ('joint field on a fixed row', edit(GOOD, '{frame: link3, type: fixed,',
                                        '{frame: link3, type: fixed, joint: j3,'),
     ["field 'joint' does not apply to a fixed row"]),
    ('revolute row without a joint', edit(GOOD, 'joint: j1, ', ''),
     ["chain[0] (frame 'link1')", "missing field 'joint'"]),
    ('rpy and quaternion together', edit(GOOD, 'xyz: [0, 0, 20],', 'rpy: [0, 0, 0],'),
     ['tool', "either 'rpy' or 'quaternion'"]),
    ('short vector', edit(GOOD, 'xyz: [0, 0, 500]', 'xyz: [0, 500]'),
     ['base', "field 'xyz' must be a list of 3 numbers"]),
    ('empty chain', 'robot: r\nbase: {frame: b}\nchain: []\n',
     ['chain', 'expected a non-empty list']),
    ('not a mapping', '- just\n- a list\n', ['expected a mapping']),
    ('empty file', '', ['expected a mapping', 'got nothing']),
    ('missing base', edit(GOOD, 'base: {frame: base0, xyz: [0, 0, 500], rpy: [0, 0, 90]}\n',
                          ''), ["missing field 'base'"]),
    ('duplicate YAML key', edit(GOOD, 'convention: standard', 'convention: standard\n'
                                'convention: modified'),
     ['not valid YAML', 'line 4', "duplicate key 'convention'"]),
    ('not YAML', 'robot: [unclosed\n', ['not valid YAML', 'line']),
    ('mimic joint name that is no joint name',
     edit(GOOD, 'mimic: {joint: j1', 'mimic: {joint: 9j'),
     ["chain[3] (frame 'link4') mimic", "field 'joint' must be a joint name", "'9j'"]),
    ('cylindrical row without d_joint',
     edit(GOOD, 'tool: {', '  - {frame: link5, type: cylindrical, joint: j5, theta: 0, d: 0, '
          'a: 0, alpha: 0}\ntool: {'),
     ["chain[4] (frame 'link5')", "missing field 'd_joint'"]),
]
PLACES = ('chain[', 'units', 'base', 'tool', 'chain')


@pytest.mark.parametrize('what, text, words', BAD_CASES, ids=[c[0] for c in BAD_CASES])
def test_every_mistake_is_one_clear_line(what, text, words, tmp_path):
    path = tmp_path / 'robot.yaml'
    path.write_text(text)
    with pytest.raises(RobotDescriptionError) as info:
        load_robot_description(path)
    message = str(info.value)
    assert '\n' not in message
    assert message.startswith(f'{path}: ')
    if words[0].startswith(PLACES):  # the place comes first, right after the file
        assert message.startswith(f'{path}: {words[0]}'), message
    for word in words:
        assert word in message, f'{word!r} not in {message!r}'


def test_missing_file_and_directory(tmp_path):
    with pytest.raises(RobotDescriptionError, match='no such file'):
        load_robot_description(tmp_path / 'nope.yaml')
    with pytest.raises(RobotDescriptionError, match='is a directory'):
        load_robot_description(tmp_path)


def test_binary_file_is_a_clear_error(tmp_path):
    path = tmp_path / 'robot.yaml'
    path.write_bytes(b'\xff\xfe\x00garbage')
    with pytest.raises(RobotDescriptionError, match='cannot be read|not valid YAML'):
        load_robot_description(path)


def test_a_cylindrical_row_with_limits_on_both_joints():
    """Both joints of a cylindrical row get their own limits, in their own units."""
    model = parse_robot_description(
        'robot: r\nunits: {length: mm, angle: deg}\nbase: {frame: b}\nchain:\n'
        '  - {frame: l1, type: cylindrical, joint: spin, d_joint: lift, theta: 0, d: 0, a: 0,'
        ' alpha: 0, limits: [-90, 90], d_limits: [0, 250], d_max_velocity: 100}\n', 'cyl.yaml')
    assert model.joint_names == ('spin', 'lift')
    np.testing.assert_allclose(model.limits, [[-math.pi / 2, math.pi / 2], [0.0, 0.25]])
    np.testing.assert_allclose(model.max_velocity, [math.inf, 0.1])


def test_a_joint_without_limits_has_none():
    """The default limits are (-inf, inf): (inf, inf) would make 'reject' refuse everything."""
    model = load_robot_description(shipped_robot_path('rl15'))
    assert model.limits.tolist() == [[-math.inf, math.inf]] * 6


def test_a_chain_of_the_largest_allowed_size_loads():
    rows = ''.join(f'  - {{frame: f{k}, joint: j{k}, theta: 0, d: 0, a: 1, alpha: 0}}\n'
                   for k in range(MAX_ROWS))
    model = parse_robot_description(f'robot: big\nbase: {{frame: b}}\nchain:\n{rows}')
    assert model.chain.dof == MAX_ROWS
    with pytest.raises(RobotDescriptionError, match=f'{MAX_ROWS + 1} rows; a robot description '
                                                    f'has at most {MAX_ROWS}'):
        parse_robot_description(f'robot: big\nbase: {{frame: b}}\nchain:\n{rows}'
                                f'  - {{frame: extra, joint: jx, theta: 0, d: 0, a: 1, '
                                f'alpha: 0}}\n')


def test_long_values_are_shortened_at_both_ends_in_messages():
    name = 'a' * 50 + 'b' * 50
    with pytest.raises(RobotDescriptionError) as caught:
        parse_robot_description(edit(GOOD, 'convention: standard', f'convention: {name}'),
                                'r.yaml')
    shown = repr(name)
    assert f"field 'convention' is {shown[:40]}...{shown[-12:]}; allowed" in str(caught.value)


def test_a_robot_model_cannot_be_changed():
    model = parse_robot_description(GOOD)
    with pytest.raises(dataclasses.FrozenInstanceError):
        model.name = 'other'


def test_static_transforms_are_base_fixed_rows_and_tool():
    model = parse_robot_description(GOOD)
    static = dict(model.static_transforms())
    assert sorted(static) == [0, 3, 5]  # base0, link3 (a fixed row), tcp
    rows = model.chain.relative_all(np.zeros(model.chain.dof))
    expected = {0: model.chain.base.coeffs, 3: rows[2], 5: model.chain.tool.coeffs}
    for k, pose in static.items():
        np.testing.assert_allclose(hm.matrix_of_pose(pose[:3], pose[3:]),
                                   hm_of(expected[k]), atol=1e-12, err_msg=k)


def test_a_fixed_last_row_is_static_with_or_without_a_tool():
    """The last row fixed: its transform is static (the tool's index comes after it)."""
    row4 = '  - {frame: link4, theta: 10, d: 0, a: 0, alpha: 0, mimic: {joint: j1, multiplier: -2,'
    last_fixed = edit(GOOD, row4 + '\n     offset: 5}}\n',
                      '  - {frame: link4, type: fixed, theta: 10, d: 30, a: 40, alpha: 20}\n')
    tool = 'tool: {frame: tcp, xyz: [0, 0, 20], quaternion: [0, 0, 0, 1]}'
    for text in (last_fixed, edit(last_fixed, tool, '')):
        model = parse_robot_description(text)
        static = dict(model.static_transforms())
        rows = model.chain.relative_all(np.zeros(model.chain.dof))
        assert 4 in static
        np.testing.assert_allclose(hm.matrix_of_pose(static[4][:3], static[4][3:]),
                                   hm_of(rows[3]), atol=1e-12)


def test_a_description_of_exactly_the_longest_length_is_taken():
    from dq_fk_ros.description.robot_model import MAX_DESCRIPTION_CHARS
    text = 'x' * MAX_DESCRIPTION_CHARS
    model = parse_robot_description(GOOD + f'description: {text}\n')
    assert model.name == 'demo'
    with pytest.raises(RobotDescriptionError, match="field 'description'"):
        parse_robot_description(GOOD + f'description: {text}x\n')


def test_the_default_end_effector_is_the_last_chain_frame():
    assert parse_robot_description(GOOD).end_effector == 'tcp'
    no_tool = edit(GOOD, 'tool: {frame: tcp, xyz: [0, 0, 20], quaternion: [0, 0, 0, 1]}', '')
    assert parse_robot_description(no_tool).end_effector == 'link4'


def test_a_text_too_large_is_refused_before_it_is_read():
    from dq_fk_ros.description.robot_model import MAX_FILE_BYTES
    with pytest.raises(RobotDescriptionError, match=f'larger than {MAX_FILE_BYTES // 1024} '
                                                    'KiB'):
        parse_robot_description(GOOD + '#' * MAX_FILE_BYTES, 'big.yaml')
    assert MAX_FILE_BYTES // 1024 == 1024


def test_a_small_integer_of_the_wrong_kind_is_shown_as_it_is():
    with pytest.raises(RobotDescriptionError) as caught:
        parse_robot_description(edit(GOOD, 'robot: demo', 'robot: 200'), 'r.yaml')
    assert 'got 200' in str(caught.value)


def test_exactly_the_most_links_are_taken():
    row = '  - {frame: l%d, parent: tcp, xyz: [0, 0, 1]}\n'
    text = GOOD + 'links:\n' + ''.join(row % k for k in range(MAX_ROWS))
    assert len(parse_robot_description(text).links) == MAX_ROWS
    with pytest.raises(RobotDescriptionError, match=f'{MAX_ROWS + 1} links; a robot '):
        parse_robot_description(text + row % MAX_ROWS)


def test_an_unknown_end_effector_lists_every_frame_but_the_fixed_one():
    with pytest.raises(RobotDescriptionError) as caught:
        parse_robot_description(GOOD + 'end_effector: hand\n', 'r.yaml')
    assert str(caught.value).endswith('frames: base0, link1, link2, link3, link4, tcp')


def test_listings_say_how_many_more_only_when_there_are_more():
    from dq_fk_ros.errors import listing
    assert listing(['a', 'b', 'c'], at_most=3) == 'a, b, c'
    assert listing(['a', 'b', 'c', 'd'], at_most=3) == 'a, b, c ... (1 more)'


def test_a_yaml_mistake_says_its_line_and_column():
    """Both counted from 1, as editors do (the YAML parser counts from 0)."""
    with pytest.raises(RobotDescriptionError) as caught:
        parse_robot_description('robot: demo\nchain: [\n  {a: 1\n', 'r.yaml')
    assert str(caught.value).startswith('r.yaml: not valid YAML at line 4, column 1: ')


def test_a_moving_first_link_without_a_tool_is_not_a_dh_row():
    text = edit(GOOD, 'tool: {frame: tcp, xyz: [0, 0, 20], quaternion: [0, 0, 0, 1]}',
                'links:\n  - {frame: jaw, parent: link4, type: revolute, axis: [1, 0, 0], '
                'mimic: {joint: j1}}')
    model = parse_robot_description(text)
    n_rows = len(model.chain.joints)
    assert model.frame_names[n_rows + 1] == 'jaw' and model.moving[n_rows + 1]
    assert [k for k, _ in model.moving_edges] == [1, 2, 4, n_rows + 1]  # each frame once
    assert dict(model.moving_edges)[n_rows + 1] == n_rows  # the link's transform, after rows


def hm_of(h):
    from dq_fk_ros.kinematics.dh import homogeneous_from_dq
    return homogeneous_from_dq(h)


def test_an_integer_too_long_to_print_is_described_by_its_size():
    # 4000 hex digits (YAML reads them; Python cannot write them in decimal: 4816 digits,
    # beyond its int-to-text limit of 4300)
    with pytest.raises(RobotDescriptionError) as caught:
        parse_robot_description(edit(GOOD, 'a: 200', 'a: 0x' + 'f' * 4000), 'r.yaml')
    assert "field 'a' must be a finite number, got an integer of about 4816 digits" in \
        str(caught.value)


# -- numbers as YAML 1.1 and 1.2 write them ------------------------------------------------
@given(st.floats(allow_nan=False, allow_infinity=False))
def test_yaml_number_reads_back_as_the_same_float_in_pyyaml(value):
    import yaml
    text = yaml_number(value)
    assert yaml.safe_load(text) == value and isinstance(yaml.safe_load(text), float)


@pytest.mark.parametrize('text, value', [('5e-05', 5e-05), ('1e+16', 1e16), ('1E16', 1e16),
                                         ('-2.5e3', -2500.0), ('.5e1', 5.0), ('1e308', 1e308)])
def test_robot_files_take_yaml_1_2_exponents(text, value):
    model = parse_robot_description(
        'robot: r\nbase: {frame: b}\nchain:\n'
        f'  - {{frame: f, joint: j, theta: {text}, d: 0, a: 0, alpha: 0}}\n', 'x.yaml')
    assert model.chain.joints[0].theta == value


def test_a_yaml_file_that_is_no_robot_is_not_quoted_for_a_remote_client():
    for text in ('root:*:20228:0:99999:7::\n', 'api_key: hunter2\n', '[hunter2, 1]\n',
                 'robot: x\nsecret: hunter2\n', '"unclosed hunter2\n'):
        with pytest.raises(RobotDescriptionError) as caught:
            parse_robot_description(text, 'f.yaml')
        assert 'hunter2' not in caught.value.public and 'root:' not in caught.value.public
        assert caught.value.public.startswith('f.yaml: ')


@pytest.mark.parametrize('robot', ['rl15', 'panda', 'ur5e'])
def test_the_array_forms_are_the_pose_lists_into_given_arrays_and_in_batches(robot):
    """frame_pose_arrays, transform_pose_array, frame_pose_arrays_batch: frame_poses' values."""
    model = load_robot_description(shipped_robot_path(robot))
    qs = np.random.default_rng(5).uniform(-1, 1, (3, model.dof))
    absolute, relative = (np.array(p) for p in model.frame_poses(qs[0]))
    got_absolute, got_relative = model.frame_pose_arrays(qs[0])
    np.testing.assert_allclose(got_absolute, absolute, atol=1e-12)
    np.testing.assert_allclose(got_relative, relative, atol=1e-12)
    out = (np.empty_like(got_absolute), np.empty_like(got_relative))
    returned = model.frame_pose_arrays(qs[0], *out)
    assert returned[0] is out[0] and returned[1] is out[1]
    into = np.empty_like(got_relative)
    assert model.transform_pose_array(qs[0], into) is into
    np.testing.assert_allclose(into, relative, atol=1e-12)
    batch_absolute, batch_relative = model.frame_pose_arrays_batch(qs)
    given = (np.empty((5,) + batch_absolute.shape[1:]), np.empty((5,) + batch_relative.shape[1:]))
    again = model.frame_pose_arrays_batch(qs, given)   # views of the first rows of ``given``
    assert np.shares_memory(again[0], given[0]) and np.shares_memory(again[1], given[1])
    np.testing.assert_array_equal(given[0][:3], batch_absolute)
    np.testing.assert_array_equal(given[1][:3], batch_relative)
    for k, q in enumerate(qs):
        one_absolute, one_relative = (np.array(p) for p in model.frame_poses(q))
        np.testing.assert_allclose(batch_absolute[k], one_absolute, atol=1e-12)
        np.testing.assert_allclose(batch_relative[k], one_relative, atol=1e-12)


def test_tf_frame_ids_take_the_prefix_and_a_dh_fixed_frame_keeps_its_name():
    model = load_robot_description(shipped_robot_path('rl15'))
    assert model.tf_frame_id('eeCarry_seg6') == 'eeCarry_seg6'   # no prefix by default
    assert model.tf_frame_id('eeCarry_seg6', 'left/') == 'left/eeCarry_seg6'
    assert model.tf_frame_id(model.fixed_frame, 'left/') == model.fixed_frame


def test_a_file_of_the_largest_size_is_read_and_a_bigger_one_refused_after_a_bounded_read(
        tmp_path, monkeypatch):
    import tracemalloc
    from dq_fk_ros.description import schema
    monkeypatch.setattr(schema, 'MAX_FILE_BYTES', len(GOOD) + 10)
    exact = tmp_path / 'exact.yaml'
    exact.write_text(GOOD + '#' * 9 + '\n')          # exactly the bound
    assert schema.load_robot_description(exact).name == 'demo'
    big = tmp_path / 'big.yaml'
    big.write_text(GOOD + '#' * (8 << 20))            # 8 MiB past it
    tracemalloc.start()
    try:
        with pytest.raises(RobotDescriptionError, match=r'big.yaml: larger than 0 KiB'):
            schema.load_robot_description(big)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 1 << 20   # the bound and a character more were read, not the file


def test_what_a_peer_is_told_of_an_unreadable_file_is_one_line_without_its_content(tmp_path):
    from dq_fk_ros.description.schema import load_robot_description
    latin = tmp_path / 'latin.yaml'
    latin.write_bytes(b'robot: caf\xe9\n')
    with pytest.raises(RobotDescriptionError) as caught:
        load_robot_description(latin)
    assert caught.value.public == f'{latin}: not UTF-8 text'
    with pytest.raises(RobotDescriptionError) as caught:
        load_robot_description(str(tmp_path / 'nul\0.yaml'))
    assert caught.value.public == f'{tmp_path}/nul\0.yaml: cannot be read'


def test_end_effector_batch_is_the_end_effectors_column_of_every_frame():
    """The last chain frame (the chain's own batch) or any other frame (the whole tree)."""
    qs = [[0.3, 0.1], [-1.0, 0.25], [1, 0]]   # whole numbers too
    for end_effector in ('tcp', 'link4', 'link2', 'base0'):
        text = GOOD + f'links:\n  - {{frame: cam, parent: link2, xyz: [0, 10, 0]}}\n' \
            f'end_effector: {end_effector}\n'
        model = parse_robot_description(text)
        want = model.forward_all_batch(np.array(qs, dtype=float))[:, model.end_effector_index]
        got = model.end_effector_batch(qs)
        assert got.shape == (3, 8)
        np.testing.assert_allclose(got, want, atol=1e-12)
        assert (got[:, 0] >= 0).all()


def test_a_pickled_model_leaves_its_engine_behind_and_computes_the_same():
    import pickle
    model = parse_robot_description(GOOD)
    assert 'kinematics' not in model.__getstate__()   # never used: nothing to leave
    q = np.array([[0.3, 0.1]])
    before = model.forward_all_batch(q)   # the engine made and cached
    assert 'kinematics' in model.__dict__
    state = model.__getstate__()
    assert 'kinematics' not in state and state['frame_names'] == model.frame_names
    assert 'kinematics' in model.__dict__   # the model itself keeps it
    again = pickle.loads(pickle.dumps(model))
    np.testing.assert_array_equal(again.forward_all_batch(q), before)


def test_a_cylindrical_rows_second_joint_is_a_joint_name_like_any():
    """Its name is taken: no other row may read it, and a mimic row may follow it."""
    head = 'robot: r\nbase: {frame: b}\nchain:\n' \
        '  - {frame: l1, type: cylindrical, joint: spin, d_joint: lift, theta: 0, d: 0, a: 0,' \
        ' alpha: 0}\n'
    with pytest.raises(RobotDescriptionError) as caught:
        parse_robot_description(head + '  - {frame: l2, joint: lift, theta: 0, d: 0, a: 0, '
                                'alpha: 0}\n', 'r.yaml')
    assert str(caught.value) == ("r.yaml: chain[1] (frame 'l2'): joint 'lift' is already read "
                                 "by chain[0] (frame 'l1'); joint names must be unique")
    model = parse_robot_description(head + '  - {frame: l2, type: prismatic, theta: 0, d: 0, '
                                    'a: 0, alpha: 0, mimic: {joint: lift}}\n', 'r.yaml')
    assert model.joint_names == ('spin', 'lift')


def test_a_mimic_in_a_robot_without_joints_says_there_are_none():
    with pytest.raises(RobotDescriptionError) as caught:
        parse_robot_description('robot: r\nbase: {frame: b}\nchain:\n  - {frame: l1, theta: 0, '
                                'd: 0, a: 0, alpha: 0, mimic: {joint: j9}}\n', 'r.yaml')
    assert str(caught.value) == ("r.yaml: chain[0] (frame 'l1') mimic: field 'joint' names "
                                 "'j9', which no row reads; joints: none")
