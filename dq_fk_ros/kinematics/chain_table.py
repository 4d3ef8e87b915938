"""
A DH chain's table laid out once (:class:`ChainTable`): what every engine and code path reads.

Built once per chain by :func:`chain_table` and frozen: the rows, the convention, the base
and tool as 8-tuples ``(w, x, y, z, w', x', y', z')``, the joint variables (which row reads
which value of ``q``), per-row arrays for the numpy batches, the factor program
([Zivkovic2023] eqs. (13)-(15)) for the kernel and the loops, and the rows' closed-form
constants ([Radavelli2014] eq. (3)). The batch, Jacobian, row and code modules are
functions of a table; :class:`~dq_fk_ros.kinematics.dh.KinematicChain` holds one.
"""

from collections.abc import Sequence
from dataclasses import dataclass
import math

from dq_fk_ros.kinematics.chain_variables import chain_variables
from dq_fk_ros.kinematics.dh_joint import CONVENTIONS, DHJoint
from dq_fk_ros.kinematics.dh_program import row_program, XStep, ZStep
import numpy as np
from numpy.typing import ArrayLike

Coeffs8 = tuple   # 8 floats (w, x, y, z, w', x', y', z')


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


def joint_value_batch(q: ArrayLike, dof: int) -> np.ndarray:
    """Return ``q`` as a contiguous ``(N, dof)`` float64 array (``ValueError`` if not)."""
    q = np.ascontiguousarray(q, dtype=float)
    if q.ndim != 2 or q.shape[1] != dof:
        raise ValueError(f'expected an (N, {dof}) array of joint values, got shape {q.shape}')
    return q


@dataclass(frozen=True, eq=False)
class ChainTable:
    """
    The frozen table of a chain (lengths m, angles rad); arrays are read, never written.

    ``theta_index``/``d_index``: per row, the variable of ``q`` its theta/d reads (-1: none);
    ``theta0``/``d0``/``a``/``alpha``/``scale``: per row; ``angular``: per variable, True for
    an angle. ``program``: the rows' factor program; ``rows``: per row ``(cos alpha/2,
    sin alpha/2, a, theta, d, scale, ti, di)``; ``pose_rows``: the same plus ``(sin alpha,
    cos alpha)`` (the kernel's ``row`` record); ``jacobian_rows``: ``(rows, 3)`` of
    ``(ti, di, scale)``.
    """

    joints: tuple[DHJoint, ...]
    convention: str
    base: Coeffs8
    tool: Coeffs8 | None
    names: tuple[str, ...]
    limits: np.ndarray
    theta_index: np.ndarray
    d_index: np.ndarray
    angular: np.ndarray
    theta0: np.ndarray
    d0: np.ndarray
    a: np.ndarray
    alpha: np.ndarray
    scale: np.ndarray
    program: tuple[ZStep | XStep, ...]
    rows: tuple[tuple, ...]
    pose_rows: tuple[tuple, ...]
    jacobian_rows: np.ndarray

    @property
    def dof(self) -> int:
        """Count the joint variables (the length of ``q``)."""
        return len(self.names)

    @property
    def n_frames(self) -> int:
        """Count the frames of the chain: frame 0..n, plus the tool if any."""
        return len(self.joints) + 1 + (self.tool is not None)

    @property
    def modified(self) -> bool:
        """Say whether the rows are Craig's (proximal) DH rather than the standard."""
        return self.convention == 'modified'

    def check_q(self, q: ArrayLike) -> np.ndarray:
        """Return ``q`` as a float vector of ``dof`` values (``ValueError`` if not)."""
        q = np.asarray(q, dtype=float)
        if q.shape != (self.dof,):
            raise ValueError(f'expected {self.dof} joint values {list(self.names)}, '
                             f'got shape {q.shape}')
        return q

    def q_vector(self, q: ArrayLike) -> np.ndarray:
        """Return ``q`` as a contiguous float64 vector (the numpy path's errors if not)."""
        return joint_value_vector(q, self.names)

    def q_list(self, q: ArrayLike) -> list[float]:
        """Return ``q`` as a list of floats (``ValueError`` naming the joints if not)."""
        return joint_value_list(q, self.names)

    def q_batch(self, q: ArrayLike) -> np.ndarray:
        """Return ``q`` as a contiguous ``(N, dof)`` float64 array (``ValueError`` if not)."""
        return joint_value_batch(q, self.dof)


def chain_table(joints: Sequence[DHJoint], convention: str, base: Coeffs8,
                tool: Coeffs8 | None) -> ChainTable:
    """
    Lay out the table of ``joints`` once (``ValueError`` for a table that is not one).

    :param base: frame 0 in the fixed frame, a unit dual quaternion's 8 coefficients.
    :param tool: frame n -> tool frame, or None.
    """
    if convention not in CONVENTIONS:
        raise ValueError(f'convention {convention!r} is not one of {CONVENTIONS}')
    joints = tuple(joints)
    if not joints:
        raise ValueError('a kinematic chain needs at least one DH row')
    v = chain_variables(joints)
    modified = convention == 'modified'
    program = tuple(op for i, j in enumerate(joints)
                    for op in row_program(j, int(v.theta_index[i]), int(v.d_index[i]),
                                          modified))
    scale = np.array([j.scale for j in joints])
    rows = tuple((math.cos(0.5 * j.alpha), math.sin(0.5 * j.alpha), j.a, j.theta, j.d,
                  j.scale, int(v.theta_index[i]), int(v.d_index[i]))
                 for i, j in enumerate(joints))
    pose_rows = tuple(row + (math.sin(j.alpha), math.cos(j.alpha))
                      for row, j in zip(rows, joints))
    jacobian_rows = np.array([[float(v.theta_index[i]), float(v.d_index[i]), scale[i]]
                              for i in range(len(joints))]).reshape(-1, 3)
    return ChainTable(
        joints, convention, tuple(float(c) for c in base),
        None if tool is None else tuple(float(c) for c in tool), v.names, v.limits,
        v.theta_index, v.d_index, v.angular, np.array([j.theta for j in joints]),
        np.array([j.d for j in joints]), np.array([j.a for j in joints]),
        np.array([j.alpha for j in joints]), scale, program, rows, pose_rows, jacobian_rows)


__all__ = ['chain_table', 'ChainTable', 'joint_value_batch', 'joint_value_list',
           'joint_value_vector']
