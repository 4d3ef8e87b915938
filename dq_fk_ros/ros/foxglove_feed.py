"""
What dq_fk_foxglove sends to Foxglove: the newest of each input, at most ``rate`` a second.

:class:`FoxgloveFeed` takes what the ROS side receives (serialized /tf, decoded /tf_static,
the URDF, serialized joint states and poses) and, at each :meth:`FoxgloveFeed.flush`, logs
the newest of each on the Foxglove SDK's channels. ``/tf`` (``tf2_msgs/msg/TFMessage``),
``/joint_states`` (``sensor_msgs/msg/JointState``) and each pose topic
(``geometry_msgs/msg/PoseStamped``) pass through as the CDR bytes they came in (schema
``ros2msg``, as foxglove_bridge and a ROS 2 MCAP file carry them), once read as that type
(anything else is counted and dropped: no byte is sent that does not parse); ``/tf_static``
is the transforms of every ``/tf_static`` message so far, as one ``foxglove.FrameTransforms``;
``/robot_description`` JSON ``{"data": urdf}`` (what the 3D panel's URDF layer reads from a
topic). Static transforms and the URDF are kept and logged again when a client subscribes
to them (what transient local does for a late ROS subscriber). The URDF's meshes are served
by :class:`~dq_fk_ros.description.meshes.MeshAssets`, replaced with each new description.

No ROS here; the channels come from the ``foxglove`` module given at construction, so the
module is imported only by the program that needs it.
"""

import json
import threading

from dq_fk_ros.bag.msgdefs import ros2msg_definition
from dq_fk_ros.errors import CdrError
from dq_fk_ros.messages.cdr import (
    JointStateNames, parse_joint_state, parse_pose_stamped, TfLatest)

MAX_POSE_TOPICS = 1024       # pose channels advertised at most (one per ~/pose/<frame>)
MAX_STATIC_FRAMES = 100_000  # static transforms kept (every child frame once)
DESCRIPTION_SCHEMA = {'type': 'object', 'properties': {'data': {'type': 'string'}}}
TF = 'tf2_msgs/msg/TFMessage'
JOINT_STATE = 'sensor_msgs/msg/JointState'
POSE_STAMPED = 'geometry_msgs/msg/PoseStamped'


def cdr_channel(foxglove, topic, msgtype) -> object:
    """Return a channel of serialized ROS 2 messages (``cdr``) of ``msgtype`` on ``topic``."""
    schema = foxglove.Schema(name=msgtype, encoding='ros2msg',
                             data=ros2msg_definition(msgtype).encode())
    return foxglove.Channel(topic, schema=schema, message_encoding='cdr')


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
        self.tf = cdr_channel(foxglove, '/tf', TF)
        self.tf_static = FrameTransformsChannel('/tf_static')
        # named as the ROS type: the 3D panel's URDF layer lists std_msgs/msg/String topics
        self.description = Channel('/robot_description', schema=foxglove.Schema(
            name='std_msgs/msg/String', encoding='jsonschema',
            data=json.dumps(DESCRIPTION_SCHEMA).encode()), message_encoding='json')
        self.joint_states = cdr_channel(foxglove, '/joint_states', JOINT_STATE)
        self.pose_channels = {}    # ROS topic -> its channel (PoseStamped, CDR)
        self.tf_latest = TfLatest()
        self.static = {}           # child -> (parent, pose, stamp_ns)
        self.urdf = None
        self.joint_state_raw = None
        self.pose_raw = {}         # topic -> newest serialized PoseStamped
        self.resend = set()        # channels a client subscribed to since the last flush
        self.static_changed = False
        self.description_changed = False
        self.counts = {'tf_messages': 0, 'bad_input': 0, 'flushes': 0}
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
        """Keep ``[(parent, child, pose, stamp_ns), ...]`` of a /tf_static message."""
        with self.lock:
            for parent, child, pose, stamp_ns in transforms:
                if child in self.static or len(self.static) < MAX_STATIC_FRAMES:
                    self.static[child] = (parent, pose, stamp_ns)
            self.static_changed = True

    def take_description(self, text) -> None:
        """Keep a new URDF; its meshes, and no other file, become fetchable."""
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
            self.pose_channels[topic] = cdr_channel(self.fox, topic, POSE_STAMPED)
            return True

    def subscribed(self, topic) -> None:
        """Note that a client subscribed to ``topic``: a kept message is sent again."""
        with self.lock:
            self.resend.add(topic)

    # -- out, at most rate times a second ------------------------------------------------
    def flush(self) -> None:
        """Log the newest of every input on its channel (and what new subscribers need)."""
        m = self.fox.messages
        with self.lock:
            newest = self.tf_latest.pop_raw()
            resend, self.resend = self.resend, set()
            static = None
            if self.static_changed or '/tf_static' in resend:
                static = [(p, c, pose, s) for c, (p, pose, s) in self.static.items()]
                self.static_changed = False
            urdf = None
            if self.description_changed or '/robot_description' in resend:
                urdf = self.urdf
                self.description_changed = False
            self.counts['flushes'] += 1
        for raw in newest:  # each read as a TFMessage when taken (its layout)
            self.tf.log(raw)
        if static:
            self.tf_static.log(frame_transforms(m, static))
        if urdf is not None:
            self.description.log(json.dumps({'data': urdf}))
        raw, self.joint_state_raw = self.joint_state_raw, None
        if raw is not None:
            try:
                parse_joint_state(raw, self._names)
            except CdrError:
                self.counts['bad_input'] += 1
            else:
                self.joint_states.log(raw)
        pending, self.pose_raw = self.pose_raw, {}
        for topic, raw in pending.items():
            channel = self.pose_channels.get(topic)
            try:
                parse_pose_stamped(raw)
            except CdrError:  # not a PoseStamped after all: counted, never sent
                self.counts['bad_input'] += 1
                continue
            if channel is not None:
                channel.log(raw)


def frame_transforms(m, transforms) -> object:
    """Return a ``foxglove.FrameTransforms`` of ``[(parent, child, pose, stamp_ns), ...]``."""
    out = []
    for parent, child, (x, y, z, qx, qy, qz, qw), stamp_ns in transforms:
        sec, nsec = divmod(int(stamp_ns), 1_000_000_000)
        out.append(m.FrameTransform(
            timestamp=m.Timestamp(sec, nsec), parent_frame_id=parent, child_frame_id=child,
            translation=m.Vector3(x=x, y=y, z=z), rotation=m.Quaternion(x=qx, y=qy, z=qz, w=qw)))
    return m.FrameTransforms(transforms=out)


__all__ = ['cdr_channel', 'FoxgloveFeed', 'frame_transforms', 'MAX_POSE_TOPICS']
