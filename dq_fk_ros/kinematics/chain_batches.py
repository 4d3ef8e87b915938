"""
A DH chain for N configurations at once, with numpy: the references of the kernel's batches.

``KinematicChain.forward_all_batch`` and ``forward_batch`` run the C kernel's batch loops;
:func:`forward_all_batch_reference` and :func:`forward_batch_reference` are what they are
held equal to (test_kernel.py, 1e-12), and what runs without the kernel (the
``ReferenceEngine`` of :mod:`~dq_fk_ros.kinematics.chain_engines`): the table's factor
program (``dh_program.run_program``) on columns of configurations, chunk by chunk.
:func:`relative_all_batch` is the rows' closed form, [Radavelli2014] eq. (3).
"""

from collections.abc import Iterator

from dq_fk_ros.kinematics.chain_table import ChainTable
from dq_fk_ros.kinematics.dh_program import run_program
from dq_fk_ros.kinematics.dual_quaternion import dq_multiply_coeffs
import numpy as np
from numpy.typing import ArrayLike

# configurations per step of the batch paths: small enough for the working set to stay in cache
BATCH_CHUNK = 4096


def row_params_batch(table: ChainTable, q: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    """Return every row's ``(theta, d)`` for N configurations: two ``(N, rows)`` arrays."""
    q = table.q_batch(q)
    qe = np.concatenate([q, np.zeros((q.shape[0], 1))], axis=1)
    theta = table.theta0 + np.where(table.theta_index >= 0,
                                    table.scale * qe[:, table.theta_index], 0.0)
    d = table.d0 + np.where(table.d_index >= 0, table.scale * qe[:, table.d_index], 0.0)
    return theta, d


def relative_all_batch(table: ChainTable, q: ArrayLike) -> np.ndarray:
    """Relative transforms of every row for N configurations: ``(N, n, 8)``."""
    theta, d = row_params_batch(table, q)
    half_t = 0.5 * theta
    ct, st = np.cos(half_t), np.sin(half_t)
    ca, sa = np.cos(0.5 * table.alpha), np.sin(0.5 * table.alpha)
    ha, hd = 0.5 * table.a, 0.5 * d
    if not table.modified:
        comps = (ca * ct, sa * ct, sa * st, ca * st,
                 -ha * sa * ct - hd * ca * st, ha * ca * ct - hd * sa * st,
                 ha * ca * st + hd * sa * ct, -ha * sa * st + hd * ca * ct)
    else:
        comps = (ca * ct, sa * ct, -sa * st, ca * st,
                 -hd * ca * st - ha * sa * ct, -hd * sa * st + ha * ca * ct,
                 -hd * sa * ct - ha * ca * st, hd * ca * ct - ha * sa * st)
    return np.stack(comps, axis=-1)


def _batches(table: ChainTable, q: ArrayLike) -> Iterator[tuple]:
    """Yield ``(slice, frames)`` per chunk; frames are 8-tuples of arrays (or floats)."""
    q = table.q_batch(q)
    for start in range(0, q.shape[0], BATCH_CHUNK):
        part = slice(start, min(start + BATCH_CHUNK, q.shape[0]))
        cols = np.ascontiguousarray(q[part].T)
        frames = run_program(table.program, table.base, cols, np.cos, np.sin)
        if table.tool is not None:
            frames.append(dq_multiply_coeffs(frames[-1], table.tool))
        yield part, frames


def forward_all_batch_reference(table: ChainTable, q: ArrayLike) -> np.ndarray:
    """``KinematicChain.forward_all_batch`` with numpy, chunk by chunk: the reference."""
    q = table.q_batch(q)
    out = np.empty((len(q), table.n_frames, 8))
    for part, frames in _batches(table, q):
        for i, frame in enumerate(frames):
            for k in range(8):
                out[part, i, k] = frame[k]
    return canonical_inplace(out)


def forward_batch_reference(table: ChainTable, q: ArrayLike) -> np.ndarray:
    """``KinematicChain.forward_batch`` with numpy, chunk by chunk: the reference."""
    q = table.q_batch(q)
    out = np.empty((len(q), 8))
    for part, frames in _batches(table, q):
        for k in range(8):
            out[part, k] = frames[-1][k]
    return canonical_inplace(out)


def canonical_inplace(h: np.ndarray) -> np.ndarray:
    """Flip, in place, the dual quaternions ``(..., 8)`` whose real part has ``w < 0``."""
    negative = h[..., 0] < 0.0
    h[negative] *= -1.0
    return h
