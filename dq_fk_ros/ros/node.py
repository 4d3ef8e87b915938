"""
The dq_fk_node executable: ``sensor_msgs/JointState`` in, every link frame out.

Thin glue: :mod:`dq_fk_ros.messages.joint_states` decides what a message means,
:mod:`dq_fk_ros.kinematics.dh` computes the frames, :mod:`dq_fk_ros.ros.conversions` fills the
messages. The README lists its topics and parameters; docs/node.md says how it acts.

Why this file is long: the node's glue (parameters checked and applied, reload, the hot
path, readers, diagnostics); its parameter table is in the same file so --help and the node
agree. The next split: the checks into a parameters object.
"""

import math
import os
import sys
import threading
import time

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from dq_fk_ros.description.errors import (
    DqFkError, first_line, listing, ParameterError, printable_line, RobotDescriptionError)
from dq_fk_ros.description.from_urdf import NODE_OPTIONS
from dq_fk_ros.description.loading import (
    FileAccess, load_robot, resolve_robot, robot_from_urdf_text)
from dq_fk_ros.description.robot_model import FRAME_ID, MAX_NAME_CHARS, TF_FRAME_ID
from dq_fk_ros.description.shipped import shipped_robots_dir
from dq_fk_ros.description.to_urdf import description_urdf
from dq_fk_ros.description.urdf_reader import tf_name
from dq_fk_ros.messages.cdr import CdrError, JointStateNames, parse_joint_state
from dq_fk_ros.messages.joint_states import (
    INCOMPLETE, JointStateMerger, MAX_UNKNOWN_LISTED, OUT_OF_LIMITS_POLICIES, PUBLISH, REJECTED,
    SequenceGaps)
from dq_fk_ros.ros.conversions import FrameBytes, FrameMessages, NS_PER_S
from dq_fk_ros.ros.executables import spin_until_shutdown
from dq_fk_ros.ros.package_paths import declare_package_paths
from dq_fk_ros.ros.parameters import declare, help_text, Param
from dq_fk_ros.ros.raw_input import raw_publisher, RawSubscriptionThread, take_queued
from geometry_msgs.msg import PoseStamped, TwistStamped
import numpy as np
from rcl_interfaces.msg import SetParametersResult
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState
from std_msgs.msg import String
from tf2_msgs.msg import TFMessage

# the parameters that say which robot: changing any of them reloads it
ROBOT_PARAMETERS = ('robot_description_file', 'robot_description', 'urdf_base_link',
                    'urdf_tip_link')
RELIABILITY = {'best_effort': ReliabilityPolicy.BEST_EFFORT,
               'reliable': ReliabilityPolicy.RELIABLE}
WARN_EVERY_S = 5.0
READERS_REFRESH_S = 0.5
DRAIN_MAX = 64  # queued joint states worked through per executor wake-up
QOS_DEPTH_MAX = 100_000  # joint states the subscription may queue (tens of MB for an arm)
INPUT_BATCH_MS_DEFAULT = 2.0  # see docs/node.md, "How it keeps up"
INPUT_BATCH_MS_MAX = 100.0
MIN_RATE_HZ = 0.01  # publish_frequency, max_publish_rate_hz: 0 (off) or at least this
MAX_RATE_HZ = 1e6
RUN_TIME_XACRO_LIMIT_S = 5.0  # a xacro set at run time (allow_runtime_xacro) is stopped then


# the node's parameters (declared from this table; `dq_fk_node --help` prints it)
NODE_PARAMETERS = (
    Param('robot_description_file', '',
          'the robot: a DH YAML file, a URDF or xacro file (converted on load), or a shipped '
          'robot name (rl15, ur5e...); empty: rl15. Setting it at run time reloads the robot if '
          'it is valid.'),
    Param('robot_description', '',
          'URDF XML, as robot_state_publisher takes it; if set, used instead of '
          'robot_description_file'),
    Param('urdf_base_link', '',
          'for a URDF: the link the robot starts at (the fixed frame; the tree below it is '
          'published); empty: the root link'),
    Param('urdf_tip_link', '',
          'for a URDF: the link the first DH chain ends at (the end effector); empty: the child '
          'of the last moving joint of the longest chain'),
    Param('publish_frequency', 0.0,
          'as robot_state_publisher: at most this many /tf updates per second of JointState '
          'stamps; 0: every update (robot_state_publisher defaults to 20)'),
    Param('ignore_timestamp', False,
          'as robot_state_publisher: publish every update whatever publish_frequency says'),
    Param('frame_prefix', '',
          'prepended to every frame id except the fixed frame'),
    Param('publish_tf', True,
          'publish /tf and /tf_static'),
    Param('publish_poses', True,
          'publish ~/pose/<frame> (PoseStamped in the fixed frame)'),
    Param('publish_robot_description', True,
          'publish the URDF of the robot on robot_description (transient local), as '
          'robot_state_publisher does; re-sent on reload'),
    Param('publish_unread_topics', False,
          'fill and publish ~/pose and ~/twist topics that nobody subscribes to (by default '
          'they are skipped; /tf is always published)'),
    Param('publish_twist', True,
          'publish ~/twist/<frame> for the end effector (and tool) when every joint has a '
          'velocity'),
    Param('use_joint_state_stamp', True,
          'stamp outputs with the JointState stamp (a zero stamp: the node clock); false: '
          'always the node clock'),
    Param('max_publish_rate_hz', 0.0,
          'at most this many updates per second; 0: all'),
    Param('out_of_limits', 'warn',
          'joint values outside their limits: warn | clamp | reject'),
    Param('robot_description_dirs', '',
          'folders (separated by colons, as ROS_PACKAGE_PATH) that robot_description_file may '
          "name at run time, symlinks resolved; empty: the start-up file's folder. The shipped "
          'robots are always allowed', read_only=True),
    Param('allow_runtime_xacro', False,
          'expand a .xacro file set as robot_description_file at run time (a xacro file is a '
          'program; any peer on the domain may set parameters)', read_only=True),
    Param('qos_depth', 1000,
          f'depth of the joint_states subscription (1 to {QOS_DEPTH_MAX})', read_only=True),
    Param('input_thread', True,
          'take joint states in a thread of their own (true) or in the executor', read_only=True),
    Param('input_batch_ms', INPUT_BATCH_MS_DEFAULT,
          'with input_thread: after an update the input thread looks for the next joint states '
          'this much later (ms; 0: at once): one wake-up serves several messages above 1 / this '
          'rate, adding at most this much latency', read_only=True),
    Param('joint_states_reliability', 'best_effort',
          'best_effort (matches reliable and best-effort publishers) | reliable', read_only=True),
)


class DqFkNode(Node):
    """Publish TF, a PoseStamped per frame and end-effector twists from joint states."""

    def __init__(self, **kwargs):
        """Declare parameters, load the robot (may raise RobotDescriptionError), wire up."""
        super().__init__('dq_fk_node', **kwargs)
        # the input thread's updates and the executor's callbacks (parameters, timers) take
        # turns on the node's state
        self._lock = threading.RLock()
        self._declare_parameters()
        get = self.get_parameter
        self._publish_tf = get('publish_tf').value
        self._publish_poses = get('publish_poses').value
        self._publish_twist = get('publish_twist').value
        self._use_joint_state_stamp = get('use_joint_state_stamp').value
        self._max_rate_hz = get('max_publish_rate_hz').value
        self._out_of_limits = get('out_of_limits').value
        self._frame_prefix = get('frame_prefix').value
        depth, batch_ms = get('qos_depth').value, get('input_batch_ms').value
        self._check_values({'out_of_limits': self._out_of_limits,
                            'max_publish_rate_hz': self._max_rate_hz,
                            'frame_prefix': self._frame_prefix, 'qos_depth': depth,
                            'input_batch_ms': batch_ms})
        reliability = get('joint_states_reliability').value
        self._check_choice('joint_states_reliability', reliability, tuple(RELIABILITY))
        self._robot_inputs = {name: get(name).value for name in ROBOT_PARAMETERS}
        self._check_values(self._robot_inputs)
        dirs = [d for d in get('robot_description_dirs').value.split(os.pathsep) if d]
        self._access = self._file_access(dirs, get('allow_runtime_xacro').value)
        self._packages = declare_package_paths(self)
        model = self._load_robot(self._robot_inputs)
        self._publish_frequency = get('publish_frequency').value
        self._ignore_timestamp = get('ignore_timestamp').value
        self._check_values({'publish_frequency': self._publish_frequency})
        self._last_stamp_ns = None

        self._tf_pub = self.create_publisher(
            TFMessage, '/tf', QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE))
        self._tf_static_pub = self.create_publisher(
            TFMessage, '/tf_static',
            QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                       durability=DurabilityPolicy.TRANSIENT_LOCAL))
        self._send_tf = raw_publisher(self._tf_pub)
        self._diag_pub = self.create_publisher(DiagnosticArray, '/diagnostics', 10)
        # as robot_state_publisher: the URDF for RViz's RobotModel and Foxglove's 3D panel
        self._description_pub = self.create_publisher(
            String, 'robot_description',
            QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                       durability=DurabilityPolicy.TRANSIENT_LOCAL))
        self._publish_description = get('publish_robot_description').value
        self._publish_unread = get('publish_unread_topics').value
        self._pose_pubs = []
        self._twist_pubs = []
        self._merger = None
        self._last_publish_ns = None
        self._last_update_ns = None
        self._apply_model(model, self._build_outputs(model, self._frame_prefix))

        self._names_cache = JointStateNames()
        self._gaps = SequenceGaps()  # joint states lost before the node took them
        self._lost_reported = 0
        # who reads which pose topic, refreshed twice a second (a new subscriber waits
        # at most that long for its first message)
        self._readers_timer = self.create_timer(READERS_REFRESH_S, self._refresh_readers)
        self._diag_timer = self.create_timer(1.0, self._publish_diagnostics)
        self.add_on_set_parameters_callback(self._on_set_parameters)
        # whether ROS time follows /clock (use_sim_time): asked once per change, not per update
        self._sim_time = self.get_clock().ros_time_is_active
        self.add_post_set_parameters_callback(self._after_set_parameters)
        # serialized in, serialized out: the messages are read and written as bytes, by
        # default in a thread of their own (the executor's wake-up costs more than an update)
        qos = QoSProfile(depth=depth, reliability=RELIABILITY[reliability])
        self._input = None
        if get('input_thread').value:
            self._input = RawSubscriptionThread(self, JointState,
                                                self.resolve_topic_name('joint_states'), qos,
                                                self._on_joint_state, batch_ms / 1000.0,
                                                self._on_input_error)
            self._joint_state_sub = self._input.subscription
        else:
            self._joint_state_sub = self.create_subscription(
                JointState, 'joint_states', self._on_joint_state_drain, qos, raw=True)
        self.get_logger().info(
            f'dq_fk_node: {model.name} from {model.source}: {len(model.frame_names)} frames '
            f'under {model.fixed_frame!r}, joints {", ".join(model.joint_names)}')

    # -- parameters ----------------------------------------------------------------------
    def _declare_parameters(self):
        declare(self, NODE_PARAMETERS)

    def _check_choice(self, name, value, allowed):
        if value not in allowed:
            raise ParameterError(f'parameter {name} is {value!r}; allowed: '
                                 f'{", ".join(allowed)}')

    def _check_values(self, new):
        """Raise ParameterError (one line) for a value the node cannot use."""
        if 'out_of_limits' in new:
            self._check_choice('out_of_limits', new['out_of_limits'], OUT_OF_LIMITS_POLICIES)
        for name in ('max_publish_rate_hz', 'publish_frequency'):
            rate = new.get(name, 0.0)
            if not (rate == 0.0 or MIN_RATE_HZ <= rate <= MAX_RATE_HZ):
                raise ParameterError(f'parameter {name} must be 0 (publish every update) '
                                     f'or from {MIN_RATE_HZ:g} to {MAX_RATE_HZ:g}, got '
                                     f'{rate:g}')
        for name in ('urdf_base_link', 'urdf_tip_link'):
            link = new.get(name, '')
            if link and (len(link) > MAX_NAME_CHARS or not TF_FRAME_ID.fullmatch(tf_name(link))):
                raise ParameterError(
                    f'parameter {name} {printable_line(link, 70)!r} is not a link name tf2 '
                    f'takes (printable ASCII without spaces; at most {MAX_NAME_CHARS})')
        depth = new.get('qos_depth', 1)
        if not 1 <= depth <= QOS_DEPTH_MAX:
            raise ParameterError(f'parameter qos_depth must be an integer from 1 to '
                                 f'{QOS_DEPTH_MAX}, got {depth}')
        batch_ms = new.get('input_batch_ms', 0.0)
        if not (math.isfinite(batch_ms) and 0.0 <= batch_ms <= INPUT_BATCH_MS_MAX):
            raise ParameterError(f'parameter input_batch_ms must be a number from 0 to '
                                 f'{INPUT_BATCH_MS_MAX:g} (0: take each joint state at '
                                 f'once), got {batch_ms}')
        prefix = new.get('frame_prefix', '')
        if prefix and (len(prefix) > 64 or not FRAME_ID.fullmatch(prefix + 'x')):
            raise ParameterError(
                f'parameter frame_prefix {prefix[:70]!r} would not give valid frame ids: use '
                f'letters, digits, underscores and inner slashes, e.g. robot1/ (at most 64)')

    def _file_access(self, dirs, xacro):
        """
        Return what a robot file set at run time may be (a :class:`FileAccess`).

        Under ``dirs`` (default: the start-up file's folder) or the shipped robots; a xacro
        only if ``xacro``.
        """
        if not dirs:
            dirs = []
            start = self._robot_inputs['robot_description_file']
            if start and not self._robot_inputs['robot_description'].strip():
                dirs.append(os.path.dirname(os.path.realpath(resolve_robot(start))))
        for folder in dirs:
            if not os.path.isdir(folder):
                raise ParameterError(f'parameter robot_description_dirs: {folder!r} is '
                                     f'not a folder')
        dirs = [os.path.realpath(d) for d in dirs] + [shipped_robots_dir()]
        return FileAccess(tuple(dict.fromkeys(dirs)), xacro, RUN_TIME_XACRO_LIMIT_S,
                          lambda: not self.context.ok())

    def _load_robot(self, inputs, access=None):
        """
        Load the robot the parameters name (RobotDescriptionError: one line).

        :param access: for a file named at run time: where it may be (see FileAccess).
        """
        base = inputs['urdf_base_link'] or None
        tip = inputs['urdf_tip_link'] or None
        if inputs['robot_description'].strip():
            robot = robot_from_urdf_text(inputs['robot_description'],
                                         'parameter robot_description', base, tip,
                                         options=NODE_OPTIONS)
        else:
            robot = load_robot(inputs['robot_description_file'] or 'rl15', base, tip,
                               access=access, packages=self._packages, options=NODE_OPTIONS)
        if robot.conversion is not None:
            self.get_logger().info(robot.summary())
        for line in robot.warnings:
            self.get_logger().warn(line)
        # compile the straight-line FK code now, outside the lock, not at the first update
        # (a robot of 250 frames takes tens of ms: the first joint states would wait)
        zero = [0.0] * robot.model.dof
        robot.model.frame_poses(zero)
        robot.model.transform_poses(zero)
        return robot.model

    def _on_set_parameters(self, params):
        """
        Validate and apply a parameter change.

        A new robot is loaded first, outside the node's lock (the input thread keeps
        publishing the robot it has meanwhile: a xacro may take seconds), then the change is
        applied under the lock. A refusal's reason never quotes a file that is not a robot
        description (a peer may name any file).
        """
        new = {p.name: p.value for p in params}
        model = None
        try:
            self._check_values(new)
            if any(name in new for name in ROBOT_PARAMETERS):
                inputs = dict(self._robot_inputs)
                inputs.update({k: v for k, v in new.items() if k in ROBOT_PARAMETERS})
                model = self._load_robot(inputs, self._access)
        except Exception as exc:  # nothing a user sets may stop the node
            return self._refuse(exc)
        with self._lock:
            return self._set_parameters(new, model)

    def _refuse(self, exc, quote=False):
        """
        Refuse a parameter change for ``exc``: one line, in the log and the reply.

        :param quote: whether an unexpected exception's text may be shown (not while a file
            is read: it may hold the file's text).
        """
        if isinstance(exc, RobotDescriptionError):
            reason = printable_line(exc.public)
        elif quote and str(exc).strip():
            reason = f'{type(exc).__name__}: {printable_line(first_line(exc))}'
        else:
            reason = f'{type(exc).__name__} while applying the change'
        self.get_logger().error(f'parameter change refused: {reason}')
        return SetParametersResult(successful=False, reason=reason)

    def _after_set_parameters(self, params):
        """Note a change of ``use_sim_time`` (rclpy's time source has applied it by now)."""
        if any(p.name == 'use_sim_time' for p in params):
            self._sim_time = self.get_clock().ros_time_is_active

    def _set_parameters(self, new, model):
        """
        Apply checked changes ``new`` and a robot ``model`` loaded for them (or None).

        Any failure while building the new publishers refuses the whole change with the
        reason (one line); the node keeps the robot it has.
        """
        outputs = None
        try:
            if model is not None or 'frame_prefix' in new:
                outputs = self._build_outputs(model or self._model,
                                              new.get('frame_prefix', self._frame_prefix))
        except Exception as exc:  # nothing a user sets may stop the node (a name too long...)
            return self._refuse(exc, quote=True)
        resend_static = new.get('publish_tf', self._publish_tf) and not self._publish_tf
        resend_description = new.get('publish_robot_description', self._publish_description) \
            and not self._publish_description
        self._publish_description = new.get('publish_robot_description',
                                            self._publish_description)
        self._robot_inputs.update({k: v for k, v in new.items() if k in ROBOT_PARAMETERS})
        self._publish_frequency = new.get('publish_frequency', self._publish_frequency)
        self._ignore_timestamp = new.get('ignore_timestamp', self._ignore_timestamp)
        self._publish_tf = new.get('publish_tf', self._publish_tf)
        self._publish_poses = new.get('publish_poses', self._publish_poses)
        self._publish_twist = new.get('publish_twist', self._publish_twist)
        self._publish_unread = new.get('publish_unread_topics', self._publish_unread)
        self._use_joint_state_stamp = new.get('use_joint_state_stamp',
                                              self._use_joint_state_stamp)
        self._max_rate_hz = new.get('max_publish_rate_hz', self._max_rate_hz)
        rebuild = model is not None or any(k in new for k in ('out_of_limits', 'frame_prefix'))
        self._out_of_limits = new.get('out_of_limits', self._out_of_limits)
        self._frame_prefix = new.get('frame_prefix', self._frame_prefix)
        if rebuild:
            self._apply_model(model or self._model, outputs)
            if model is not None:
                self.get_logger().info(f'reloaded robot {model.name} from {model.source}')
        else:
            if resend_static:
                self._tf_static_pub.publish(
                    self._messages.static_tf(self.get_clock().now().to_msg()))
            if resend_description:
                self._send_description()
        self._refresh_readers()
        return SetParametersResult(successful=True)

    def _build_outputs(self, model, prefix):
        """
        Return ``(messages, pose publishers, twist publishers)`` for a robot and prefix.

        Built before anything is replaced: if a topic name is refused (too long in this
        namespace, say), the publishers made so far are destroyed and the error raised.
        """
        messages = FrameMessages(model, prefix)
        made = []
        try:
            for topic in model.topic_names:
                made.append(self.create_publisher(PoseStamped, f'~/pose/{topic}', 10))
            for k in messages.twist_frames:
                made.append(self.create_publisher(
                    TwistStamped, f'~/twist/{model.topic_names[k]}', 10))
        except Exception:
            for pub in made:
                self.destroy_publisher(pub)
            raise
        n = len(model.frame_names)
        return messages, made[:n], made[n:]

    def _apply_model(self, model, outputs=None):
        """(Re)build everything that depends on the robot: publishers, merger, messages."""
        counts = self._merger.counts if self._merger is not None else None
        unknown = self._merger.unknown if self._merger is not None else set()
        self._model = model
        self._merger = JointStateMerger(model.joint_names, model.limits, self._out_of_limits,
                                        required=len(model.required_joints))
        if counts is not None:
            self._merger.counts = counts
        self._merger.unknown = {n for n in unknown if n not in model.joint_names}
        if outputs is not None:
            for pub in self._pose_pubs + self._twist_pubs:
                self.destroy_publisher(pub)
            self._messages, self._pose_pubs, self._twist_pubs = outputs
            # bytes straight to the handles: publishers are replaced under the node's lock
            self._send_pose = [raw_publisher(pub) for pub in self._pose_pubs]
            self._send_twist = [raw_publisher(pub) for pub in self._twist_pubs]
            self._bytes = FrameBytes(self._messages)
            self._shown_optional = ()
            self._refresh_readers()
            if model.branches:
                self.get_logger().info(
                    f'{len(model.branches) + 1} chains, {model.dof} joints: each transform is '
                    f'published once joint states have named the joints it depends on')
            elif model.optional_joints:
                self.get_logger().info(
                    f'side-branch joints {listing(model.optional_joints, 10)}: their links '
                    f'are published once joint states name them')
        if self._publish_tf:
            self._tf_static_pub.publish(self._messages.static_tf(self.get_clock().now().to_msg()))
        self._send_description()

    def _send_description(self):
        """Publish the URDF of the robot (without frame_prefix, as robot_state_publisher)."""
        if not self._publish_description:
            return
        try:
            text = description_urdf(self._model)
        except ValueError as exc:  # a robot URDF cannot express (a scale other than +-1)
            self.get_logger().warn(f'no robot_description: {exc}')
            return
        self._description_pub.publish(String(data=text))

    # -- the hot path --------------------------------------------------------------------
    def _on_joint_state(self, raw, info=None):
        """
        Take a serialized JointState: read, merge, publish (under the node's lock).

        :param info: rclpy's message info; its sequence number counts what was lost before.
        """
        with self._lock:
            if info is not None:
                self._gaps.note(info.get('publication_sequence_number'))
            self._on_raw(raw)

    def _on_joint_state_drain(self, raw, info):
        """
        Take a serialized JointState from the executor, and whatever else is queued.

        Up to :data:`DRAIN_MAX` more in the same call: one executor wake-up costs more than
        an update, so a burst is worked through without paying it per message.
        """
        self._on_joint_state(raw, info)
        try:
            take_queued(self._joint_state_sub, self._on_joint_state, DRAIN_MAX, with_info=True)
        except Exception:  # destroyed meanwhile (a shutdown): the executor decides
            return

    def _on_input_error(self, exc):
        """Log an exception the input thread caught (it counts it and goes on)."""
        self.get_logger().error(f'input thread: joint state not processed: {exc!r}',
                                throttle_duration_sec=WARN_EVERY_S)

    def _on_raw(self, raw):
        try:
            try:
                stamp_ns, names, positions, velocities = parse_joint_state(
                    raw, self._names_cache, as_tuples=True)
            except CdrError as exc:
                self._merger.counts['received'] += 1
                self._merger.count_rejected('malformed_cdr')
                self.get_logger().warn(f'joint state rejected (malformed_cdr): {exc}',
                                       throttle_duration_sec=WARN_EVERY_S)
                return
            self._handle_fields(names, positions, velocities, stamp_ns)
        except Exception as exc:  # nothing a user sends may stop the node
            if not self.context.ok():
                return  # shutting down: the publishers are gone
            self._merger.count_rejected('internal_error')
            self.get_logger().error(f'joint state not processed: {exc!r}',
                                    throttle_duration_sec=WARN_EVERY_S)

    def _handle_fields(self, names, positions, velocities, stamp_ns):
        result = self._merger.merge(names, positions, velocities, stamp_ns)
        if result.status != PUBLISH or result.new_unknown or result.time_jump or \
                result.out_of_limits or result.unknown_overflow:
            if not self._report(result):
                return
        # ROS time is the system time unless /clock drives it (use_sim_time): skip the Time
        # object then (2.5 us of an update)
        now_ns = self.get_clock().now().nanoseconds if self._sim_time else time.time_ns()
        self._last_update_ns = now_ns
        if self._max_rate_hz > 0 and self._last_publish_ns is not None and \
                now_ns - self._last_publish_ns < 1e9 / self._max_rate_hz:
            self._merger.counts['rate_limited'] += 1
            return
        stamp = stamp_ns or now_ns
        if self._publish_frequency > 0 and not self._ignore_timestamp:
            # robot_state_publisher's throttle: by the stamps, not the clock (bags replay
            # alike at any rate); a stamp back in time publishes and starts over
            last = self._last_stamp_ns
            if last is not None and last <= stamp < last + 1e9 / self._publish_frequency:
                self._merger.counts['rate_limited'] += 1
                return
        self._last_stamp_ns = stamp
        self._publish(stamp_ns if (self._use_joint_state_stamp and stamp_ns) else now_ns,
                      result.q, result.qdot)
        self._last_publish_ns = now_ns
        self._merger.counts['published'] += 1

    def _report(self, result):
        """Log what a merge result says; return whether the update is to be published."""
        log = self.get_logger()
        if result.new_unknown:
            log.warn(f'ignoring joints that {self._model.name} does not have: '
                     f'{", ".join(result.new_unknown)} (reported once)')
        if result.unknown_overflow:
            log.warn(f'more than {MAX_UNKNOWN_LISTED} unknown joint names; further ones are '
                     f'only counted (unknown_names_unlisted in /diagnostics)')
        if result.time_jump:
            log.info('joint state stamps jumped back in time; state reset')
        if result.status == REJECTED:
            log.warn(f'joint state rejected ({result.reason}): {result.detail}',
                     throttle_duration_sec=WARN_EVERY_S)
            return False
        if result.out_of_limits:
            log.warn(f'joints outside their limits ({self._out_of_limits}): '
                     f'{", ".join(result.out_of_limits)}', throttle_duration_sec=WARN_EVERY_S)
        if result.status == INCOMPLETE:
            log.warn(f'waiting for joints never seen: {", ".join(result.missing)}',
                     throttle_duration_sec=WARN_EVERY_S)
            return False
        return True

    def _show_branches(self, seen):
        """Publish the links of the side-branch joints ``seen`` from now on (rare: rebuild)."""
        model = self._model
        new = [name for name in seen if name not in self._shown_optional]
        self._messages = FrameMessages(model, self._frame_prefix, seen, self._messages.helpers)
        self._bytes = FrameBytes(self._messages)
        self._shown_optional = seen
        hidden = self._messages.hidden
        self._pose_read = [read and k not in hidden for k, read in enumerate(self._pose_read)]
        self._note_read_poses()
        if new:
            self.get_logger().info(f'joint states name joints {listing(new, 10)}: publishing '
                                   f'the links that depend on them')

    def _publish(self, stamp_ns, q, qdot):
        """Publish /tf and the read pose and twist topics, serialized, stamped ``stamp_ns``."""
        model = self._model
        if model.optional_joints:
            seen = self._merger.seen_optional
            if seen != self._shown_optional:
                self._show_branches(seen)
        poses = self._publish_poses and bool(self._read_poses)
        twists = self._publish_twist and qdot is not None and self._any_twist_read
        if twists and model.branches:  # a tree: the first chain's velocities may be unknown
            twists = all(map(math.isfinite, qdot[:model.chain.dof]))
        if poses or twists:
            absolute, relative = model.frame_poses(q)
        else:  # /tf alone needs the transforms only (half the work for a DH chain)
            relative = model.transform_poses(q)
        sec, nanosec = divmod(int(stamp_ns), NS_PER_S)
        out = self._bytes
        if self._publish_tf and out.sends_tf:
            self._send_tf(out.tf(sec, nanosec, relative, q))
        if poses:
            for send, data in zip(self._send_read_poses,
                                  out.poses(sec, nanosec, absolute, self._read_poses)):
                send(data)
        if twists:
            dof = model.chain.dof
            v, w = model.chain.twist(q[:dof], qdot[:dof])
            p_end = np.array(absolute[model.n_chain_frames - 1][:3])
            for send, read, k in zip(self._send_twist, self._twist_read,
                                     self._messages.twist_frames):
                if read:
                    # the same rigid-body motion seen at another origin: v + w x (p_k - p)
                    v_k = v + np.cross(w, np.array(absolute[k][:3]) - p_end)
                    send(out.twist(sec, nanosec, v_k.tolist(), w.tolist()))

    def _refresh_readers(self):
        """
        Note which pose and twist topics have subscribers (nobody reads: not filled).

        Counted outside the node's lock (asking DDS for matched readers can take long
        enough to stall the input thread: 5 kHz input lost messages that way), then set
        under it if the publishers are still the same ones.
        """
        pose_pubs, twist_pubs, always = self._pose_pubs, self._twist_pubs, self._publish_unread
        pose = [always or pub.get_subscription_count() > 0 for pub in pose_pubs]
        twist = [always or pub.get_subscription_count() > 0 for pub in twist_pubs]
        joint_states = getattr(self, '_joint_state_sub', None)
        publishers = joint_states.get_publisher_count() if joint_states is not None else 0
        with self._lock:
            if joint_states is not None:
                self._gaps.single_publisher(publishers == 1)
            if pose_pubs is self._pose_pubs and twist_pubs is self._twist_pubs:
                hidden = self._messages.hidden  # side-branch links not named yet
                self._pose_read = [read and k not in hidden for k, read in enumerate(pose)]
                self._twist_read = twist
                self._any_twist_read = any(twist)
                self._note_read_poses()

    def _note_read_poses(self):
        """Index the pose topics someone reads, and their senders (for :meth:`_publish`)."""
        self._read_poses = [k for k, read in enumerate(self._pose_read) if read]
        self._send_read_poses = [self._send_pose[k] for k in self._read_poses]

    # -- diagnostics ---------------------------------------------------------------------
    def diagnostics(self):
        """Return the node's counters as one DiagnosticStatus."""
        counts = self._merger.counts
        # a tree waits for no joint: its transforms wait for theirs, so every joint counts
        never_seen = self._merger.never_seen_any if self._model.branches else \
            self._merger.never_seen
        age = ('never' if self._last_update_ns is None else
               f'{(self.get_clock().now().nanoseconds - self._last_update_ns) / 1e9:.3f}')
        values = {'robot': self._model.name,
                  'updates_received': counts['received'],
                  'updates_published': counts['published'],
                  'updates_incomplete': counts['incomplete'],
                  'updates_rate_limited': counts['rate_limited'],
                  'updates_rejected': counts['rejected'],
                  'time_jumps': counts['time_jumps'],
                  'joints_never_seen': ', '.join(never_seen),
                  'unknown_joints': ', '.join(sorted(self._merger.unknown)),
                  'unknown_names_unlisted': counts['unknown_names_unlisted'],
                  'velocities_non_finite': counts['velocities_non_finite'],
                  'updates_lost': self._gaps.lost,
                  'input_errors': self._input.errors if self._input is not None else 0,
                  'last_update_age_s': age}
        for key in sorted(counts):
            if key.startswith('rejected_'):
                values[key] = counts[key]
        lost_now = self._gaps.lost - self._lost_reported
        if lost_now:
            level, message = DiagnosticStatus.WARN, \
                f'{lost_now} joint states lost before the node took them (overload?)'
        elif never_seen:
            level, message = DiagnosticStatus.WARN, f'{len(never_seen)} joints never seen'
        elif counts['rejected']:
            level, message = DiagnosticStatus.WARN, f"{counts['rejected']} updates rejected"
        else:
            level, message = DiagnosticStatus.OK, 'ok'
        level = level if isinstance(level, bytes) else bytes([level])
        return DiagnosticStatus(
            level=level, name=f'{self.get_name()}: joint states', message=message,
            hardware_id=self._model.name,
            values=[KeyValue(key=k, value=str(v)) for k, v in values.items()])

    def destroy_node(self):
        """Stop the input thread first, then destroy the node."""
        if getattr(self, '_input', None) is not None:
            self._input.close()
            self._input = None
        return super().destroy_node()

    def _publish_diagnostics(self):
        msg = DiagnosticArray()
        msg.header.stamp = self.get_clock().now().to_msg()
        with self._lock:
            msg.status = [self.diagnostics()]
            self._lost_reported = self._gaps.lost
        self._diag_pub.publish(msg)


def main(args=None):
    """Run dq_fk_node until SIGINT/SIGTERM (as ``ros2 run dq_fk_ros dq_fk_node``)."""
    usage = help_text('dq_fk_node', 'sensor_msgs/JointState in (joint_states), every link '
                      'frame out: /tf, /tf_static, ~/pose/<frame>, ~/twist/<frame>, the '
                      'robot_description; see the README, "dq_fk_node".', NODE_PARAMETERS)
    return spin_until_shutdown('dq_fk_node', DqFkNode, DqFkError, args, usage)


if __name__ == '__main__':
    sys.exit(main())
