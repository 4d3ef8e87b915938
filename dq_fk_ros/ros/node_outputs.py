"""
dq_fk_node's outputs of one robot: the output table's topics, filled and published per update.

:class:`NodeOutputs` makes a publisher per topic of every per-frame row of
:data:`~dq_fk_ros.messages.outputs.FRAME_OUTPUTS` (the poses, the twists: topic, type and QoS
from the row, the frames from the :class:`~dq_fk_ros.messages.output_plan.OutputPlan`, the
messages from a :class:`~dq_fk_ros.messages.frame_streams.FrameStream`, as ``dq_fk_bag
process`` writes them for a batch), knows which of them someone reads and publishes an
update: ``/tf`` (its transforms only, unless a per-frame topic is read, serialized by
:class:`~dq_fk_ros.ros.conversions.FrameBytes`), then each row switched on by its parameter.
The node swaps whole ``NodeOutputs`` when the robot, the prefix or ``publish_dh_frames``
change.
"""

import importlib

from dq_fk_ros.errors import listing
from dq_fk_ros.messages import outputs as output_table
from dq_fk_ros.messages.frame_streams import FrameStream
from dq_fk_ros.ros.conversions import FrameBytes, FrameMessages, NS_PER_S, qos_profile
from dq_fk_ros.ros.publisher_group import PublisherGroup
import numpy as np


def message_class(msgtype: str) -> type:
    """Return the rclpy message class of ``'pkg/msg/Name'``."""
    package, kind, name = msgtype.split('/')
    return getattr(importlib.import_module(f'{package}.{kind}'), name)


class NodeOutputs:
    """
    The per-update outputs of ``model`` on ``node`` (see the module).

    Made before anything is replaced: a topic name the node refuses raises, and the
    publishers made so far are destroyed. ``tf_group`` publishes ``/tf`` (the node's, kept
    across robots).
    """

    def __init__(self, node, model, prefix: str, dh_frames, tf_group: PublisherGroup):
        """Make the publishers of every per-frame output of ``model`` under ``prefix``."""
        self.node, self.model, self.tf_group = node, model, tf_group
        self.messages = messages = FrameMessages(model, prefix, dh_frames=dh_frames)
        self.streams = [FrameStream(output, messages.plan)
                        for output in output_table.FRAME_OUTPUTS]
        self.publishers = []   # per stream, one per frame
        try:
            for stream in self.streams:
                output = stream.output
                kind, qos = message_class(output.msgtype), qos_profile(output)
                made = []
                self.publishers.append(made)
                for k in stream.frames:
                    made.append(node.create_publisher(
                        kind, output.topic_for(model.topic_names[k]), qos))
        except Exception:
            self.close()
            raise
        self.groups = [PublisherGroup([]) for _ in self.streams]
        self.bytes = FrameBytes(messages)
        self.tf_bytes = self.bytes.tf_writer()
        self.shown_optional = ()
        self.readers = [[False] * len(s.frames) for s in self.streams]
        self.shown = [s.shown(()) for s in self.streams]   # none of the optional joints yet
        self.read = [[] for _ in self.streams]   # per stream, the positions read and shown
        self.active = []   # the streams with a topic read
        self._on, self._on_without_velocities, self._on_for = [], [], None
        # the poses of an update, written in place by the robot's engine (the kernel's
        # Model, or the reference): RobotModel.frame_pose_arrays / transform_pose_array
        # without their two pass-through calls
        self.absolute = np.empty((len(model.frame_names), 7))
        self.relative = np.empty((model.n_transforms, 7))
        self._absolute_n = self.absolute[None]   # the same memory, as a batch of one
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
        self.close_groups()
        for made in self.publishers:
            for pub in made:
                self.node.destroy_publisher(pub)

    def close_groups(self) -> None:
        """Let go of the publishers' handles the groups hold (before they are destroyed)."""
        for group in getattr(self, 'groups', ()):
            group.close()

    def count_readers(self, always: bool) -> list:
        """Return, per per-frame output, which of its topics someone reads (``always``: all)."""
        return [[always or pub.get_subscription_count() > 0 for pub in made]
                for made in self.publishers]

    def set_readers(self, readers: list) -> None:
        """Take the reader flags of :meth:`count_readers` (under the node's lock)."""
        self.readers = readers
        self.note_read()

    def note_read(self) -> None:
        """Index the topics someone reads of frames shown, and group their publishers."""
        for s, (made, readers, shown) in enumerate(
                zip(self.publishers, self.readers, self.shown)):
            read = [i for i, (on, known) in enumerate(zip(readers, shown)) if on and known]
            self.read[s] = read
            self.groups[s] = self.groups[s].regroup([made[i] for i in read])
        self.active = [s for s, read in enumerate(self.read) if read]
        self._on_for = None

    def on_for(self, params) -> list:
        """
        Return (and keep) the streams read and switched on by ``params``.

        Per stream its values, serializer, frames, publish, whether it needs velocities and
        its read topics; a pose row straight to the C writer instead
        (``FrameStream.direct_writer``): None, the writer, the read frames, publish.

        ``NodeParameters`` is replaced, never changed, when a parameter changes: the list is
        kept for one parameters object (and made again when the readers change).
        """
        self._on = []
        for s in self.active:
            stream, send = self.streams[s], self.groups[s].publish
            if not getattr(params, stream.output.switch):
                continue
            each = stream.direct_writer()
            if each is not None:   # the poses as they are: straight to the C writer
                self._on.append((None, each, [stream.frames[i] for i in self.read[s]], send,
                                 False, None))
            else:
                self._on.append((stream.output.values, stream.serialize, stream.frames,
                                 send, stream.output.velocities, self.read[s]))
        self._on_without_velocities = [row for row in self._on if not row[4]]
        self._on_for = params
        return self._on

    def wanted(self, params) -> bool:
        """Say whether an update has anything but ``/tf`` to send (a read topic switched on)."""
        return bool(self._on if params is self._on_for else self.on_for(params))

    def show_branches(self, seen: tuple) -> list:
        """Publish the links of the side-branch joints ``seen`` from now on; return new ones."""
        new = [name for name in seen if name not in self.shown_optional]
        self.messages = FrameMessages(self.model, self.messages.plan.prefix, seen,
                                      self.messages.plan)
        self.bytes = FrameBytes(self.messages)
        self.tf_bytes = self.bytes.tf_writer()
        self.shown_optional = seen
        self.shown = [stream.shown(seen) for stream in self.streams]
        self.note_read()
        return new

    def publish(self, params, stamp_ns: int, q, qdot, send_tf: bool = True) -> None:
        """Publish ``/tf`` and the read per-frame topics, stamped ``stamp_ns``."""
        if params is not self._on_for:  # (parameters change by a new object: see on_for)
            self.on_for(params)
        on = self._on if qdot is not None else self._on_without_velocities
        absolute, relative = self.absolute, self.relative
        if on:
            self.fill_poses(q, absolute, relative)
        else:  # /tf alone needs the transforms only
            self.fill_transforms(q, relative)
        sec, nanosec = divmod(int(stamp_ns), NS_PER_S)
        if send_tf and params.publish_tf and self.bytes.sends_tf:
            self.tf_group.publish((self.tf_bytes(sec, nanosec, relative, q),))
        if not on:
            return
        q_n = None
        for values_of, serialize, frames, send, _, read in on:
            if values_of is None:   # (serialize: the C writer; frames: the read ones)
                send(serialize(sec, nanosec, absolute, frames))
                continue
            if q_n is None:   # N = 1: the update as a batch of one (views of the arrays)
                q_n = q[None] if type(q) is np.ndarray else np.asarray(q, dtype=float)[None]
                qdot_n = None if qdot is None else np.asarray(qdot, dtype=float)[None]
            got = values_of(self.messages.plan, q_n, qdot_n, self._absolute_n, frames)
            if got is not None and got[2] is None:
                array, columns, _ = got
                values = absolute if array is self._absolute_n else array[0]
                send(serialize(sec, nanosec, values, columns, read))


__all__ = ['NodeOutputs']
