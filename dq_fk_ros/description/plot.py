"""
A picture of the robot at given joint values, without RViz: ``dq_fk plot``.

Headless matplotlib (the Agg canvas, no pyplot state): the links as segments (for a DH
file the cylinders of its URDF, :func:`~dq_fk_ros.description.to_urdf.link_segments`; for a
robot from a URDF one segment from each link's URDF parent to it), every published frame's
x, y, z axes in red, green, blue with its name (the DH method's helper frames, ``dh0``...,
only with ``helpers``: :func:`~dq_fk_ros.description.to_urdf.is_helper_frame`), a grid on the
fixed frame's xy plane, equal scale on all three axes, and a title with the robot and the
joint values. A DH mistake (a wrong sign of alpha, a length in the wrong row) shows at a
glance.
"""

from collections.abc import Mapping
import math
import os

from dq_fk_ros.description.robot_model import RobotModel
from dq_fk_ros.description.to_urdf import is_helper_frame, link_segments
import numpy as np
from numpy.typing import ArrayLike

AXIS_COLOURS = ('#d62728', '#2ca02c', '#1f77b4')  # x red, y green, z blue (as RViz)
SEGMENT_COLOUR = '#7f7f86'
DEFAULT_VIEW = (-60.0, 25.0)   # azimuth, elevation in degrees


def draw_robot(model: RobotModel, q: ArrayLike, view: tuple = DEFAULT_VIEW,
               size_in: tuple = (8.0, 7.0), dpi: int = 100, helpers: bool = False) -> object:
    """
    Return a matplotlib ``Figure`` of ``model`` at joint values ``q`` (chain order).

    :param view: ``(azimuth, elevation)`` of the camera, degrees.
    :param size_in: figure size in inches; ``dpi``: its resolution.
    :param helpers: draw the DH method's helper frames too (hidden by default).
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    q = np.asarray(q, dtype=float)
    fig = Figure(figsize=size_in, dpi=dpi)
    FigureCanvasAgg(fig)
    ax = fig.add_subplot(projection='3d')
    frames = list(model.forward_all(q))
    origins = np.array([_matrix(h)[:3, 3] for h in frames])
    segments = link_segments(model, q) if model.urdf is None else \
        urdf_link_segments(model, origins)
    points = np.vstack([origins, np.zeros((1, 3))] + [np.array(s) for s in segments])
    low, high = points.min(axis=0), points.max(axis=0)
    span = float(max((high - low).max(), 1e-3))
    centre = (low + high) / 2
    half = 0.6 * span
    axis_length = 0.12 * span

    _grid(ax, centre, half)
    for start, end in segments:
        ax.plot(*np.transpose([start, end]), color=SEGMENT_COLOUR, linewidth=4,
                solid_capstyle='round', zorder=1)
    matrices = [np.eye(4)] + [_matrix(h) for h in frames]
    names = [model.fixed_frame] + list(model.frame_names)
    if not helpers:
        kept = [k for k, name in enumerate(names) if k == 0 or not is_helper_frame(name)]
        matrices, names = [matrices[k] for k in kept], [names[k] for k in kept]
    for m in matrices:
        _axes(ax, m, axis_length)
    # one label per place: frames at the same origin share it, one name per line
    labels = []
    for name, m in zip(names, matrices):
        for label in labels:
            if np.linalg.norm(label[0] - m[:3, 3]) < 1e-3 * span:
                label[1].append(name)
                break
        else:
            labels.append((m[:3, 3], [name]))
    for origin, group in labels:
        ax.text(*origin, '\n'.join('  ' + n for n in group), fontsize=7, color='black',
                zorder=4, gid='label:' + ','.join(group), va='center')

    ax.set_xlim(centre[0] - half, centre[0] + half)
    ax.set_ylim(centre[1] - half, centre[1] + half)
    ax.set_zlim(centre[2] - half, centre[2] + half)
    ax.set_box_aspect((1, 1, 1))  # equal scale on x, y and z
    ax.grid(False)  # the grid drawn is the fixed frame's, on its xy plane
    ax.set_xlabel('x (m)')
    ax.set_ylabel('y (m)')
    ax.set_zlabel('z (m)')
    ax.view_init(azim=view[0], elev=view[1])
    ax.set_title(_title(model, q), fontsize=9)
    fig.tight_layout()
    return fig


def urdf_link_segments(model: RobotModel, origins: Mapping[str, np.ndarray]) -> list:
    """
    Return ``[(start, end), ...]``: from each URDF link's URDF parent to it (fixed frame).

    ``origins``: every frame's origin, in ``model.frame_names`` order (the links are the
    frames after the DH chains', their TF parents their URDF parents).
    """
    where = dict(zip(model.frame_names, origins))
    where[model.fixed_frame] = np.zeros(3)
    segments = []
    for name, parent in zip(model.frame_names[model.n_dh_frames:],
                            model.parent_frames[model.n_dh_frames:]):
        if np.linalg.norm(where[name] - where[parent]) > 1e-9:
            segments.append((where[parent], where[name]))
    return segments


def save_robot_plot(model: RobotModel, q: ArrayLike, path: str | os.PathLike,
                    view: tuple = DEFAULT_VIEW, helpers: bool = False) -> None:
    """Draw ``model`` at ``q`` and save it as PNG or SVG (by the file's extension)."""
    fig = draw_robot(model, q, view, helpers=helpers)
    fig.savefig(path)
    return fig


def _matrix(h):
    from dq_fk_ros.kinematics.dh import homogeneous_from_dq
    return homogeneous_from_dq(h)


def _axes(ax, m, length):
    """Draw a frame's x, y, z axes in red, green, blue."""
    origin = m[:3, 3]
    for k, colour in enumerate(AXIS_COLOURS):
        tip = origin + length * m[:3, k]
        ax.plot(*np.transpose([origin, tip]), color=colour, linewidth=2, zorder=3)


def _grid(ax, centre, half):
    """Draw a grid on the fixed frame's xy plane (z = 0) under the robot."""
    step = _nice_step(2 * half / 8)
    lo_x = math.floor((centre[0] - half) / step) * step
    lo_y = math.floor((centre[1] - half) / step) * step
    xs = np.arange(lo_x, centre[0] + half + step / 2, step)
    ys = np.arange(lo_y, centre[1] + half + step / 2, step)
    for x in xs:
        ax.plot([x, x], [ys[0], ys[-1]], [0, 0], color='#bdbdbd', linewidth=0.7, zorder=0)
    for y in ys:
        ax.plot([xs[0], xs[-1]], [y, y], [0, 0], color='#bdbdbd', linewidth=0.7, zorder=0)


def _nice_step(raw):
    """Return a grid step of 1, 2 or 5 times a power of ten, close to ``raw``."""
    power = 10.0 ** math.floor(math.log10(raw))
    return min((m * power for m in (1, 2, 5, 10)), key=lambda s: abs(s - raw))


def _title(model, q):
    """Return the title: the robot and its joint values (degrees, metres)."""
    angle = model.angular
    parts = [f'{name}={math.degrees(v):.1f}°' if is_angle else f'{name}={v:.3f} m'
             for name, v, is_angle in zip(model.joint_names, q, angle)]
    lines, line = [], model.name + ': '
    for part in parts:
        if len(line) + len(part) > 100:
            lines.append(line.rstrip(', '))
            line = ''
        line += part + ', '
    lines.append(line.rstrip(', '))
    return '\n'.join(lines)
