"""
A robot's DH tables as straight-line code, and a chain's factor program run with its tool.

Two ways to the same frames, to the bit:

* :func:`run_chain_program` (the reference, under :meth:`KinematicChain.frame_poses_general`
  and the batches): the table's factor program (:func:`~.dh_program.run_program`,
  [Zivkovic2023] eqs. (13)-(15)) run in a loop, on floats or on numpy columns, then the tool.
* :func:`unrolled_frame_poses` (fast): the same operations written out as Python source,
  constants in place, and compiled once per robot (``f.source`` prints it; ``dq_fk fk
  --code`` too). test_dh.py's ``test_the_unrolled_frame_poses_are_the_general_path_to_the_bit``
  and test_links.py's ``test_the_unrolled_frame_poses_with_links_are_the_general_path`` hold
  them equal.

Dual quaternions are 8 coefficients ``(w, x, y, z, w', x', y', z')``; in the generated code
the real part is ``aw, ax, ay, az``, the dual part ``bw, bx, by, bz``.
"""

from collections.abc import Callable, Sequence
import math

from dq_fk_ros.kinematics.chain_table import ChainTable
from dq_fk_ros.kinematics.dh_program import row_program, run_program, Z
from dq_fk_ros.kinematics.dual_quaternion import (
    dq_inverse_coeffs, dq_multiply_coeffs, pose_xyzw_from_coeffs)

_DQ = 'aw, ax, ay, az, bw, bx, by, bz'
_Z_STEP = (f'{_DQ} = (aw * c - az * s, ax * c + ay * s, ay * c - ax * s, az * c + aw * s, '
           f'bw * c - bz * s, bx * c + by * s, by * c - bx * s, bz * c + bw * s)')
_X_STEP = (f'{_DQ} = (aw * c - ax * s, ax * c + aw * s, ay * c + az * s, az * c - ay * s, '
           f'bw * c - bx * s, bx * c + bw * s, by * c + bz * s, bz * c - by * s)')
_MARK = ('s = -1.0 if aw < 0.0 else 1.0',  # pose_xyzw_from_coeffs, inline
         'absolute.append((2.0 * (bx * aw - bw * ax - by * az + bz * ay), '
         '2.0 * (by * aw - bw * ay + bx * az - bz * ax), '
         '2.0 * (bz * aw - bw * az - bx * ay + by * ax), s * ax, s * ay, s * az, s * aw))')


_IDENTITY = (1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
_PARENT = 'u0, u1, u2, u3, u4, u5, u6, u7'
# the terms of dq_multiply_coeffs ([Zivkovic2023] eq. (12)), in its order: (sign, a, b)
_PRODUCT_TERMS = (
    (('+', 0, 0), ('-', 1, 1), ('-', 2, 2), ('-', 3, 3)),
    (('+', 0, 1), ('+', 1, 0), ('+', 2, 3), ('-', 3, 2)),
    (('+', 0, 2), ('-', 1, 3), ('+', 2, 0), ('+', 3, 1)),
    (('+', 0, 3), ('+', 1, 2), ('-', 2, 1), ('+', 3, 0)),
    (('+', 0, 4), ('-', 1, 5), ('-', 2, 6), ('-', 3, 7),
     ('+', 4, 0), ('-', 5, 1), ('-', 6, 2), ('-', 7, 3)),
    (('+', 0, 5), ('+', 1, 4), ('+', 2, 7), ('-', 3, 6),
     ('+', 4, 1), ('+', 5, 0), ('+', 6, 3), ('-', 7, 2)),
    (('+', 0, 6), ('-', 1, 7), ('+', 2, 4), ('+', 3, 5),
     ('+', 4, 2), ('-', 5, 3), ('+', 6, 0), ('+', 7, 1)),
    (('+', 0, 7), ('+', 1, 6), ('-', 2, 5), ('+', 3, 4),
     ('+', 4, 3), ('+', 5, 2), ('-', 6, 1), ('+', 7, 0)),
)


def _product_code(a, b):
    """
    Write the 8 components of ``dq_multiply_coeffs(a, b)`` as Python expressions.

    ``a``: 8 variable names; ``b``: 8 constants (floats). Terms with a zero constant are
    left out, a factor 1.0 is dropped; the other terms keep their order, so the values are
    the product's (a sum of exact zeros may differ only in the sign of a zero).
    """
    out = []
    for terms in _PRODUCT_TERMS:
        code = ''
        for sign, i, k in terms:
            if b[k] == 0.0:
                continue
            term = a[i] if b[k] == 1.0 else f'{a[i]} * {b[k]!r}'
            code += f' {sign} {term}' if code else (term if sign == '+' else f'-{term}')
        out.append(code or '0.0')
    return out


def run_chain_program(table: ChainTable, base: Sequence, q: Sequence, cos: Callable,
                      sin: Callable) -> list[tuple]:
    """
    Return the frames of a chain's ``table`` (frame 0..n, then the tool) from ``base``.

    ``base`` is frame 0 (8 coefficients: floats, or arrays for a batch); a branch of a tree
    starts from its parent frame times its base transform. ``q``: the chain's variables.
    """
    frames = run_program(table.program, base, q, cos, sin)
    if table.tool is not None:
        frames.append(dq_multiply_coeffs(frames[-1], table.tool))
    return frames


def _chain_code(table, q_index, first, keep, mark=_MARK):
    """
    Write the straight-line code of one chain, starting from the frame 0 in ``aw..bz``.

    ``q_index``: where each chain variable is in ``q``; ``first``: the index of frame 0
    among all frames (the names ``f<k>`` of kept frames); ``keep``: keep frames as ``f<k>``;
    ``mark``: the lines that append a frame's pose to ``absolute`` (none: not wanted).
    """
    r = repr
    lines = list(mark)
    if keep:
        lines.append(f'f{first} = ({_DQ})')
    modified = table.modified
    for i, joint in enumerate(table.joints):
        ti, di = int(table.theta_index[i]), int(table.d_index[i])
        ca, sa, a, theta, d, scale, _, _, s_alpha, c_alpha = table.pose_rows[i]
        if ti >= 0:
            lines += [f'half = 0.5 * ({r(theta)} + {r(scale)} * q[{q_index[ti]}])',
                      'ct, st = cos(half), sin(half)']
        else:
            lines.append(f'ct, st = {r(math.cos(0.5 * theta))}, {r(math.sin(0.5 * theta))}')
        lines.append(f'd = {r(d)} + {r(scale)} * q[{q_index[di]}]' if di >= 0 else
                     f'd = {r(d)}')
        for op, p1, _, _, p4, p5, _ in row_program(joint, ti, di, modified):
            if op == Z:
                lines += ['c, s = ct, st', _Z_STEP]
                if p5 >= 0 or p4:
                    lines += ['hd = 0.5 * d',
                              'bw, bx, by, bz = bw - hd * az, bx + hd * ay, by - hd * ax, '
                              'bz + hd * aw']
            else:
                if p1:
                    lines.append(f'bw, bx, by, bz = bw - {r(p1)} * ax, bx + {r(p1)} * aw, '
                                 f'by + {r(p1)} * az, bz - {r(p1)} * ay')
                if p4:
                    lines += [f'c, s = {r(math.cos(0.5 * joint.alpha))}, '
                              f'{r(math.sin(0.5 * joint.alpha))}', _X_STEP]
        lines += list(mark)
        if keep:
            lines.append(f'f{first + i + 1} = ({_DQ})')
        if modified:
            lines += [f'qx, qy, qz, qw = {r(sa)} * ct, -{r(sa)} * st, {r(ca)} * st, {r(ca)} * ct',
                      f'x, y, z = {r(a)}, -d * {r(s_alpha)}, d * {r(c_alpha)}']
        else:
            lines += [f'qx, qy, qz, qw = {r(sa)} * ct, {r(sa)} * st, {r(ca)} * st, {r(ca)} * ct',
                      f'x, y, z = {r(a)} * (1.0 - 2.0 * st * st), 2.0 * {r(a)} * st * ct, d']
        lines += ['if qw < 0.0:', '    qx, qy, qz, qw = -qx, -qy, -qz, -qw',
                  'relative.append((x, y, z, qx, qy, qz, qw))']
    if table.tool is not None:
        lines += [f'{_DQ} = multiply(({_DQ}), {table.tool!r})'] + list(mark)
        if keep:
            lines.append(f'f{first + table.n_frames - 1} = ({_DQ})')
    return lines


def unrolled_frame_poses(table: ChainTable, links: Sequence[tuple] = (),
                         motion: Callable | None = None, branches: Sequence[tuple] = (),
                         absolute: bool = True) -> Callable[[list[float]], tuple[list, list]]:
    """
    Write and compile ``frame_poses`` as straight-line code of a chain's table (and more).

    The loops of :func:`run_program` and :meth:`KinematicChain.row_poses` unrolled, with
    each row's constants in place and the half-angle cosine and sine shared by the row's
    z factor and its pose: the same floating-point operations in the same order, so the
    same results to the bit, in about half the time.

    :param links: rigid frames attached to the chain's frames, as
        :class:`~dq_fk_ros.description.robot_model.RobotModel` plans them: ``(attachment
        index, TF-parent index, offset 8-tuple, motion)`` (index -1: the fixed frame); a
        constant offset is multiplied in with its zero terms left out.
    :param motion: ``motion(motion, q, cos, sin) -> 8-tuple`` for links that move.
    :param branches: the other chains of a tree, ``(table, index of the frame it hangs from
        (-1: the fixed frame), index in q of each of its variables)``, in order; their
        frames follow the chain's, their rows' transforms its rows'.
    :param absolute: False: the TF transforms alone (``absolute`` is returned empty; the
        frames' poses are not converted, about a third less work for a tree).
    :returns: ``f(q_list) -> (absolute, relative)`` as ``frame_poses`` returns them; its
        source is ``f.source``.
    """
    keep = bool(links or branches)  # keep the frames the links and branches hang from
    mark = _MARK if absolute else ()
    lines = ['def frame_poses(q):', 'absolute, relative = [], []', f'{_DQ} = {table.base!r}']
    lines += _chain_code(table, range(table.dof), 0, keep, mark)
    n_frames = table.n_frames
    for branch, parent, q_index in branches:
        if parent >= 0:
            lines += [f'{_PARENT} = f{parent}',
                      f'{_DQ} = (' + ', '.join(_product_code(_PARENT.split(', '),
                                                             branch.base)) + ')']
        else:
            lines.append(f'{_DQ} = {branch.base!r}')
        lines += _chain_code(branch, q_index, n_frames, keep, mark)
        n_frames += branch.n_frames
    for j, (attach, tf_parent, offset, moves) in enumerate(links):
        k = n_frames + j
        parent = f'f{attach}' if attach >= 0 else repr(_IDENTITY)
        if moves is not None:  # offset times the joint's motion: as the general path
            lines += [f'o = multiply({offset!r}, motion({moves!r}, q, cos, sin))',
                      f'{_DQ} = multiply({parent}, o)']
        elif attach >= 0:
            lines += [f'{_PARENT} = {parent}',
                      f'{_DQ} = (' + ', '.join(_product_code(_PARENT.split(', '), offset)) + ')']
        else:
            lines.append(f'{_DQ} = {dq_multiply_coeffs(_IDENTITY, offset)!r}')
        lines += [f'f{k} = ({_DQ})'] + list(mark)
        if tf_parent == attach:
            lines.append('relative.append(pose(o))' if moves is not None else
                         f'relative.append({pose_xyzw_from_coeffs(offset)!r})')
        else:
            above = f'f{tf_parent}' if tf_parent >= 0 else repr(_IDENTITY)
            lines.append(f'relative.append(pose(multiply(inverse({above}), f{k})))')
    lines.append('return absolute, relative')
    source = '\n    '.join(lines) + '\n'
    namespace = {'cos': math.cos, 'sin': math.sin, 'multiply': dq_multiply_coeffs,
                 'inverse': dq_inverse_coeffs, 'pose': pose_xyzw_from_coeffs,
                 'motion': motion}
    rows = len(table.joints) + sum(len(b.joints) for b, _, _ in branches)
    exec(compile(source, f'<frame_poses of {1 + len(branches)} chain(s), {rows} rows, '
                         f'{len(links)} links>', 'exec'), namespace)
    function = namespace['frame_poses']
    function.source = source
    return function


__all__ = ['run_chain_program', 'unrolled_frame_poses']
