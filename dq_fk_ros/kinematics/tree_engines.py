"""
The two engines of a tree of DH chains and links, one chosen per tree: the kernel, or numpy.

A :class:`TreeLayout` is the tree laid out once (its chains, where each hangs, the links,
the sizes). Both engines offer ``poses(q, absolute, relative)`` (every frame's pose and
every TF transform of one configuration, ``(x, y, z, qx, qy, qz, qw)`` rows),
``transforms(q, relative)``, ``frames(q)`` (``(n_frames, 8)``, ``w >= 0``) and
``poses_batch(q, absolute, relative)``. :class:`CompiledTreeEngine` runs the kernel's
``Model`` (the tree copied into it once); :class:`ReferenceTreeEngine` the straight-line code
of one configuration and the numpy batch (:func:`tree_batch`). test_kernel.py
(``test_the_model_kernel_equals_the_general_path``) and test_kernel_tree.py
(``test_batches_equal_the_numpy_batch``) hold them equal.
"""

from collections.abc import Callable, Sequence
from dataclasses import dataclass

from dq_fk_ros.kinematics.chain_table import joint_value_batch, joint_value_vector
from dq_fk_ros.kinematics.dh import KinematicChain
from dq_fk_ros.kinematics.dh_code import run_chain_program
from dq_fk_ros.kinematics.dual_quaternion import dq_multiply_array, dq_to_pose_xyzw
from dq_fk_ros.kinematics.kernel import KERNEL
from dq_fk_ros.kinematics.kernel_layout import link_record, pack, pose_row_record
import numpy as np
from numpy.typing import ArrayLike

IDENTITY = (1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
_CONJUGATE = np.array([1.0, -1.0, -1.0, -1.0, 1.0, -1.0, -1.0, -1.0])


@dataclass(frozen=True, eq=False)
class TreeLayout:
    """
    A tree laid out once, its sizes and joint names.

    ``chains``: ``((chain, parent frame index (-1: fixed), q indices of its variables),
    ...)``, the root first; ``links`` as ``TreeKinematics`` takes them.
    """

    chains: tuple[tuple[KinematicChain, int, tuple], ...]
    links: tuple
    joint_names: tuple[str, ...]
    n_frames: int
    n_transforms: int

    @property
    def dof(self) -> int:
        """Count the joint variables (the length of ``q``)."""
        return len(self.joint_names)

    def q_batch(self, q: ArrayLike) -> np.ndarray:
        """Return ``q`` as a contiguous ``(N, dof)`` float64 array (``ValueError`` if not)."""
        return joint_value_batch(q, self.dof)


def link_motion(motion: tuple, q: Sequence, cos: Callable, sin: Callable) -> tuple:
    """Return the coefficients of a link's motion at ``q`` (floats, or arrays)."""
    prismatic, (ax, ay, az), k, multiplier, offset = motion
    value = multiplier * q[k] + offset
    zero = 0.0 * value
    if prismatic:  # 1 + eps t/2
        half = 0.5 * value
        return (1.0 + zero, zero, zero, zero, zero, half * ax, half * ay, half * az)
    c, s = cos(0.5 * value), sin(0.5 * value)
    return (c, s * ax, s * ay, s * az, zero, zero, zero, zero)


def tree_batch(layout: TreeLayout, q: ArrayLike, relative: bool) -> tuple:
    """
    Return every frame and TF transform of N configurations, with numpy: the reference.

    ``(absolute, relative)``: ``(N, n_frames, 8)`` (``w >= 0``) and, if ``relative``,
    ``(N, n_transforms, 8)`` (else None).
    """
    q = layout.q_batch(q)
    (root, _, _), branches = layout.chains[0], layout.chains[1:]
    absolute = root.forward_all_batch(q[:, :root.dof])
    rel = root.relative_all_batch(q[:, :root.dof]) if relative else None
    if not branches and not layout.links:
        return absolute, rel
    n = absolute.shape[0]
    frames = [absolute[:, k] for k in range(absolute.shape[1])]
    rels = [rel] if relative else []
    identity = np.broadcast_to(np.array(IDENTITY), (n, 8))
    for branch, parent, q_map in branches:
        q_branch = q[:, list(q_map)]
        base_t = np.array(branch.table.base)
        base = dq_multiply_array(frames[parent], base_t) if parent >= 0 \
            else np.broadcast_to(base_t, (n, 8))
        columns = np.ascontiguousarray(q_branch.T)
        out = run_chain_program(branch.table, tuple(base.T), columns, np.cos, np.sin)
        frames += [np.stack(np.broadcast_arrays(*f), axis=-1) for f in out]
        if relative:
            rels.append(branch.relative_all_batch(q_branch))
    extra = []
    columns = q.T
    for attach, tf_parent, offset, motion in layout.links:
        offset = np.broadcast_to(np.array(offset), (n, 8))
        if motion is not None:
            offset = dq_multiply_array(offset, np.stack(
                np.broadcast_arrays(*link_motion(motion, columns, np.cos, np.sin)), axis=-1))
        pose = dq_multiply_array(frames[attach] if attach >= 0 else identity, offset)
        frames.append(pose)
        if relative:
            if tf_parent == attach:
                extra.append(offset)
            else:
                above = frames[tf_parent] if tf_parent >= 0 else identity
                extra.append(dq_multiply_array(above * _CONJUGATE, pose))
    absolute = np.stack(frames, axis=1)
    absolute[absolute[..., 0] < 0.0] *= -1.0
    if relative:
        if extra:
            rels.append(np.stack(extra, axis=1))
        rel = np.concatenate(rels, axis=1)
    return absolute, rel


class ReferenceTreeEngine:
    """A tree in Python floats (straight-line code) and numpy batches: the reference."""

    def __init__(self, layout: TreeLayout, frame_poses: Callable, transform_poses: Callable):
        """Run ``layout``; one configuration through the given straight-line code."""
        self.layout = layout
        self.frame_poses, self.transform_poses = frame_poses, transform_poses

    def poses(self, q: ArrayLike, absolute: np.ndarray, relative: np.ndarray) -> None:
        """Fill ``absolute`` ``(n_frames, 7)`` and ``relative`` ``(n_transforms, 7)`` at ``q``."""
        poses, transforms = self.frame_poses(q)
        absolute[...] = poses
        relative[...] = np.array(transforms).reshape(-1, 7)

    def transforms(self, q: ArrayLike, relative: np.ndarray) -> None:
        """Fill ``relative`` ``(n_transforms, 7)`` with the TF transforms at ``q``."""
        relative[...] = np.array(self.transform_poses(q)).reshape(-1, 7)

    def frames(self, q: ArrayLike) -> np.ndarray:
        """Return every frame at ``q``, ``(n_frames, 8)``, ``w >= 0``."""
        return tree_batch(self.layout, np.asarray(q, dtype=float)[None, :], False)[0][0]

    def poses_batch(self, q: ArrayLike, absolute: np.ndarray, relative: np.ndarray) -> None:
        """Fill ``absolute`` ``(N, n_frames, 7)`` and ``relative`` ``(N, n_transforms, 7)``."""
        frames, transforms = tree_batch(self.layout, q, relative=True)
        absolute[...], relative[...] = dq_to_pose_xyzw(frames), dq_to_pose_xyzw(transforms)


class CompiledTreeEngine:
    """A tree on the kernel's ``Model``: its chains (the kernel's copies) and links, once."""

    def __init__(self, layout: TreeLayout):
        """Copy the tree and its links into the kernel."""
        self.layout = layout
        chains = [(chain.engine.kernel_chain, parent, np.array(q_map, dtype=float),
                   pack(KERNEL.LAYOUTS, 'row',
                        [pose_row_record(r) for r in chain.table.pose_rows]),
                   not chain.table.modified)
                  for chain, parent, q_map in layout.chains]
        links = pack(KERNEL.LAYOUTS, 'link', [link_record(*link) for link in layout.links])
        self.model = KERNEL.Model(chains, links, layout.dof)

    def __reduce__(self):
        """Pickle the layout only; the kernel's copy is made again on unpickling."""
        return CompiledTreeEngine, (self.layout,)

    def _q(self, q):
        return joint_value_vector(q, self.layout.joint_names)

    def poses(self, q: ArrayLike, absolute: np.ndarray, relative: np.ndarray) -> None:
        """Fill ``absolute`` ``(n_frames, 7)`` and ``relative`` ``(n_transforms, 7)`` at ``q``."""
        try:  # a float64 vector of the right length goes straight in
            self.model.poses(q, absolute, relative)
        except (ValueError, TypeError):  # a list, another dtype... or a wrong q: its error
            self.model.poses(self._q(q), absolute, relative)

    def transforms(self, q: ArrayLike, relative: np.ndarray) -> None:
        """Fill ``relative`` ``(n_transforms, 7)`` with the TF transforms at ``q``."""
        try:
            self.model.poses(q, None, relative)
        except (ValueError, TypeError):
            self.model.poses(self._q(q), None, relative)

    def frames(self, q: ArrayLike) -> np.ndarray:
        """Return every frame at ``q``, ``(n_frames, 8)``, ``w >= 0``."""
        out = np.empty((self.layout.n_frames, 8))
        self.model.frames(self._q(q), out)
        return out

    def poses_batch(self, q: ArrayLike, absolute: np.ndarray, relative: np.ndarray) -> None:
        """Fill ``absolute`` ``(N, n_frames, 7)`` and ``relative`` ``(N, n_transforms, 7)``."""
        self.model.poses_batch(q, absolute, relative)


def tree_engine(layout: TreeLayout, frame_poses: Callable,
                transform_poses: Callable) -> CompiledTreeEngine | ReferenceTreeEngine:
    """Return the engine of ``layout``: the kernel's where it is loaded, else the reference."""
    if KERNEL is None:
        return ReferenceTreeEngine(layout, frame_poses, transform_poses)
    return CompiledTreeEngine(layout)


__all__ = ['CompiledTreeEngine', 'IDENTITY', 'link_motion', 'ReferenceTreeEngine',
           'tree_batch', 'tree_engine', 'TreeLayout']
