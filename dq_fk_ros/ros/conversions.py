"""
The one place where kinematics become ROS messages, and ROS messages become numbers.

Poses arrive as tuples ``(x, y, z, qx, qy, qz, qw)`` (metres, the ROS quaternion order,
``qw >= 0``) from :meth:`dq_fk_ros.description.robot_model.RobotModel.frame_poses`.
:class:`FrameMessages` builds the messages of one robot once as message objects;
:class:`FrameBytes` writes the same messages already serialized (CDR, the bytes
``rclpy.serialization.serialize_message`` gives), packed for every update, for
``Publisher.publish(bytes)``: the node's hot path (a test holds the two equal, byte for
byte).
"""

from builtin_interfaces.msg import Time
from dq_fk_ros.description.to_urdf import HelperFrames
from dq_fk_ros.messages.cdr import (
    pose_stamped_template, tf_message_template, twist_stamped_template)
from geometry_msgs.msg import PoseStamped, TransformStamped, TwistStamped
from tf2_msgs.msg import TFMessage

NS_PER_S = 1_000_000_000


def stamp_to_ns(stamp):
    """Return the nanoseconds of a ``builtin_interfaces/Time``."""
    return stamp.sec * NS_PER_S + stamp.nanosec


def ns_to_stamp(ns):
    """Return a ``builtin_interfaces/Time`` of ``ns`` nanoseconds."""
    return Time(sec=ns // NS_PER_S, nanosec=ns % NS_PER_S)


def joint_state_fields(msg):
    """Return names, positions, velocities and stamp (ns) of a ``sensor_msgs/JointState``."""
    return msg.name, msg.position, msg.velocity, stamp_to_ns(msg.header.stamp)


def set_transform(transform, pose):
    """Fill a ``geometry_msgs/Transform`` from ``(x, y, z, qx, qy, qz, qw)``."""
    t, r = transform.translation, transform.rotation
    t.x, t.y, t.z, r.x, r.y, r.z, r.w = pose


def set_pose(msg_pose, pose):
    """Fill a ``geometry_msgs/Pose`` from ``(x, y, z, qx, qy, qz, qw)``."""
    p, r = msg_pose.position, msg_pose.orientation
    p.x, p.y, p.z, r.x, r.y, r.z, r.w = pose


class FrameMessages:
    """
    The messages of one robot model under one ``frame_prefix``, built once, refilled often.

    ``frame_prefix`` is prepended to every frame id the model names, except a DH file's
    fixed frame, so that several robots hang in one TF tree under a shared world frame (a
    URDF's root link is prefixed too, as robot_state_publisher does:
    :meth:`RobotModel.tf_frame_id`). The
    URDF's helper links (:class:`~dq_fk_ros.description.to_urdf.HelperFrames`) are published
    as children of their DH frames: constant ones on /tf_static, moving ones on /tf.
    """

    def __init__(self, model, frame_prefix='', shown_optional=(), helpers=None):
        """
        Build the message objects for ``model``.

        :param shown_optional: the optional joints (side branches, a tree's) named so far:
            transforms and poses that need others are left out (``hidden``).
        :param helpers: the model's :class:`HelperFrames` if already made (they depend on
            the model alone; making them for a big robot takes tens of ms).
        """
        self.model = model
        self.prefix = frame_prefix
        self.fixed_frame_id = fixed = model.tf_frame_id(model.fixed_frame, frame_prefix)
        self.frame_ids = [frame_prefix + name for name in model.frame_names]
        self._parent_ids = [model.tf_frame_id(p, frame_prefix) for p in model.parent_frames]
        self.hidden = hidden_frames(model, shown_optional)
        # moving TF transforms: DH rows and links on other bodies than their TF parents,
        # those whose joints are known (robot_state_publisher's rule)
        hidden_edges = hidden_frames(model, shown_optional, model.edge_needs)
        self.moving_edges = tuple(e for e in model.moving_edges if e[0] not in hidden_edges)
        self.helpers = HelperFrames(model) if helpers is None else helpers
        self.tf = TFMessage(transforms=[
            _transform_stamped(self._parent_ids[k], self.frame_ids[k])
            for k, _ in self.moving_edges] + [
            _transform_stamped(self.frame_ids[anchor], frame_prefix + name)
            for name, anchor in self.helpers.moving])
        self._helper_transforms = self.tf.transforms[len(self.moving_edges):]
        self.poses = []
        for _ in self.frame_ids:
            msg = PoseStamped()
            msg.header.frame_id = fixed
            self.poses.append(msg)
        # the chain's end and, if there is one, the tool; and the end effector if a link
        n_chain = model.n_chain_frames
        self.twist_frames = list(range(n_chain))[-1 - (model.chain.tool is not None):]
        if model.end_effector_index >= n_chain:
            self.twist_frames.append(model.end_effector_index)
        self.twists = []
        for _ in self.twist_frames:
            msg = TwistStamped()
            msg.header.frame_id = fixed
            self.twists.append(msg)

    def fill(self, stamp, absolute, relative, q=None):
        """Refill /tf and pose messages for one update at joints ``q``; ``(tf, poses)``."""
        for transform, (_, k) in zip(self.tf.transforms, self.moving_edges):
            transform.header.stamp = stamp
            set_transform(transform.transform, relative[k])
        if self._helper_transforms:
            for transform, pose in zip(self._helper_transforms, self.helpers.moving_poses(q)):
                transform.header.stamp = stamp
                set_transform(transform.transform, [float(v) for v in pose])
        for msg, pose in zip(self.poses, absolute):
            msg.header.stamp = stamp
            set_pose(msg.pose, pose)
        return self.tf, self.poses

    def fill_twists(self, stamp, twists):
        """Refill the twist messages from ``[(v, omega), ...]`` in fixed-frame axes."""
        for msg, (v, w) in zip(self.twists, twists):
            msg.header.stamp = stamp
            lin, ang = msg.twist.linear, msg.twist.angular
            lin.x, lin.y, lin.z = (float(c) for c in v)
            ang.x, ang.y, ang.z = (float(c) for c in w)
        return self.twists

    def static_tf(self, stamp):
        """Return one TFMessage with every static transform: base, fixed rows, tool, links."""
        transforms = [_transform_stamped(self._parent_ids[k], self.frame_ids[k], stamp, pose)
                      for k, pose in self.model.static_transforms()]
        for name, anchor, offset in self.helpers.static:
            transforms.append(_transform_stamped(self.frame_ids[anchor], self.prefix + name, stamp,
                                                 offset.to_pose_xyzw()))
        return TFMessage(transforms=transforms)


def hidden_frames(model, shown_optional, needs=None):
    """
    Return the indices of the frames that need an optional joint not in ``shown_optional``.

    :param needs: per frame, the joints it needs: ``model.frame_needs`` (default: its pose
        in the fixed frame) or ``model.edge_needs`` (its TF transform).
    """
    if not model.optional_joints:
        return frozenset()
    shown = frozenset(shown_optional)
    needs = model.frame_needs if needs is None else needs
    return frozenset(k for k, need in enumerate(needs) if not need <= shown)


def _transform_stamped(parent, child, stamp=None, pose=None):
    msg = TransformStamped()
    msg.header.frame_id = parent
    msg.child_frame_id = child
    if stamp is not None:
        msg.header.stamp = stamp
    if pose is not None:
        set_transform(msg.transform, [float(v) for v in pose])
    return msg


class FrameBytes:
    """
    The node's /tf, pose and twist messages of one robot, serialized per update.

    The fast path; the reference is :class:`FrameMessages` (rclpy's message objects), held
    equal byte for byte by test_frame_bytes.py's
    ``test_serialized_output_equals_the_message_objects``.

    Each message's fixed bytes (frame ids, padding) are laid out once; an update packs them
    with its stamp and float64 fields in one ``struct`` call
    (:class:`~dq_fk_ros.messages.cdr.CdrPacker`) and hands ``bytes`` to
    ``Publisher.publish``. The same messages as :class:`FrameMessages`, byte for byte.
    """

    def __init__(self, messages):
        """Lay out the messages of a :class:`FrameMessages` (same robot, same prefix)."""
        self.helpers = messages.helpers
        self.moving_edges = messages.moving_edges
        self._moving = [k for _, k in self.moving_edges]
        self.sends_tf = bool(messages.tf.transforms)  # a robot with nothing moving: no /tf
        edges = [(t.header.frame_id, t.child_frame_id) for t in messages.tf.transforms]
        tf = tf_message_template(edges)
        pose = pose_stamped_template(messages.fixed_frame_id)
        twist = twist_stamped_template(messages.fixed_frame_id)
        self.templates = {'tf': tf, 'pose': pose, 'twist': twist}  # layouts, for the tests
        self._tf = tf.packer()
        self._pose = pose.packer()
        self._twist = twist.packer()

    def tf(self, sec, nanosec, relative, q=None):
        """Return the serialized /tf message: every moving row's (and helper's) transform."""
        poses = [relative[k] for k in self._moving]
        if self.helpers.moving:
            poses += self.helpers.moving_poses(q)
        return self._tf.pack(sec, nanosec, poses)

    def pose(self, sec, nanosec, pose):
        """Return a serialized PoseStamped of ``pose`` in the fixed frame."""
        return self._pose.pack(sec, nanosec, (pose,))

    def poses(self, sec, nanosec, absolute, frames):
        """Return serialized PoseStampeds of the poses ``absolute[k]`` for k in ``frames``."""
        pack = self._pose.pack
        return [pack(sec, nanosec, (absolute[k],)) for k in frames]

    def twist(self, sec, nanosec, v, w):
        """Return a serialized TwistStamped: linear ``v``, angular ``w`` (fixed-frame axes)."""
        return self._twist.pack(sec, nanosec, (v, w))
