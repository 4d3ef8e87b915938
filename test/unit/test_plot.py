"""``dq_fk plot``: the picture shows each frame where its pose projects, and says so."""

import math

from dq_fk_ros.cli.dq_fk import main
from dq_fk_ros.description.plot import AXIS_COLOURS, draw_robot
from dq_fk_ros.description.schema import load_robot_description
from dq_fk_ros.description.shipped import shipped_robot_path
from matplotlib import colors
from matplotlib.image import imread
from mpl_toolkits.mplot3d import proj3d
import numpy as np
import pytest

CASES = [
    ('rl15', np.zeros(6), 'eeCarry_seg6'),      # the paper's Fig. 4 pose
    ('panda', np.array([0.3, -0.4, 0.2, -2.1, 0.1, 1.9, 0.7]), 'panda_link8'),  # modified DH
]


def pixel_of(fig, point):
    """(column, row) of a 3-D point in the saved image, from the figure's own transforms."""
    ax = fig.axes[0]
    x2, y2, _ = proj3d.proj_transform(*point, ax.get_proj())
    px, py = ax.transData.transform((x2, y2))
    height = fig.bbox.height
    return px, height - py


def near(image, col, row, radius, rgb, tolerance=0.12):
    """Whether a pixel of colour ``rgb`` lies within ``radius`` pixels of (col, row)."""
    r0, r1 = int(max(row - radius, 0)), int(min(row + radius + 1, image.shape[0]))
    c0, c1 = int(max(col - radius, 0)), int(min(col + radius + 1, image.shape[1]))
    patch = image[r0:r1, c0:c1, :3]
    return bool((np.abs(patch - np.array(rgb)).max(axis=2) < tolerance).any())


@pytest.mark.parametrize('robot, q, end', CASES)
def test_the_end_effector_is_drawn_where_its_pose_projects(tmp_path, robot, q, end):
    model = load_robot_description(shipped_robot_path(robot))
    assert model.frame_names[-1] == end
    fig = draw_robot(model, q)
    path = tmp_path / 'robot.png'
    fig.savefig(path)
    image = imread(path)
    assert image.shape[:2] == (int(fig.bbox.height), int(fig.bbox.width))
    not_white = (image[:, :, :3] < 0.9).any(axis=2).mean()
    assert not_white > 0.02, 'the picture is blank'
    pose = model.chain.forward(q)
    col, row = pixel_of(fig, pose.translation)
    for rgb in (colors.to_rgb(c) for c in AXIS_COLOURS):  # its x, y, z axes start there
        assert near(image, col, row, 4, rgb), (robot, rgb, col, row)
    # its name is anchored at its origin, and drawn to the right of it
    labels = [t for t in fig.axes[0].texts if end in t.get_text().split()]
    assert len(labels) == 1
    np.testing.assert_allclose(labels[0].get_position_3d(), pose.translation, atol=1e-12)
    lines = labels[0].get_text().count('\n') + 1  # frames at one place share a label
    window = image[int(row - 8 * lines):int(row + 8 * lines), int(col + 4):int(col + 110), :3]
    assert (window.max(axis=2) < 0.3).sum() > 20, 'the label is not drawn'


def test_the_title_names_the_robot_and_its_joint_values():
    model = load_robot_description(shipped_robot_path('rrc'))
    fig = draw_robot(model, [math.radians(30), 0, 0, 0.125])
    title = fig.axes[0].get_title()
    assert title.startswith('rrc: theta_1=30.0°') and 'd_3=0.125 m' in title


def test_equal_scale_on_every_axis():
    fig = draw_robot(load_robot_description(shipped_robot_path('ur5e')), np.zeros(6))
    ax = fig.axes[0]
    spans = [np.ptp(ax.get_xlim()), np.ptp(ax.get_ylim()), np.ptp(ax.get_zlim())]
    assert spans == pytest.approx([spans[0]] * 3)
    assert tuple(ax.get_box_aspect()) == pytest.approx((1, 1, 1), rel=1e-6) or \
        np.ptp(ax.get_box_aspect()) < 1e-9


def test_the_command_writes_png_and_svg(tmp_path, capsys):
    png, svg = tmp_path / 'rl15.png', tmp_path / 'rl15.svg'
    assert main(['plot', 'rl15', '--joints', '0', '30', '0', '0', '0', '0', '--deg', '-o',
                 str(png), '--view', '-90', '10']) == 0
    assert png.read_bytes()[:8] == b'\x89PNG\r\n\x1a\n'
    assert main(['plot', 'rl15', '-o', str(svg)]) == 0
    assert b'<svg' in svg.read_bytes()[:500]
    assert capsys.readouterr().err.count('wrote ') == 2


@pytest.mark.parametrize('args, words', [
    (['rl15', '-o', 'x.jpg'], '-o x.jpg: give a .png or .svg file name'),
    (['rl15', '-o', 'x.png', '--view', 'nan', '0'], '--view: azimuth and elevation must be'),
    (['rl15', '-o', 'no/such/dir/x.png'], 'does not exist'),
    (['rl15', '-o', 'x.png', '--joints', 'joint_9=1'], "unknown joint 'joint_9'"),
    (['nope_robot', '-o', 'x.png'], 'nope_robot: no such file'),
])
def test_bad_arguments_are_one_line(tmp_path, capsys, monkeypatch, args, words):
    monkeypatch.chdir(tmp_path)
    assert main(['plot'] + args) == 1
    err = capsys.readouterr().err
    assert err.startswith('dq_fk: ') and err.count('\n') == 1 and words in err, err
    assert not (tmp_path / 'x.png').exists()


def lines_of(ax, colour):
    """Return the 3-D points of every line drawn in ``colour``: ``[(3, 2) arrays]``."""
    return [np.array(line.get_data_3d()) for line in ax.lines
            if colors.to_hex(line.get_color()) == colors.to_hex(colour)]


@pytest.mark.parametrize('robot', ['rl15', 'puma560', 'ur5e', 'panda', 'rrc',
                                   'human_centrifuge', 'anthropomorphic_arm'])
def test_the_grid_lies_on_the_fixed_frames_xy_plane_in_round_steps(robot):
    from dq_fk_ros.description.plot import _nice_step
    from dq_fk_ros.description.to_urdf import link_segments
    model = load_robot_description(shipped_robot_path(robot))
    q = np.full(model.dof, 0.3)
    fig = draw_robot(model, q)
    ax = fig.axes[0]
    grid = lines_of(ax, '#bdbdbd')
    assert grid and all(np.all(line[2] == 0.0) for line in grid)  # z = 0
    half = np.ptp(ax.get_xlim()) / 2
    step = _nice_step(2 * half / 8)
    along_y = [line for line in grid if line[0][0] == line[0][1]]  # constant x
    along_x = [line for line in grid if line[1][0] == line[1][1]]  # constant y
    assert len(along_x) + len(along_y) == len(grid)
    xs = sorted(line[0][0] for line in along_y)
    ys = sorted(line[1][0] for line in along_x)
    for values, (low, high) in ((xs, ax.get_xlim()), (ys, ax.get_ylim())):
        np.testing.assert_allclose(np.diff(values), step, rtol=1e-9)
        np.testing.assert_allclose(np.array(values) / step, np.round(np.array(values) / step),
                                   atol=1e-9)  # on multiples of the step
        # from the step at or below the lower limit to within half a step of the upper one
        assert low - step < values[0] <= low + 1e-9
        # the last line: the last multiple of the step within half a step beyond the limit
        assert values[-1] <= high + step / 2 + 1e-9 < values[-1] + step
    for line in along_y:  # each line spans the grid
        assert (line[1].min(), line[1].max()) == (ys[0], ys[-1])
    for line in along_x:
        assert (line[0].min(), line[0].max()) == (xs[0], xs[-1])
    # the view is centred on everything drawn: frame origins, links and the fixed frame
    from dq_fk_ros.kinematics.dh import homogeneous_from_dq
    points = [m[:3, 3] for m in homogeneous_from_dq(model.forward_all(q))] + [np.zeros(3)]
    points += [p for segment in link_segments(model, q) for p in segment]
    centre = (np.min(points, axis=0) + np.max(points, axis=0)) / 2
    np.testing.assert_allclose([np.mean(ax.get_xlim()), np.mean(ax.get_ylim()),
                                np.mean(ax.get_zlim())], centre, atol=1e-9)
    assert np.ptp(ax.get_xlim()) == pytest.approx(1.2 * np.ptp(points, axis=0).max())


@pytest.mark.parametrize('raw, step', [(0.23, 0.2), (0.7, 0.5), (0.08, 0.1), (3.3, 2.0),
                                       (9.0, 10.0), (0.0013, 0.001), (40.0, 50.0)])
def test_grid_steps_are_1_2_or_5_times_a_power_of_ten(raw, step):
    from dq_fk_ros.description.plot import _nice_step
    assert _nice_step(raw) == pytest.approx(step)


def test_links_and_axes_are_drawn_where_the_kinematics_put_them():
    from dq_fk_ros.description.plot import SEGMENT_COLOUR
    from dq_fk_ros.description.to_urdf import link_segments
    from dq_fk_ros.kinematics.dh import homogeneous_from_dq
    model = load_robot_description(shipped_robot_path('puma560'))
    q = np.array([0.3, -0.6, 0.4, 0.2, -0.5, 0.9])
    ax = draw_robot(model, q).axes[0]
    drawn = lines_of(ax, SEGMENT_COLOUR)
    expected = link_segments(model, q)
    assert len(drawn) == len(expected)
    for line, (start, end) in zip(drawn, expected):
        np.testing.assert_allclose(line.T, [start, end], atol=1e-12)
    span = np.ptp(ax.get_xlim()) / 1.2  # the limits are 0.6 span either side
    frames = homogeneous_from_dq(model.forward_all(q))
    for k, colour in enumerate(AXIS_COLOURS):  # x, y, z of the fixed frame, then each frame
        axes = lines_of(ax, colour)
        assert len(axes) == 1 + len(frames)
        for line, m in zip(axes, [np.eye(4)] + list(frames)):
            np.testing.assert_allclose(line.T, [m[:3, 3], m[:3, 3] + 0.12 * span * m[:3, k]],
                                       atol=1e-9)


def test_frames_closer_than_a_thousandth_of_the_picture_share_a_label():
    from dq_fk_ros.description.schema import parse_robot_description
    model = parse_robot_description(
        'robot: r\nbase: {frame: b}\nchain:\n'
        '  - {frame: l1, joint: j1, theta: 0, d: 2.0, a: 2.0, alpha: 0}\n'
        'links:\n  - {frame: close, parent: l1, xyz: [0, 0, 0.001]}\n'
        '  - {frame: apart, parent: l1, xyz: [0, 0, 0.01]}\n')  # the picture spans 2 m
    texts = [t.get_text().split() for t in draw_robot(model, [0.0]).axes[0].texts]
    assert ['l1', 'close'] in texts and ['apart'] in texts


def test_the_look_of_the_picture():
    """The documented look: sizes, drawing order, axis names, the camera, the layout."""
    from dq_fk_ros.description.plot import SEGMENT_COLOUR
    fig = draw_robot(load_robot_description(shipped_robot_path('rl15')), np.zeros(6),
                     view=(-90.0, 10.0))
    ax = fig.axes[0]
    assert tuple(fig.get_size_inches() * fig.dpi) == (800.0, 700.0)  # 8 x 7 in at 100 dpi
    assert (ax.azim, ax.elev) == (-90.0, 10.0)
    assert (ax.get_xlabel(), ax.get_ylabel(), ax.get_zlabel()) == ('x (m)', 'y (m)', 'z (m)')
    style = {}
    for line in ax.lines:
        style.setdefault(colors.to_hex(line.get_color()), set()).add(
            (line.get_linewidth(), line.get_zorder()))
    assert style['#bdbdbd'] == {(0.7, 0)}               # the grid: thin, underneath
    assert style[colors.to_hex(SEGMENT_COLOUR)] == {(4.0, 1)}  # links: thick
    for colour in AXIS_COLOURS:
        assert style[colors.to_hex(colour)] == {(2.0, 3)}  # axes: above the links
    assert {(t.get_fontsize(), t.get_zorder()) for t in ax.texts} == {(7.0, 4)}  # on top
    # laid out to use the figure: more of it than matplotlib's default subplot
    left, bottom, width, height = ax.get_position().bounds
    assert width > 0.7 and height > 0.85


def test_a_long_title_wraps_and_keeps_every_joint():
    model = load_robot_description(shipped_robot_path('panda'))
    title = draw_robot(model, np.full(7, 0.25)).axes[0].get_title()
    lines = title.split('\n')
    assert len(lines) == 2 and all(len(line) <= 100 for line in lines)
    assert all(title.count(f'{name}=14.3°') == 1 for name in model.joint_names)


def test_a_urdf_robot_is_drawn_by_its_links_and_helper_frames_only_when_asked():
    import os
    import sys
    sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    from vendor_urdfs import UR5, vendor_robot
    model = vendor_robot(UR5).model
    q = np.array([0.3, -1.2, 1.0, -0.5, 0.8, 0.2])
    fig = draw_robot(model, q)
    names = {n for t in fig.axes[0].texts for n in t.get_text().split()}
    assert {'shoulder_link', 'wrist_3_link', 'tool0'} <= names
    assert not {n for n in names if n.startswith('dh')}, names  # dh0..dh6 hidden
    shown = {n for t in draw_robot(model, q, helpers=True).axes[0].texts
             for n in t.get_text().split()}
    assert {f'dh{k}' for k in range(7)} <= shown
    # one segment per URDF joint with an offset, from the parent link's origin to the link's
    from dq_fk_ros.description.plot import urdf_link_segments
    from dq_fk_ros.kinematics.dh import homogeneous_from_dq
    frames = homogeneous_from_dq(model.forward_all(q))
    origins = frames[:, :3, 3]
    segments = urdf_link_segments(model, origins)
    where = dict(zip(model.frame_names, origins))
    where[model.fixed_frame] = np.zeros(3)
    import xml.etree.ElementTree as ElementTree
    pairs = [(j.find('parent').get('link'), j.find('child').get('link'))
             for j in ElementTree.fromstring(vendor_robot(UR5).urdf).findall('joint')]
    want = [(where[p], where[c]) for p, c in pairs if np.linalg.norm(where[c] - where[p]) > 1e-9]
    assert len(segments) == len(want) >= 6
    for (a, b), (c, d) in zip(sorted(segments, key=lambda s: tuple(s[1])),
                              sorted(want, key=lambda s: tuple(s[1]))):
        np.testing.assert_allclose(np.concatenate([a, b]), np.concatenate([c, d]), atol=1e-12)


def wrapped_title(robot_name, names):
    from dq_fk_ros.description.schema import parse_robot_description
    rows = ''.join(f'  - {{frame: f{k}, joint: {n}, theta: 0, d: 0.1, a: 0.2, alpha: 0}}\n'
                   for k, n in enumerate(names))
    model = parse_robot_description(f'robot: {robot_name}\nbase: {{frame: b}}\nchain:\n' + rows)
    return draw_robot(model, np.zeros(len(names))).axes[0].get_title().split('\n')


def test_a_title_line_takes_a_joint_that_ends_it_at_100_characters_not_one_that_passes():
    names = [f'joint{k:03d}' for k in range(8)]          # 'joint000=0.0°': 13 characters
    parts = [f'{n}=0.0°' for n in names]
    # 'abcdefghij: ' and five parts with their ', ' are 87: the sixth ends the line at 100
    assert wrapped_title('abcdefghij', names) == [
        'abcdefghij: ' + ', '.join(parts[:6]), ', '.join(parts[6:])]
    # one character more in the name: the sixth would end it at 101, so it starts the next
    assert wrapped_title('abcdefghijk', names) == [
        'abcdefghijk: ' + ', '.join(parts[:5]), ', '.join(parts[5:])]


def test_labels_are_named_for_svg_and_drawn_as_documented():
    from dq_fk_ros.description.schema import parse_robot_description
    model = parse_robot_description(
        'robot: r\nbase: {frame: b}\nchain:\n'
        '  - {frame: l1, joint: j1, theta: 0, d: 2.0, a: 2.0, alpha: 0}\n'
        'links:\n  - {frame: close, parent: l1, xyz: [0, 0, 0.001]}\n')
    fig = draw_robot(model, [0.0], dpi=50)
    ax = fig.axes[0]
    assert fig.dpi == 50 and tuple(fig.get_size_inches() * fig.dpi) == (400.0, 350.0)
    gids = {t.get_gid() for t in ax.texts}
    assert 'label:l1,close' in gids and all(g.startswith('label:') for g in gids)
    assert {(colors.to_hex(t.get_color()), t.get_verticalalignment()) for t in ax.texts} == \
        {('#000000', 'center')}
    assert ax.title.get_fontsize() == 9.0
    from dq_fk_ros.description.plot import SEGMENT_COLOUR
    assert {line.get_solid_capstyle() for line in ax.lines
            if colors.to_hex(line.get_color()) == colors.to_hex(SEGMENT_COLOUR)} == {'round'}
    assert ax._draw_grid is False   # matplotlib's own grid off: the fixed frame's is drawn


def test_save_robot_plot_draws_with_the_view_and_helpers_asked_for(tmp_path, monkeypatch):
    from dq_fk_ros.description import plot
    asked = []
    real = plot.draw_robot
    monkeypatch.setattr(plot, 'draw_robot', lambda *a, **k: asked.append((a[2:], k)) or
                        real(*a, **k))
    model = load_robot_description(shipped_robot_path('rrc'))
    plot.save_robot_plot(model, np.zeros(model.dof), tmp_path / 'a.png')
    plot.save_robot_plot(model, np.zeros(model.dof), tmp_path / 'b.svg', view=(10.0, 20.0),
                         helpers=True)
    assert asked == [((plot.DEFAULT_VIEW,), {'helpers': False}),
                     (((10.0, 20.0),), {'helpers': True})]
    assert (tmp_path / 'a.png').stat().st_size > 0 and (tmp_path / 'b.svg').stat().st_size > 0


def test_a_urdf_robots_links_are_drawn_from_its_links_not_its_dh_rows():
    """The links drawn are the URDF's (a joint without an offset draws nothing)."""
    from dq_fk_ros.description.loading import robot_from_urdf_text
    from dq_fk_ros.description.plot import SEGMENT_COLOUR
    limit = '<limit lower="-1" upper="1" effort="1" velocity="1"/>'
    urdf = ('<robot name="u"><link name="b"/><link name="l1"/><link name="l2"/>'
            '<link name="flange"/><joint name="j1" type="revolute"><parent link="b"/>'
            f'<child link="l1"/><origin xyz="0 0 0.5"/><axis xyz="0 0 1"/>{limit}</joint>'
            '<joint name="j2" type="revolute"><parent link="l1"/><child link="l2"/>'
            f'<origin xyz="0.4 0 0.3"/><axis xyz="0 1 0"/>{limit}</joint>'
            '<joint name="f" type="fixed"><parent link="l2"/><child link="flange"/></joint>'
            '</robot>')
    model = robot_from_urdf_text(urdf).model
    drawn = lines_of(draw_robot(model, [0.0, 0.0]).axes[0], SEGMENT_COLOUR)
    ends = sorted(tuple(np.round(p.T.ravel(), 9)) for p in drawn)
    assert ends == [(0.0, 0.0, 0.0, 0.0, 0.0, 0.5), (0.0, 0.0, 0.5, 0.4, 0.0, 0.8)]
