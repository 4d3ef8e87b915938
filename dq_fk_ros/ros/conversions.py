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

from typing import Callable, TYPE_CHECKING

from builtin_interfaces.msg import Time
from dq_fk_ros.messages.output_plan import OutputPlan
from dq_fk_ros.messages.outputs import TF
from geometry_msgs.msg import PoseStamped, TransformStamped, TwistStamped
import numpy as np
from tf2_msgs.msg import TFMessage

if TYPE_CHECKING:  # imported where used: rclpy need not load with the messages
    from rclpy.qos import QoSProfile

NS_PER_S = 1_000_000_000


def qos_profile(output) -> 'QoSProfile':
    """Return the rclpy ``QoSProfile`` of a :class:`~dq_fk_ros.messages.outputs.Output`."""
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
    durability = DurabilityPolicy.TRANSIENT_LOCAL if output.latched else \
        DurabilityPolicy.VOLATILE
    return QoSProfile(depth=output.depth, reliability=ReliabilityPolicy.RELIABLE,
                      durability=durability)


def stamp_to_ns(stamp) -> int:
    """Return the nanoseconds of a ``builtin_interfaces/Time``."""
    return stamp.sec * NS_PER_S + stamp.nanosec


def ns_to_stamp(ns) -> Time:
    """Return a ``builtin_interfaces/Time`` of ``ns`` nanoseconds."""
    return Time(sec=ns // NS_PER_S, nanosec=ns % NS_PER_S)


def joint_state_fields(msg) -> tuple:
    """Return names, positions, velocities and stamp (ns) of a ``sensor_msgs/JointState``."""
    return msg.name, msg.position, msg.velocity, stamp_to_ns(msg.header.stamp)


def set_transform(transform, pose) -> None:
    """Fill a ``geometry_msgs/Transform`` from ``(x, y, z, qx, qy, qz, qw)``."""
    t, r = transform.translation, transform.rotation
    t.x, t.y, t.z, r.x, r.y, r.z, r.w = pose


def set_pose(msg_pose, pose) -> None:
    """Fill a ``geometry_msgs/Pose`` from ``(x, y, z, qx, qy, qz, qw)``."""
    p, r = msg_pose.position, msg_pose.orientation
    p.x, p.y, p.z, r.x, r.y, r.z, r.w = pose


class FrameMessages:
    """
    The messages of one robot model under one ``frame_prefix``, built once, refilled often.

    Laid out from the robot's :class:`~dq_fk_ros.messages.output_plan.OutputPlan` (frame
    ids, TF parents, static and moving transforms, helper frames: the bag tool writes from
    the same plan). With the DH frames on TF, the URDF's helper links are published as
    children of their DH frames: constant ones on /tf_static, moving ones on /tf.
    ``poses[k]`` is frame k's PoseStamped, in the root of its TF tree.
    """

    def __init__(self, model, frame_prefix='', shown_optional=(), plan=None, dh_frames=None):
        """
        Build the message objects for ``model``.

        :param shown_optional: the optional joints (side branches, a tree's) named so far:
            transforms and poses that need others are left out (``hidden``).
        :param plan: the :class:`OutputPlan` of ``model`` and ``frame_prefix`` if already made
            (making its helper frames for a big robot takes tens of ms).
        :param dh_frames: whether TF carries the DH frames (None: the model's default);
            ignored when ``plan`` is given.
        """
        self.model = model
        self.plan = plan = OutputPlan(model, frame_prefix, dh_frames) if plan is None else plan
        self.fixed_frame_id = fixed = plan.fixed_frame_id
        self.frame_ids = plan.frame_ids
        self.helpers = plan.helpers
        self.hidden = plan.hidden(shown_optional)
        # moving TF transforms: DH rows and links on other bodies than their TF parents,
        # those whose joints are known (robot_state_publisher's rule)
        self.moving_edges = plan.shown_edges(shown_optional)
        self.tf = TFMessage(transforms=[
            _transform_stamped(parent, child) for parent, child in
            plan.tf_edges(self.moving_edges)])
        self._helper_transforms = self.tf.transforms[len(self.moving_edges):]
        self.poses = []
        for k in range(len(self.frame_ids)):
            msg = PoseStamped()
            msg.header.frame_id = plan.pose_frame_ids.get(k, fixed)
            self.poses.append(msg)
        self.twist_frames = plan.twist_frames
        self.twists = []
        for _ in self.twist_frames:
            msg = TwistStamped()
            msg.header.frame_id = fixed
            self.twists.append(msg)

    def fill(self, stamp, absolute, relative, q=None) -> tuple:
        """Refill /tf and pose messages for one update at joints ``q``; ``(tf, poses)``."""
        for transform, (_, k) in zip(self.tf.transforms, self.moving_edges):
            transform.header.stamp = stamp
            set_transform(transform.transform, relative[k])
        if self._helper_transforms:
            for transform, pose in zip(self._helper_transforms, self.helpers.moving_poses(q)):
                transform.header.stamp = stamp
                set_transform(transform.transform, [float(v) for v in pose])
        if self.plan.rooted:
            absolute = self.plan.rooted_poses(np.array(absolute, dtype=float)).tolist()
        for msg, pose in zip(self.poses, absolute):
            msg.header.stamp = stamp
            set_pose(msg.pose, pose)
        return self.tf, self.poses

    def fill_twists(self, stamp, twists) -> list:
        """Refill the twist messages from ``[(v, omega), ...]`` in fixed-frame axes."""
        for msg, (v, w) in zip(self.twists, twists):
            msg.header.stamp = stamp
            lin, ang = msg.twist.linear, msg.twist.angular
            lin.x, lin.y, lin.z = (float(c) for c in v)
            ang.x, ang.y, ang.z = (float(c) for c in w)
        return self.twists

    def static_tf(self, stamp) -> TFMessage:
        """Return one TFMessage with every static transform: base, fixed rows, tool, links."""
        values = self.plan.static_poses().reshape(-1, 7)
        return TFMessage(transforms=[
            _transform_stamped(parent, child, stamp, pose)
            for (parent, child), pose in zip(self.plan.static_edges, values)])


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
    The node's /tf message of one robot, serialized per update.

    (The per-frame topics: :class:`~dq_fk_ros.messages.frame_streams.FrameStream`.)
    The fast path; the reference is :class:`FrameMessages` (rclpy's message objects), held
    equal byte for byte by test_frame_bytes.py's
    ``test_serialized_output_equals_the_message_objects``.

    The message's fixed bytes (frame ids, padding) are laid out once; an update fills them
    with its stamp and float64 fields and hands ``bytes`` to ``Publisher.publish``.
    Transforms given as the arrays of :meth:`RobotModel.frame_pose_arrays` go to the C
    writer (:meth:`CdrTemplate.compiled`); lists, or no C writer, to
    :class:`~dq_fk_ros.messages.cdr_templates.CdrPacker` (one ``struct`` call), its
    reference (``test_the_c_writer_equals_the_packer_byte_for_byte``).
    """

    def __init__(self, messages):
        """Lay out the messages of a :class:`FrameMessages` (same robot, same prefix)."""
        self.helpers = messages.helpers
        self.plan = messages.plan
        self.moving_edges = messages.moving_edges
        self._moving = tuple(k for _, k in self.moving_edges)
        self.sends_tf = bool(messages.tf.transforms)  # a robot with nothing moving: no /tf
        self.template = tf = TF.template(self.plan, self.moving_edges)  # (also the tests')
        self._tf = tf.packer()
        self._tf_c = tf.compiled(7)

    def tf_writer(self) -> Callable[..., bytes]:
        """
        Return a function ``(sec, nanosec, relative, q) -> bytes`` equal to :meth:`tf`.

        For ``relative`` as an array: where the C writer is built and no helper frame moves,
        its ``one`` bound to the moving rows (the node's update, without :meth:`tf`'s
        checks); else :meth:`tf` itself.
        """
        if self._tf_c is None or self.helpers.moving:
            return self.tf
        one, moving = self._tf_c.one, self._moving
        return lambda sec, nanosec, relative, q=None: one(sec, nanosec, relative, moving)

    def tf(self, sec, nanosec, relative, q=None) -> bytes:
        """
        Return the serialized /tf message: every moving row's (and helper's) transform.

        :param relative: the TF transforms of :meth:`RobotModel.frame_pose_arrays` (an
            ``(n, 7)`` float64 array) or of :meth:`RobotModel.frame_poses` (a list).
        :param q: the joint values (for helper frames that move).
        """
        if self._tf_c is not None and isinstance(relative, np.ndarray):
            if not self.helpers.moving:
                return self._tf_c.one(sec, nanosec, relative, self._moving)
            helpers = np.array(self.helpers.moving_poses(q), dtype=float).reshape(-1, 7)
            n = len(relative)
            return self._tf_c.one(sec, nanosec, np.concatenate([relative, helpers]),
                                  self._moving + tuple(range(n, n + len(helpers))))
        # the reference: the /tf row's values (the bag tool's), one message of them
        values = TF.values(self.plan, None if q is None else np.asarray(q, dtype=float)[None],
                           np.asarray(relative, dtype=float)[None], self.moving_edges)[0]
        return self._tf.pack(sec, nanosec, values.reshape(-1, 7).tolist())
