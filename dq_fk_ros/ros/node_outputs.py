"""
dq_fk_node's outputs of one robot: the output table's topics, filled and published per update.

:class:`NodeOutputs` makes the pose and twist publishers of a robot under a frame prefix (a
row of :data:`~dq_fk_ros.messages.outputs.OUTPUTS` each: topic, type, QoS; the frames from
the :class:`~dq_fk_ros.messages.output_plan.OutputPlan`), knows which of them someone reads,
and publishes an update: ``/tf`` (its transforms only, unless a pose or twist is read), the
read pose topics and the twist topics (``kinematics.twists.frame_twists``), serialized by
:class:`~dq_fk_ros.ros.conversions.FrameBytes`. The node swaps whole ``NodeOutputs`` when the
robot, the prefix or ``publish_dh_frames`` change; ``dq_fk_bag process`` writes the same
rows from the same plan (``bag/outputs.py``).
"""

import math

from dq_fk_ros.errors import listing
from dq_fk_ros.kinematics.twists import frame_twists
from dq_fk_ros.messages.outputs import POSE, TWIST
from dq_fk_ros.ros.conversions import FrameBytes, FrameMessages, NS_PER_S, qos_profile
from dq_fk_ros.ros.publisher_group import PublisherGroup
from dq_fk_ros.ros.raw_input import raw_publisher
from geometry_msgs.msg import PoseStamped, TwistStamped
import numpy as np


class NodeOutputs:
    """
    The per-update outputs of ``model`` on ``node`` (see the module).

    Made before anything is replaced: a topic name the node refuses raises, and the
    publishers made so far are destroyed. ``tf_group`` publishes ``/tf`` (the node's, kept
    across robots).
    """

    def __init__(self, node, model, prefix: str, dh_frames, tf_group: PublisherGroup):
        """Make the pose and twist publishers of ``model`` under ``prefix`` on ``node``."""
        self.node, self.model, self.tf_group = node, model, tf_group
        self.messages = messages = FrameMessages(model, prefix, dh_frames=dh_frames)
        made = []
        try:
            for k in messages.plan.pose_frames:
                made.append(node.create_publisher(
                    PoseStamped, POSE.topic_for(model.topic_names[k]), qos_profile(POSE)))
            for k in messages.twist_frames:
                made.append(node.create_publisher(
                    TwistStamped, TWIST.topic_for(model.topic_names[k]), qos_profile(TWIST)))
        except Exception:
            for pub in made:
                node.destroy_publisher(pub)
            raise
        n = len(messages.plan.pose_frames)
        self.pose_pubs, self.twist_pubs = made[:n], made[n:]
        self.pose_frames = messages.plan.pose_frames   # the frame index of each pose topic
        self.pose_group = PublisherGroup([])
        self.send_twist = [raw_publisher(pub) for pub in self.twist_pubs]   # bytes, direct
        self.bytes = FrameBytes(messages)
        self.shown_optional = ()
        self.pose_readers = [False] * n
        self.twist_read = [False] * len(self.twist_pubs)
        self.any_twist_read = False
        self.read_poses = []
        # the poses of an update, written in place by the robot's engine (the kernel's
        # Model, or the reference): RobotModel.frame_pose_arrays / transform_pose_array
        # without their two pass-through calls
        self.absolute = np.empty((len(model.frame_names), 7))
        self.relative = np.empty((model.n_transforms, 7))
        engine = model.kinematics.engine
        self.fill_poses, self.fill_transforms = engine.poses, engine.transforms

    def describe(self) -> list:
        """Return the lines the node logs when it takes these outputs."""
        model, lines = self.model, [self.messages.plan.summary()]
        if model.branches:
            lines.append(f'{len(model.branches) + 1} chains, {model.dof} joints: each transform '
                         f'is published once joint states have named the joints it depends on')
        elif model.optional_joints:
            lines.append(f'side-branch joints {listing(model.optional_joints, 10)}: their '
                         f'links are published once joint states name them')
        return lines

    def close(self) -> None:
        """Let go of the publishers (their group, then the publishers themselves)."""
        self.pose_group.close()
        for pub in self.pose_pubs + self.twist_pubs:
            self.node.destroy_publisher(pub)

    def count_readers(self, always: bool) -> tuple:
        """Return which pose and which twist topics someone reads (``always``: all)."""
        return ([always or pub.get_subscription_count() > 0 for pub in self.pose_pubs],
                [always or pub.get_subscription_count() > 0 for pub in self.twist_pubs])

    def set_readers(self, pose: list, twist: list) -> None:
        """Take the reader flags of :meth:`count_readers` (under the node's lock)."""
        self.pose_readers, self.twist_read = pose, twist
        self.any_twist_read = any(twist)
        self.note_read_poses()

    def note_read_poses(self) -> None:
        """Index the pose topics someone reads of links shown, and their publishers."""
        hidden = self.messages.hidden  # side-branch links not named yet
        read = [i for i, (k, on) in enumerate(zip(self.pose_frames, self.pose_readers))
                if on and k not in hidden]
        self.read_poses = [self.pose_frames[i] for i in read]
        self.pose_group = self.pose_group.regroup([self.pose_pubs[i] for i in read])

    def wanted(self, params) -> bool:
        """Say whether an update has anything but ``/tf`` to send (a pose or twist read)."""
        return bool(params.publish_poses and self.read_poses or
                    params.publish_twist and self.any_twist_read)

    def show_branches(self, seen: tuple) -> list:
        """Publish the links of the side-branch joints ``seen`` from now on; return new ones."""
        new = [name for name in seen if name not in self.shown_optional]
        self.messages = FrameMessages(self.model, self.messages.plan.prefix, seen,
                                      self.messages.plan)
        self.bytes = FrameBytes(self.messages)
        self.shown_optional = seen
        self.note_read_poses()
        return new

    def publish(self, params, stamp_ns: int, q, qdot, send_tf: bool = True) -> None:
        """Publish ``/tf`` and the read pose and twist topics, stamped ``stamp_ns``."""
        model = self.model
        poses = params.publish_poses and bool(self.read_poses)
        twists = params.publish_twist and qdot is not None and self.any_twist_read
        if twists and model.branches:  # a tree: the first chain's velocities may be unknown
            twists = all(map(math.isfinite, qdot[:model.chain.dof]))
        absolute, relative = self.absolute, self.relative
        if poses or twists:
            self.fill_poses(q, absolute, relative)
        else:  # /tf alone needs the transforms only
            self.fill_transforms(q, relative)
        sec, nanosec = divmod(int(stamp_ns), NS_PER_S)
        out = self.bytes
        if send_tf and params.publish_tf and out.sends_tf:
            self.tf_group.publish((out.tf(sec, nanosec, relative, q),))
        if poses:
            self.pose_group.publish(out.poses(sec, nanosec, absolute, self.read_poses))
        if twists:
            frames, dof = self.messages.twist_frames, model.chain.dof
            moving = frame_twists(model.chain, q[:dof], qdot[:dof],
                                  absolute[model.n_chain_frames - 1, :3], absolute[frames, :3])
            for send, read, twist in zip(self.send_twist, self.twist_read, moving.tolist()):
                if read:
                    send(out.twist(sec, nanosec, twist[:3], twist[3:]))


__all__ = ['NodeOutputs']
