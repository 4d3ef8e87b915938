"""
A URDF equivalent to a :class:`~dq_fk_ros.description.robot_model.RobotModel` (RViz).

Links are named after the frames the package publishes, so RViz draws the robot from the
TF this package sends (no robot_state_publisher needed). A moving DH row ``pre * Z(q) *
post`` becomes a URDF joint with origin ``pre * Rz(theta0) Tz(d0)`` and axis z, and, where
``post`` is not the identity, a helper link ``<frame>_dh_z`` plus a fixed joint with origin
``post``; standard DH has ``post = Tx(a) Rx(alpha)``, modified DH ``pre = Rx(alpha) Tx(a)``.
Every constant joint offset is drawn as a thin cylinder in its parent link.
"""

from collections.abc import Sequence
from dataclasses import dataclass, replace
import math
import re

from dq_fk_ros.description.robot_model import RobotModel
from dq_fk_ros.kinematics.dual_quaternion import DualQuaternion
import numpy as np
from numpy.typing import ArrayLike

LINK_RADIUS_M = 0.02
# an XML attribute's value between double quotes, as xml.sax.saxutils.quoteattr escapes it
# (that module imports urllib and http.client: ~25 ms at every start of a command)
_ATTRIBUTE = str.maketrans({'&': '&amp;', '<': '&lt;', '>': '&gt;', '"': '&quot;',
                            '\n': '&#10;', '\r': '&#13;', '\t': '&#9;'})
# Frames that exist for the DH method only: the DH frames `dq_fk from-urdf` names (dh0...,
# dh_0..., dq_fk_dh0..., <tip>_dh0... of the other chains, dq_fk_chain<k>_dh0...) and the
# helper links of the URDF written here (<frame>_dh_z, _dh_z0, _dh_x). The view and the plot
# hide them by default; web/app.js has the same pattern (HELPER_FRAME).
HELPER_FRAME = re.compile(r'^(dh|dh_|dq_fk_dh)\d+$|_dh_z\d*$|_dh_x$|_(dh|dh_|dq_fk_dh)\d+$'
                          r'|^dq_fk_chain\d+_dh\d+$')


def is_helper_frame(name: str) -> bool:
    """Say whether frame ``name`` exists for the DH method only (:data:`HELPER_FRAME`)."""
    return HELPER_FRAME.search(name) is not None


def _xml_attribute(text: str) -> str:
    """Return ``text`` as a double-quoted XML attribute value (escaped: :data:`_ATTRIBUTE`)."""
    return '"' + text.translate(_ATTRIBUTE) + '"'


def _rot_x(alpha):
    return DualQuaternion.from_rotation([1.0, 0.0, 0.0], alpha)


def _rot_z(theta):
    return DualQuaternion.from_rotation([0.0, 0.0, 1.0], theta)


def _tx(a):
    return DualQuaternion.from_translation([a, 0.0, 0.0])


def _tz(d):
    return DualQuaternion.from_translation([0.0, 0.0, d])


def matrix_to_rpy(m: np.ndarray) -> tuple[float, float, float]:
    """URDF roll, pitch, yaw of a rotation matrix (``R = Rz(yaw) Ry(pitch) Rx(roll)``)."""
    pitch = math.atan2(-m[2, 0], math.hypot(m[0, 0], m[1, 0]))
    if math.hypot(m[0, 0], m[1, 0]) < 1e-12:  # gimbal lock: put everything in yaw
        return 0.0, pitch, math.atan2(-m[0, 1], m[1, 1])
    return math.atan2(m[2, 1], m[2, 2]), pitch, math.atan2(m[1, 0], m[0, 0])


def _origin(pose):
    m = pose.to_matrix()
    xyz = ' '.join(_num(v) for v in m[:3, 3])
    rpy = ' '.join(_num(v) for v in matrix_to_rpy(m[:3, :3]))
    return f'<origin xyz="{xyz}" rpy="{rpy}"/>'


def _num(value):
    value = float(value)
    return '0' if value == 0.0 else repr(value)


# URDF requires finite effort and velocity limits on every revolute and prismatic joint, and
# finite position limits on a prismatic one (urdfdom, hence pinocchio, refuses 'inf'). Where
# the DH description gives none, these stand for "no limit known" (README, docs).
NO_LIMIT_SPEED = 1e9            # rad/s or m/s, and N or Nm for effort (never in a DH table)
NO_LIMIT_STROKE_M = 1e3         # +- this, for a prismatic joint without limits


@dataclass(frozen=True)
class UrdfJoint:
    """
    One URDF joint of a robot: what :func:`robot_to_urdf` writes and the node publishes.

    ``origin`` is the joint frame in the parent link (a :class:`DualQuaternion`); ``kind``
    is ``fixed``, ``revolute``, ``continuous``, ``prismatic`` or ``floating`` (a floating
    link's, at its origin); ``variable`` names the
    joint value that moves it (the followed joint for a mimic joint); ``limits`` is
    ``(lower, upper, velocity, effort)`` or None; ``mimic`` is ``(joint, multiplier)`` or
    ``(joint, multiplier, offset)``.
    ``anchor`` is the index (in ``model.frame_names``) of the DH frame a helper link
    belongs to, or None when ``child`` is itself a published frame.
    """

    name: str
    kind: str
    parent: str
    child: str
    origin: DualQuaternion
    axis: tuple = None
    limits: tuple = None
    mimic: tuple = None
    variable: str = None
    anchor: int = None
    note: str = ''


def urdf_joints(model: RobotModel) -> list['UrdfJoint']:
    """
    Return the URDF joints of ``model`` in tree order (parents before children).

    Links are the published frames plus, where a DH row's motion is not the last factor
    of its operator (``post`` not identity: standard DH with ``a`` or ``alpha``), a helper
    link ``<frame>_dh_z`` (and ``<frame>_dh_z0`` for the first of a cylindrical row's two
    motions) between the row's parent frame and its frame.
    """
    joints = []
    velocity = dict(zip(model.joint_names, model.max_velocity))
    limits = dict(zip(model.joint_names, model.limits.tolist()))
    for branch, (parent, chain, start) in zip((None,) + model.branches, model.chains):
        external = branch.external if branch is not None else ()
        joints += _chain_joints(model, chain, start, parent, external, velocity, limits)
    for link in model.links:  # fixed to the frame they are attached to, or its mimic
        if link.motion is None:  # (a floating one at its origin: the URDF it came from)
            kind = 'floating' if link.floating else 'fixed'
            joints.append(UrdfJoint(f'{link.frame}_{kind}', kind, link.parent, link.frame,
                                    link.offset))
            continue
        kind, axis, variable, multiplier, offset = link.motion
        lower, upper = link.limits
        bounded = math.isfinite(lower) and math.isfinite(upper)
        speed = link.max_velocity if math.isfinite(link.max_velocity) else NO_LIMIT_SPEED
        limits = None
        if link.joint and bounded:
            limits = (float(lower), float(upper), float(speed), NO_LIMIT_SPEED)
        elif kind == 'prismatic':
            limits = (-NO_LIMIT_STROKE_M, NO_LIMIT_STROKE_M, float(speed), NO_LIMIT_SPEED)
        joints.append(UrdfJoint(
            link.joint or f'{link.frame}_joint', kind if limits else 'continuous', link.parent,
            link.frame, link.offset, axis, limits,
            None if link.joint else (variable, multiplier, offset), variable))
    return joints


def _chain_joints(model, chain, start, parent_frame, external, velocity, limits):
    """Return the URDF joints of one chain: its base, rows (and helper links), tool."""
    names = model.frame_names[start:start + chain.n_frames]
    joints = [UrdfJoint(f'{names[0]}_fixed', 'fixed', parent_frame, names[0], chain.base)]
    modified = chain.convention == 'modified'
    for i, joint in enumerate(chain.joints):
        parent, child = names[i], names[i + 1]
        if joint.name in external:  # a row mimicking another chain's joint
            joint = replace(joint, follows=joint.name)
        pre = (_rot_x(joint.alpha) * _tx(joint.a)) if modified else DualQuaternion.identity()
        post = DualQuaternion.identity() if modified else (_tx(joint.a) * _rot_x(joint.alpha))
        if joint.joint_type == 'fixed':
            joints.append(UrdfJoint(f'{child}_fixed', 'fixed', parent, child,
                                    pre * _rot_z(joint.theta) * _tz(joint.d) * post))
            continue
        if abs(abs(joint.scale) - 1.0) > 1e-12 and not joint.follows:
            raise ValueError(f'{model.source}: row {i} (frame {child!r}) has scale '
                             f'{joint.scale}; a URDF joint can only express scale +-1')
        sign = math.copysign(1.0, joint.scale)
        motions = []
        if joint.joint_type in ('revolute', 'cylindrical'):
            motions.append(('revolute', joint.follows or joint.name))
        if joint.joint_type in ('prismatic', 'cylindrical'):
            motions.append(('prismatic', joint.follows or (joint.d_name if joint.joint_type
                                                           == 'cylindrical' else joint.name)))
        has_post = not post.isclose(DualQuaternion.identity(), atol=1e-15)
        link = parent
        origin = pre * _rot_z(joint.theta) * _tz(joint.d)
        for k, (kind, variable) in enumerate(motions):
            last = k == len(motions) - 1
            target = child if last and not has_post else f'{child}_dh_z{"" if last else k}'
            if joint.follows:
                name, mimic, axis = f'{child}_joint', (joint.follows, joint.scale), (0, 0, 1.0)
                lower, upper = np.sort(joint.scale * np.asarray(limits[variable]))
            else:
                name, mimic, axis = variable, None, (0.0, 0.0, sign)
                lower, upper = limits[variable]
            anchor = None if target == child else start + i + 1
            bounded = math.isfinite(lower) and math.isfinite(upper)
            note = ''
            if kind == 'revolute' and not bounded:
                joints.append(UrdfJoint(name, 'continuous', link, target, origin, axis,
                                        mimic=mimic, variable=variable, anchor=anchor))
            else:
                if not bounded:
                    lower, upper = -NO_LIMIT_STROKE_M, NO_LIMIT_STROKE_M
                    note = (f'no limits in the description: +-{NO_LIMIT_STROKE_M:g} m stands '
                            f'for none (URDF needs finite ones)')
                speed = velocity.get(joint.follows or variable, math.inf)
                if not math.isfinite(speed):
                    speed = NO_LIMIT_SPEED
                joints.append(UrdfJoint(name, kind, link, target, origin, axis,
                                        (float(lower), float(upper), float(speed),
                                         NO_LIMIT_SPEED), mimic, variable, anchor, note))
            link, origin = target, DualQuaternion.identity()
        if has_post:
            joints.append(UrdfJoint(f'{child}_dh_x', 'fixed', link, child, post))
    if chain.tool is not None:
        joints.append(UrdfJoint(f'{names[-1]}_fixed', 'fixed', names[-2], names[-1], chain.tool))
    return joints


def link_poses(model: RobotModel, q: ArrayLike,
               joints: Sequence['UrdfJoint'] | None = None) -> dict[str, DualQuaternion]:
    """
    Return ``{link: DualQuaternion}``: every URDF link's pose in the fixed frame at ``q``.

    Composed from the URDF joints (origin, then the motion about or along the axis), as a
    URDF consumer such as robot_state_publisher would; ``q`` in chain order.
    """
    joints = urdf_joints(model) if joints is None else joints
    value = dict(zip(model.joint_names, np.asarray(q, dtype=float).tolist()))
    poses = {model.fixed_frame: DualQuaternion.identity()}
    for j in joints:
        pose = poses[j.parent] * j.origin
        if j.kind not in ('fixed', 'floating'):  # a floating joint at its origin
            amount = value[j.variable] * (j.mimic[1] if j.mimic else 1.0) + \
                (j.mimic[2] if j.mimic and len(j.mimic) > 2 else 0.0)
            if j.kind == 'prismatic':
                pose = pose * DualQuaternion.from_translation(np.multiply(j.axis, amount))
            else:
                pose = pose * DualQuaternion.from_rotation(j.axis, amount)
        poses[j.child] = pose
    return poses


class HelperFrames:
    """
    The URDF's helper links as TF frames: each a child of the DH frame it belongs to.

    ``static``: ``(helper, frame index, DualQuaternion)`` whose offset from the DH frame is
    constant (sent once on /tf_static); ``moving``: ``(helper, frame index)`` whose offset
    depends on the joints (a cylindrical row's first motion; sent on /tf with every update,
    :meth:`moving_poses`). Publishing them keeps the tree of the DH frames as it is
    (``eeCarry_seg6`` under ``wrist_seg5``) and gives every URDF link a transform.
    """

    def __init__(self, model: RobotModel, enabled: bool = True):
        """Find the helper links of ``model``'s URDF and their offsets (none if not enabled)."""
        self.model = model
        self.static, self.moving = [], []
        if not enabled:
            return
        try:
            self._joints = urdf_joints(model)
        except ValueError:  # no URDF for this robot (a scale other than +-1): no helpers
            return
        # a helper ends one motion of its row; only the row's last motion's helper is fixed
        # to the DH frame (the fixed 'post' transform follows it)
        zero = link_poses(model, np.zeros(model.dof), self._joints)
        for name, anchor in ((j.child, j.anchor) for j in self._joints
                             if j.anchor is not None):
            if name.endswith('_dh_z'):
                frame = model.frame_names[anchor]
                self.static.append((name, anchor, zero[frame].inverse() * zero[name]))
            else:
                self.moving.append((name, anchor))

    def moving_poses(self, q: ArrayLike) -> list[np.ndarray]:
        """Return the offsets ``(x, y, z, qx, qy, qz, qw)`` of the moving helpers at ``q``."""
        if not self.moving:
            return []
        poses = link_poses(self.model, q, self._joints)
        names = self.model.frame_names
        return [(poses[names[anchor]].inverse() * poses[name]).to_pose_xyzw()
                for name, anchor in self.moving]


def robot_to_urdf(model: RobotModel) -> str:
    """Return URDF XML text for ``model``; joint names are the model's joint names."""
    links = {model.fixed_frame: []}
    lines = []
    for j in urdf_joints(model):  # parents before children: every parent is known
        links.setdefault(j.child, [])
        out = [f'  <joint name={_xml_attribute(j.name)} type="{j.kind}">']
        if j.note:
            out.insert(0, f'  <!-- {j.note} -->')
        out += [f'    <parent link={_xml_attribute(j.parent)}/>',
                f'    <child link={_xml_attribute(j.child)}/>',
                f'    {_origin(j.origin)}']
        if j.axis is not None:
            out.append(f'    <axis xyz="{" ".join(_num(v) for v in j.axis)}"/>')
        if j.limits is not None:
            lower, upper, velocity, effort = j.limits
            out.append(f'    <limit lower="{_num(lower)}" upper="{_num(upper)}" '
                       f'effort="{_num(effort)}" velocity="{_num(velocity)}"/>')
        if j.mimic is not None:
            offset = j.mimic[2] if len(j.mimic) > 2 else 0.0
            out.append(f'    <mimic joint={_xml_attribute(j.mimic[0])} '
                       f'multiplier="{_num(j.mimic[1])}" offset="{_num(offset)}"/>')
        out.append('  </joint>')
        lines.append('\n'.join(out))
        segment = _segment(j.origin)
        if segment:
            links[j.parent].append(segment)
    out = ['<?xml version="1.0"?>',
           '<!-- Generated by dq_fk_ros from a DH robot description (dq_fk urdf). Velocity '
           f'and effort limits of {_num(NO_LIMIT_SPEED)} stand for "none given". -->',
           f'<robot name={_xml_attribute(model.name)}>',
           '  <material name="dq_fk_grey"><color rgba="0.6 0.6 0.65 1"/></material>']
    for name, visuals in links.items():
        if visuals:
            out += [f'  <link name={_xml_attribute(name)}>'] + visuals + ['  </link>']
        else:
            out.append(f'  <link name={_xml_attribute(name)}/>')
    return '\n'.join(out + lines + ['</robot>']) + '\n'


def description_urdf(model: RobotModel) -> str:
    """
    Return the URDF to publish as ``robot_description`` for ``model``.

    The URDF a robot was converted from (its meshes and names as the vendor wrote them),
    else :func:`robot_to_urdf`'s (ValueError if a URDF cannot express the robot).
    """
    return model.urdf if model.urdf is not None else robot_to_urdf(model)


def link_segments(model: RobotModel, q: ArrayLike,
                  joints: Sequence['UrdfJoint'] | None = None) -> list[tuple]:
    """
    Return ``[(start, end), ...]``: the segments the URDF draws, in the fixed frame at ``q``.

    One per joint with a non-zero origin offset: from the parent link's origin to the
    joint's origin (the cylinders of :func:`robot_to_urdf`).
    """
    joints = urdf_joints(model) if joints is None else joints
    poses = link_poses(model, q, joints)
    segments = []
    for j in joints:
        if np.linalg.norm(j.origin.translation) > 1e-9:
            segments.append((poses[j.parent].translation,
                             (poses[j.parent] * j.origin).translation))
    return segments


def _segment(origin):
    """Return the visual cylinder along a joint origin's offset (parent link), or None."""
    t = origin.translation
    length = float(np.linalg.norm(t))
    if length < 1e-9:
        return None
    z = t / length
    # rotation taking the cylinder's z axis onto t
    axis = np.cross([0.0, 0.0, 1.0], z)
    angle = math.atan2(np.linalg.norm(axis), z[2])
    rot = (DualQuaternion.from_rotation(axis, angle) if np.linalg.norm(axis) > 1e-12
           else _rot_x(math.pi if z[2] < 0 else 0.0))
    pose = DualQuaternion.from_pose(rot.real, t / 2)
    return (f'    <visual>\n      {_origin(pose)}\n      <geometry><cylinder '
            f'radius="{_num(LINK_RADIUS_M)}" length="{_num(length)}"/></geometry>\n'
            f'      <material name="dq_fk_grey"/>\n    </visual>')


__all__ = ['description_urdf', 'HELPER_FRAME', 'HelperFrames', 'is_helper_frame', 'link_poses',
           'link_segments', 'matrix_to_rpy', 'robot_to_urdf', 'urdf_joints', 'UrdfJoint']
