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

:class:`KinematicChain` is a facade: its table is laid out once
(:mod:`~dq_fk_ros.kinematics.chain_table`), its engine chosen once
(:mod:`~dq_fk_ros.kinematics.chain_engines`: the compiled kernel, or the numpy reference
with the same methods); the straight-line code of one configuration is in
:mod:`~dq_fk_ros.kinematics.dh_code`, a row's closed form in :mod:`.dh_rows`, the
dual-quaternion Jacobian in :mod:`.chain_jacobians`. Each fast path's docstring names its
reference and the test that holds them equal.
"""

from collections.abc import Callable, Sequence
from functools import cached_property
import math

from dq_fk_ros.kinematics.chain_batches import relative_all_batch, row_params_batch
from dq_fk_ros.kinematics.chain_engines import chain_engine
from dq_fk_ros.kinematics.chain_jacobians import jacobian_dq
from dq_fk_ros.kinematics.chain_table import chain_table, joint_value_list, joint_value_vector
from dq_fk_ros.kinematics.dh_code import run_chain_program, unrolled_frame_poses
from dq_fk_ros.kinematics.dh_joint import CONVENTIONS, DHJoint, JOINT_TYPES
from dq_fk_ros.kinematics.dh_rows import relative_tuples, row_poses
from dq_fk_ros.kinematics.dual_quaternion import (
    Coeffs, dq_translation_array, DualQuaternion, Pose, pose_xyzw_from_coeffs, quat_to_matrix)
import numpy as np
from numpy.typing import ArrayLike


class KinematicChain:
    """
    A serial chain of :class:`DHJoint` rows with a fixed base and an optional tool.

    ``joint_names`` lists the joint variables in the order ``q`` is given.
    ``forward_all(q)`` returns the absolute pose of every frame (0..n, then the tool) in the
    fixed frame in one pass of cumulative products ([Zivkovic2023] eq. (16)). ``table``:
    the chain laid out once; ``engine``: the compiled kernel's or the numpy reference.
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
        self.base = (base or DualQuaternion.identity()).normalized()
        self.tool = tool.normalized() if tool is not None else None
        self.table = chain_table(joints, convention, self.base.coeffs.tolist(),
                                 None if tool is None else self.tool.coeffs.tolist())
        self.engine = chain_engine(self.table)
        self._bind_engine()
        self.joints, self.convention = self.table.joints, convention
        self.joint_names, self.limits = self.table.names, self.table.limits
        self.dof, self.n_frames = self.table.dof, self.table.n_frames

    def _bind_engine(self):
        """
        Send the two hottest single calls straight to the engine's methods.

        :meth:`forward_all` and :meth:`forward` below say what they are; bound here, a call
        skips the facade's own frame (7 % of a 1 us call, the A/B of the table's redesign).
        """
        self.forward_all, self.forward = self.engine.frames, self.engine.pose

    def __getstate__(self):
        """Pickle without the generated code and the bound calls (made again on load)."""
        made = ('frame_poses_code', 'forward_all', 'forward')
        return {k: v for k, v in self.__dict__.items() if k not in made}

    def __setstate__(self, state):
        """Unpickle, and bind the engine's calls again."""
        self.__dict__.update(state)
        self._bind_engine()

    def row_parameters(self, q: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """Return the DH table at ``q``: arrays ``(theta, d)`` of every row, radians and metres."""
        theta, d = row_params_batch(self.table, self.table.check_q(q)[None, :])
        return theta[0], d[0]

    def frame_coeffs(self, q: ArrayLike) -> list[Coeffs]:
        """Frames 0..n (and the tool) as 8-tuples of plain floats, not made ``w >= 0``."""
        table = self.table
        return run_chain_program(table, table.base, table.q_list(q), math.cos, math.sin)

    def row_poses(self, q: ArrayLike) -> list[Pose]:
        """Every row's transform frame i-1 -> frame i, ``(x, y, z, qx..qw)``, ``qw >= 0``."""
        return row_poses(self.table, joint_value_list(q, self.joint_names))

    def frame_poses(self, q: ArrayLike) -> tuple[list[Pose], list[Pose]]:
        """
        Poses for publishing, as plain tuples ``(x, y, z, qx, qy, qz, qw)`` (``qw >= 0``).

        Returns ``(absolute, relative)``: every frame in the fixed frame (as
        :meth:`forward_all`), and every row's transform (as :meth:`row_poses`). The node's
        hot path: the chain's own straight-line code (:attr:`frame_poses_code`); reference:
        :meth:`frame_poses_general` (test_dh.py's
        ``test_the_unrolled_frame_poses_are_the_general_path_to_the_bit``).
        """
        return self.frame_poses_code(joint_value_list(q, self.joint_names))

    @cached_property
    def frame_poses_code(self) -> Callable[[list[float]], tuple[list[Pose], list[Pose]]]:
        """:meth:`frame_poses` as straight-line code (``.source``), made on first use."""
        return unrolled_frame_poses(self.table)

    def frame_poses_general(self, q: ArrayLike) -> tuple[list[Pose], list[Pose]]:
        """:meth:`frame_poses` by the general (looping) path: the reference."""
        absolute = [pose_xyzw_from_coeffs(h) for h in self.frame_coeffs(q)]
        return absolute, self.row_poses(q)

    def relative_all(self, q: ArrayLike) -> np.ndarray:
        """Relative transform of every row, frame i-1 -> frame i, as an ``(n, 8)`` array."""
        return np.array(relative_tuples(self.table, self.table.check_q(q).tolist()))

    def forward_all(self, q: ArrayLike, out: np.ndarray | None = None) -> np.ndarray:
        """
        Absolute pose of every frame in the fixed frame, ``(n_frames, 8)``, ``w >= 0``.

        Rows: frame 0 (the base transform), frames 1..n, then the tool if any. ``out``: a
        C-contiguous float64 ``(n_frames, 8)`` array to fill and return, else a new one.
        """
        return self.engine.frames(q, out)

    def relative_all_batch(self, q: ArrayLike) -> np.ndarray:
        """Relative transforms of every row for N configurations: ``(N, n, 8)`` (numpy)."""
        return relative_all_batch(self.table, q)

    def forward_all_batch(self, q: ArrayLike, out: np.ndarray | None = None) -> np.ndarray:
        """Absolute poses of every frame for N configurations: ``(N, n_frames, 8)``."""
        return self.engine.frames_batch(q, _checked_out(out, (self.n_frames, 8)))

    def forward_batch(self, q: ArrayLike, out: np.ndarray | None = None) -> np.ndarray:
        """End-effector poses (tool if any) for N configurations: ``(N, 8)``, ``w >= 0``."""
        return self.engine.end_batch(q, _checked_out(out, (8,)))

    def jacobian_dq(self, q: ArrayLike) -> np.ndarray:
        """Return the 8 x dof dual-quaternion Jacobian (``chain_jacobians.jacobian_dq``)."""
        return jacobian_dq(self.table, q)

    def jacobian_geometric(self, q: ArrayLike) -> np.ndarray:
        """Return the 6 x dof geometric Jacobian (rows: linear, angular) in the fixed frame."""
        return self.engine.jacobian(q)

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
        """Return the end-effector pose (tool if any, else frame n), a :class:`DualQuaternion`."""
        return DualQuaternion.from_array(self.engine.end(q))


def _checked_out(out, shape):
    """Return ``out`` if it is a C-contiguous writable float64 ``(N,) + shape`` array, or None."""
    if out is not None and not (
            isinstance(out, np.ndarray) and out.dtype == np.float64 and
            out.flags.c_contiguous and out.flags.writeable and out.shape[1:] == shape):
        raise ValueError(f'out must be a C-contiguous writable float64 (N, '
                         f'{", ".join(map(str, shape))}) array')
    return out


def homogeneous_from_dq(h: ArrayLike) -> np.ndarray:
    """4x4 matrices ``(..., 4, 4)`` of unit dual quaternions ``(..., 8)``."""
    h = np.asarray(h, dtype=float)
    m = np.zeros(h.shape[:-1] + (4, 4))
    m[..., :3, :3] = quat_to_matrix(h[..., :4])
    m[..., :3, 3] = dq_translation_array(h)
    m[..., 3, 3] = 1.0
    return m


__all__ = ['CONVENTIONS', 'DHJoint', 'JOINT_TYPES', 'joint_value_list', 'joint_value_vector',
           'KinematicChain', 'homogeneous_from_dq']
