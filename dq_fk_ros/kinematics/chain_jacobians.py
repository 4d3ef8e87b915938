"""
A DH chain's differential kinematics with numpy: the Jacobians and their reference.

:func:`jacobian_dq`: the 8 x dof dual-quaternion Jacobian (Adorno; [DQFKcpp2023]);
:func:`jacobian_geometric_reference`: the 6 x dof geometric Jacobian axis by axis, the
reference of the kernel's ``Chain.jacobian`` (``KinematicChain.jacobian_geometric``,
test_kernel.py holds them equal to 1e-12).
"""

import math

from dq_fk_ros.kinematics.chain_table import ChainTable
from dq_fk_ros.kinematics.dh_code import run_chain_program
from dq_fk_ros.kinematics.dual_quaternion import (
    canonical, dq_multiply_array, dq_translation_array, quat_conjugate, quat_to_matrix)
import numpy as np
from numpy.typing import ArrayLike


def joint_axes(table: ChainTable, q: list) -> tuple[list, tuple]:
    """
    Per joint variable: the pose whose z axis is its joint axis, and the end pose.

    Standard DH moves row i about/along z of frame i-1; modified DH about/along z of
    frame i. Rows following another joint add their contribution to that joint.
    """
    frames = run_chain_program(table, table.base, q, math.cos, math.sin)
    end = frames[-1]
    axes = []  # (variable index, kind, scale, axis frame)
    for i in range(len(table.joints)):
        frame = frames[i + 1] if table.modified else frames[i]
        if table.theta_index[i] >= 0:
            axes.append((int(table.theta_index[i]), 'rot', table.scale[i], frame))
        if table.d_index[i] >= 0:
            axes.append((int(table.d_index[i]), 'trans', table.scale[i], frame))
    return axes, end


def jacobian_dq(table: ChainTable, q: ArrayLike) -> np.ndarray:
    """
    Return the 8 x dof dual-quaternion Jacobian ``d vec(h_end) / d q`` (Adorno; [DQFKcpp2023]).

    Column j is ``(1/2) xi_j h_end`` with ``xi_j`` the joint's unit screw (its z axis as
    a line, dual part for a prismatic joint) in the fixed frame; ``h_end`` is the
    canonical end pose returned by ``KinematicChain.forward``.
    """
    axes, end = joint_axes(table, table.check_q(q).tolist())
    end = canonical(np.array(end))
    jac = np.zeros((8, table.dof))
    k_rot = np.array([0.0, 0, 0, 1, 0, 0, 0, 0])
    k_trans = np.array([0.0, 0, 0, 0, 0, 0, 0, 1])
    for var, kind, scale, frame in axes:
        frame = np.array(frame)
        inv = np.concatenate([quat_conjugate(frame[:4]), quat_conjugate(frame[4:])])
        unit = k_rot if kind == 'rot' else k_trans
        xi = dq_multiply_array(dq_multiply_array(frame, unit), inv)
        jac[:, var] += 0.5 * scale * dq_multiply_array(xi, end)
    return jac


def jacobian_geometric_reference(table: ChainTable, q: ArrayLike) -> np.ndarray:
    """``KinematicChain.jacobian_geometric`` with numpy, axis by axis: the reference."""
    axes, end = joint_axes(table, table.check_q(q).tolist())
    p_end = dq_translation_array(np.array(end))
    jac = np.zeros((6, table.dof))
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
