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
:mod:`dq_fk_ros.kinematics.dh_code`, a row's closed form in :mod:`.dh_rows`, the numpy
references of the batches in :mod:`.chain_batches` and the Jacobians in
:mod:`.chain_jacobians`; the compiled kernel is chosen in :mod:`dq_fk_ros.kinematics.kernel`.
Each fast path's docstring names its reference and the test that holds them equal.
"""

from array import array
from collections.abc import Sequence
from dataclasses import dataclass
from functools import cached_property
import math

from dq_fk_ros.kinematics.chain_batches import (
    forward_all_batch_reference, forward_batch_reference, q_batch, relative_all_batch,
    row_params_batch)
from dq_fk_ros.kinematics.chain_jacobians import jacobian_dq, jacobian_geometric_reference
from dq_fk_ros.kinematics.chain_variables import chain_variables
from dq_fk_ros.kinematics.dh_code import row_program, run_program, unrolled_frame_poses
from dq_fk_ros.kinematics.dh_rows import relative_tuples, row_poses
from dq_fk_ros.kinematics.dual_quaternion import (
    Coeffs, dq_multiply_coeffs, dq_translation_array, DualQuaternion, Pose, pose_xyzw_from_coeffs,
    quat_to_matrix)
from dq_fk_ros.kinematics.kernel import KERNEL
from dq_fk_ros.kinematics.kernel_layout import pack, program_record
import numpy as np
from numpy.typing import ArrayLike

CONVENTIONS = ('standard', 'modified')
JOINT_TYPES = ('revolute', 'prismatic', 'cylindrical', 'fixed')


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
        self._base_t = tuple(self.base.coeffs.tolist())
        self._tool_t = tuple(self.tool.coeffs.tolist()) if tool is not None else None
        self._build_variable_map()
        # the compiled kernel's inputs: the factor program, by kernel_layout.h's op fields
        self._dof = len(self.joint_names)
        # per row: its theta variable, its d variable (-1: none) and scale, for the Jacobian
        self._jacobian_rows = np.array(
            [[float(self._theta_index[i]), float(self._d_index[i]), self._scale[i]]
             for i in range(len(self.joints))]).reshape(-1, 3)
        self._make_kernel_chain()

    def _make_kernel_chain(self):
        """Check and copy the program into the kernel once (its single calls take 2 buffers)."""
        self._kernel_chain = self._kernel_args = None
        if KERNEL is not None:
            self._kernel_args = (
                pack(KERNEL.LAYOUTS, 'op', [program_record(op) for op in self._program]),
                np.array(self._base_t), None if self.tool is None else np.array(self._tool_t))
            self._kernel_chain = KERNEL.Chain(*self._kernel_args, self._dof, self._jacobian_rows,
                                              self.convention == 'modified')

    def __getstate__(self):
        """Pickle without the kernel's copy (made again on unpickling) and generated code."""
        state = dict(self.__dict__)
        for made in ('_kernel_chain', '_kernel_args', '_unrolled'):
            state.pop(made, None)
        return state

    def __setstate__(self, state):
        """Unpickle, and copy the program into the kernel again."""
        self.__dict__.update(state)
        self._make_kernel_chain()

    # -- structure ---------------------------------------------------------------------
    def _build_variable_map(self):
        variables = chain_variables(self.joints)
        self.joint_names, self.limits = variables.names, variables.limits
        self._theta_index, self._d_index = variables.theta_index, variables.d_index
        self._angular = variables.angular
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
        theta, d = row_params_batch(self, self._check_q(q)[None, :])
        return theta[0], d[0]

    def _check_q(self, q):
        q = np.asarray(q, dtype=float)
        if q.shape != (self.dof,):
            raise ValueError(f'expected {self.dof} joint values {list(self.joint_names)}, '
                             f'got shape {q.shape}')
        return q

    # -- single configuration (plain floats: no per-call numpy overhead) ---------------
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
        """Every row's transform frame i-1 -> frame i, ``(x, y, z, qx..qw)``, ``qw >= 0``."""
        return row_poses(self, joint_value_list(q, self.joint_names))

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
        return np.array(relative_tuples(self, self._check_q(q).tolist()))

    def _q_vector(self, q):
        """Return ``q`` as a contiguous float64 vector (the numpy path's errors if not)."""
        return joint_value_vector(q, self.joint_names)

    def _q_batch(self, q):
        """Return ``q`` as a contiguous ``(N, dof)`` float64 array (the numpy path's errors)."""
        return q_batch(self, q)

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

    # -- batches: the kernel's, numpy's the reference (chain_batches.py) ----------------
    def relative_all_batch(self, q: ArrayLike) -> np.ndarray:
        """Relative transforms of every row for N configurations: ``(N, n, 8)`` (numpy)."""
        return relative_all_batch(self, q)

    def forward_all_batch(self, q: ArrayLike, out: np.ndarray | None = None) -> np.ndarray:
        """
        Absolute poses of every frame for N configurations: ``(N, n_frames, 8)``.

        Fast path: the C kernel; reference: ``chain_batches.forward_all_batch_reference``
        (test_kernel.py). ``out``: a C-contiguous float64 ``(N, n_frames, 8)`` array to fill
        and return (no allocation), else a new one.
        """
        return self._batch_into(q, out, (self.n_frames, 8), 'frames_batch',
                                forward_all_batch_reference)

    def forward_batch(self, q: ArrayLike, out: np.ndarray | None = None) -> np.ndarray:
        """
        End-effector poses (tool if any) for N configurations: ``(N, 8)``, ``w >= 0``.

        Fast path: the C kernel; reference: ``chain_batches.forward_batch_reference``
        (test_kernel.py). ``out``: a C-contiguous float64 ``(N, 8)`` array, else a new one.
        """
        return self._batch_into(q, out, (8,), 'end_batch', forward_batch_reference)

    def _batch_into(self, q, out, shape, kernel, reference):
        """Run the kernel chain's batch method ``kernel`` into ``out`` (made if None)."""
        if out is not None and not (
                isinstance(out, np.ndarray) and out.dtype == np.float64 and
                out.flags.c_contiguous and out.flags.writeable and out.shape[1:] == shape):
            raise ValueError(f'out must be a C-contiguous writable float64 (N, '
                             f'{", ".join(map(str, shape))}) array')
        if KERNEL is None:
            result = reference(self, q)
            if out is None:
                return result
            out[...] = result
            return out
        q = self._q_batch(q)
        if out is None:
            out = np.empty((len(q),) + shape)
        getattr(self._kernel_chain, kernel)(q, out)
        return out

    # -- differential kinematics (chain_jacobians.py) ------------------------------------
    def jacobian_dq(self, q: ArrayLike) -> np.ndarray:
        """Return the 8 x dof dual-quaternion Jacobian (``chain_jacobians.jacobian_dq``)."""
        return jacobian_dq(self, q)

    def jacobian_geometric(self, q: ArrayLike) -> np.ndarray:
        """
        Return the 6 x dof geometric Jacobian of the end effector in the fixed frame.

        Rows 0-2: linear velocity of the end-effector origin; rows 3-5: angular velocity.
        Fast path: the C kernel; reference: ``chain_jacobians.jacobian_geometric_reference``
        (test_kernel.py holds them equal to 1e-12).
        """
        if KERNEL is None:
            return jacobian_geometric_reference(self, q)
        out = np.empty((6, self._dof))
        try:
            self._kernel_chain.jacobian(q, out)
        except (ValueError, TypeError):
            self._kernel_chain.jacobian(self._q_vector(q), out)
        return out

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


def homogeneous_from_dq(h: ArrayLike) -> np.ndarray:
    """4x4 matrices ``(..., 4, 4)`` of unit dual quaternions ``(..., 8)``."""
    h = np.asarray(h, dtype=float)
    m = np.zeros(h.shape[:-1] + (4, 4))
    m[..., :3, :3] = quat_to_matrix(h[..., :4])
    m[..., :3, 3] = dq_translation_array(h)
    m[..., 3, 3] = 1.0
    return m


__all__ = ['CONVENTIONS', 'DHJoint', 'JOINT_TYPES', 'KinematicChain', 'homogeneous_from_dq']
