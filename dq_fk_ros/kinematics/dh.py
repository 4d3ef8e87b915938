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

The rows' factor program and the straight-line code generated from it are in
:mod:`dq_fk_ros.kinematics.dh_code`; the compiled kernel in :mod:`dq_fk_ros.kinematics.kernel`.

Why this file is long: each of the chain's fast paths (the C kernel) stands beside its
numpy reference (``_forward_all_reference``...), so that a change to one is seen next to the
other; test_kernel.py holds them equal.
"""

from array import array
from collections.abc import Sequence
from dataclasses import dataclass
from functools import cached_property
import math

from dq_fk_ros.kinematics.dh_code import row_program, run_program, unrolled_frame_poses
from dq_fk_ros.kinematics.dual_quaternion import (
    canonical, Coeffs, dq_multiply_array, dq_multiply_coeffs, dq_translation_array, DualQuaternion,
    Pose, pose_xyzw_from_coeffs, quat_conjugate, quat_to_matrix)
from dq_fk_ros.kinematics.kernel import KERNEL
import numpy as np
from numpy.typing import ArrayLike

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


def joint_value_list(q: ArrayLike, joint_names: Sequence[str]) -> list[float]:
    """Return ``q`` as a list of floats, one per joint (ValueError naming the joints if not)."""
    if isinstance(q, np.ndarray) and q.ndim != 1:
        raise ValueError(f'expected {len(joint_names)} joint values {list(joint_names)}, '
                         f'got an array of shape {q.shape}')
    if len(q) != len(joint_names):
        raise ValueError(f'expected {len(joint_names)} joint values {list(joint_names)}, '
                         f'got {len(q)}')
    return q.tolist() if isinstance(q, np.ndarray) else [float(v) for v in q]


def joint_value_vector(q: ArrayLike, joint_names: Sequence[str]) -> np.ndarray:
    """Return ``q`` as a contiguous float64 vector for the kernel (ValueError as above)."""
    q = np.ascontiguousarray(q, dtype=float)
    if q.ndim != 1 or len(q) != len(joint_names):
        joint_value_list(q, joint_names)  # raises the numpy path's ValueError
    return q


class KinematicChain:
    """
    A serial chain of :class:`DHJoint` rows with a fixed base and an optional tool.

    ``joint_names`` lists the joint variables in the order ``q`` is given.
    ``forward_all(q)`` returns the absolute pose of every frame (0..n, then the tool) in the
    fixed frame in one pass of cumulative products ([Zivkovic2023] eq. (16)).
    """

    def __init__(self, joints: Sequence[DHJoint], convention: str = 'standard',
                 base: DualQuaternion | None = None, tool: DualQuaternion | None = None):
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
        # the compiled kernel's inputs: the factor program as an (n_ops, 7) array
        self._dof = len(self.joint_names)
        # per row: its theta variable, its d variable (-1: none) and scale, for the Jacobian
        self._jacobian_rows = np.array(
            [[float(self._theta_index[i]), float(self._d_index[i]), self._scale[i]]
             for i in range(len(self.joints))]).reshape(-1, 3)
        self._kernel_args = (
            np.array([[float(v) for v in op] for op in self._program]).reshape(-1, 7),
            np.array(self._base_t), None if tool is None else np.array(self._tool_t))
        self._make_kernel_chain()

    def _make_kernel_chain(self):
        """Check and copy the program into the kernel once (its single calls take 2 buffers)."""
        self._kernel_chain = None if KERNEL is None else KERNEL.Chain(
            *self._kernel_args, self._dof, self._jacobian_rows, self.convention == 'modified')

    def __getstate__(self):
        """Pickle without the kernel's copy (made again on unpickling) and generated code."""
        state = dict(self.__dict__)
        state.pop('_kernel_chain', None)
        state.pop('_unrolled', None)
        return state

    def __setstate__(self, state):
        """Unpickle, and copy the program into the kernel again."""
        self.__dict__.update(state)
        self._make_kernel_chain()

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
                              for op in row_program(j, int(self._theta_index[i]),
                                                    int(self._d_index[i]), modified))
        # the closed-form operators of [Radavelli2014] eq. (3), for relative_all
        self._rows = tuple(
            (math.cos(0.5 * j.alpha), math.sin(0.5 * j.alpha), j.a, j.theta, j.d, j.scale,
             int(self._theta_index[i]), int(self._d_index[i]))
            for i, j in enumerate(self.joints))
        self._pose_rows = tuple(row + (math.sin(j.alpha), math.cos(j.alpha))
                                for row, j in zip(self._rows, self.joints))

    @property
    def dof(self) -> int:
        """Count the joint variables (the length of ``q``)."""
        return len(self.joint_names)

    @property
    def n_frames(self) -> int:
        """Count the frames ``forward_all`` returns: frame 0..n, plus the tool if any."""
        return len(self.joints) + 1 + (self.tool is not None)

    def row_parameters(self, q: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
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
        frames = run_program(self._program, self._base_t, q, math.cos, math.sin)
        if self._tool_t is not None:
            frames.append(dq_multiply_coeffs(frames[-1], self._tool_t))
        return frames

    def frame_coeffs(self, q: ArrayLike) -> list[Coeffs]:
        """Frames 0..n (and the tool) as 8-tuples of plain floats, not made ``w >= 0``."""
        return self._absolute_tuples(q)

    def row_poses(self, q: ArrayLike) -> list[Pose]:
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

    def frame_poses(self, q: ArrayLike) -> tuple[list[Pose], list[Pose]]:
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

    def frame_poses_general(self, q: ArrayLike) -> tuple[list[Pose], list[Pose]]:
        """
        :meth:`frame_poses` by the general (looping) path: the reference.

        The fast path is the straight-line code of :func:`unrolled_frame_poses`; test_dh.py's
        ``test_the_unrolled_frame_poses_are_the_general_path_to_the_bit`` holds them equal.
        """
        absolute = [pose_xyzw_from_coeffs(h) for h in self._absolute_tuples(q)]
        return absolute, self.row_poses(q)

    def relative_all(self, q: ArrayLike) -> np.ndarray:
        """Relative transform of every row, frame i-1 -> frame i, as an ``(n, 8)`` array."""
        return np.array(self._relative_tuples(self._check_q(q).tolist()))

    def _q_vector(self, q):
        """Return ``q`` as a contiguous float64 vector (the numpy path's errors if not)."""
        return joint_value_vector(q, self.joint_names)

    def _q_batch(self, q):
        """Return ``q`` as a contiguous ``(N, dof)`` float64 array (the numpy path's errors)."""
        q = np.ascontiguousarray(q, dtype=float)
        if q.ndim != 2 or q.shape[1] != self.dof:
            raise ValueError(f'expected an (N, {self.dof}) array of joint values, '
                             f'got shape {q.shape}')
        return q

    def forward_all(self, q: ArrayLike, out: np.ndarray | None = None) -> np.ndarray:
        """
        Absolute pose of every frame in the fixed frame, ``(n_frames, 8)``, ``w >= 0``.

        Rows: frame 0 (the base transform), frames 1..n, then the tool if any. Fast path: the
        C kernel (:mod:`dq_fk_ros.kinematics.kernel`); reference: :meth:`_forward_all_reference`
        (test_kernel.py holds them equal to 1e-12).

        :param out: a C-contiguous float64 ``(n_frames, 8)`` array to fill and return (no
            allocation; the C kernel only), else a new one.
        """
        if KERNEL is None:
            result = self._forward_all_reference(q)
            if out is None:
                return result
            out[...] = result
            return out
        if out is None:
            out = np.empty((self.n_frames, 8))
        try:  # a float64 vector of the right length goes straight in
            self._kernel_chain.frames(q, out)
        except (ValueError, TypeError):  # a list, another dtype... or a wrong q: its error
            self._kernel_chain.frames(self._q_vector(q), out)
        return out

    def _forward_all_reference(self, q):
        """:meth:`forward_all` in Python floats: the reference of the kernel."""
        flat = []
        for f in self._absolute_tuples(q):
            flat += f if f[0] >= 0.0 else [-v for v in f]
        return np.frombuffer(array('d', flat)).reshape(-1, 8)

    def forward(self, q: ArrayLike) -> DualQuaternion:
        """
        Return the end-effector pose (tool if any, else frame n), a :class:`DualQuaternion`.

        Fast path: the C kernel; reference: the last row of :meth:`_forward_all_reference`.
        """
        if KERNEL is not None:
            out = np.empty(8)
            try:
                self._kernel_chain.end(q, out)
            except (ValueError, TypeError):
                self._kernel_chain.end(self._q_vector(q), out)
            return DualQuaternion.from_array(out)
        end = self._absolute_tuples(q)[-1]
        return DualQuaternion.from_array(np.frombuffer(
            array('d', end if end[0] >= 0.0 else [-v for v in end])))

    # -- batches -----------------------------------------------------------------------
    def _row_params_batch(self, q):
        q = self._q_batch(q)
        qe = np.concatenate([q, np.zeros((q.shape[0], 1))], axis=1)
        theta = self._theta0 + np.where(self._theta_index >= 0,
                                        self._scale * qe[:, self._theta_index], 0.0)
        d = self._d0 + np.where(self._d_index >= 0, self._scale * qe[:, self._d_index], 0.0)
        return theta, d

    def relative_all_batch(self, q: ArrayLike) -> np.ndarray:
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
        q = self._q_batch(q)
        for start in range(0, q.shape[0], BATCH_CHUNK):
            part = slice(start, min(start + BATCH_CHUNK, q.shape[0]))
            cols = np.ascontiguousarray(q[part].T)
            frames = run_program(self._program, self._base_t, cols, np.cos, np.sin)
            if self._tool_t is not None:
                frames.append(dq_multiply_coeffs(frames[-1], self._tool_t))
            yield part, frames

    def forward_all_batch(self, q: ArrayLike, out: np.ndarray | None = None) -> np.ndarray:
        """
        Absolute poses of every frame for N configurations: ``(N, n_frames, 8)``.

        Fast path: the C kernel; reference: :meth:`_forward_all_batch_reference`
        (test_kernel.py).

        :param out: a C-contiguous float64 ``(N, n_frames, 8)`` array to fill and return (no
            allocation), else a new one.
        """
        return self._batch_into(q, out, (self.n_frames, 8), 'frames_batch',
                                self._forward_all_batch_reference)

    def _batch_into(self, q, out, shape, kernel, reference):
        """Run the kernel chain's batch method ``kernel`` into ``out`` (made if None)."""
        if out is not None and not (
                isinstance(out, np.ndarray) and out.dtype == np.float64 and
                out.flags.c_contiguous and out.flags.writeable and out.shape[1:] == shape):
            raise ValueError(f'out must be a C-contiguous writable float64 (N, '
                             f'{", ".join(map(str, shape))}) array')
        if KERNEL is None:
            result = reference(q)
            if out is None:
                return result
            out[...] = result
            return out
        q = self._q_batch(q)
        if out is None:
            out = np.empty((len(q),) + shape)
        getattr(self._kernel_chain, kernel)(q, out)
        return out

    def _forward_all_batch_reference(self, q):
        """:meth:`forward_all_batch` with numpy, chunk by chunk: the reference."""
        out = np.empty((len(q), self.n_frames, 8))
        for part, frames in self._batches(q):
            for i, frame in enumerate(frames):
                for k in range(8):
                    out[part, i, k] = frame[k]
        return _canonical_inplace(out)

    def forward_batch(self, q: ArrayLike, out: np.ndarray | None = None) -> np.ndarray:
        """
        End-effector poses (tool if any) for N configurations: ``(N, 8)``, ``w >= 0``.

        Fast path: the C kernel; reference: :meth:`_forward_batch_reference` (test_kernel.py).

        :param out: a C-contiguous float64 ``(N, 8)`` array to fill and return (no
            allocation), else a new one.
        """
        return self._batch_into(q, out, (8,), 'end_batch', self._forward_batch_reference)

    def _forward_batch_reference(self, q):
        """:meth:`forward_batch` with numpy, chunk by chunk: the reference."""
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

    def jacobian_dq(self, q: ArrayLike) -> np.ndarray:
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

    def jacobian_geometric(self, q: ArrayLike) -> np.ndarray:
        """
        Return the 6 x dof geometric Jacobian of the end effector in the fixed frame.

        Rows 0-2: linear velocity of the end-effector origin; rows 3-5: angular velocity.
        Fast path: the C kernel; reference: :meth:`_jacobian_geometric_reference`
        (test_kernel.py holds them equal to 1e-12).
        """
        if KERNEL is None:
            return self._jacobian_geometric_reference(q)
        out = np.empty((6, self._dof))
        try:
            self._kernel_chain.jacobian(q, out)
        except (ValueError, TypeError):
            self._kernel_chain.jacobian(self._q_vector(q), out)
        return out

    def _jacobian_geometric_reference(self, q):
        """:meth:`jacobian_geometric` with numpy, axis by axis: the reference."""
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

    def twist(self, q: ArrayLike, qdot: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """End-effector twist ``(v, omega)`` in the fixed frame from joint velocities."""
        qdot = np.asarray(qdot, dtype=float)
        if qdot.shape != (self.dof,):
            raise ValueError(f'expected {self.dof} joint velocities, got shape {qdot.shape}')
        v = self.jacobian_geometric(q) @ qdot
        return v[:3], v[3:]

    def pose_rate(self, q: ArrayLike, qdot: ArrayLike) -> np.ndarray:
        """Time derivative of the end pose's 8 coefficients, ``J_dq qdot`` ([DQFKcpp2023])."""
        return self.jacobian_dq(q) @ np.asarray(qdot, dtype=float)


def _canonical_inplace(h):
    """Flip, in place, the dual quaternions ``(..., 8)`` whose real part has ``w < 0``."""
    negative = h[..., 0] < 0.0
    h[negative] *= -1.0
    return h


def homogeneous_from_dq(h: ArrayLike) -> np.ndarray:
    """4x4 matrices ``(..., 4, 4)`` of unit dual quaternions ``(..., 8)``."""
    h = np.asarray(h, dtype=float)
    m = np.zeros(h.shape[:-1] + (4, 4))
    m[..., :3, :3] = quat_to_matrix(h[..., :4])
    m[..., :3, 3] = dq_translation_array(h)
    m[..., 3, 3] = 1.0
    return m


__all__ = ['CONVENTIONS', 'DHJoint', 'JOINT_TYPES', 'KinematicChain', 'homogeneous_from_dq']
