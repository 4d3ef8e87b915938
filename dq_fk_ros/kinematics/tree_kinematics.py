"""
Forward kinematics of a tree of DH chains and the links fixed to them: one engine, two paths.

:class:`TreeKinematics` is what a robot (``description.RobotModel``) hands its chains and
links to: a root chain, branches hanging from frames of earlier chains, and links fixed to
(or moving with one joint about an axis from) any frame before them, in frame order. Every
frame's pose in the fixed frame and every TF transform (each DH row's, then each link's from
its TF parent) come from it, for one configuration or a batch.

Fast paths: the compiled kernel's ``Model`` (``frame_pose_arrays``, ``forward_all``, the
batches) and straight-line Python (``frame_poses``, ``dh_code.unrolled_frame_poses``).
References: ``frame_poses_general`` (loops, floats) and the numpy batch (``_batch``),
held equal to them by test_kernel.py (``test_the_model_kernel_equals_the_general_path``),
test_kernel_tree.py (``test_batches_equal_the_numpy_batch``), test_links.py and
test_chains.py (to the bit). The kernel is chosen in one place, :mod:`.kernel`.
"""

from collections.abc import Callable, Sequence
from functools import cached_property
import math

from dq_fk_ros.kinematics.dh import joint_value_list, joint_value_vector, KinematicChain
from dq_fk_ros.kinematics.dh_code import run_chain_program, unrolled_frame_poses
from dq_fk_ros.kinematics.dual_quaternion import (
    dq_inverse_coeffs, dq_multiply_array, dq_multiply_coeffs, dq_to_pose_xyzw, Pose,
    pose_xyzw_from_coeffs)
from dq_fk_ros.kinematics.kernel import KERNEL
from dq_fk_ros.kinematics.kernel_layout import link_record, pack, pose_row_record
import numpy as np
from numpy.typing import ArrayLike

_IDENTITY = (1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
_CONJUGATE = np.array([1.0, -1.0, -1.0, -1.0, 1.0, -1.0, -1.0, -1.0])


class TreeKinematics:
    """
    Every frame of a tree of chains and links, and its TF transforms (see the module).

    :param chain: the root chain; its joints are ``q``'s first values.
    :param branches: ``((chain, index of the frame it hangs from (-1: fixed), q indices of
        its variables), ...)`` in frame order.
    :param links: ``((attach index, TF-parent index, offset coefficients (8), motion),
        ...)``, -1 the fixed frame; ``motion`` None or ``(prismatic?, unit axis, q index,
        multiplier, offset value)``: ``M(multiplier * q[k] + offset)`` about / along axis.
    :param joint_names: the names of ``q``'s values.
    """

    def __init__(self, chain: KinematicChain, branches: Sequence[tuple],
                 links: Sequence[tuple], joint_names: Sequence[str]) -> None:
        self.chain, self.branches, self.links = chain, tuple(branches), tuple(links)
        self.joint_names = tuple(joint_names)
        self.dof = len(self.joint_names)
        self.n_frames = chain.n_frames + sum(b.n_frames for b, _, _ in self.branches) + \
            len(self.links)
        self.n_transforms = len(chain.joints) + sum(
            len(b.joints) for b, _, _ in self.branches) + len(self.links)
        self._plain = not self.links and not self.branches  # one chain: its own paths

    def __getstate__(self) -> dict:
        """Pickle without the kernel's copy and the generated code (made again on use)."""
        state = dict(self.__dict__)
        for made in ('_kernel_model', '_unrolled', '_unrolled_transforms'):
            state.pop(made, None)
        return state

    # -- one configuration, Python floats -----------------------------------------------
    def frame_poses(self, q: ArrayLike) -> tuple[list[Pose], list[Pose]]:
        """
        ``(absolute, relative)`` poses ``(x, y, z, qx, qy, qz, qw)`` (``qw >= 0``) at ``q``.

        Straight-line code (``unrolled_frame_poses``); the reference is
        :meth:`frame_poses_general`, equal to the bit (test_links.py, test_chains.py).
        """
        if self._plain:
            return self.chain.frame_poses(q)
        return self._unrolled(joint_value_list(q, self.joint_names))

    def frame_poses_code(self) -> str:
        """Return the Python source of :meth:`frame_poses`' straight-line code (generated)."""
        return self.chain._unrolled.source if self._plain else self._unrolled.source

    @cached_property
    def _unrolled(self):
        return unrolled_frame_poses(self.chain, self.links, link_motion, self.branches)

    @cached_property
    def _unrolled_transforms(self):
        return unrolled_frame_poses(self.chain, self.links, link_motion, self.branches,
                                    absolute=False)

    def transform_poses(self, q: ArrayLike) -> list[Pose]:
        """
        Return the TF transforms of :meth:`frame_poses` alone (``relative``), at ``q``.

        Without converting the absolute poses (about half the work); the same values as
        :meth:`frame_poses`' to the bit (``test_chains.py``).
        """
        if self._plain:
            return self.chain.row_poses(q)
        return self._unrolled_transforms(joint_value_list(q, self.joint_names))[1]

    def frame_poses_general(self, q: ArrayLike) -> tuple[list[Pose], list[Pose]]:
        """:meth:`frame_poses` by the general (looping) path: the reference."""
        if self._plain:
            return self.chain.frame_poses_general(q)
        q = joint_value_list(q, self.joint_names)
        q_chain = q[:self.chain.dof]
        coeffs = self.chain.frame_coeffs(q_chain)
        relative = self.chain.row_poses(q_chain)
        for chain, parent, q_map in self.branches:
            q_branch = [q[k] for k in q_map]
            base = dq_multiply_coeffs(coeffs[parent], chain._base_t) if parent >= 0 \
                else chain._base_t
            coeffs += run_chain_program(chain, base, q_branch, math.cos, math.sin)
            relative += chain.row_poses(q_branch)
        absolute = [pose_xyzw_from_coeffs(h) for h in coeffs]
        for attach, tf_parent, offset, motion in self.links:
            parent = coeffs[attach] if attach >= 0 else _IDENTITY
            if motion is not None:
                offset = dq_multiply_coeffs(offset, link_motion(motion, q, math.cos, math.sin))
            pose = dq_multiply_coeffs(parent, offset)
            coeffs.append(pose)
            absolute.append(pose_xyzw_from_coeffs(pose))
            if tf_parent == attach:
                relative.append(pose_xyzw_from_coeffs(offset))
            else:
                above = coeffs[tf_parent] if tf_parent >= 0 else _IDENTITY
                relative.append(pose_xyzw_from_coeffs(
                    dq_multiply_coeffs(dq_inverse_coeffs(above), pose)))
        return absolute, relative

    # -- one configuration into arrays: the kernel --------------------------------------
    def frame_pose_arrays(self, q: ArrayLike, absolute: np.ndarray | None = None,
                          relative: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """
        :meth:`frame_poses` as float64 arrays ``(n_frames, 7)`` and ``(n_transforms, 7)``.

        Fast path: the kernel's ``Model`` writes into ``absolute`` and ``relative``
        (C-contiguous float64 arrays the caller owns: no allocation; made when None);
        reference: :meth:`frame_poses_general` (test_kernel.py). Without the kernel, the
        straight-line code of :meth:`frame_poses` fills them.
        """
        if absolute is None:
            absolute = np.empty((self.n_frames, 7))
        if relative is None:
            relative = np.empty((self.n_transforms, 7))
        kernel = self._kernel_model
        if kernel is None:
            poses, transforms = self.frame_poses(q)
            absolute[...] = poses
            relative[...] = np.array(transforms).reshape(-1, 7)
            return absolute, relative
        try:  # a float64 vector of the right length goes straight in
            kernel.poses(q, absolute, relative)
        except (ValueError, TypeError):  # a list, another dtype... or a wrong q: its error
            kernel.poses(joint_value_vector(q, self.joint_names), absolute, relative)
        return absolute, relative

    def transform_pose_array(self, q: ArrayLike,
                             relative: np.ndarray | None = None) -> np.ndarray:
        """:meth:`transform_poses` as one ``(n_transforms, 7)`` array; paths as above."""
        if relative is None:
            relative = np.empty((self.n_transforms, 7))
        kernel = self._kernel_model
        if kernel is None:
            relative[...] = np.array(self.transform_poses(q)).reshape(-1, 7)
            return relative
        try:
            kernel.poses(q, None, relative)
        except (ValueError, TypeError):
            kernel.poses(joint_value_vector(q, self.joint_names), None, relative)
        return relative

    def forward_all(self, q: ArrayLike) -> np.ndarray:
        """
        Every frame in the fixed frame: ``(n_frames, 8)``, ``w >= 0``.

        Fast path: the kernel (a chain's, or the tree's ``Model``); reference: the numpy
        batch of one configuration (:meth:`forward_all_batch`), test_kernel.py.
        """
        if self._plain:
            return self.chain.forward_all(q)
        kernel = self._kernel_model
        if kernel is None:
            return self.forward_all_batch(np.asarray(q, dtype=float)[None, :])[0]
        out = np.empty((self.n_frames, 8))
        kernel.frames(joint_value_vector(q, self.joint_names), out)
        return out

    @cached_property
    def _kernel_model(self):
        """Copy the tree and its links into the kernel once (None: the numpy path)."""
        if KERNEL is None:
            return None
        chains = [(chain._kernel_chain, parent, np.array(q_map, dtype=float),
                   pack(KERNEL.LAYOUTS, 'row', [pose_row_record(r) for r in chain._pose_rows]),
                   chain.convention == 'standard')
                  for chain, parent, q_map in
                  [(self.chain, -1, range(self.chain.dof))] + list(self.branches)]
        links = pack(KERNEL.LAYOUTS, 'link', [link_record(*link) for link in self.links])
        return KERNEL.Model(chains, links, self.dof)

    # -- N configurations --------------------------------------------------------------
    def frame_pose_arrays_batch(self, q: ArrayLike, out: tuple | None = None
                                ) -> tuple[np.ndarray, np.ndarray]:
        """
        :meth:`frame_pose_arrays` for N configurations: ``(N, n_frames, 7)``, ``(N, n, 7)``.

        ``out``: ``(absolute, relative)`` float64 C-contiguous arrays of at least N rows of
        those shapes, written in their first N rows (a bag's batches reuse them: a fresh
        array's pages fault in at first touch, which costs more than the FK here). The
        views of those rows are returned.

        Fast path: the kernel's ``Model``, configuration by configuration; reference: the
        numpy batch (:meth:`_batch`), test_kernel_tree.py's
        ``test_batches_equal_the_numpy_batch``.
        """
        kernel = self._kernel_model
        if kernel is None:
            absolute, relative = self.frame_pose_arrays_batch_reference(q)
            if out is None:
                return absolute, relative
            out = _rows_of(out, len(absolute), self.n_frames, self.n_transforms)
            out[0][...], out[1][...] = absolute, relative
            return out
        q = np.ascontiguousarray(q, dtype=float)
        if q.ndim != 2 or q.shape[1] != self.dof:
            raise ValueError(f'expected an (N, {self.dof}) array of joint values, '
                             f'got shape {q.shape}')
        if out is None:
            absolute = np.empty((len(q), self.n_frames, 7))
            relative = np.empty((len(q), self.n_transforms, 7))
        else:
            absolute, relative = _rows_of(out, len(q), self.n_frames, self.n_transforms)
        kernel.poses_batch(q, absolute, relative)
        return absolute, relative

    def frame_pose_arrays_batch_reference(self, q: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`frame_pose_arrays_batch` on numpy: the reference."""
        absolute, relative = self._batch(q, relative=True)
        return dq_to_pose_xyzw(absolute), dq_to_pose_xyzw(relative)

    def forward_all_batch(self, q: ArrayLike) -> np.ndarray:
        """Every frame for N configurations: ``(N, n_frames, 8)``, ``w >= 0`` (numpy)."""
        return self._batch(q, relative=False)[0]

    def relative_batch(self, q: ArrayLike) -> np.ndarray:
        """Return the TF transforms for N configurations: ``(N, n_transforms, 8)`` (numpy)."""
        return self._batch(q, relative=True)[1]

    def _batch(self, q, relative):
        chain = self.chain
        q = np.asarray(q, dtype=float)
        if q.ndim != 2 or q.shape[1] != self.dof:
            raise ValueError(f'expected an (N, {self.dof}) array of joint values, '
                             f'got shape {q.shape}')
        absolute = chain.forward_all_batch(q[:, :chain.dof])
        rel = chain.relative_all_batch(q[:, :chain.dof]) if relative else None
        if self._plain:
            return absolute, rel
        n = absolute.shape[0]
        frames = [absolute[:, k] for k in range(absolute.shape[1])]
        rels = [rel] if relative else []
        identity = np.broadcast_to(np.array(_IDENTITY), (n, 8))
        for branch, parent, q_map in self.branches:
            q_branch = q[:, list(q_map)]
            base = dq_multiply_array(frames[parent], np.array(branch._base_t)) if parent >= 0 \
                else np.broadcast_to(np.array(branch._base_t), (n, 8))
            columns = np.ascontiguousarray(q_branch.T)
            out = run_chain_program(branch, tuple(base.T), columns, np.cos, np.sin)
            frames += [np.stack(np.broadcast_arrays(*f), axis=-1) for f in out]
            if relative:
                rels.append(branch.relative_all_batch(q_branch))
        extra = []
        columns = q.T
        for attach, tf_parent, offset, motion in self.links:
            offset = np.broadcast_to(np.array(offset), (n, 8))
            if motion is not None:
                offset = dq_multiply_array(offset, np.stack(
                    np.broadcast_arrays(*link_motion(motion, columns, np.cos, np.sin)),
                    axis=-1))
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


def _rows_of(out, n, n_frames, n_transforms):
    """Return the first ``n`` rows of ``out``'s two arrays, checked against their shapes."""
    absolute, relative = out
    for array, width, what in ((absolute, n_frames, 'absolute'),
                               (relative, n_transforms, 'relative')):
        if not isinstance(array, np.ndarray) or array.dtype != np.float64 or \
                array.ndim != 3 or array.shape[1:] != (width, 7) or len(array) < n or \
                not array.flags.c_contiguous or not array.flags.writeable:
            raise ValueError(f'out: {what} must be a writable C-contiguous float64 array of '
                             f'at least ({n}, {width}, 7)')
    return absolute[:n], relative[:n]
