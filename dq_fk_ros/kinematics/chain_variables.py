"""
The joint variables of a DH chain: which row reads which value of ``q``.

A revolute row reads its theta from one variable, a prismatic row its d, a cylindrical row
both (two variables); a row that ``follows`` another joint reads that joint's variable (a
mimic row), a fixed row none. :func:`chain_variables` names them in the order ``q`` is given.
"""

from collections.abc import Sequence
import math
from typing import NamedTuple

import numpy as np


class ChainVariables(NamedTuple):
    """The variables of a chain: names, limits ``(dof, 2)``, and per row its indices."""

    names: tuple            # in the order q is given
    limits: np.ndarray      # (dof, 2), rad or m; +-inf: none given
    theta_index: np.ndarray  # per row: the variable its theta reads, -1: constant
    d_index: np.ndarray      # per row: the variable its d reads, -1: constant
    angular: np.ndarray      # per variable: True for an angle (a theta, rad), else m


def chain_variables(joints: Sequence) -> ChainVariables:
    """
    Name the variables of ``joints`` (:class:`~dq_fk_ros.kinematics.dh.DHJoint` rows).

    Raises ``ValueError`` for a name used twice or a row following an unknown joint.
    """
    names, limits, angles = [], [], set()
    theta_map, d_map = {}, {}

    def add(name, lim):
        if name in names:
            raise ValueError(f'joint variable name {name!r} is used twice')
        names.append(name)
        limits.append(tuple(lim) if lim is not None else (-math.inf, math.inf))
        return len(names) - 1

    for i, j in enumerate(joints):
        if j.follows:
            continue
        t_i = d_i = -1
        default = j.name or f'joint_{i + 1}'
        if j.joint_type == 'revolute':
            t_i = add(default, j.limits)
        elif j.joint_type == 'prismatic':
            d_i = add(default, j.limits)
        elif j.joint_type == 'cylindrical':
            lim = j.limits if j.limits is not None else (None, None)
            t_i = add(default, lim[0])
            d_i = add(j.d_name or default + '_d', lim[1])
        theta_map[i], d_map[i] = t_i, d_i
        if t_i >= 0:
            angles.add(t_i)
    # rows that follow another joint read that joint's variable
    for i, j in enumerate(joints):
        if not j.follows:
            continue
        if j.follows not in names:
            raise ValueError(f'row {i + 1} follows unknown joint {j.follows!r}; '
                             f'joints are {names}')
        k = names.index(j.follows)
        theta_map[i] = k if j.joint_type == 'revolute' else -1
        d_map[i] = k if j.joint_type == 'prismatic' else -1
    n = len(joints)
    return ChainVariables(tuple(names), np.array(limits, dtype=float).reshape(-1, 2),
                          np.array([theta_map[i] for i in range(n)], dtype=int),
                          np.array([d_map[i] for i in range(n)], dtype=int),
                          np.array([k in angles for k in range(len(names))], dtype=bool))
