"""
The robot description: one YAML file per robot (a DH chain or a tree of them), validated.

Plain Python (PyYAML + numpy), no ROS. The file format is documented in
``docs/robot_description.md``; in short::

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

Every length and angle in the file is in the file's ``units``; the model holds metres and
radians only (REP 103). Any mistake raises :class:`RobotDescriptionError` with a single
line naming the file, the place (row index and frame), the field, what was found and what
is allowed.
"""

from dataclasses import dataclass
from functools import cached_property
import math
import os
import re

from dq_fk_ros.description.errors import RobotDescriptionError  # noqa: F401 (its home was here)
from dq_fk_ros.kinematics.dh import (
    CONVENTIONS, DHJoint, JOINT_TYPES, joint_value_list, KinematicChain, run_chain_program,
    unrolled_frame_poses)
from dq_fk_ros.kinematics.dual_quaternion import (
    dq_inverse_coeffs, dq_multiply_array, dq_multiply_coeffs, DualQuaternion,
    pose_xyzw_from_coeffs, quat_from_matrix)
import numpy as np
import yaml

LENGTH_UNITS = {'m': 1.0, 'cm': 0.01, 'mm': 0.001}
ANGLE_UNITS = {'rad': 1.0, 'deg': math.pi / 180.0}
ROW_TYPES = JOINT_TYPES  # a row's type is its joint's
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

TOP_FIELDS = ('robot', 'description', 'convention', 'units', 'fixed_frame', 'base', 'chain',
              'tool', 'chains', 'links', 'end_effector')
CHAIN_FIELDS = ('parent', 'base', 'chain', 'tool')
LINK_FIELDS = ('frame', 'parent', 'tf_parent', 'xyz', 'rpy', 'quaternion', 'type', 'axis',
               'joint', 'limits', 'max_velocity', 'mimic')
LINK_TYPES = ('fixed', 'revolute', 'prismatic')
UNIT_FIELDS = ('length', 'angle')
TRANSFORM_FIELDS = ('frame', 'xyz', 'rpy', 'quaternion')
ROW_FIELDS = ('frame', 'joint', 'type', 'theta', 'd', 'a', 'alpha', 'scale', 'limits',
              'max_velocity', 'mimic', 'd_joint', 'd_limits', 'd_max_velocity')
MIMIC_FIELDS = ('joint', 'multiplier', 'offset')


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
    """

    frame: str
    parent: str
    offset: DualQuaternion
    tf_parent: str
    motion: tuple = None
    joint: str = ''
    limits: tuple = (-math.inf, math.inf)
    max_velocity: float = math.inf


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
    was converted from (None for a DH file). Lengths are metres, angles radians.
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

    @cached_property
    def joint_names(self):
        """
        Joint names in the order ``q`` is given: each chain's own, then the links' own joints.

        A robot of one chain needs every chain joint before anything is published
        (:attr:`required_joints`); the links' own joints (side branches such as a gripper)
        and, in a tree of chains, every joint are optional: a frame is published once the
        joints it depends on are known (:attr:`frame_needs`, :attr:`edge_needs`).
        """
        return global_joint_names(self.chain, self.branches, self.links)

    @property
    def required_joints(self):
        """Name the joints every update needs: the chain's for one chain, none for a tree."""
        return () if self.branches else self.chain.joint_names

    @cached_property
    def optional_joints(self):
        """Name the joints after :attr:`required_joints` in ``joint_names``."""
        return self.joint_names[len(self.required_joints):]

    @cached_property
    def chains(self):
        """``((parent frame, KinematicChain, index of its frame 0), ...)``: the first first."""
        out, start = [], 0
        for parent, chain in [(self.fixed_frame, self.chain)] + [
                (b.parent, b.chain) for b in self.branches]:
            out.append((parent, chain, start))
            start += chain.n_frames
        return tuple(out)

    @property
    def n_dh_frames(self):
        """Count the frames of all chains: the first ones of ``frame_names`` (links follow)."""
        return sum(chain.n_frames for _, chain, _ in self.chains)

    @cached_property
    def _q_maps(self):
        """Per chain: where each of its variables is in ``q`` (indices into joint_names)."""
        index = {name: k for k, name in enumerate(self.joint_names)}
        return tuple(tuple(index[n] for n in chain.joint_names) for _, chain, _ in self.chains)

    @property
    def dof(self):
        """Count the joint values of ``q``: chain joints, then optional ones."""
        return len(self.joint_names)

    @cached_property
    def limits(self):
        """Joint limits ``(dof, 2)``, lower and upper, in rad or m (+-inf: none given)."""
        own = {}
        for branch, (_, chain, _) in zip((None,) + self.branches, self.chains):
            external = branch.external if branch is not None else ()
            own.update((n, lim) for n, lim in zip(chain.joint_names, chain.limits.tolist())
                       if n not in external)
        own.update((link.joint, link.limits) for link in self.links if link.joint)
        return np.array([own[n] for n in self.joint_names], dtype=float).reshape(-1, 2)

    @property
    def angular(self):
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
    def frame_needs(self):
        """Per frame: the optional joints its pose in the fixed frame depends on (frozensets)."""
        paths, _ = self._paths
        return tuple(self._needs(paths[name]) for name in self.frame_names)

    @cached_property
    def edge_needs(self):
        """
        Per frame: the optional joints its TF transform (from its TF parent) depends on.

        Those on the way between the two frames only, as robot_state_publisher sends a
        joint's transform once a message names that joint: a gripper's links need the
        gripper's joints, not the arm's.
        """
        paths, _ = self._paths
        return tuple(self._needs(paths[name] ^ paths[parent])
                     for name, parent in zip(self.frame_names, self.parent_frames))

    def tf_frame_id(self, name, prefix=''):
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
    def topic_names(self):
        """Per frame of ``frame_names``: its ``~/pose/...`` topic (:func:`pose_topic_name`)."""
        return tuple(pose_topic_name(frame) for frame in self.frame_names)

    @property
    def n_chain_frames(self):
        """Count the chain's frames (base, rows, tool): the first ones of ``frame_names``."""
        return self.chain.n_frames

    @property
    def end_effector_index(self):
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
    def moving_edges(self):
        """``(frame index, index in frame_poses' relative)`` of every moving TF transform."""
        return tuple((k, r) for k, r in enumerate(self._relative_index) if self.moving[k])

    @cached_property
    def _branch_plan(self):
        """Per branch: ``(chain, index of the frame it hangs from (-1: fixed), q indices)``."""
        index = {name: k for k, name in enumerate(self.frame_names)}
        index[self.fixed_frame] = -1
        return tuple((chain, index[parent], q_map) for (parent, chain, _), q_map in
                     zip(self.chains[1:], self._q_maps[1:]))

    def frame_poses(self, q):
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

    def frame_poses_code(self):
        """Return the Python source of :meth:`frame_poses`' straight-line code (generated)."""
        if not self.links and not self.branches:
            return self.chain._unrolled.source
        return self._unrolled.source

    @cached_property
    def _unrolled(self):
        """:meth:`frame_poses` as straight-line code (``unrolled_frame_poses``)."""
        return unrolled_frame_poses(self.chain, self._link_plan, _motion, self._branch_plan)

    def frame_poses_general(self, q):
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

    def transform_poses(self, q):
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

    def forward_all(self, q):
        """Every frame of ``frame_names`` in the fixed frame: ``(n, 8)``, ``w >= 0``."""
        if self.links or self.branches:
            return self.forward_all_batch(np.asarray(q, dtype=float)[None, :])[0]
        return self.chain.forward_all(q)

    def forward_all_batch(self, q):
        """Every frame of ``frame_names`` for N configurations: ``(N, n, 8)``, ``w >= 0``."""
        absolute, _ = self._batch(q, relative=False)
        return absolute

    def end_effector_batch(self, q):
        """Return the end effector's pose for N configurations: ``(N, 8)``, ``w >= 0``."""
        k = self.end_effector_index
        if k == self.n_chain_frames - 1:
            return self.chain.forward_batch(np.asarray(q, dtype=float)[:, :self.chain.dof])
        return self.forward_all_batch(q)[:, k]

    def relative_batch(self, q):
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

    def static_transforms(self):
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


def global_joint_names(chain, branches=(), links=()):
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


class _UniqueKeyLoader(yaml.SafeLoader):
    """A SafeLoader that refuses a mapping with the same key twice."""


def _construct_mapping(loader, node, deep=False):
    seen = set()
    for key_node, _ in node.value:
        key = loader.construct_object(key_node, deep=deep)
        if key in seen:
            raise yaml.constructor.ConstructorError(
                None, None, f'duplicate key {_short(key)}', key_node.start_mark)
        seen.add(key)
    return yaml.SafeLoader.construct_mapping(loader, node, deep)


_UniqueKeyLoader.add_constructor(yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG,
                                 _construct_mapping)
# YAML 1.2 writes exponents as 5e-05 or 1E16 (no point, or no sign): YAML 1.1, PyYAML's
# dialect, reads those as strings; robot files take them as numbers
_UniqueKeyLoader.add_implicit_resolver(
    'tag:yaml.org,2002:float',
    re.compile(r'^[-+]?(?:[0-9][0-9_]*(?:\.[0-9_]*)?|\.[0-9_]+)[eE][-+]?[0-9]+$'),
    list('-+0123456789.'))


def yaml_number(value):
    """
    Write a finite float so that YAML 1.1 and 1.2 both read it back as the same float.

    ``repr`` gives the shortest text that reads back exactly; YAML 1.1 also wants a point
    in the mantissa and a sign in the exponent (``5e-05`` -> ``5.0e-05``).
    """
    text = repr(float(value))
    mantissa, e, exponent = text.partition('e')
    if e and '.' not in mantissa:
        text = f'{mantissa}.0e{exponent}'
    return text


def load_robot_description(path):
    """Read and validate a robot description file; raise :class:`RobotDescriptionError`."""
    path = os.fspath(path)
    if os.path.exists(path) and not os.path.isdir(path) and not os.path.isfile(path):
        # a FIFO or a device would block the reader or never end
        raise RobotDescriptionError(f'{path}: not a regular file')
    try:
        with open(path, encoding='utf-8') as stream:
            text = stream.read(MAX_FILE_BYTES + 1)
        if len(text) > MAX_FILE_BYTES:
            raise RobotDescriptionError(f'{path}: larger than {MAX_FILE_BYTES // 1024} KiB; '
                                        f'a robot description file is at most that big')
    except FileNotFoundError:
        raise RobotDescriptionError(f'{path}: no such file') from None
    except IsADirectoryError:
        raise RobotDescriptionError(f'{path}: is a directory, not a robot description file') \
            from None
    except UnicodeDecodeError as exc:
        raise RobotDescriptionError(f'{path}: cannot be read ({exc})',
                                    f'{path}: not UTF-8 text') from None
    except (OSError, ValueError) as exc:
        raise RobotDescriptionError(f'{path}: cannot be read ({exc})',
                                    f'{path}: cannot be read') from None
    return parse_robot_description(text, path)


def parse_robot_description(text, source='<string>'):
    """
    Validate the YAML text of a robot description; ``source`` names it in errors.

    Every problem, whatever the text holds, is a :class:`RobotDescriptionError` with one
    line (the limits: :data:`MAX_FILE_BYTES`, :data:`MAX_ROWS`, :data:`MAX_NAME_CHARS`).
    """
    if len(text) > MAX_FILE_BYTES:
        raise RobotDescriptionError(f'{source}: larger than {MAX_FILE_BYTES // 1024} KiB; a '
                                    f'robot description is at most that big')
    try:
        data = yaml.load(text, Loader=_UniqueKeyLoader)
    except yaml.YAMLError as exc:
        mark = getattr(exc, 'problem_mark', None)
        where = f' at line {mark.line + 1}, column {mark.column + 1}' if mark else ''
        problem = getattr(exc, 'problem', None) or str(exc).splitlines()[0]
        raise RobotDescriptionError(f'{source}: not valid YAML{where}: {problem}',
                                    f'{source}: not valid YAML{where}') from None
    except RecursionError:
        raise RobotDescriptionError(f'{source}: YAML nested too deeply to be a robot '
                                    f'description') from None
    except (ValueError, TypeError, OverflowError) as exc:  # e.g. a 5000-digit integer
        problem = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise RobotDescriptionError(f'{source}: not valid YAML: {problem}',
                                    f'{source}: not valid YAML') from None
    if not _looks_like_description(data):
        public = (f'{source}: not a robot description (a YAML mapping with the fields robot, '
                  f'base and chain (or chains), and no others than {", ".join(TOP_FIELDS)})')
        try:
            _Parser(source).robot(data)
        except RecursionError:
            raise RobotDescriptionError(public) from None
        except RobotDescriptionError as exc:
            raise RobotDescriptionError(str(exc), public) from None
    try:
        return _Parser(source).robot(data)
    except RecursionError:  # a value nested so deeply that describing it recurses
        raise RobotDescriptionError(f'{source}: YAML nested too deeply to be a robot '
                                    f'description') from None


def _looks_like_description(data):
    """Say whether YAML data is a robot description at its top: then errors may quote it."""
    return isinstance(data, dict) and all(isinstance(k, str) and k in TOP_FIELDS for k in data) \
        and 'robot' in data and (all(k in data for k in ('base', 'chain')) or 'chains' in data)


class _Parser:
    """Walks the YAML data, converting units and raising one-line errors."""

    def __init__(self, source):
        self.source = source
        self.length = 1.0
        self.angle = 1.0

    def fail(self, where, message):
        prefix = f'{self.source}: {where}: ' if where else f'{self.source}: '
        raise RobotDescriptionError(prefix + message)

    # -- generic checks ------------------------------------------------------------------
    def mapping(self, value, where, allowed, required=()):
        if not isinstance(value, dict):
            self.fail(where, f'expected a mapping with fields {", ".join(allowed)}, '
                      f'got {_describe(value)}')
        for key in value:
            if key not in allowed:
                self.fail(where, f'unknown field {_short(key)}; allowed fields: '
                          f'{", ".join(allowed)}')
        for key in required:
            if key not in value:
                self.fail(where, f'missing field {key!r} (required: {", ".join(required)})')
        return value

    def number(self, value, where, field, unit=1.0):
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            self.fail(where, f'field {field!r} must be a number, got {_describe(value)}')
        try:
            scaled = float(value) * unit
        except OverflowError:  # an integer beyond the float range
            scaled = math.inf
        if not math.isfinite(scaled):
            self.fail(where, f'field {field!r} must be a finite number, got '
                      f'{_describe(value)}')
        return scaled

    def offset(self, value, where, field):
        """Return a length given in the file's unit in metres (at most :data:`MAX_LENGTH_M`)."""
        metres = self.number(value, where, field, self.length)
        if abs(metres) > MAX_LENGTH_M:
            self.fail(where, f'field {field!r} is {metres:g} m; offsets are at most '
                      f'{MAX_LENGTH_M:g} m')
        return metres

    def vector(self, value, where, field, size, unit=1.0):
        if not isinstance(value, list) or len(value) != size:
            self.fail(where, f'field {field!r} must be a list of {size} numbers, '
                      f'got {_describe(value)}')
        return [self.number(v, where, f'{field}[{k}]', unit) for k, v in enumerate(value)]

    def name(self, value, where, field, pattern, what):
        if not isinstance(value, str) or len(value) > MAX_NAME_CHARS or \
                not pattern.fullmatch(value):
            self.fail(where, f'field {field!r} must be {what} (at most {MAX_NAME_CHARS} '
                      f'characters), got {_describe(value)}')
        return value

    def frame(self, value, where, field='frame'):
        return self.name(value, where, field, TF_FRAME_ID,
                         'a tf2 frame id (printable ASCII without spaces, not starting with '
                         'a slash)')

    def choice(self, value, where, field, allowed):
        if not isinstance(value, str) or value not in allowed:
            self.fail(where, f'field {field!r} is {_short(value)}; allowed: {", ".join(allowed)}')
        return value

    # -- sections ------------------------------------------------------------------------
    def robot(self, data):
        data = self.mapping(data, '', TOP_FIELDS, required=('robot',))
        name = data['robot']
        if not isinstance(name, str) or not name.strip() or not name.isprintable() or \
                len(name) > MAX_NAME_CHARS:
            self.fail('', f"field 'robot' must be a non-empty name of printable characters "
                      f'(at most {MAX_NAME_CHARS}), got {_describe(name)}')
        text = data.get('description', '')
        if not isinstance(text, str) or len(text) > MAX_DESCRIPTION_CHARS or \
                not text.replace('\n', ' ').replace('\t', ' ').isprintable():
            self.fail('', f"field 'description' must be text of printable characters (at "
                      f'most {MAX_DESCRIPTION_CHARS}), got {_describe(text)}')
        convention = self.choice(data.get('convention', 'standard'), '', 'convention',
                                 CONVENTIONS)
        units = self.mapping(data.get('units', {}), 'units', UNIT_FIELDS)
        self.length = LENGTH_UNITS[self.choice(units.get('length', 'm'), 'units', 'length',
                                               tuple(LENGTH_UNITS))]
        self.angle = ANGLE_UNITS[self.choice(units.get('angle', 'rad'), 'units', 'angle',
                                             tuple(ANGLE_UNITS))]
        fixed_frame = self.frame(data.get('fixed_frame', 'world'), '', 'fixed_frame')
        seen = {fixed_frame: 'fixed_frame'}
        specs = self.chain_specs(data, fixed_frame, seen)
        link_rows = data.get('links', [])
        if not isinstance(link_rows, list):
            self.fail('links', f'expected a list of {{frame, parent, xyz, rpy | quaternion}}, '
                      f'got {_describe(link_rows)}')
        if len(link_rows) > MAX_ROWS:
            self.fail('links', f'{len(link_rows)} links; a robot description has at most '
                      f'{MAX_ROWS}')

        # the rigid body each frame moves with: a moving row starts a new one
        body = {fixed_frame: 0}
        frames, parents, moving = [], [], []
        for spec in specs:
            chain_frames = spec['frames']
            body[chain_frames[0]] = body[spec['parent']]
            for k, p in enumerate(spec['parsed']):
                body[p['frame']] = (spec['prefix'], k) if p['type'] != 'fixed' \
                    else body[chain_frames[k]]
            if spec['tool_frame']:
                body[spec['tool_frame']] = body[chain_frames[len(spec['parsed'])]]
            frames += chain_frames
            parents += [spec['parent']] + chain_frames[:-1]
            moving += [False] + [p['type'] != 'fixed' for p in spec['parsed']] + \
                ([False] if spec['tool_frame'] else [])
        links = []
        for k, row in enumerate(link_rows):
            link = self.link(row, k, seen)
            seen[link.frame] = f'links[{k}]'
            # a link that moves (a mimic) is a rigid body of its own
            body[link.frame] = body[link.parent] if link.motion is None else f'links[{k}]'
            links.append(link)
        end_effector = specs[0]['frames'][-1]
        if 'end_effector' in data:
            end_effector = self.frame(data['end_effector'], '', 'end_effector')
            if end_effector not in seen or end_effector == fixed_frame:
                self.fail('', f"field 'end_effector' names {end_effector!r}, which is not a "
                          f'frame of the robot; frames: {_listing(list(seen)[1:])}')

        chains = self.chains(specs, convention)
        chain = chains[0][1]
        branches = tuple(Branch(parent, c, external) for parent, c, external in chains[1:])
        joint_names = list(global_joint_names(chain, branches))
        for k, link in enumerate(links):
            if link.joint:
                if link.joint in joint_names:
                    self.fail(f'links[{k}] (frame {_short(link.frame)})',
                              f'joint {link.joint!r} is already a joint of the robot; joint '
                              f'names must be unique')
                joint_names.append(link.joint)
        for k, link in enumerate(links):
            if link.motion is not None and not link.joint and \
                    link.motion[2] not in joint_names:
                self.fail(f'links[{k}] (frame {_short(link.frame)}) mimic',
                          f"field 'joint' names {link.motion[2]!r}, which no row or link "
                          f'has; joints: {_listing(joint_names)}')
        velocity = {}
        for spec in specs:
            for p in spec['parsed']:
                velocity.update(p['velocity'])
        velocity.update((link.joint, link.max_velocity) for link in links if link.joint)
        moving += [body[link.frame] != body[link.tf_parent] for link in links]
        topics = {}
        for frame in frames + [link.frame for link in links]:
            topic = pose_topic_name(frame)
            if topic in topics:
                self.fail('', f'frames {topics[topic]!r} and {frame!r} would both publish on '
                          f'~/pose/{topic} (topic names take letters, digits and _); rename '
                          f'one')
            topics[topic] = frame
        return RobotModel(
            name=name, source=self.source, fixed_frame=fixed_frame,
            frame_names=tuple(frames + [link.frame for link in links]),
            parent_frames=tuple(parents + [link.tf_parent for link in links]),
            moving=tuple(moving), chain=chain,
            max_velocity=np.array([velocity.get(n, math.inf) for n in joint_names]),
            links=tuple(links), end_effector=end_effector, branches=branches)

    def chain_specs(self, data, fixed_frame, seen):
        """Parse ``base``/``chain``/``tool`` or ``chains``: one dict per chain, frames noted."""
        if 'chains' in data:
            for field in ('base', 'chain', 'tool'):
                if field in data:
                    self.fail('', f"field {field!r} goes inside an entry of 'chains' when the "
                              f"file has 'chains' (give either chains, or base and chain)")
            entries = data['chains']
            if not isinstance(entries, list) or not entries:
                self.fail('chains', f'expected a non-empty list of {{parent, base, chain, '
                          f'tool}}, got {_describe(entries)}')
            if len(entries) > MAX_ROWS:
                self.fail('chains', f'{len(entries)} chains; a robot description has at '
                          f'most {MAX_ROWS}')
            entries = [(self.mapping(e, f'chains[{c}]', CHAIN_FIELDS,
                                     required=('parent', 'base', 'chain')), f'chains[{c}].')
                       for c, e in enumerate(entries)]
        else:
            for field in ('base', 'chain'):
                if field not in data:
                    self.fail('', f'missing field {field!r} (required: robot, base, chain; '
                              f'or robot, chains)')
            entries = [({'parent': fixed_frame, **{f: data[f] for f in ('base', 'chain', 'tool')
                                                   if f in data}}, '')]
        specs, total = [], 0
        for c, (entry, prefix) in enumerate(entries):
            parent = self.frame(entry['parent'], prefix[:-1], 'parent')
            if c == 0 and parent != fixed_frame:
                self.fail(prefix[:-1], f"field 'parent' of the first chain must be the fixed "
                          f'frame {fixed_frame!r}, got {parent!r}')
            if parent not in seen:
                self.fail(prefix[:-1], f"field 'parent' names {parent!r}, which is not the "
                          f'fixed frame or a frame of an earlier chain; frames so far: '
                          f'{_listing(seen)}')
            base_frame, base = self.transform(entry['base'], prefix + 'base')
            rows = entry['chain']
            if not isinstance(rows, list) or not rows:
                self.fail(prefix + 'chain', f'expected a non-empty list of DH rows, got '
                          f'{_describe(rows)}')
            total += len(rows)
            if total > MAX_ROWS:
                self.fail(prefix + 'chain', f'{total} rows; a robot description has at most '
                          f'{MAX_ROWS}')
            parsed = [self.row(row, k, prefix) for k, row in enumerate(rows)]
            tool_frame, tool = (self.transform(entry['tool'], prefix + 'tool')
                                if 'tool' in entry else (None, None))
            frames = [base_frame] + [p['frame'] for p in parsed]
            if tool_frame:
                frames.append(tool_frame)
            places = [prefix + 'base'] + [p['where'] for p in parsed] + [prefix + 'tool']
            for frame, place in zip(frames, places):
                if frame in seen:
                    self.fail(place, f'frame {frame!r} is already used by {seen[frame]}; '
                              f'frame names must be unique')
                seen[frame] = place
            specs.append({'parent': parent, 'prefix': prefix, 'base': base, 'tool': tool,
                          'parsed': parsed, 'frames': frames, 'tool_frame': tool_frame})
        return specs

    def chains(self, specs, convention):
        """Return ``[(parent, KinematicChain, external variables), ...]`` of the specs."""
        owners, chain_of = {}, {}
        for c, spec in enumerate(specs):
            for p in spec['parsed']:
                for key in ('joint', 'd_joint'):
                    if key in p:
                        if p[key] in owners:
                            self.fail(p['where'], f'joint {p[key]!r} is already read by '
                                      f'{owners[p[key]]}; joint names must be unique')
                        owners[p[key]] = p['where']
                        chain_of[p[key]] = c
        out = []
        for c, spec in enumerate(specs):
            joints, external = [], []
            for p in spec['parsed']:
                follows, name = p.get('follows', ''), p.get('joint', '')
                if follows and follows not in owners:
                    self.fail(p['where'] + ' mimic', f"field 'joint' names {follows!r}, "
                              f'which no row reads; joints: {_listing(owners) or "none"}')
                if follows and chain_of[follows] != c:
                    if c == 0:
                        self.fail(p['where'] + ' mimic', f"field 'joint' names {follows!r}, "
                                  f"a joint of another chain; the first chain's rows mimic "
                                  f'its own joints')
                    if follows not in external:  # the row reads that joint's value itself
                        external.append(follows)
                        follows, name = '', follows
                limits = p.get('limits')
                if p['type'] == 'cylindrical':
                    limits = (limits, p.get('d_limits'))
                joints.append(DHJoint(
                    a=p['a'], alpha=p['alpha'], d=p['d'], theta=p['theta'],
                    joint_type=p['type'], scale=p['scale'], name=name,
                    d_name=p.get('d_joint', ''), follows=follows, limits=limits))
            try:
                chain = KinematicChain(joints, convention, base=spec['base'], tool=spec['tool'])
            except ValueError as exc:  # anything the core refuses that the checks missed
                self.fail(spec['prefix'] + 'chain', str(exc))
            out.append((spec['parent'], chain, tuple(external)))
        return out

    def link(self, row, k, seen):
        """One entry of ``links``: a frame fixed to an earlier frame (``seen``: name -> place)."""
        where = f'links[{k}]'
        if isinstance(row, dict) and isinstance(row.get('frame'), str):
            where = f"links[{k}] (frame {_short(row['frame'])})"
        row = self.mapping(row, where, LINK_FIELDS, required=('frame', 'parent'))
        frame, offset = self.transform({f: v for f, v in row.items() if f in TRANSFORM_FIELDS},
                                       where)
        if frame in seen:
            self.fail(where, f'frame {frame!r} is already used by {seen[frame]}; frame names '
                      f'must be unique')
        parents = {}
        for field in ('parent', 'tf_parent'):
            parents[field] = self.frame(row.get(field, row['parent']), where, field)
            if parents[field] not in seen:
                self.fail(where, f'field {field!r} names {parents[field]!r}, which is not an '
                          f'earlier frame; frames so far: {_listing(seen)}')
        kind = self.choice(row.get('type', 'fixed'), where, 'type', LINK_TYPES)
        if kind == 'fixed':
            for field in ('axis', 'joint', 'limits', 'max_velocity', 'mimic'):
                if field in row:
                    self.fail(where, f'field {field!r} applies only to a link of type revolute '
                              f'or prismatic')
            return LinkFrame(frame, parents['parent'], offset, parents['tf_parent'])
        if ('mimic' in row) == ('joint' in row):
            given = 'both' if 'mimic' in row else 'neither'
            self.fail(where, f"a {kind} link takes either 'joint' (a joint of its own) or "
                      f"'mimic' (moving with another joint), not {given}")
        axis = np.array(self.vector(row.get('axis', [0, 0, 1]), where, 'axis', 3))
        largest = float(np.max(np.abs(axis)))
        if not largest > 0.0 or not np.linalg.norm(axis / largest) * largest > 1e-9:
            self.fail(where, "field 'axis' must not be all zeros")
        axis = axis / largest  # no overflow for huge components
        axis = tuple((axis / np.linalg.norm(axis)).tolist())
        unit = self.length if kind == 'prismatic' else self.angle
        if 'joint' in row:
            joint = self.name(row['joint'], where, 'joint', JOINT_NAME, 'a joint name')
            speed = {}
            self.max_velocity(row, where, 'max_velocity', unit, joint, {'velocity': speed})
            return LinkFrame(frame, parents['parent'], offset, parents['tf_parent'],
                             (kind, axis, joint, 1.0, 0.0), joint,
                             self.limits(row, where, 'limits', unit) or (-math.inf, math.inf),
                             speed.get(joint, math.inf))
        for field in ('limits', 'max_velocity'):
            if field in row:
                self.fail(where, f"field {field!r} does not go with 'mimic' (the link moves "
                          f'with its source joint)')
        mimic = self.mapping(row['mimic'], where + ' mimic', MIMIC_FIELDS, required=('joint',))
        joint = self.name(mimic['joint'], where + ' mimic', 'joint', JOINT_NAME, 'a joint name')
        multiplier = self.number(mimic.get('multiplier', 1.0), where + ' mimic', 'multiplier')
        value_offset = self.number(mimic.get('offset', 0.0), where + ' mimic', 'offset', unit)
        return LinkFrame(frame, parents['parent'], offset, parents['tf_parent'],
                         (kind, axis, joint, multiplier, value_offset))

    def transform(self, value, where):
        value = self.mapping(value, where, TRANSFORM_FIELDS, required=('frame',))
        frame = self.frame(value['frame'], where)
        xyz = value.get('xyz', [0, 0, 0])
        self.vector(xyz, where, 'xyz', 3)
        xyz = [self.offset(v, where, f'xyz[{k}]') for k, v in enumerate(xyz)]
        if 'rpy' in value and 'quaternion' in value:
            self.fail(where, "give either 'rpy' or 'quaternion', not both")
        if 'quaternion' in value:
            xyzw = self.vector(value['quaternion'], where, 'quaternion', 4)
            largest = max(abs(c) for c in xyzw)
            if largest == 0.0 or math.sqrt(sum(c * c for c in xyzw)) < 1e-9:
                self.fail(where, "field 'quaternion' (x, y, z, w) must not be all zeros")
            xyzw = [c / largest for c in xyzw]  # no overflow for huge components
            norm = math.sqrt(sum(c * c for c in xyzw))
            rotation = (xyzw[3] / norm, xyzw[0] / norm, xyzw[1] / norm, xyzw[2] / norm)
        else:
            roll, pitch, yaw = self.vector(value.get('rpy', [0, 0, 0]), where, 'rpy', 3,
                                           self.angle)
            rotation = quat_from_matrix(rpy_matrix(roll, pitch, yaw))
        return frame, DualQuaternion.from_pose(rotation, xyz)

    def row(self, row, k, prefix=''):
        where = f'{prefix}chain[{k}]'
        if isinstance(row, dict) and isinstance(row.get('frame'), str):
            where = f"{prefix}chain[{k}] (frame {_short(row['frame'])})"
        row = self.mapping(row, where, ROW_FIELDS, required=('frame', 'theta', 'd', 'a',
                                                             'alpha'))
        frame = self.frame(row['frame'], where)
        kind = self.choice(row.get('type', 'revolute'), where, 'type', ROW_TYPES)
        out = {'frame': frame, 'type': kind, 'where': where, 'velocity': {},
               'theta': self.number(row['theta'], where, 'theta', self.angle),
               'd': self.offset(row['d'], where, 'd'),
               'a': self.offset(row['a'], where, 'a'),
               'alpha': self.number(row['alpha'], where, 'alpha', self.angle)}
        scale = self.number(row.get('scale', 1.0), where, 'scale')
        if scale == 0.0:
            self.fail(where, "field 'scale' must not be 0 (it multiplies the joint value)")
        out['scale'] = scale
        var_unit = self.length if kind == 'prismatic' else self.angle
        if kind == 'fixed':
            for field in ('joint', 'limits', 'max_velocity', 'mimic', 'd_joint', 'd_limits',
                          'd_max_velocity', 'scale'):
                if field in row:
                    self.fail(where, f'field {field!r} does not apply to a fixed row')
            return out
        if kind != 'cylindrical':
            for field in ('d_joint', 'd_limits', 'd_max_velocity'):
                if field in row:
                    self.fail(where, f'field {field!r} applies only to a cylindrical row')
        if 'mimic' in row:
            if kind == 'cylindrical':
                self.fail(where, "field 'mimic' does not apply to a cylindrical row")
            for field in ('joint', 'limits', 'max_velocity', 'scale'):
                if field in row:
                    self.fail(where, f"field {field!r} does not go with 'mimic' (the row "
                              f'moves with its source joint)')
            mimic = self.mapping(row['mimic'], where + ' mimic', MIMIC_FIELDS,
                                 required=('joint',))
            out['follows'] = self.name(mimic['joint'], where + ' mimic', 'joint', JOINT_NAME,
                                       'a joint name')
            out['scale'] = self.number(mimic.get('multiplier', 1.0), where + ' mimic',
                                       'multiplier')
            offset = self.number(mimic.get('offset', 0.0), where + ' mimic', 'offset',
                                 var_unit)
            out['theta' if kind == 'revolute' else 'd'] += offset
            return out
        if 'joint' not in row:
            self.fail(where, f"missing field 'joint' (the JointState name a {kind} row "
                      f"reads; or give 'mimic')")
        out['joint'] = self.name(row['joint'], where, 'joint', JOINT_NAME, 'a joint name')
        out['limits'] = self.limits(row, where, 'limits', var_unit)
        self.max_velocity(row, where, 'max_velocity', var_unit, out['joint'], out)
        if kind == 'cylindrical':
            if 'd_joint' not in row:
                self.fail(where, "missing field 'd_joint' (a cylindrical row reads two "
                          "joints: 'joint' for theta, 'd_joint' for d)")
            out['d_joint'] = self.name(row['d_joint'], where, 'd_joint', JOINT_NAME,
                                       'a joint name')
            out['d_limits'] = self.limits(row, where, 'd_limits', self.length)
            self.max_velocity(row, where, 'd_max_velocity', self.length, out['d_joint'], out)
        return out

    def limits(self, row, where, field, unit):
        if field not in row:
            return None
        lower, upper = self.vector(row[field], where, field, 2, unit)
        if lower > upper:
            self.fail(where, f'field {field!r} has lower {_short(row[field][0])} above upper '
                      f'{_short(row[field][1])}; give [lower, upper]')
        return (lower, upper)

    def max_velocity(self, row, where, field, unit, joint, out):
        if field not in row:
            return
        value = self.number(row[field], where, field, unit)
        if value <= 0.0:
            self.fail(where, f'field {field!r} must be a positive speed (per second), '
                      f'got {_short(row[field])}')
        out['velocity'][joint] = value


def pose_topic_name(frame):
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


def rpy_matrix(roll, pitch, yaw):
    """Rotation matrix of URDF's fixed-axis roll, pitch, yaw: ``Rz(yaw) Ry(pitch) Rx(roll)``."""
    cr, sr = math.cos(roll), math.sin(roll)
    cp, sp = math.cos(pitch), math.sin(pitch)
    cy, sy = math.cos(yaw), math.sin(yaw)
    return np.array([[cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
                     [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
                     [-sp, cp * sr, cp * cr]])


def _describe(value):
    """Describe a YAML value briefly for an error message (one line, at most ~80 chars)."""
    if value is None:
        return 'nothing'
    if isinstance(value, bool):
        return f'{value!r} (a boolean)'
    if isinstance(value, (dict, list)):
        kind = 'a mapping' if isinstance(value, dict) else f'a list of {len(value)}'
        return kind
    if isinstance(value, int) and abs(value) > 10**15:
        try:
            return f'an integer of {len(str(abs(value)))} digits'
        except ValueError:  # beyond Python's int-to-text limit
            return f'an integer of about {int(value.bit_length() * 0.30103)} digits'
    return f'{_short(value)} ({type(value).__name__})'


def _listing(names, at_most=20):
    """Join names for an error message: at most ``at_most`` of them, then how many more."""
    names = list(names)
    text = ', '.join(names[:at_most])
    return text + (f' ... ({len(names) - at_most} more)' if len(names) > at_most else '')


def printable_line(text, at_most=None):
    """Return ``text`` for one line of a message or log: every unprintable character as ``?``."""
    text = ''.join(c if c.isprintable() else '?' for c in str(text))
    return text if at_most is None else text[:at_most]


def _short(value):
    """``repr(value)``, shortened to about 60 characters."""
    text = repr(value)
    return text if len(text) <= 60 else text[:40] + '...' + text[-12:]


def shipped_robot_path(name):
    """
    Find a robot file shipped with the package by name, e.g. ``'rl15'``.

    Looks in the installed share directory (colcon) first, then in the source tree's
    ``config/`` (an editable install).
    """
    filename = name if name.endswith('.yaml') else name + '.yaml'
    candidates = []
    try:
        from ament_index_python.packages import get_package_share_directory
        candidates.append(os.path.join(get_package_share_directory('dq_fk_ros'), 'config'))
    except Exception:  # not installed through ament (or ament_index missing): source tree
        pass
    source_tree = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    candidates.append(os.path.join(source_tree, 'config'))
    for folder in candidates:
        path = os.path.join(folder, filename)
        if os.path.isfile(path):
            return path
    raise FileNotFoundError(f'no shipped robot {filename!r} in {" or ".join(candidates)}')


def shipped_robots():
    """List the names of the robot files shipped in ``config/``."""
    folder = os.path.dirname(shipped_robot_path('rl15'))
    return sorted(f[:-5] for f in os.listdir(folder) if f.endswith('.yaml'))
