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

Its forward kinematics are those of :class:`~dq_fk_ros.kinematics.tree_kinematics.
TreeKinematics` (``RobotModel.kinematics``), which holds the fast paths and their references.
"""

from collections.abc import Sequence
from dataclasses import dataclass
from functools import cached_property
import math
import re

from dq_fk_ros.description.joint_needs import edge_needs_of, frame_needs_of
from dq_fk_ros.kinematics.dh import KinematicChain
from dq_fk_ros.kinematics.dual_quaternion import DualQuaternion, Pose
from dq_fk_ros.kinematics.tree_kinematics import TreeKinematics
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
            for name, angle in zip(chain.joint_names, chain.table.angular):
                if angle and name not in external:
                    mask[index[name]] = True
        for link in self.links:
            if link.joint and link.motion[0] == 'revolute':
                mask[index[link.joint]] = True
        return mask

    @cached_property
    def frame_needs(self) -> tuple[frozenset, ...]:
        """Per frame: the optional joints its pose in the fixed frame depends on (frozensets)."""
        return frame_needs_of(self)

    @cached_property
    def edge_needs(self) -> tuple[frozenset, ...]:
        """Per frame: the optional joints its TF transform depends on (:mod:`.joint_needs`)."""
        return edge_needs_of(self)

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

    # -- forward kinematics: the tree's engine (kinematics/tree_kinematics.py) ------------
    @cached_property
    def kinematics(self) -> TreeKinematics:
        """Return the FK engine of this tree of chains and links (fast and reference paths)."""
        return TreeKinematics(self.chain, self._branch_plan, self._link_plan, self.joint_names)

    def frame_poses(self, q: ArrayLike) -> tuple[list[Pose], list[Pose]]:
        """
        Return every frame of ``frame_names`` in the fixed frame and the TF transforms.

        ``(absolute, relative)``, tuples ``(x, y, z, qx, qy, qz, qw)``: see
        :meth:`TreeKinematics.frame_poses` (DH rows chain by chain, then the links).
        """
        return self.kinematics.frame_poses(q)

    def frame_poses_code(self) -> str:
        """Return the Python source of :meth:`frame_poses`' straight-line code (generated)."""
        return self.kinematics.frame_poses_code()

    def frame_poses_general(self, q: ArrayLike) -> tuple[list[Pose], list[Pose]]:
        """Return :meth:`frame_poses` by the reference path (``TreeKinematics``'s)."""
        return self.kinematics.frame_poses_general(q)

    def frame_pose_arrays(self, q: ArrayLike, absolute: np.ndarray | None = None,
                          relative: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Return :meth:`frame_poses` as float64 arrays (``TreeKinematics``'s)."""
        return self.kinematics.frame_pose_arrays(q, absolute, relative)

    def transform_pose_array(self, q: ArrayLike,
                             relative: np.ndarray | None = None) -> np.ndarray:
        """Return the TF transforms alone as one array (``TreeKinematics``'s)."""
        return self.kinematics.transform_pose_array(q, relative)

    def frame_pose_arrays_batch(self, q: ArrayLike, out: tuple | None = None
                                ) -> tuple[np.ndarray, np.ndarray]:
        """Return :meth:`frame_pose_arrays` for N configurations (``TreeKinematics``'s)."""
        return self.kinematics.frame_pose_arrays_batch(q, out)

    @property
    def n_transforms(self) -> int:
        """Count the TF transforms of :meth:`frame_poses`' relative: DH rows, then links."""
        return self.kinematics.n_transforms

    def transform_poses(self, q: ArrayLike) -> list[Pose]:
        """Return the TF transforms of :meth:`frame_poses` alone (``TreeKinematics``'s)."""
        return self.kinematics.transform_poses(q)

    def forward_all(self, q: ArrayLike) -> np.ndarray:
        """Every frame of ``frame_names`` in the fixed frame: ``(n, 8)``, ``w >= 0``."""
        return self.kinematics.forward_all(q)

    def forward_all_batch(self, q: ArrayLike) -> np.ndarray:
        """Every frame of ``frame_names`` for N configurations: ``(N, n, 8)``, ``w >= 0``."""
        return self.kinematics.forward_all_batch(q)

    def end_effector_batch(self, q: ArrayLike) -> np.ndarray:
        """Return the end effector's pose for N configurations: ``(N, 8)``, ``w >= 0``."""
        k = self.end_effector_index
        if k == self.n_chain_frames - 1:
            return self.chain.forward_batch(np.asarray(q, dtype=float)[:, :self.chain.dof])
        return self.forward_all_batch(q)[:, k]

    def relative_batch(self, q: ArrayLike) -> np.ndarray:
        """``frame_poses``' relative transforms for N configurations: ``(N, rows + links, 8)``."""
        return self.kinematics.relative_batch(q)

    def __getstate__(self) -> dict:
        """Pickle without the engine (made again on use, with its kernel copy)."""
        state = dict(self.__dict__)
        state.pop('kinematics', None)
        return state

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


def global_joint_names(chain: KinematicChain, branches: Sequence = (),
                       links: Sequence = ()) -> tuple[str, ...]:
    """Name the joints of ``q``: ``chain``'s, each branch's own, then the links' own."""
    names = list(chain.joint_names)
    for branch in branches:
        names += [n for n in branch.chain.joint_names if n not in branch.external]
    return tuple(names) + tuple(link.joint for link in links if link.joint)


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
