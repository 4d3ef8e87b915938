"""
What dq_fk_foxglove sends to Foxglove: the newest of each input, at most ``rate`` a second.

:class:`FoxgloveFeed` takes what the ROS side receives (serialized /tf, decoded /tf_static,
the URDF, serialized joint states and poses) and, at each :meth:`FoxgloveFeed.flush`, logs
the newest of each on the Foxglove SDK's channels: ``/tf`` (each publisher's newest) and
``/tf_static`` (every static transform so far) as ``foxglove.FrameTransforms``, each pose
topic as ``foxglove.PoseInFrame``, ``/joint_states`` as JSON (the fields of
``sensor_msgs/JointState``; a value that is not finite as null), ``/robot_description`` as
JSON ``{"data": urdf}`` (what the 3D panel's URDF layer reads from a topic). Every input is
read as its type first: bytes that do not parse are counted and dropped, never sent. Only
the newest message of each input is read, so the conversion costs ``rate`` messages a
second whatever the input rate. Static transforms and the URDF are kept and logged again
when a client subscribes to them (what transient local does for a late ROS subscriber). The
URDF's meshes are served by :class:`~dq_fk_ros.description.meshes.MeshAssets`, replaced
with each new description.

No ROS here; the channels come from the ``foxglove`` module given at construction, so the
module is imported only by the program that needs it.
"""

import json
import math
import threading
import time

from dq_fk_ros.description.urdf_reader import MAX_URDF_BYTES
from dq_fk_ros.errors import CdrError
from dq_fk_ros.messages.cdr import JointStateNames, parse_joint_state
from dq_fk_ros.messages.cdr_tf import parse_pose_stamped, tf_stamp, tf_values, TfLatest
from dq_fk_ros.viewers.foxglove_encoding import (
    FrameTransformsEncoder, joint_state_json, MAX_TEMPLATED_BYTES)

MAX_STAMP_NS = (1 << 32) * 1_000_000_000  # foxglove.Timestamp: unsigned 32-bit seconds
RESEND_INTERVAL_S = 1.0     # a channel's kept message is sent again at most this often
MAX_POSE_TOPICS = 1024       # pose channels advertised at most (one per ~/pose/<frame>)
MAX_STATIC_FRAMES = 100_000  # static transforms kept (every child frame once)
MAX_ENCODERS = 8             # /tf layouts whose FrameTransforms templates are kept
DESCRIPTION_SCHEMA = {'type': 'object', 'properties': {'data': {'type': 'string'}}}
_NUMBERS = {'type': 'array', 'items': {'type': ['number', 'null']}}
JOINT_STATE_SCHEMA = {
    'type': 'object', 'properties': {
        'header': {'type': 'object', 'properties': {
            'stamp': {'type': 'object', 'properties': {
                'sec': {'type': 'integer'}, 'nanosec': {'type': 'integer'}}},
            'frame_id': {'type': 'string'}}},
        'name': {'type': 'array', 'items': {'type': 'string'}},
        'position': _NUMBERS, 'velocity': _NUMBERS}}


class FoxgloveFeed:
    """The channels of one Foxglove server and the newest input for each (thread-safe)."""

    def __init__(self, foxglove, assets, log=print):
        """
        Create the fixed channels with the ``foxglove`` module (the SDK) and its context.

        :param assets: a :class:`~dq_fk_ros.description.meshes.MeshAssets`, replaced here
            with each new robot description.
        :param log: called with one line per thing a user should know (a mesh not served).
        """
        from foxglove import Channel
        from foxglove.channels import FrameTransformsChannel
        self.fox = foxglove
        self.assets = assets
        self.log = log
        self.lock = threading.Lock()
        # /tf's FrameTransforms are encoded here (FrameTransformsEncoder), /tf_static's by
        # the SDK: one schema, the SDK's own
        frames = foxglove.messages.FrameTransforms.get_schema()
        self.tf = Channel('/tf', schema=frames, message_encoding='protobuf')
        self._encoders = {}        # TfLayout -> its FrameTransformsEncoder
        self._names_text = (None, None)   # (names, their JSON text), the last set seen
        self.tf_static = FrameTransformsChannel('/tf_static')
        # named as the ROS type: the 3D panel's URDF layer lists std_msgs/msg/String topics
        self.description = Channel('/robot_description', schema=foxglove.Schema(
            name='std_msgs/msg/String', encoding='jsonschema',
            data=json.dumps(DESCRIPTION_SCHEMA).encode()), message_encoding='json')
        # named as the ROS type, its fields as JSON
        self.joint_states = Channel('/joint_states', schema=foxglove.Schema(
            name='sensor_msgs/msg/JointState', encoding='jsonschema',
            data=json.dumps(JOINT_STATE_SCHEMA).encode()), message_encoding='json')
        self.pose_channels = {}    # ROS topic -> its PoseInFrameChannel
        self.tf_latest = TfLatest()
        self.static = {}           # child -> (parent, pose, stamp_ns)
        self.urdf = None
        self.joint_state_raw = None
        self.pose_raw = {}         # topic -> newest serialized PoseStamped
        self.resend = set()        # channels a client subscribed to since the last flush
        self.static_changed = False
        self.description_changed = False
        self.counts = {'tf_messages': 0, 'bad_input': 0, 'bad_static': 0, 'flushes': 0}
        self._told_description_size = False
        self._resent_at = {}       # channel -> when its kept message was last sent again
        self._names = JointStateNames()

    # -- in, from the ROS callbacks ------------------------------------------------------
    def take_raw_tf(self, raw) -> None:
        """Keep a serialized /tf if it is its layout's newest (unreadable bytes: counted)."""
        with self.lock:
            self.counts['tf_messages'] += 1
            try:
                self.tf_latest.take(raw)
            except CdrError:
                self.counts['bad_input'] += 1

    def take_static(self, transforms) -> None:
        """
        Keep ``[(parent, child, pose, stamp_ns), ...]`` of a /tf_static message.

        A transform Foxglove cannot carry (a stamp before 1970 or past 2106, a value that is
        not finite) is dropped alone and counted (``bad_static``): the others still go.
        """
        with self.lock:
            for parent, child, pose, stamp_ns in transforms:
                if not (0 <= stamp_ns < MAX_STAMP_NS and all(map(math.isfinite, pose))):
                    self.counts['bad_static'] += 1
                    continue
                if child in self.static or len(self.static) < MAX_STATIC_FRAMES:
                    self.static[child] = (parent, pose, stamp_ns)
            self.static_changed = True

    def take_description(self, text) -> None:
        """
        Keep a new URDF; its meshes, and no other file, become fetchable.

        A text over :data:`~dq_fk_ros.description.urdf_reader.MAX_URDF_BYTES` (the node's
        bound) is not relayed: one log line, counted (``bad_input``).
        """
        if len(text) > MAX_URDF_BYTES:
            with self.lock:
                self.counts['bad_input'] += 1
                told, self._told_description_size = self._told_description_size, True
            if not told:   # (once: a peer sending it again and again writes no more lines)
                self.log(f'robot_description: {len(text)} characters, more than a URDF may '
                         f'have ({MAX_URDF_BYTES >> 20} MiB); not relayed (said once)')
            return
        with self.lock:
            if text == self.urdf:
                return
        for problem in self.assets.replace(text):
            self.log(problem)
        with self.lock:
            self.urdf = text
            self.description_changed = True

    def take_joint_state(self, raw) -> None:
        """Keep the newest serialized JointState."""
        self.joint_state_raw = raw

    def take_pose(self, topic, raw) -> None:
        """Keep the newest serialized PoseStamped of ``topic``."""
        self.pose_raw[topic] = raw

    def add_pose_topic(self, topic) -> bool:
        """Advertise a pose topic's channel (at most MAX_POSE_TOPICS); say whether it is new."""
        with self.lock:
            if topic in self.pose_channels or len(self.pose_channels) >= MAX_POSE_TOPICS:
                return False
            from foxglove.channels import PoseInFrameChannel
            self.pose_channels[topic] = PoseInFrameChannel(topic)
            return True

    def subscribed(self, topic) -> None:
        """Note that a client subscribed to ``topic``: a kept message is sent again."""
        with self.lock:
            self.resend.add(topic)

    # -- out, at most rate times a second ------------------------------------------------
    def flush(self) -> None:
        """Log the newest of every input on its channel (and what new subscribers need)."""
        m = self.fox.messages
        now = time.monotonic()
        with self.lock:
            newest = self.tf_latest.pop_raw()
            # a kept message sent again for new subscribers at most once a RESEND_INTERVAL_S
            # a channel: every client gets it, so toggling a subscription must not make a
            # stream of URDFs to everyone (440 MiB in 5 s to a bystander)
            resend = {t for t in self.resend
                      if now - self._resent_at.get(t, -RESEND_INTERVAL_S) >= RESEND_INTERVAL_S}
            self.resend -= resend
            self._resent_at.update(dict.fromkeys(resend, now))
            static = None
            if self.static_changed or '/tf_static' in resend:
                static = [(p, c, pose, s) for c, (p, pose, s) in self.static.items()]
                self.static_changed = False
            urdf = None
            if self.description_changed or '/robot_description' in resend:
                urdf = self.urdf
                self.description_changed = False
            self.counts['flushes'] += 1
        for layout, raw in newest:  # each layout's (a publisher's) newest
            self._log(self.tf, self._frame_transforms, layout, raw)
        if static:
            self._log(self.tf_static, frame_transforms, m, static)
        if urdf is not None:
            self.description.log(json.dumps({'data': urdf}))
        raw, self.joint_state_raw = self.joint_state_raw, None
        if raw is not None:
            self._log_joint_state(raw)
        pending, self.pose_raw = self.pose_raw, {}
        for topic, raw in pending.items():
            channel = self.pose_channels.get(topic)
            try:
                stamp_ns, frame_id, pose = parse_pose_stamped(raw)
            except CdrError:  # not a PoseStamped after all: counted, never sent
                self.counts['bad_input'] += 1
                continue
            if channel is not None:
                self._log(channel, pose_in_frame, m, stamp_ns, frame_id, pose)

    def _log(self, channel, make, *args):
        """Log ``make(*args)``; a stamp Foxglove cannot carry (before 1970) is counted."""
        try:
            message = make(*args)
        except (OverflowError, ValueError):  # foxglove.Timestamp: unsigned seconds
            self.counts['bad_input'] += 1
            return
        channel.log(message)

    def _log_joint_state(self, raw):
        try:
            stamp_ns, names, positions, velocities = parse_joint_state(raw, self._names)
        except CdrError:  # not a JointState after all: counted, never sent
            self.counts['bad_input'] += 1
            return
        if self._names_text[0] != names:
            self._names_text = (names, json.dumps(list(names)))
        self.joint_states.log(joint_state_json(stamp_ns, names, positions, velocities,
                                               self._names_text[1]))

    def _frame_transforms(self, layout, raw):
        """Return the FrameTransforms (protobuf bytes) of a /tf message of ``layout``."""
        if len(raw) > MAX_TEMPLATED_BYTES:   # a huge /tf: the SDK's objects, no template kept
            transforms, stamp_ns = tf_values(raw, layout)
            return frame_transforms(self.fox.messages, [(p, c, pose, stamp_ns)
                                                        for p, c, pose in transforms]).encode()
        encoder = self._encoders.get(id(layout))
        if encoder is None or encoder.layout is not layout:
            if len(self._encoders) >= MAX_ENCODERS:   # publishers of many layouts: bounded
                self._encoders.clear()
            encoder = self._encoders[id(layout)] = FrameTransformsEncoder(layout)
        return encoder.encode(raw, tf_stamp(raw, layout))


def frame_transforms(m, transforms) -> object:
    """Return a ``foxglove.FrameTransforms`` of ``[(parent, child, pose, stamp_ns), ...]``."""
    out = []
    for parent, child, (x, y, z, qx, qy, qz, qw), stamp_ns in transforms:
        sec, nsec = divmod(int(stamp_ns), 1_000_000_000)
        out.append(m.FrameTransform(
            timestamp=m.Timestamp(sec, nsec), parent_frame_id=parent, child_frame_id=child,
            translation=m.Vector3(x=x, y=y, z=z), rotation=m.Quaternion(x=qx, y=qy, z=qz, w=qw)))
    return m.FrameTransforms(transforms=out)


def pose_in_frame(m, stamp_ns, frame_id, pose) -> object:
    """Return a ``foxglove.PoseInFrame`` of a pose ``(x, y, z, qx, qy, qz, qw)``."""
    x, y, z, qx, qy, qz, qw = pose
    sec, nsec = divmod(int(stamp_ns), 1_000_000_000)
    return m.PoseInFrame(timestamp=m.Timestamp(sec, nsec), frame_id=frame_id, pose=m.Pose(
        position=m.Vector3(x=x, y=y, z=z), orientation=m.Quaternion(x=qx, y=qy, z=qz, w=qw)))


__all__ = ['FoxgloveFeed', 'frame_transforms', 'MAX_POSE_TOPICS', 'pose_in_frame']
