"""
A robot description written as YAML text (what ``dq_fk from-urdf`` writes).

Flow mappings of numbers, names and small lists (JSON is valid YAML), one comment line per
row and link saying where it came from; numbers as YAML 1.1 and 1.2 both read them
(:func:`~dq_fk_ros.description.schema.yaml_number`).
"""

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
import json

from dq_fk_ros.description.yaml_fields import yaml_number
from dq_fk_ros.errors import printable_line
from dq_fk_ros.kinematics.dual_quaternion import quat_from_matrix
import numpy as np

NOISE = 1e-15               # numbers written as 0 (m or rad; far below the tests' 1e-12)


def flow(mapping: Mapping) -> str:
    """Write a YAML flow mapping of numbers, names and small lists (JSON is valid YAML)."""
    parts = []
    for key, value in mapping.items():
        parts.append(f'{key}: {value_text(value)}')
    return '{' + ', '.join(parts) + '}'


def value_text(value: object) -> str:
    """Write one value: a mapping, a list, a quoted name or a number (noise written as 0)."""
    if isinstance(value, dict):
        return flow(value)
    if isinstance(value, (list, tuple)):
        return '[' + ', '.join(value_text(v) for v in value) + ']'
    if isinstance(value, str):
        return json.dumps(value)
    value = float(value)
    value = 0.0 if abs(value) < NOISE else value  # rounding noise (and -0.0) written as 0
    return yaml_number(value)


def comment(text: str) -> str:
    """Make user text fit one YAML comment line: no line breaks, printable only."""
    return printable_line(text, 300)


def transform(frame: str, m: np.ndarray) -> str:
    """Write ``{frame, xyz, quaternion}`` of a 4x4 pose (the quaternion as x, y, z, w)."""
    w, x, y, z = quat_from_matrix(m[:3, :3])
    return flow({'frame': frame, 'xyz': m[:3, 3].tolist(), 'quaternion': [x, y, z, w]})


@dataclass(frozen=True)
class ChainText:
    """One chain to write: its parent frame, frame 0's pose in it (4x4), frame names, rows."""

    parent: str
    base: object            # 4x4 matrix
    names: tuple            # its DH frames, frame 0 first
    rows: tuple             # (row mapping, comment) per DH row
    comment: str = ''


def description_yaml(comments: Sequence[str], robot: str, convention: str, fixed_frame: str,
                     chains: Sequence['ChainText'], links: Sequence[Mapping],
                     end_effector: str, publish_dh_frames: bool = True) -> str:
    """
    Return the YAML text of a robot description (``docs/robot_description.md``).

    :param comments: lines written first, each as a comment (made printable; long parts are
        the caller's to cut, see :func:`comment`).
    :param chains: :class:`ChainText` per chain; one chain is written as ``base``/``chain``,
        more as ``chains:``.
    :param links: ``(entry mapping, comment)`` per ``links`` entry.
    :param publish_dh_frames: whether TF carries the DH frames by default (false: written).
    """
    lines = [f'# {printable_line(text)}' for text in comments]
    lines += [f'robot: {json.dumps(comment(robot)[:128])}', f'convention: {convention}',
              f'fixed_frame: {fixed_frame}']

    def rows(chain, indent):
        out = []
        for row, note in chain.rows:
            out += [f'{indent}# {comment(note)}', f'{indent}- {flow(row)}']
        return out

    if len(chains) == 1:
        lines += ['# frame 0 of the DH chain, in the base link',
                  'base: ' + transform(chains[0].names[0], chains[0].base), 'chain:']
        lines += rows(chains[0], '  ')
    else:
        lines.append('chains:')
        for chain in chains:
            lines += [f'  # {comment(chain.comment)}', f'  - parent: {json.dumps(chain.parent)}',
                      '    base: ' + transform(chain.names[0], chain.base), '    chain:']
            lines += rows(chain, '      ')
    if links:
        lines.append('links:')
        for entry, note in links:
            lines += [f'  # {comment(note)}', f'  - {flow(entry)}']
    lines.append(f'end_effector: {end_effector}')
    if not publish_dh_frames:
        lines += ['# TF carries the links, not the DH frames (the node parameter '
                  'publish_dh_frames overrides)', 'publish_dh_frames: false']
    return '\n'.join(lines) + '\n'


__all__ = ['ChainText', 'comment', 'description_yaml', 'flow', 'NOISE', 'transform']
