"""
Forward kinematics of a tree of DH chains and the links fixed to them: one engine, two paths.

:class:`TreeKinematics` is what a robot (``description.RobotModel``) hands its chains and
links to: a root chain, branches hanging from frames of earlier chains, and links fixed to
(or moving with one joint about an axis from) any frame before them, in frame order. Every
frame's pose in the fixed frame and every TF transform (each DH row's, then each link's from
its TF parent) come from it, for one configuration or a batch.

A facade: the tree laid out once (``layout``), its engine chosen once (``engine``,
:mod:`.tree_engines`: the compiled kernel's ``Model`` for ``frame_pose_arrays``,
``forward_all`` and the batches, or the numpy reference with the same methods), and the
straight-line Python of one configuration (``frame_poses``,
``dh_code.unrolled_frame_poses``). References: ``frame_poses_general`` (loops, floats) and
the numpy batch (``tree_engines.tree_batch``), held equal to them by test_kernel.py
(``test_the_model_kernel_equals_the_general_path``), test_kernel_tree.py
(``test_batches_equal_the_numpy_batch``), test_links.py and test_chains.py (to the bit).
"""

from collections.abc import Callable, Sequence
from functools import cached_property
import math

from dq_fk_ros.kinematics.chain_table import joint_value_list
from dq_fk_ros.kinematics.dh import KinematicChain
from dq_fk_ros.kinematics.dh_code import run_chain_program, unrolled_frame_poses
from dq_fk_ros.kinematics.dual_quaternion import (
    dq_inverse_coeffs, dq_multiply_coeffs, dq_to_pose_xyzw, Pose, pose_xyzw_from_coeffs)
from dq_fk_ros.kinematics.tree_engines import (
    CompiledTreeEngine, IDENTITY, link_motion, ReferenceTreeEngine, tree_batch, tree_engine,
    TreeLayout)
import numpy as np
from numpy.typing import ArrayLike


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
        self.layout = TreeLayout(((chain, -1, tuple(range(chain.dof))),) + tuple(
            (b, parent, tuple(q_map)) for b, parent, q_map in self.branches), self.links,
            self.joint_names, self.n_frames, self.n_transforms)
        self.plain = not self.links and not self.branches  # one chain: its own paths

    def __getstate__(self) -> dict:
        """Pickle without the engine and the generated code (made again on use)."""
        made = ('engine', 'unrolled', 'unrolled_transforms')
        return {k: v for k, v in self.__dict__.items() if k not in made}

    @cached_property
    def engine(self) -> CompiledTreeEngine | ReferenceTreeEngine:
        """Make the tree's engine once: the compiled or the numpy one (:mod:`.tree_engines`)."""
        return tree_engine(self.layout, self.frame_poses, self.transform_poses)

    # -- one configuration, Python floats -----------------------------------------------
    def frame_poses(self, q: ArrayLike) -> tuple[list[Pose], list[Pose]]:
        """
        ``(absolute, relative)`` poses ``(x, y, z, qx, qy, qz, qw)`` (``qw >= 0``) at ``q``.

        Straight-line code (``unrolled_frame_poses``); the reference is
        :meth:`frame_poses_general`, equal to the bit (test_links.py, test_chains.py).
        """
        if self.plain:
            return self.chain.frame_poses(q)
        return self.unrolled(joint_value_list(q, self.joint_names))

    def frame_poses_code(self) -> str:
        """Return the Python source of :meth:`frame_poses`' straight-line code (generated)."""
        return self.chain.frame_poses_code.source if self.plain else self.unrolled.source

    @cached_property
    def unrolled(self) -> Callable[[list[float]], tuple[list[Pose], list[Pose]]]:
        """:meth:`frame_poses` as straight-line code, made on first use."""
        return unrolled_frame_poses(self.chain.table, self.links, link_motion,
                                    self._branch_tables())

    @cached_property
    def unrolled_transforms(self) -> Callable[[list[float]], tuple[list, list[Pose]]]:
        """:meth:`transform_poses` as straight-line code, made on first use."""
        return unrolled_frame_poses(self.chain.table, self.links, link_motion,
                                    self._branch_tables(), absolute=False)

    def _branch_tables(self):
        return tuple((b.table, parent, q_map) for b, parent, q_map in self.branches)

    def transform_poses(self, q: ArrayLike) -> list[Pose]:
        """
        Return the TF transforms of :meth:`frame_poses` alone (``relative``), at ``q``.

        Without converting the absolute poses (about half the work); the same values as
        :meth:`frame_poses`' to the bit (``test_chains.py``).
        """
        if self.plain:
            return self.chain.row_poses(q)
        return self.unrolled_transforms(joint_value_list(q, self.joint_names))[1]

    def frame_poses_general(self, q: ArrayLike) -> tuple[list[Pose], list[Pose]]:
        """:meth:`frame_poses` by the general (looping) path: the reference."""
        if self.plain:
            return self.chain.frame_poses_general(q)
        q = joint_value_list(q, self.joint_names)
        q_chain = q[:self.chain.dof]
        coeffs = self.chain.frame_coeffs(q_chain)
        relative = self.chain.row_poses(q_chain)
        for chain, parent, q_map in self.branches:
            q_branch = [q[k] for k in q_map]
            base = dq_multiply_coeffs(coeffs[parent], chain.table.base) if parent >= 0 \
                else chain.table.base
            coeffs += run_chain_program(chain.table, base, q_branch, math.cos, math.sin)
            relative += chain.row_poses(q_branch)
        absolute = [pose_xyzw_from_coeffs(h) for h in coeffs]
        for attach, tf_parent, offset, motion in self.links:
            parent = coeffs[attach] if attach >= 0 else IDENTITY
            if motion is not None:
                offset = dq_multiply_coeffs(offset, link_motion(motion, q, math.cos, math.sin))
            pose = dq_multiply_coeffs(parent, offset)
            coeffs.append(pose)
            absolute.append(pose_xyzw_from_coeffs(pose))
            if tf_parent == attach:
                relative.append(pose_xyzw_from_coeffs(offset))
            else:
                above = coeffs[tf_parent] if tf_parent >= 0 else IDENTITY
                relative.append(pose_xyzw_from_coeffs(
                    dq_multiply_coeffs(dq_inverse_coeffs(above), pose)))
        return absolute, relative

    # -- one configuration into arrays: the engine ---------------------------------------
    def frame_pose_arrays(self, q: ArrayLike, absolute: np.ndarray | None = None,
                          relative: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """
        :meth:`frame_poses` as float64 arrays ``(n_frames, 7)`` and ``(n_transforms, 7)``.

        The engine writes into ``absolute`` and ``relative`` (C-contiguous float64 arrays
        the caller owns: no allocation; made when None): the kernel's ``Model``, or the
        straight-line code of :meth:`frame_poses`; reference: :meth:`frame_poses_general`
        (test_kernel.py).
        """
        if absolute is None:
            absolute = np.empty((self.n_frames, 7))
        if relative is None:
            relative = np.empty((self.n_transforms, 7))
        self.engine.poses(q, absolute, relative)
        return absolute, relative

    def transform_pose_array(self, q: ArrayLike,
                             relative: np.ndarray | None = None) -> np.ndarray:
        """:meth:`transform_poses` as one ``(n_transforms, 7)`` array; paths as above."""
        if relative is None:
            relative = np.empty((self.n_transforms, 7))
        self.engine.transforms(q, relative)
        return relative

    def forward_all(self, q: ArrayLike) -> np.ndarray:
        """
        Every frame in the fixed frame: ``(n_frames, 8)``, ``w >= 0``.

        The engine (a chain's, or the tree's); reference: the numpy batch of one
        configuration (:meth:`forward_all_batch`), test_kernel.py.
        """
        return self.chain.forward_all(q) if self.plain else self.engine.frames(q)

    # -- N configurations --------------------------------------------------------------
    def frame_pose_arrays_batch(self, q: ArrayLike, out: tuple | None = None
                                ) -> tuple[np.ndarray, np.ndarray]:
        """
        :meth:`frame_pose_arrays` for N configurations: ``(N, n_frames, 7)``, ``(N, n, 7)``.

        ``out``: ``(absolute, relative)`` float64 C-contiguous arrays of at least N rows of
        those shapes, written in their first N rows (a bag's batches reuse them: a fresh
        array's pages fault in at first touch, which costs more than the FK here). The
        views of those rows are returned.

        The engine (the kernel's ``Model``, configuration by configuration); reference:
        :meth:`frame_pose_arrays_batch_reference`, test_kernel_tree.py's
        ``test_batches_equal_the_numpy_batch``.
        """
        q = self.layout.q_batch(q)
        if out is None:
            absolute = np.empty((len(q), self.n_frames, 7))
            relative = np.empty((len(q), self.n_transforms, 7))
        else:
            absolute, relative = _rows_of(out, len(q), self.n_frames, self.n_transforms)
        self.engine.poses_batch(q, absolute, relative)
        return absolute, relative

    def frame_pose_arrays_batch_reference(self, q: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`frame_pose_arrays_batch` on numpy: the reference."""
        absolute, relative = tree_batch(self.layout, q, relative=True)
        return dq_to_pose_xyzw(absolute), dq_to_pose_xyzw(relative)

    def forward_all_batch(self, q: ArrayLike) -> np.ndarray:
        """Every frame for N configurations: ``(N, n_frames, 8)``, ``w >= 0`` (numpy)."""
        return tree_batch(self.layout, q, relative=False)[0]

    def relative_batch(self, q: ArrayLike) -> np.ndarray:
        """Return the TF transforms for N configurations: ``(N, n_transforms, 8)`` (numpy)."""
        return tree_batch(self.layout, q, relative=True)[1]


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


__all__ = ['link_motion', 'TreeKinematics']
