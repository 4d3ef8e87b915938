"""
The velocity of frames moving with a chain's end, from the joint velocities: node and bag alike.

The chain's end twist ``(v, w)`` in the fixed frame is its geometric Jacobian times the joint
velocities (``KinematicChain.jacobian_geometric``, [DQFKcpp2023]); a frame rigidly attached
to the end moves with the same ``w`` and, at its origin ``p_k``, ``v_k = v + w x (p_k -
p_end)`` (the same rigid-body motion seen at another point). Twists are
``(vx, vy, vz, wx, wy, wz)`` in m/s and rad/s, fixed-frame axes. :func:`frame_twists` is one
configuration (the node), :func:`frame_twists_batch` N of them (``dq_fk_bag process``), the
same operations row by row: test_twists.py holds them equal to the bit, and both to finite
differences of the frames' poses.
"""

from dq_fk_ros.kinematics.dh import KinematicChain
import numpy as np
from numpy.typing import ArrayLike


def frame_twists(chain: KinematicChain, q: ArrayLike, qdot: ArrayLike, p_end: ArrayLike,
                 points: ArrayLike) -> np.ndarray:
    """
    Return the ``(m, 6)`` twists of m frames moving with the chain's end at ``q``, ``qdot``.

    :param q: the chain's joint values; ``qdot``: their velocities (rad/s, m/s).
    :param p_end: the chain end's origin, ``(3,)`` m; ``points``: the frames' origins,
        ``(m, 3)`` m, all in the fixed frame.
    """
    v, w = chain.twist(q, qdot)
    out = np.empty((len(points), 6))
    out[:, :3] = v + np.cross(w, np.asarray(points, dtype=float) - p_end)
    out[:, 3:] = w
    return out


def frame_twists_batch(chain: KinematicChain, q: ArrayLike, qdot: ArrayLike,
                       p_end: ArrayLike, points: ArrayLike) -> np.ndarray:
    """
    Return the ``(N, m, 6)`` twists of :func:`frame_twists` for N configurations.

    :param q: ``(N, dof)``; ``qdot``: ``(N, dof)``; ``p_end``: ``(N, 3)``; ``points``:
        ``(N, m, 3)``.
    """
    q, qdot = np.asarray(q, dtype=float), np.asarray(qdot, dtype=float)
    p_end, points = np.asarray(p_end, dtype=float), np.asarray(points, dtype=float)
    n, m = len(q), points.shape[1]
    moving = np.empty((n, 6))   # the end's (v, w) per configuration: J qdot, row by row
    for i in range(n):
        moving[i] = chain.jacobian_geometric(q[i]) @ qdot[i]
    out = np.empty((n, m, 6))
    v, w = moving[:, None, :3], np.broadcast_to(moving[:, None, 3:], (n, m, 3))
    out[..., :3] = v + np.cross(w, points - p_end[:, None, :])
    out[..., 3:] = w
    return out


__all__ = ['frame_twists', 'frame_twists_batch']
