"""
The robot model: a tree of DH chains, the links fixed to them, and the names ROS needs.

Plain Python (numpy), no ROS. :mod:`dq_fk_ros.description.schema` reads it from the YAML
file documented in ``docs/robot_description.md``; in short::

    robot: rl15
    convention: standard        # standard (Spong, distal) | modified (Craig, proximal)
    units: {length: mm, angle: deg}
    fixed_frame: world
    base: {frame: base_seg0, xyz: [0, 0, 730], rpy: [0, 0, 0]}
    chain:
      - {frame: shoulder_seg1, joint: joint_1, theta: 0, d: 0, a: 200, alpha: 90}
      ...
    tool: {frame: tcp, xyz: [0, 0, 100], quaternion: [0, 0, 0, 1]}   # x y z w
    links:                      # named frames fixed to the others (URDF links, sensors)
      - {frame: flange, parent: tcp, xyz: [0, 0, 10], rpy: [0, 0, 0]}

or, for a tree, ``chains: [{parent, base, chain, tool}, ...]`` instead of base/chain/tool.

The model holds metres and radians only (REP 103), and the rules of names and sizes every
robot follows (frame ids as tf2 takes them, joint names, limits).

Why this file is long: the model's evaluation paths (straight-line code, the general
reference, batches) for a tree of chains stay together: they must agree to the bit.
"""

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import cached_property
import math
import re

from dq_fk_ros.kinematics.dh import joint_value_list, joint_value_vector, KinematicChain
from dq_fk_ros.kinematics.dh_code import run_chain_program, unrolled_frame_poses
from dq_fk_ros.kinematics.dual_quaternion import (
    dq_inverse_coeffs, dq_multiply_array, dq_multiply_coeffs, dq_to_pose_xyzw, DualQuaternion,
    Pose, pose_xyzw_from_coeffs)
from dq_fk_ros.kinematics.kernel import KERNEL
import numpy as np
from numpy.typing import ArrayLike

# A frame id as tf2 takes it: printable ASCII without spaces, not starting with a slash (tf2
# strips a leading one). The Allegro hand's link_11.0 and names with '-' are frame ids; the
# node's topic for a frame (~/pose/<topic name>) is made from it by pose_topic_name.
TF_FRAME_ID = re.compile(r'[!-.0-~][!-~]*')
# What ROS topic names take: tokens of letters, digits and underscores that do not start with
# a digit, joined by single inner slashes (a frame_prefix, a frame's pose topic name).
FRAME_ID = re.compile(r'[A-Za-z_][A-Za-z0-9_]*(/[A-Za-z_][A-Za-z0-9_]*)*')
_NOT_TOKEN = re.compile(r'[^A-Za-z0-9_]')
# Joint names only travel inside JointState messages and URDF attributes.
JOINT_NAME = re.compile(r'[A-Za-z_][A-Za-z0-9_./-]*')
MAX_NAME_CHARS = 128            # frame, joint and robot names (topic names stay < 247 chars)
MAX_DESCRIPTION_CHARS = 4096
MAX_FILE_BYTES = 1 << 20        # a robot description file is at most 1 MiB ...
MAX_ROWS = 256                  # ... and at most this many DH rows
MAX_LENGTH_M = 1e6              # offsets (xyz, d, a) of at most 1000 km: no overflow in FK


@dataclass(frozen=True)
class LinkFrame:
    """
    A named frame fixed to another frame of the robot: a URDF link, a flange, a sensor.

    ``offset`` is its pose in ``parent`` (a :class:`DualQuaternion`; ``parent`` is a DH
    frame, the tool, an earlier link or the fixed frame). TF carries it under ``tf_parent``
    (by default ``parent``; ``dq_fk from-urdf`` sets the URDF's parent link).
    ``motion``, if given, is ``(kind, unit axis, joint, multiplier, offset)``: the link
    moves with a joint, its pose ``parent * offset * M(multiplier * q[joint] + offset)``
    with ``M`` a rotation about (``revolute``) or a translation along (``prismatic``)
    ``axis``, in rad or m. The joint is a chain joint or another link's (a mimic), or the
    link's own: ``joint`` then names it (a side-branch joint, such as a gripper's, with
    ``limits`` and ``max_velocity``; optional in joint states, see
    :attr:`RobotModel.optional_joints`).
    ``floating``: the link hangs from a URDF floating joint: computed at the joint's origin,
    it gets no TF transform (joint states cannot say where it is: odometry or localisation
    publishes it) and roots a TF tree of its own (:attr:`RobotModel.tree_roots`).
    """

    frame: str
    parent: str
    offset: DualQuaternion
    tf_parent: str
    motion: tuple = None
    joint: str = ''
    limits: tuple = (-math.inf, math.inf)
    max_velocity: float = math.inf
    floating: bool = False


@dataclass(frozen=True)
class Branch:
    """
    A DH chain hanging from a frame of the robot: an arm on a torso, a finger on a palm.

    ``parent`` is the frame it hangs from (the fixed frame or a frame of an earlier chain);
    the chain's ``base`` is frame 0 posed in ``parent``. ``external`` names the variables of
    ``chain`` that are other chains' joints (rows mimicking them read their values).
    """

    parent: str
    chain: KinematicChain
    external: tuple = ()


@dataclass(frozen=True)
class RobotModel:
    """
    A validated robot: a tree of DH chains, the links fixed to them, and the names ROS needs.

    ``chain`` is the first chain (from the fixed frame), ``branches`` the others
    (:class:`Branch`, each hanging from a frame of an earlier one). ``frame_names`` are the
    first chain's frames (frame 0 = ``base.frame``, the row frames, the tool frame if any;
    the order of :meth:`KinematicChain.forward_all`), each branch's the same way, then the
    ``links``.
    ``parent_frames[i]`` is the TF parent of ``frame_names[i]`` (frame 0's is
    ``fixed_frame``); ``moving[i]`` says whether that parent -> child transform depends on
    joint values (else it is static). ``end_effector`` names the frame a user means by
    "the end effector" (default: the last chain frame). ``urdf`` is the URDF XML the robot
    was converted from (None for a DH file). ``publish_dh_frames`` says whether the DH
    frames are frames a user means to see on TF (a DH file: they are its link frames) or
    only the computation's (a URDF's: its links are the frames; ``dq_fk from-urdf`` writes
    ``publish_dh_frames: false``). Lengths are metres, angles radians.
    """

    name: str
    source: str
    fixed_frame: str
    frame_names: tuple
    parent_frames: tuple
    moving: tuple
    chain: KinematicChain
    max_velocity: np.ndarray
    links: tuple = ()
    end_effector: str = ''
    urdf: str = None
    branches: tuple = ()
    publish_dh_frames: bool = True

    @cached_property
    def joint_names(self) -> tuple[str, ...]:
        """
        Joint names in the order ``q`` is given: each chain's own, then the links' own joints.

        A robot of one chain needs every chain joint before anything is published
        (:attr:`required_joints`); the links' own joints (side branches such as a gripper)
        and, in a tree of chains, every joint are optional: a frame is published once the
        joints it depends on are known (:attr:`frame_needs`, :attr:`edge_needs`).
        """
        return global_joint_names(self.chain, self.branches, self.links)

    @property
    def required_joints(self) -> tuple[str, ...]:
        """Name the joints every update needs: the chain's for one chain, none for a tree."""
        return () if self.branches else self.chain.joint_names

    @cached_property
    def optional_joints(self) -> tuple[str, ...]:
        """Name the joints after :attr:`required_joints` in ``joint_names``."""
        return self.joint_names[len(self.required_joints):]

    @cached_property
    def chains(self) -> tuple[tuple[str, KinematicChain, int], ...]:
        """``((parent frame, KinematicChain, index of its frame 0), ...)``: the first first."""
        out, start = [], 0
        for parent, chain in [(self.fixed_frame, self.chain)] + [
                (b.parent, b.chain) for b in self.branches]:
            out.append((parent, chain, start))
            start += chain.n_frames
        return tuple(out)

    @property
    def n_dh_frames(self) -> int:
        """Count the frames of all chains: the first ones of ``frame_names`` (links follow)."""
        return sum(chain.n_frames for _, chain, _ in self.chains)

    @cached_property
    def _q_maps(self):
        """Per chain: where each of its variables is in ``q`` (indices into joint_names)."""
        index = {name: k for k, name in enumerate(self.joint_names)}
        return tuple(tuple(index[n] for n in chain.joint_names) for _, chain, _ in self.chains)

    @property
    def dof(self) -> int:
        """Count the joint values of ``q``: chain joints, then optional ones."""
        return len(self.joint_names)

    @cached_property
    def limits(self) -> np.ndarray:
        """Joint limits ``(dof, 2)``, lower and upper, in rad or m (+-inf: none given)."""
        own = {}
        for branch, (_, chain, _) in zip((None,) + self.branches, self.chains):
            external = branch.external if branch is not None else ()
            own.update((n, lim) for n, lim in zip(chain.joint_names, chain.limits.tolist())
                       if n not in external)
        own.update((link.joint, link.limits) for link in self.links if link.joint)
        return np.array([own[n] for n in self.joint_names], dtype=float).reshape(-1, 2)

    @property
    def angular(self) -> np.ndarray:
        """Per joint (``joint_names`` order): True where the value is an angle (rad), else m."""
        index = {name: k for k, name in enumerate(self.joint_names)}
        mask = np.zeros(len(index), dtype=bool)
        for branch, (_, chain, _) in zip((None,) + self.branches, self.chains):
            external = branch.external if branch is not None else ()
            for j in chain.joints:
                if j.joint_type in ('revolute', 'cylindrical') and not j.follows and \
                        j.name not in external:
                    mask[index[j.name]] = True
        for link in self.links:
            if link.joint and link.motion[0] == 'revolute':
                mask[index[link.joint]] = True
        return mask

    @cached_property
    def _paths(self):
        """
        ``(paths, reads)``: per frame name, the moving rows and links its pose depends on.

        ``paths[frame]`` is a frozenset of moving elements (``(chain, row)`` or ``('link',
        k)``) between the fixed frame and it; ``reads[element]`` the joints that one reads.
        """
        paths = {self.fixed_frame: frozenset()}
        reads = {}
        for c, (parent, chain, start) in enumerate(self.chains):
            here = paths[parent]
            paths[self.frame_names[start]] = here
            for i, joint in enumerate(chain.joints):
                if joint.joint_type != 'fixed':
                    reads[(c, i)] = frozenset(
                        chain.joint_names[int(k)] for k in
                        (chain._theta_index[i], chain._d_index[i]) if k >= 0)
                    here = here | {(c, i)}
                paths[self.frame_names[start + i + 1]] = here
            if chain.tool is not None:
                paths[self.frame_names[start + chain.n_frames - 1]] = here
        for k, link in enumerate(self.links):
            here = paths[link.parent]
            if link.motion is not None:
                reads[('link', k)] = frozenset((link.motion[2],))
                here = here | {('link', k)}
            paths[link.frame] = here
        return paths, reads

    def _needs(self, elements):
        paths, reads = self._paths
        optional = set(self.optional_joints)
        return frozenset().union(*(reads[e] for e in elements)) & optional

    @cached_property
    def frame_needs(self) -> tuple[frozenset, ...]:
        """Per frame: the optional joints its pose in the fixed frame depends on (frozensets)."""
        paths, _ = self._paths
        return tuple(self._needs(paths[name]) for name in self.frame_names)

    @cached_property
    def edge_needs(self) -> tuple[frozenset, ...]:
        """
        Per frame: the optional joints its TF transform (from its TF parent) depends on.

        Those on the way between the two frames only, as robot_state_publisher sends a
        joint's transform once a message names that joint: a gripper's links need the
        gripper's joints, not the arm's.
        """
        paths, _ = self._paths
        return tuple(self._needs(paths[name] ^ paths[parent])
                     for name, parent in zip(self.frame_names, self.parent_frames))

    def tf_frame_id(self, name: str, prefix: str = '') -> str:
        """
        Return the TF frame id of frame ``name`` (or the fixed frame) under ``frame_prefix``.

        Every frame gets the prefix, the fixed frame too when it is a URDF's root link (as
        robot_state_publisher prefixes every link); a DH file's fixed frame (``world``) is
        shared by the robots in one tree and keeps its name.
        """
        if name == self.fixed_frame and self.urdf is None:
            return name
        return prefix + name

    @cached_property
    def tree_roots(self) -> tuple[int, ...]:
        """
        Per frame: the index of the root of its TF tree, -1 for the fixed frame.

        A floating link (:attr:`LinkFrame.floating`) roots a tree of its own (itself), as
        robot_state_publisher leaves a floating joint's child without a parent on TF; every
        other frame is in its TF parent's tree.
        """
        index = {name: k for k, name in enumerate(self.frame_names)}
        index[self.fixed_frame] = -1
        floating = {self.n_dh_frames + j for j, link in enumerate(self.links) if link.floating}
        roots = []
        for k, parent in enumerate(self.parent_frames):  # TF parents come first
            p = index[parent]
            roots.append(k if k in floating else (-1 if p < 0 else roots[p]))
        return tuple(roots)

    @cached_property
    def topic_names(self) -> list[str]:
        """Per frame of ``frame_names``: its ``~/pose/...`` topic (:func:`pose_topic_name`)."""
        return tuple(pose_topic_name(frame) for frame in self.frame_names)

    @property
    def n_chain_frames(self) -> int:
        """Count the chain's frames (base, rows, tool): the first ones of ``frame_names``."""
        return self.chain.n_frames

    @property
    def end_effector_index(self) -> int:
        """Index of ``end_effector`` in ``frame_names``."""
        return self.frame_names.index(self.end_effector or self.frame_names[
            self.n_chain_frames - 1])

    @cached_property
    def _link_plan(self):
        """
        Per link: (attachment index, TF-parent index, offset 8-tuple, motion); -1 = fixed frame.

        ``motion`` is None or ``(prismatic?, axis tuple, q index, multiplier, offset)``.
        """
        index = {name: k for k, name in enumerate(self.frame_names)}
        index[self.fixed_frame] = -1
        joints = {name: k for k, name in enumerate(self.joint_names)}
        plan = []
        for link in self.links:
            motion = None
            if link.motion is not None:
                kind, axis, joint, multiplier, offset = link.motion
                motion = (kind == 'prismatic', tuple(float(v) for v in axis), joints[joint],
                          float(multiplier), float(offset))
            plan.append((index[link.parent], index[link.tf_parent],
                         tuple(link.offset.coeffs.tolist()), motion))
        return tuple(plan)

    @cached_property
    def _relative_index(self):
        """Per frame: its transform's index in ``frame_poses``' relative, or -1 (base, tool)."""
        out = [-1] * len(self.frame_names)
        r = 0
        for _, chain, start in self.chains:
            for i in range(len(chain.joints)):
                out[start + i + 1] = r
                r += 1
        for j in range(len(self.links)):
            out[self.n_dh_frames + j] = r + j
        return tuple(out)

    @cached_property
    def moving_edges(self) -> tuple[tuple[int, int], ...]:
        """``(frame index, index in frame_poses' relative)`` of every moving TF transform."""
        return tuple((k, r) for k, r in enumerate(self._relative_index) if self.moving[k])

    @cached_property
    def _branch_plan(self):
        """Per branch: ``(chain, index of the frame it hangs from (-1: fixed), q indices)``."""
        index = {name: k for k, name in enumerate(self.frame_names)}
        index[self.fixed_frame] = -1
        return tuple((chain, index[parent], q_map) for (parent, chain, _), q_map in
                     zip(self.chains[1:], self._q_maps[1:]))

    def frame_poses(self, q: ArrayLike) -> tuple[list[Pose], list[Pose]]:
        """
        Poses for publishing, tuples ``(x, y, z, qx, qy, qz, qw)`` (``qw >= 0``), at ``q``.

        Returns ``(absolute, relative)``: every frame of ``frame_names`` in the fixed frame,
        and the TF transforms: every DH row's (frame i-1 -> frame i, chain by chain), then
        every link's (``tf_parent`` -> link). Straight-line code (``unrolled_frame_poses``);
        the reference is :meth:`frame_poses_general`, held equal to the bit by
        ``test_links.py`` and ``test_chains.py``.
        """
        if not self.links and not self.branches:
            return self.chain.frame_poses(q)
        return self._unrolled(joint_value_list(q, self.joint_names))

    def frame_poses_code(self) -> Callable:
        """Return the Python source of :meth:`frame_poses`' straight-line code (generated)."""
        if not self.links and not self.branches:
            return self.chain._unrolled.source
        return self._unrolled.source

    @cached_property
    def _unrolled(self):
        """:meth:`frame_poses` as straight-line code (``unrolled_frame_poses``)."""
        return unrolled_frame_poses(self.chain, self._link_plan, _motion, self._branch_plan)

    def frame_poses_general(self, q: ArrayLike) -> tuple[list[Pose], list[Pose]]:
        """
        :meth:`frame_poses` by the general (looping) path: the reference.

        The fast path is :meth:`frame_poses` (straight-line code); test_links.py and
        test_chains.py hold them equal to the bit.
        """
        if not self.links and not self.branches:
            return self.chain.frame_poses_general(q)
        q = joint_value_list(q, self.joint_names)
        q_chain = q[:self.chain.dof]
        coeffs = self.chain.frame_coeffs(q_chain)
        relative = self.chain.row_poses(q_chain)
        for chain, parent, q_map in self._branch_plan:
            q_branch = [q[k] for k in q_map]
            base = dq_multiply_coeffs(coeffs[parent], chain._base_t) if parent >= 0 \
                else chain._base_t
            frames = run_chain_program(chain, base, q_branch, math.cos, math.sin)
            coeffs += frames
            relative += chain.row_poses(q_branch)
        absolute = [pose_xyzw_from_coeffs(h) for h in coeffs]
        for attach, tf_parent, offset, motion in self._link_plan:
            parent = coeffs[attach] if attach >= 0 else _IDENTITY
            if motion is not None:
                offset = dq_multiply_coeffs(offset, _motion(motion, q, math.cos, math.sin))
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

    def frame_pose_arrays(self, q: ArrayLike, absolute: np.ndarray | None = None,
                          relative: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """
        :meth:`frame_poses` as float64 arrays ``(n_frames, 7)`` and ``(n_transforms, 7)``.

        Fast path: the C kernel's ``Model`` writes into ``absolute`` and ``relative``
        (C-contiguous float64 arrays the caller owns: no allocation; made when None);
        reference: :meth:`frame_poses_general`, held equal by test_kernel.py's
        ``test_the_model_kernel_equals_the_general_path``. Without the kernel, the
        straight-line code of :meth:`frame_poses` fills them.
        """
        if absolute is None:
            absolute = np.empty((len(self.frame_names), 7))
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
        """
        :meth:`transform_poses` as one float64 array ``(n_transforms, 7)``.

        Fast path and reference as :meth:`frame_pose_arrays` (the kernel skips the absolute
        poses' conversion).
        """
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

    def frame_pose_arrays_batch(self, q: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """
        :meth:`frame_pose_arrays` for N configurations: ``(N, n_frames, 7)``, ``(N, n, 7)``.

        Fast path: the C kernel's ``Model``, configuration by configuration; reference: the
        numpy batch (:meth:`forward_all_batch`, :meth:`relative_batch`), held equal by
        test_kernel_tree.py's ``test_batches_equal_the_numpy_batch``.
        """
        kernel = self._kernel_model
        if kernel is None:
            return self._frame_pose_arrays_batch_reference(q)
        q = np.ascontiguousarray(q, dtype=float)
        if q.ndim != 2 or q.shape[1] != self.dof:
            raise ValueError(f'expected an (N, {self.dof}) array of joint values, '
                             f'got shape {q.shape}')
        absolute = np.empty((len(q), len(self.frame_names), 7))
        relative = np.empty((len(q), self.n_transforms, 7))
        kernel.poses_batch(q, absolute, relative)
        return absolute, relative

    def _frame_pose_arrays_batch_reference(self, q):
        """:meth:`frame_pose_arrays_batch` on numpy: the reference."""
        absolute, relative = self._batch(q, relative=True)
        return dq_to_pose_xyzw(absolute), dq_to_pose_xyzw(relative)

    @property
    def n_transforms(self) -> int:
        """Count the TF transforms of :meth:`frame_poses`' relative: DH rows, then links."""
        return sum(len(chain.joints) for _, chain, _ in self.chains) + len(self.links)

    @cached_property
    def _kernel_model(self):
        """Copy the tree and its links into the C kernel once (None: the numpy path)."""
        if KERNEL is None:
            return None
        index = {name: k for k, name in enumerate(self.frame_names)}
        index[self.fixed_frame] = -1
        chains = [(chain._kernel_chain, index[parent], np.array(q_map, dtype=float),
                   np.array(chain._pose_rows, dtype=float).reshape(-1, 10),
                   chain.convention == 'standard')
                  for (parent, chain, _), q_map in zip(self.chains, self._q_maps)]
        links = []
        for attach, tf_parent, offset, motion in self._link_plan:
            row = [float(attach), float(tf_parent), *offset]
            if motion is None:
                row += [-1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]
            else:
                prismatic, axis, k, multiplier, value = motion
                row += [float(prismatic), *axis, float(k), multiplier, value]
            links.append(row)
        return KERNEL.Model(chains, np.array(links, dtype=float).reshape(-1, 17), self.dof)

    def __getstate__(self):
        """Pickle without the kernel's copy and the generated code (made again on use)."""
        state = dict(self.__dict__)
        for made in ('_kernel_model', '_unrolled', '_unrolled_transforms'):
            state.pop(made, None)
        return state

    def transform_poses(self, q: ArrayLike) -> list[Pose]:
        """
        Return the TF transforms of :meth:`frame_poses` alone (``relative``), at ``q``.

        Computed without converting the absolute poses (for one chain without links, without
        them at all: about half the work); the same values as :meth:`frame_poses`' to the
        bit (``test_chains.py``).
        """
        if self.links or self.branches:
            return self._unrolled_transforms(joint_value_list(q, self.joint_names))[1]
        return self.chain.row_poses(q)

    @cached_property
    def _unrolled_transforms(self):
        """:meth:`transform_poses` of a tree or links: ``frame_poses`` without the poses."""
        return unrolled_frame_poses(self.chain, self._link_plan, _motion, self._branch_plan,
                                    absolute=False)

    def forward_all(self, q: ArrayLike) -> np.ndarray:
        """
        Every frame of ``frame_names`` in the fixed frame: ``(n, 8)``, ``w >= 0``.

        Fast path: the C kernel (a chain's, or the tree's ``Model``); reference: the numpy
        batch of one configuration (:meth:`forward_all_batch`), test_kernel.py.
        """
        if self.links or self.branches:
            kernel = self._kernel_model
            if kernel is None:
                return self.forward_all_batch(np.asarray(q, dtype=float)[None, :])[0]
            out = np.empty((len(self.frame_names), 8))
            kernel.frames(joint_value_vector(q, self.joint_names), out)
            return out
        return self.chain.forward_all(q)

    def forward_all_batch(self, q: ArrayLike) -> np.ndarray:
        """Every frame of ``frame_names`` for N configurations: ``(N, n, 8)``, ``w >= 0``."""
        absolute, _ = self._batch(q, relative=False)
        return absolute

    def end_effector_batch(self, q: ArrayLike) -> np.ndarray:
        """Return the end effector's pose for N configurations: ``(N, 8)``, ``w >= 0``."""
        k = self.end_effector_index
        if k == self.n_chain_frames - 1:
            return self.chain.forward_batch(np.asarray(q, dtype=float)[:, :self.chain.dof])
        return self.forward_all_batch(q)[:, k]

    def relative_batch(self, q: ArrayLike) -> np.ndarray:
        """``frame_poses``' relative transforms for N configurations: ``(N, rows + links, 8)``."""
        _, relative = self._batch(q, relative=True)
        return relative

    def _batch(self, q, relative):
        chain = self.chain
        q = np.asarray(q, dtype=float)
        if q.ndim != 2 or q.shape[1] != self.dof:
            raise ValueError(f'expected an (N, {self.dof}) array of joint values, '
                             f'got shape {q.shape}')
        absolute = chain.forward_all_batch(q[:, :chain.dof])
        rel = chain.relative_all_batch(q[:, :chain.dof]) if relative else None
        if not self.links and not self.branches:
            return absolute, rel
        n = absolute.shape[0]
        frames = [absolute[:, k] for k in range(absolute.shape[1])]
        rels = [rel] if relative else []
        identity = np.broadcast_to(np.array(_IDENTITY), (n, 8))
        for branch, parent, q_map in self._branch_plan:
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
        for attach, tf_parent, offset, motion in self._link_plan:
            offset = np.broadcast_to(np.array(offset), (n, 8))
            if motion is not None:
                offset = dq_multiply_array(offset, np.stack(
                    np.broadcast_arrays(*_motion(motion, columns, np.cos, np.sin)), axis=-1))
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

    def static_transforms(self) -> list[tuple[int, Pose]]:
        """``[(frame index, (x, y, z, qx, qy, qz, qw)), ...]``: every static TF transform."""
        _, relative = self.frame_poses([0.0] * self.dof)
        special = {}
        for _, chain, start in self.chains:
            special[start] = chain.base.to_pose_xyzw()
            if chain.tool is not None:
                special[start + chain.n_frames - 1] = chain.tool.to_pose_xyzw()
        out = []
        for k, r in enumerate(self._relative_index):
            if not self.moving[k]:
                pose = relative[r] if r >= 0 else special[k]
                out.append((k, tuple(float(v) for v in pose)))
        return out


_IDENTITY = (1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)


def global_joint_names(chain: KinematicChain, branches: Sequence = (),
                       links: Sequence = ()) -> tuple[str, ...]:
    """Name the joints of ``q``: ``chain``'s, each branch's own, then the links' own."""
    names = list(chain.joint_names)
    for branch in branches:
        names += [n for n in branch.chain.joint_names if n not in branch.external]
    return tuple(names) + tuple(link.joint for link in links if link.joint)


def _motion(motion, q, cos, sin):
    """Return the coefficients of a link's mimic motion at ``q`` (floats, or arrays)."""
    prismatic, (ax, ay, az), k, multiplier, offset = motion
    value = multiplier * q[k] + offset
    zero = 0.0 * value
    if prismatic:  # 1 + eps t/2
        half = 0.5 * value
        return (1.0 + zero, zero, zero, zero, zero, half * ax, half * ay, half * az)
    c, s = cos(0.5 * value), sin(0.5 * value)
    return (c, s * ax, s * ay, s * az, zero, zero, zero, zero)


_CONJUGATE = np.array([1.0, -1.0, -1.0, -1.0, 1.0, -1.0, -1.0, -1.0])


def pose_topic_name(frame: str) -> str:
    """
    Return the topic name token(s) of a frame's ``~/pose/...`` topic.

    The frame id itself where ROS takes it as a topic name; else, per ``/``-separated part,
    every character other than a letter, digit or ``_`` becomes ``_``, an empty part ``_``,
    and a part starting with a digit gets a leading ``_`` (``link_11.0`` -> ``link_11_0``,
    ``finger-1`` -> ``finger_1``, ``2nd`` -> ``_2nd``).
    """
    if FRAME_ID.fullmatch(frame):
        return frame
    parts = []
    for part in frame.split('/'):
        part = _NOT_TOKEN.sub('_', part) or '_'
        parts.append('_' + part if part[0].isdigit() else part)
    return '/'.join(parts)


def rpy_matrix(roll: float, pitch: float, yaw: float) -> np.ndarray:
    """Rotation matrix of URDF's fixed-axis roll, pitch, yaw: ``Rz(yaw) Ry(pitch) Rx(roll)``."""
    cr, sr = math.cos(roll), math.sin(roll)
    cp, sp = math.cos(pitch), math.sin(pitch)
    cy, sy = math.cos(yaw), math.sin(yaw)
    return np.array([[cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
                     [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
                     [-sp, cp * sr, cp * cr]])
