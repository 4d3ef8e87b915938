"""``dq_fk plot``: the picture shows each frame where its pose projects, and says so."""

import math

from dq_fk_ros.cli.dq_fk import main
from dq_fk_ros.description.plot import AXIS_COLOURS, draw_robot
from dq_fk_ros.description.robot_model import load_robot_description, shipped_robot_path
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
