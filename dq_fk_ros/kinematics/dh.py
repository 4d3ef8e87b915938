"""
Denavit-Hartenberg chains in dual quaternions: every link frame, batches, Jacobians.

Conventions (per chain):

* ``standard`` (distal, Spong; the papers'): ``T_i = Rz(theta) Tz(d) Tx(a) Rx(alpha)``, the
  closed form of [Radavelli2014] eq. (3), [Zivkovic2023] eqs. (13)-(15).
* ``modified`` (proximal, Craig): ``T_i = Rx(alpha) Tx(a) Rz(theta) Tz(d)``.

Lengths are metres, angles radians. A row's variable parameter is ``scale * q + offset``,
where ``q`` is a joint variable and ``offset`` is the row's ``theta`` (revolute) or ``d``
(prismatic) value. Frames are numbered as in the papers: frame 0 is the base of the chain
(``base`` transform from the fixed/world frame), frame ``i`` is the child of row ``i``,
and an optional fixed ``tool`` transform follows frame ``n``.

Dual quaternions are 8-vectors (w, x, y, z, w', x', y', z'); see
:mod:`dq_fk_ros.kinematics.dual_quaternion`.

Why this file is long: the DH chain core with its generated straight-line code beside the
general reference path it must equal to the bit.
"""

from array import array
from dataclasses import dataclass
from functools import cached_property
import math
from typing import NamedTuple

from dq_fk_ros.kinematics.dual_quaternion import (
    canonical, dq_inverse_coeffs, dq_multiply_array, dq_multiply_coeffs, dq_translation_array,
    DualQuaternion, pose_xyzw_from_coeffs, quat_conjugate, quat_to_matrix)
import numpy as np

CONVENTIONS = ('standard', 'modified')
JOINT_TYPES = ('revolute', 'prismatic', 'cylindrical', 'fixed')
# configurations per step of the batch paths: small enough for the working set to stay in cache
BATCH_CHUNK = 4096


@dataclass(frozen=True)
class DHJoint:
    """
    One DH row: a (m), alpha (rad), d (m), theta (rad), and which of them move.

    ``joint_type``: ``revolute`` (theta = scale*q + theta), ``prismatic``
    (d = scale*q + d), ``cylindrical`` (both: two joint variables, theta's then d's, the
    RRC robot's third joint in [Radavelli2014]) or ``fixed`` (no variable).
    ``name`` names the joint variable (cylindrical rows get ``name`` and ``name + '_d'``
    unless ``d_name`` is given). ``follows`` makes the row read another joint's variable
    instead of having its own (a mimic joint: ``scale`` is the multiplier).
    ``limits``: ``(lower, upper)`` of the row's own variable, in joint units.
    """

    a: float = 0.0
    alpha: float = 0.0
    d: float = 0.0
    theta: float = 0.0
    joint_type: str = 'revolute'
    scale: float = 1.0
    name: str = ''
    d_name: str = ''
    follows: str = ''
    limits: tuple = None

    def __post_init__(self):
        """Reject unknown joint types and non-finite numbers."""
        if self.joint_type not in JOINT_TYPES:
            raise ValueError(f'joint_type {self.joint_type!r} is not one of {JOINT_TYPES}')
        for field in ('a', 'alpha', 'd', 'theta', 'scale'):
            value = getattr(self, field)
            if not math.isfinite(value):
                raise ValueError(f'DH parameter {field} must be finite, got {value!r}')
        if self.follows and self.joint_type not in ('revolute', 'prismatic'):
            raise ValueError('only revolute and prismatic rows can follow another joint')


def _row_standard(ca, sa, a, theta, d):
    """Evaluate the standard DH operator in closed form, [Radavelli2014] eq. (3)."""
    ct = math.cos(0.5 * theta)
    st = math.sin(0.5 * theta)
    ha = 0.5 * a
    hd = 0.5 * d
    return (ca * ct, sa * ct, sa * st, ca * st,
            -ha * sa * ct - hd * ca * st, ha * ca * ct - hd * sa * st,
            ha * ca * st + hd * sa * ct, -ha * sa * st + hd * ca * ct)


def _row_modified(ca, sa, a, theta, d):
    """Evaluate the modified DH operator, closed form ``h_x(alpha, a) h_z(theta, d)``."""
    ct = math.cos(0.5 * theta)
    st = math.sin(0.5 * theta)
    ha = 0.5 * a
    hd = 0.5 * d
    return (ca * ct, sa * ct, -sa * st, ca * st,
            -hd * ca * st - ha * sa * ct, -hd * sa * st + ha * ca * ct,
            -hd * sa * ct - ha * ca * st, hd * ca * ct - ha * sa * st)


# The sparse factorisation of a DH row ([Zivkovic2023] eqs. (13)-(15)): the z factor
# Rz(theta) Tz(d) = (c + s k)(1 + eps d/2 k) and the x factor Tx(a) Rx(alpha) =
# (1 + eps a/2 i)(c + s i) each touch a few coefficients only, so applying them costs a
# fraction of a full product with the row's eq. (3) operator.
_Z, _X = 0, 1


class ZStep(NamedTuple):
    """
    A row's z factor ``Rz(theta) Tz(d)``: theta = theta + scale q[ti], d = d + scale q[di].

    An index of -1 means constant; ``mark``: the row's frame is complete after this step.
    """

    kind: int          # _Z
    theta: float
    scale: float
    ti: int
    d: float
    di: int
    mark: bool


class XStep(NamedTuple):
    """A row's x factor ``Tx(a) Rx(alpha)``, constant; ``mark`` as for :class:`ZStep`."""

    kind: int          # _X
    half_a: float
    cos_half_alpha: float
    sin_half_alpha: float
    has_rotation: bool
    unused: int        # (the same length as ZStep: the loops unpack both alike)
    mark: bool


def _row_program(joint, ti, di, modified):
    """
    Compile one DH row into its z and x factors (:class:`ZStep`, :class:`XStep`).

    Standard: ``Rz(theta) Tz(d) Tx(a) Rx(alpha)``; modified: ``Rx(alpha) Tx(a) Rz(theta)
    Tz(d)``; the last factor marks the row's frame.
    """
    ops = [[_Z, joint.theta, joint.scale, ti, joint.d, di, False]]
    if joint.a or joint.alpha:
        ops.append([_X, 0.5 * joint.a, math.cos(0.5 * joint.alpha),
                    math.sin(0.5 * joint.alpha), bool(joint.alpha), 0, False])
        if modified:
            ops.reverse()
    ops[-1][-1] = True
    return [ZStep(*op) if op[0] == _Z else XStep(*op) for op in ops]


def _run_program(program, base, q, cos, sin):
    """
    Multiply ``base`` by the compiled factors; return the frames marked along the way.

    Works on floats (``q`` a list, ``cos``/``sin`` from math) and on numpy arrays (``q`` a
    sequence of columns, one per joint variable, ``cos``/``sin`` from numpy) alike.
    The real part is ``(aw, ax, ay, az)``, the dual part ``(bw, bx, by, bz)``.
    """
    aw, ax, ay, az, bw, bx, by, bz = base
    frames = [base]
    for op, p1, p2, p3, p4, p5, mark in program:
        if op == _Z:  # h (c + s k) (1 + eps hd k)
            half = 0.5 * p1 if p3 < 0 else 0.5 * (p1 + p2 * q[p3])
            c, s = cos(half), sin(half)
            aw, ax, ay, az, bw, bx, by, bz = (
                aw * c - az * s, ax * c + ay * s, ay * c - ax * s, az * c + aw * s,
                bw * c - bz * s, bx * c + by * s, by * c - bx * s, bz * c + bw * s)
            if p5 >= 0 or p4:
                hd = 0.5 * p4 if p5 < 0 else 0.5 * (p4 + p2 * q[p5])
                bw, bx, by, bz = bw - hd * az, bx + hd * ay, by - hd * ax, bz + hd * aw
        else:  # h (1 + eps ha i) (c + s i), constant
            if p1:
                bw, bx, by, bz = bw - p1 * ax, bx + p1 * aw, by + p1 * az, bz - p1 * ay
            if p4:
                aw, ax, ay, az, bw, bx, by, bz = (
                    aw * p2 - ax * p3, ax * p2 + aw * p3, ay * p2 + az * p3, az * p2 - ay * p3,
                    bw * p2 - bx * p3, bx * p2 + bw * p3, by * p2 + bz * p3, bz * p2 - by * p3)
        if mark:
            frames.append((aw, ax, ay, az, bw, bx, by, bz))
    return frames


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


def joint_value_list(q, joint_names):
    """Return ``q`` as a list of floats, one per joint (ValueError naming the joints if not)."""
    if len(q) != len(joint_names):
        raise ValueError(f'expected {len(joint_names)} joint values {list(joint_names)}, '
                         f'got {len(q)}')
    return q.tolist() if isinstance(q, np.ndarray) else [float(v) for v in q]


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


def run_chain_program(chain, base, q, cos, sin):
    """
    Return the frames of ``chain`` (frame 0..n, then the tool) starting from ``base``.

    ``base`` is frame 0 (8 coefficients: floats, or arrays for a batch); a branch of a tree
    starts from its parent frame times its base transform. ``q``: the chain's variables.
    """
    frames = _run_program(chain._program, base, q, cos, sin)
    if chain._tool_t is not None:
        frames.append(dq_multiply_coeffs(frames[-1], chain._tool_t))
    return frames


def _chain_code(chain, q_index, first, keep, mark=_MARK):
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
    modified = chain.convention == 'modified'
    for i, joint in enumerate(chain.joints):
        ti, di = int(chain._theta_index[i]), int(chain._d_index[i])
        ca, sa, a, theta, d, scale, _, _, s_alpha, c_alpha = chain._pose_rows[i]
        if ti >= 0:
            lines += [f'half = 0.5 * ({r(theta)} + {r(scale)} * q[{q_index[ti]}])',
                      'ct, st = cos(half), sin(half)']
        else:
            lines.append(f'ct, st = {r(math.cos(0.5 * theta))}, {r(math.sin(0.5 * theta))}')
        lines.append(f'd = {r(d)} + {r(scale)} * q[{q_index[di]}]' if di >= 0 else
                     f'd = {r(d)}')
        for op, p1, _, _, p4, p5, _ in _row_program(joint, ti, di, modified):
            if op == _Z:
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
    if chain._tool_t is not None:
        lines += [f'{_DQ} = multiply(({_DQ}), {chain._tool_t!r})'] + list(mark)
        if keep:
            lines.append(f'f{first + chain.n_frames - 1} = ({_DQ})')
    return lines


def unrolled_frame_poses(chain, links=(), motion=None, branches=(), absolute=True):
    """
    Write and compile ``frame_poses`` as straight-line code for a chain (its branches, links).

    The loops of :func:`_run_program` and :meth:`KinematicChain.row_poses` unrolled, with
    each row's constants in place and the half-angle cosine and sine shared by the row's
    z factor and its pose: the same floating-point operations in the same order, so the
    same results to the bit, in about half the time.

    :param links: rigid frames attached to the chain's frames, as
        :class:`~dq_fk_ros.description.robot_model.RobotModel` plans them: ``(attachment
        index, TF-parent index, offset 8-tuple, motion)`` (index -1: the fixed frame); a
        constant offset is multiplied in with its zero terms left out.
    :param motion: ``motion(motion, q, cos, sin) -> 8-tuple`` for links that move.
    :param branches: the other chains of a tree, ``(chain, index of the frame it hangs from
        (-1: the fixed frame), index in q of each of its variables)``, in order; their
        frames follow the chain's, their rows' transforms its rows'.
    :param absolute: False: the TF transforms alone (``absolute`` is returned empty; the
        frames' poses are not converted, about a third less work for a tree).
    :returns: ``f(q_list) -> (absolute, relative)`` as ``frame_poses`` returns them; its
        source is ``f.source``.
    """
    keep = bool(links or branches)  # keep the frames the links and branches hang from
    mark = _MARK if absolute else ()
    lines = ['def frame_poses(q):', 'absolute, relative = [], []', f'{_DQ} = {chain._base_t!r}']
    lines += _chain_code(chain, range(chain.dof), 0, keep, mark)
    n_frames = chain.n_frames
    for branch, parent, q_index in branches:
        if parent >= 0:
            lines += [f'{_PARENT} = f{parent}',
                      f'{_DQ} = (' + ', '.join(_product_code(_PARENT.split(', '),
                                                             branch._base_t)) + ')']
        else:
            lines.append(f'{_DQ} = {branch._base_t!r}')
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
    rows = len(chain.joints) + sum(len(b.joints) for b, _, _ in branches)
    exec(compile(source, f'<frame_poses of {1 + len(branches)} chain(s), {rows} rows, '
                         f'{len(links)} links>', 'exec'), namespace)
    function = namespace['frame_poses']
    function.source = source
    return function


class KinematicChain:
    """
    A serial chain of :class:`DHJoint` rows with a fixed base and an optional tool.

    ``joint_names`` lists the joint variables in the order ``q`` is given.
    ``forward_all(q)`` returns the absolute pose of every frame (0..n, then the tool) in the
    fixed frame in one pass of cumulative products ([Zivkovic2023] eq. (16)).
    """

    def __init__(self, joints, convention='standard', base=None, tool=None):
        """
        Build a chain.

        :param joints: sequence of :class:`DHJoint`, from the base outwards.
        :param convention: ``'standard'`` (Spong, distal) or ``'modified'`` (Craig, proximal).
        :param base: :class:`DualQuaternion` fixed frame -> frame 0 (default identity).
        :param tool: :class:`DualQuaternion` frame n -> tool frame, or None for no tool.
        """
        if convention not in CONVENTIONS:
            raise ValueError(f'convention {convention!r} is not one of {CONVENTIONS}')
        self.joints = tuple(joints)
        if not self.joints:
            raise ValueError('a kinematic chain needs at least one DH row')
        self.convention = convention
        self.base = (base or DualQuaternion.identity()).normalized()
        self.tool = tool.normalized() if tool is not None else None
        self._row = _row_standard if convention == 'standard' else _row_modified
        self._base_t = tuple(self.base.coeffs.tolist())
        self._tool_t = tuple(self.tool.coeffs.tolist()) if tool is not None else None
        self._build_variable_map()

    # -- structure ---------------------------------------------------------------------
    def _build_variable_map(self):
        names, limits = [], []
        theta_idx, d_idx = [], []

        def add(name, lim):
            if name in names:
                raise ValueError(f'joint variable name {name!r} is used twice')
            names.append(name)
            limits.append(tuple(lim) if lim is not None else (-math.inf, math.inf))
            return len(names) - 1

        for i, j in enumerate(self.joints):
            t_i = d_i = -1
            if j.follows:
                continue
            default = j.name or f'joint_{i + 1}'
            if j.joint_type == 'revolute':
                t_i = add(default, j.limits)
            elif j.joint_type == 'prismatic':
                d_i = add(default, j.limits)
            elif j.joint_type == 'cylindrical':
                lim = j.limits if j.limits is not None else (None, None)
                t_i = add(default, lim[0])
                d_i = add(j.d_name or default + '_d', lim[1])
            theta_idx.append((i, t_i))
            d_idx.append((i, d_i))
        # rows that follow another joint read that joint's variable
        theta_map = dict(theta_idx)
        d_map = dict(d_idx)
        for i, j in enumerate(self.joints):
            if not j.follows:
                continue
            if j.follows not in names:
                raise ValueError(f'row {i + 1} follows unknown joint {j.follows!r}; '
                                 f'joints are {names}')
            k = names.index(j.follows)
            theta_map[i] = k if j.joint_type == 'revolute' else -1
            d_map[i] = k if j.joint_type == 'prismatic' else -1
        n = len(self.joints)
        self.joint_names = tuple(names)
        self.limits = np.array(limits, dtype=float).reshape(-1, 2)
        self._theta_index = np.array([theta_map[i] for i in range(n)], dtype=int)
        self._d_index = np.array([d_map[i] for i in range(n)], dtype=int)
        self._a = np.array([j.a for j in self.joints])
        self._alpha = np.array([j.alpha for j in self.joints])
        self._d0 = np.array([j.d for j in self.joints])
        self._theta0 = np.array([j.theta for j in self.joints])
        self._scale = np.array([j.scale for j in self.joints])
        modified = self.convention == 'modified'
        self._program = tuple(op for i, j in enumerate(self.joints)
                              for op in _row_program(j, int(self._theta_index[i]),
                                                     int(self._d_index[i]), modified))
        # the closed-form operators of [Radavelli2014] eq. (3), for relative_all
        self._rows = tuple(
            (math.cos(0.5 * j.alpha), math.sin(0.5 * j.alpha), j.a, j.theta, j.d, j.scale,
             int(self._theta_index[i]), int(self._d_index[i]))
            for i, j in enumerate(self.joints))
        self._pose_rows = tuple(row + (math.sin(j.alpha), math.cos(j.alpha))
                                for row, j in zip(self._rows, self.joints))

    @property
    def dof(self):
        """Count the joint variables (the length of ``q``)."""
        return len(self.joint_names)

    @property
    def n_frames(self):
        """Count the frames ``forward_all`` returns: frame 0..n, plus the tool if any."""
        return len(self.joints) + 1 + (self.tool is not None)

    def row_parameters(self, q):
        """Return the DH table at ``q``: arrays ``(theta, d)`` of every row, radians and metres."""
        theta, d = self._row_params_batch(self._check_q(q)[None, :])
        return theta[0], d[0]

    def _check_q(self, q):
        q = np.asarray(q, dtype=float)
        if q.shape != (self.dof,):
            raise ValueError(f'expected {self.dof} joint values {list(self.joint_names)}, '
                             f'got shape {q.shape}')
        return q

    # -- single configuration (plain floats: no per-call numpy overhead) ---------------
    def _relative_tuples(self, q):
        row = self._row
        out = []
        for ca, sa, a, theta, d, scale, ti, di in self._rows:
            if ti >= 0:
                theta = theta + scale * q[ti]
            if di >= 0:
                d = d + scale * q[di]
            out.append(row(ca, sa, a, theta, d))
        return out

    def _absolute_tuples(self, q):
        """Frames 0..n (and the tool) as 8-tuples of floats; the scalar fast path."""
        q = joint_value_list(q, self.joint_names)
        frames = _run_program(self._program, self._base_t, q, math.cos, math.sin)
        if self._tool_t is not None:
            frames.append(dq_multiply_coeffs(frames[-1], self._tool_t))
        return frames

    def frame_coeffs(self, q):
        """Frames 0..n (and the tool) as 8-tuples of plain floats, not made ``w >= 0``."""
        return self._absolute_tuples(q)

    def row_poses(self, q):
        """
        Every row's transform frame i-1 -> frame i as ``(x, y, z, qx, qy, qz, qw)``, ``qw >= 0``.

        Read off the row's operator directly: standard ``Rz(theta) Tz(d) Tx(a) Rx(alpha)``
        turns by ``(cos t/2 + k sin t/2)(cos al/2 + i sin al/2)`` and moves by
        ``(a cos t, a sin t, d)``; modified ``Rx(alpha) Tx(a) Rz(theta) Tz(d)`` turns by
        ``(cos al/2 + i sin al/2)(cos t/2 + k sin t/2)`` and moves by ``(a, -d sin al,
        d cos al)``: the same transforms as [Radavelli2014] eq. (3), without the dual part.
        """
        q = joint_value_list(q, self.joint_names)
        cos, sin = math.cos, math.sin
        out = []
        append = out.append
        standard = self.convention == 'standard'
        for ca, sa, a, theta, d, scale, ti, di, s_alpha, c_alpha in self._pose_rows:
            if ti >= 0:
                theta = theta + scale * q[ti]
            if di >= 0:
                d = d + scale * q[di]
            half = 0.5 * theta
            ct, st = cos(half), sin(half)
            if standard:
                qx, qy, qz, qw = sa * ct, sa * st, ca * st, ca * ct
                x, y, z = a * (1.0 - 2.0 * st * st), 2.0 * a * st * ct, d
            else:
                qx, qy, qz, qw = sa * ct, -sa * st, ca * st, ca * ct
                x, y, z = a, -d * s_alpha, d * c_alpha
            if qw < 0.0:
                qx, qy, qz, qw = -qx, -qy, -qz, -qw
            append((x, y, z, qx, qy, qz, qw))
        return out

    def frame_poses(self, q):
        """
        Poses for publishing, as plain tuples ``(x, y, z, qx, qy, qz, qw)`` (``qw >= 0``).

        Returns ``(absolute, relative)``: every frame in the fixed frame (as
        :meth:`forward_all`), and every row's transform frame i-1 -> frame i (as
        :meth:`row_poses`). The node's hot path: the chain's own straight-line code
        (:func:`unrolled_frame_poses`), the same arithmetic as the general path, to the bit.
        """
        return self._unrolled(joint_value_list(q, self.joint_names))

    @cached_property
    def _unrolled(self):
        """:meth:`frame_poses` as straight-line code, made on first use."""
        return unrolled_frame_poses(self)

    def frame_poses_general(self, q):
        """
        :meth:`frame_poses` by the general (looping) path: the reference.

        The fast path is the straight-line code of :func:`unrolled_frame_poses`; test_dh.py's
        ``test_the_unrolled_frame_poses_are_the_general_path_to_the_bit`` holds them equal.
        """
        absolute = [pose_xyzw_from_coeffs(h) for h in self._absolute_tuples(q)]
        return absolute, self.row_poses(q)

    def relative_all(self, q):
        """Relative transform of every row, frame i-1 -> frame i, as an ``(n, 8)`` array."""
        return np.array(self._relative_tuples(self._check_q(q).tolist()))

    def forward_all(self, q):
        """
        Absolute pose of every frame in the fixed frame, ``(n_frames, 8)``, ``w >= 0``.

        Rows: frame 0 (the base transform), frames 1..n, then the tool if any.
        """
        flat = []
        for f in self._absolute_tuples(q):
            flat += f if f[0] >= 0.0 else [-v for v in f]
        return np.frombuffer(array('d', flat)).reshape(-1, 8)

    def forward(self, q):
        """Return the end-effector pose (tool if any, else frame n), a :class:`DualQuaternion`."""
        end = self._absolute_tuples(q)[-1]
        return DualQuaternion.from_array(np.frombuffer(
            array('d', end if end[0] >= 0.0 else [-v for v in end])))

    # -- batches -----------------------------------------------------------------------
    def _row_params_batch(self, q):
        q = np.asarray(q, dtype=float)
        if q.ndim != 2 or q.shape[1] != self.dof:
            raise ValueError(f'expected an (N, {self.dof}) array of joint values, '
                             f'got shape {q.shape}')
        qe = np.concatenate([q, np.zeros((q.shape[0], 1))], axis=1)
        theta = self._theta0 + np.where(self._theta_index >= 0,
                                        self._scale * qe[:, self._theta_index], 0.0)
        d = self._d0 + np.where(self._d_index >= 0, self._scale * qe[:, self._d_index], 0.0)
        return theta, d

    def relative_all_batch(self, q):
        """Relative transforms of every row for N configurations: ``(N, n, 8)``."""
        theta, d = self._row_params_batch(q)
        half_t = 0.5 * theta
        ct, st = np.cos(half_t), np.sin(half_t)
        ca, sa = np.cos(0.5 * self._alpha), np.sin(0.5 * self._alpha)
        ha, hd = 0.5 * self._a, 0.5 * d
        if self.convention == 'standard':
            comps = (ca * ct, sa * ct, sa * st, ca * st,
                     -ha * sa * ct - hd * ca * st, ha * ca * ct - hd * sa * st,
                     ha * ca * st + hd * sa * ct, -ha * sa * st + hd * ca * ct)
        else:
            comps = (ca * ct, sa * ct, -sa * st, ca * st,
                     -hd * ca * st - ha * sa * ct, -hd * sa * st + ha * ca * ct,
                     -hd * sa * ct - ha * ca * st, hd * ca * ct - ha * sa * st)
        return np.stack(comps, axis=-1)

    def _batches(self, q):
        """Yield ``(slice, frames)`` per chunk; frames are 8-tuples of arrays (or floats)."""
        q = np.asarray(q, dtype=float)
        if q.ndim != 2 or q.shape[1] != self.dof:
            raise ValueError(f'expected an (N, {self.dof}) array of joint values, '
                             f'got shape {q.shape}')
        for start in range(0, q.shape[0], BATCH_CHUNK):
            part = slice(start, min(start + BATCH_CHUNK, q.shape[0]))
            cols = np.ascontiguousarray(q[part].T)
            frames = _run_program(self._program, self._base_t, cols, np.cos, np.sin)
            if self._tool_t is not None:
                frames.append(dq_multiply_coeffs(frames[-1], self._tool_t))
            yield part, frames

    def forward_all_batch(self, q):
        """Absolute poses of every frame for N configurations: ``(N, n_frames, 8)``."""
        out = np.empty((len(q), self.n_frames, 8))
        for part, frames in self._batches(q):
            for i, frame in enumerate(frames):
                for k in range(8):
                    out[part, i, k] = frame[k]
        return _canonical_inplace(out)

    def forward_batch(self, q):
        """End-effector poses (tool if any) for N configurations: ``(N, 8)``, ``w >= 0``."""
        out = np.empty((len(q), 8))
        for part, frames in self._batches(q):
            for k in range(8):
                out[part, k] = frames[-1][k]
        return _canonical_inplace(out)

    # -- differential kinematics -------------------------------------------------------
    def _joint_axes(self, q):
        """
        Per joint variable: the pose whose z axis is its joint axis, and the end pose.

        Standard DH moves row i about/along z of frame i-1; modified DH about/along z of
        frame i. Rows following another joint add their contribution to that joint.
        """
        frames = self._absolute_tuples(q)
        n = len(self.joints)
        end = frames[-1]
        axes = []  # (variable index, kind, scale, axis frame)
        for i in range(n):
            frame = frames[i] if self.convention == 'standard' else frames[i + 1]
            if self._theta_index[i] >= 0:
                axes.append((int(self._theta_index[i]), 'rot', self._scale[i], frame))
            if self._d_index[i] >= 0:
                axes.append((int(self._d_index[i]), 'trans', self._scale[i], frame))
        return axes, end

    def jacobian_dq(self, q):
        """
        Return the 8 x dof dual-quaternion Jacobian ``d vec(h_end) / d q`` (Adorno; [DQFKcpp2023]).

        Column j is ``(1/2) xi_j h_end`` with ``xi_j`` the joint's unit screw (its z axis as
        a line, dual part for a prismatic joint) in the fixed frame; ``h_end`` is the
        canonical end pose returned by :meth:`forward`.
        """
        axes, end = self._joint_axes(self._check_q(q).tolist())
        end = canonical(np.array(end))
        jac = np.zeros((8, self.dof))
        k_rot = np.array([0.0, 0, 0, 1, 0, 0, 0, 0])
        k_trans = np.array([0.0, 0, 0, 0, 0, 0, 0, 1])
        for var, kind, scale, frame in axes:
            frame = np.array(frame)
            inv = np.concatenate([quat_conjugate(frame[:4]), quat_conjugate(frame[4:])])
            unit = k_rot if kind == 'rot' else k_trans
            xi = dq_multiply_array(dq_multiply_array(frame, unit), inv)
            jac[:, var] += 0.5 * scale * dq_multiply_array(xi, end)
        return jac

    def jacobian_geometric(self, q):
        """
        Return the 6 x dof geometric Jacobian of the end effector in the fixed frame.

        Rows 0-2: linear velocity of the end-effector origin; rows 3-5: angular velocity.
        """
        axes, end = self._joint_axes(self._check_q(q).tolist())
        p_end = dq_translation_array(np.array(end))
        jac = np.zeros((6, self.dof))
        for var, kind, scale, frame in axes:
            frame = np.array(frame)
            z = quat_to_matrix(frame[:4])[:, 2]
            if kind == 'rot':
                p = dq_translation_array(frame)
                jac[:3, var] += scale * np.cross(z, p_end - p)
                jac[3:, var] += scale * z
            else:
                jac[:3, var] += scale * z
        return jac

    def twist(self, q, qdot):
        """End-effector twist ``(v, omega)`` in the fixed frame from joint velocities."""
        qdot = np.asarray(qdot, dtype=float)
        if qdot.shape != (self.dof,):
            raise ValueError(f'expected {self.dof} joint velocities, got shape {qdot.shape}')
        v = self.jacobian_geometric(q) @ qdot
        return v[:3], v[3:]

    def pose_rate(self, q, qdot):
        """Time derivative of the end pose's 8 coefficients, ``J_dq qdot`` ([DQFKcpp2023])."""
        return self.jacobian_dq(q) @ np.asarray(qdot, dtype=float)


def _canonical_inplace(h):
    """Flip, in place, the dual quaternions ``(..., 8)`` whose real part has ``w < 0``."""
    negative = h[..., 0] < 0.0
    h[negative] *= -1.0
    return h


def homogeneous_from_dq(h):
    """4x4 matrices ``(..., 4, 4)`` of unit dual quaternions ``(..., 8)``."""
    h = np.asarray(h, dtype=float)
    m = np.zeros(h.shape[:-1] + (4, 4))
    m[..., :3, :3] = quat_to_matrix(h[..., :4])
    m[..., :3, 3] = dq_translation_array(h)
    m[..., 3, 3] = 1.0
    return m


__all__ = ['CONVENTIONS', 'DHJoint', 'JOINT_TYPES', 'KinematicChain', 'homogeneous_from_dq']
