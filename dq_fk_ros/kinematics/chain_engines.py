"""
The two engines of a DH chain, one chosen per chain: the compiled kernel, and its reference.

Both take a :class:`~dq_fk_ros.kinematics.chain_table.ChainTable` and offer the same
methods: ``frames(q, out)`` (every frame, ``(n_frames, 8)``, ``w >= 0``), ``end(q)`` (and
``pose(q)``, the same as a ``DualQuaternion``),
``frames_batch(q, out)``, ``end_batch(q, out)`` and ``jacobian(q)`` (6 x dof, geometric).
:class:`CompiledEngine` runs the C kernel's ``Chain`` (the factor program copied into it
once); :class:`ReferenceEngine` runs the same program in Python floats and numpy
(:func:`~.dh_program.run_program`, :mod:`.chain_batches`, :mod:`.chain_jacobians`).
test_kernel.py holds the two engines of the same tables equal (1e-12); :func:`chain_engine`
picks the compiled one wherever :mod:`~dq_fk_ros.kinematics.kernel` loaded the kernel.
"""

from array import array
import math

from dq_fk_ros.kinematics.chain_batches import (
    forward_all_batch_reference, forward_batch_reference)
from dq_fk_ros.kinematics.chain_jacobians import jacobian_geometric_reference
from dq_fk_ros.kinematics.chain_table import ChainTable
from dq_fk_ros.kinematics.dh_code import run_chain_program
from dq_fk_ros.kinematics.dual_quaternion import DualQuaternion
from dq_fk_ros.kinematics.kernel import KERNEL
from dq_fk_ros.kinematics.kernel_layout import pack, program_record
import numpy as np
from numpy.typing import ArrayLike


def _filled(result, out):
    if out is None:
        return result
    out[...] = result
    return out


class ReferenceEngine:
    """A chain's frames in Python floats, its batches and Jacobian in numpy: the reference."""

    kernel_chain = None   # (the kernel's copy of the chain: none)

    def __init__(self, table: ChainTable):
        """Run ``table`` (nothing is copied)."""
        self.table = table

    def coeffs(self, q: ArrayLike) -> list[tuple]:
        """Return frames 0..n (and the tool) as 8-tuples of floats, not made ``w >= 0``."""
        table = self.table
        return run_chain_program(table, table.base, table.q_list(q), math.cos, math.sin)

    def frames(self, q: ArrayLike, out: np.ndarray | None = None) -> np.ndarray:
        """Return every frame, ``(n_frames, 8)``, ``w >= 0`` (into ``out`` if given)."""
        flat = []
        for f in self.coeffs(q):
            flat += f if f[0] >= 0.0 else [-v for v in f]
        return _filled(np.frombuffer(array('d', flat)).reshape(-1, 8), out)

    def end(self, q: ArrayLike) -> np.ndarray:
        """Return the last frame (the tool, if any), 8 coefficients, ``w >= 0``."""
        end = self.coeffs(q)[-1]
        return np.frombuffer(array('d', end if end[0] >= 0.0 else [-v for v in end]))

    def pose(self, q: ArrayLike) -> DualQuaternion:
        """Return the last frame as a :class:`DualQuaternion` (``KinematicChain.forward``)."""
        return DualQuaternion.from_array(self.end(q))

    def frames_batch(self, q: ArrayLike, out: np.ndarray | None = None) -> np.ndarray:
        """Return every frame of N configurations, ``(N, n_frames, 8)``."""
        return _filled(forward_all_batch_reference(self.table, q), out)

    def end_batch(self, q: ArrayLike, out: np.ndarray | None = None) -> np.ndarray:
        """Return the last frame of N configurations, ``(N, 8)``."""
        return _filled(forward_batch_reference(self.table, q), out)

    def jacobian(self, q: ArrayLike) -> np.ndarray:
        """Return the 6 x dof geometric Jacobian of the last frame, in the fixed frame."""
        return jacobian_geometric_reference(self.table, q)


def kernel_chain_args(table: ChainTable) -> tuple:
    """Return what ``_kernel.Chain`` is made from: program, base, tool, dof, rows, modified."""
    return (pack(KERNEL.LAYOUTS, 'op', [program_record(op) for op in table.program]),
            np.array(table.base), None if table.tool is None else np.array(table.tool),
            table.dof, table.jacobian_rows, table.modified)


class CompiledEngine:
    """A chain on the C kernel (``_kernel.Chain``): its program checked and copied in once."""

    def __init__(self, table: ChainTable):
        """Copy ``table``'s program, base, tool and Jacobian rows into the kernel."""
        self.table = table
        self.kernel_chain = KERNEL.Chain(*kernel_chain_args(table))
        self.frames_shape = (table.n_frames, 8)

    def __reduce__(self):
        """Pickle the table only; the kernel's copy is made again on unpickling."""
        return CompiledEngine, (self.table,)

    # (each call tries the kernel with ``q`` as given: a float64 vector of the right length
    # goes straight in; a list, another dtype... or a wrong q is converted, or refused with
    # the numpy path's error; written out in each method: a helper call costs ~5 % here)
    def frames(self, q: ArrayLike, out: np.ndarray | None = None) -> np.ndarray:
        """Return every frame, ``(n_frames, 8)``, ``w >= 0`` (into ``out`` if given)."""
        if out is None:
            out = np.empty(self.frames_shape)
        try:
            self.kernel_chain.frames(q, out)
        except (ValueError, TypeError):
            self.kernel_chain.frames(self.table.q_vector(q), out)
        return out

    def end(self, q: ArrayLike) -> np.ndarray:
        """Return the last frame (the tool, if any), 8 coefficients, ``w >= 0``."""
        out = np.empty(8)
        try:
            self.kernel_chain.end(q, out)
        except (ValueError, TypeError):
            self.kernel_chain.end(self.table.q_vector(q), out)
        return out

    def pose(self, q: ArrayLike) -> DualQuaternion:
        """Return the last frame as a :class:`DualQuaternion` (``KinematicChain.forward``)."""
        out = np.empty(8)
        try:
            self.kernel_chain.end(q, out)
        except (ValueError, TypeError):
            self.kernel_chain.end(self.table.q_vector(q), out)
        return DualQuaternion.from_array(out)

    def frames_batch(self, q: ArrayLike, out: np.ndarray | None = None) -> np.ndarray:
        """Return every frame of N configurations, ``(N, n_frames, 8)``."""
        q = self.table.q_batch(q)
        out = np.empty((len(q), self.table.n_frames, 8)) if out is None else out
        self.kernel_chain.frames_batch(q, out)
        return out

    def end_batch(self, q: ArrayLike, out: np.ndarray | None = None) -> np.ndarray:
        """Return the last frame of N configurations, ``(N, 8)``."""
        q = self.table.q_batch(q)
        out = np.empty((len(q), 8)) if out is None else out
        self.kernel_chain.end_batch(q, out)
        return out

    def jacobian(self, q: ArrayLike) -> np.ndarray:
        """Return the 6 x dof geometric Jacobian of the last frame, in the fixed frame."""
        out = np.empty((6, self.table.dof))
        try:
            self.kernel_chain.jacobian(q, out)
        except (ValueError, TypeError):
            self.kernel_chain.jacobian(self.table.q_vector(q), out)
        return out


def chain_engine(table: ChainTable) -> CompiledEngine | ReferenceEngine:
    """Return the engine of ``table``: compiled where the kernel is loaded, else the reference."""
    return ReferenceEngine(table) if KERNEL is None else CompiledEngine(table)


__all__ = ['chain_engine', 'CompiledEngine', 'kernel_chain_args', 'ReferenceEngine']
