"""
The dq_fk_node executable: ``sensor_msgs/JointState`` in, every link frame out.

Thin glue: :class:`~dq_fk_ros.messages.joint_state_input.JointStateInput` takes a message
in by the node's input rules (:mod:`dq_fk_ros.messages.joint_states`), and
:class:`~dq_fk_ros.ros.node_outputs.NodeOutputs` computes the frames
(:meth:`RobotModel.frame_pose_arrays`) and publishes them. The README lists its
topics and parameters; docs/node.md says how it acts.

Its parameters and their checks are :class:`~dq_fk_ros.ros.node_parameters.NodeParameters`;
its /diagnostics status is written by :mod:`dq_fk_ros.ros.node_diagnostics`.
"""

import sys
import threading
import time

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from dq_fk_ros.description.to_urdf import description_urdf
from dq_fk_ros.errors import DqFkError, listing
from dq_fk_ros.messages.joint_state_input import JointStateInput
from dq_fk_ros.messages.joint_states import JointStateMerger, SequenceGaps
from dq_fk_ros.messages.outputs import DIAGNOSTICS, ROBOT_DESCRIPTION, TF, TF_STATIC
from dq_fk_ros.ros.conversions import qos_profile
from dq_fk_ros.ros.executables import run_main, spin_until_shutdown
from dq_fk_ros.ros.node_diagnostics import (
    joint_state_status, log_merge_result, WARN_EVERY_S)
from dq_fk_ros.ros.node_outputs import NodeOutputs
from dq_fk_ros.ros.node_parameters import (
    load_robot_of, NODE_PARAMETERS, NodeParameters, refusal, ROBOT_PARAMETERS)
from dq_fk_ros.ros.package_paths import declare_package_paths
from dq_fk_ros.ros.parameters import declare, help_text
from dq_fk_ros.ros.publisher_group import PublisherGroup
from dq_fk_ros.ros.raw_input import RawSubscriptionThread, take_queued
from rcl_interfaces.msg import SetParametersResult
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState
from std_msgs.msg import String
from tf2_msgs.msg import TFMessage

RELIABILITY = {'best_effort': ReliabilityPolicy.BEST_EFFORT,
               'reliable': ReliabilityPolicy.RELIABLE}
READERS_REFRESH_S = 0.5
DRAIN_MAX = 64  # queued joint states worked through per executor wake-up
RUN_TIME_XACRO_LIMIT_S = 5.0  # a xacro set at run time (allow_runtime_xacro) is stopped then


class DqFkNode(Node):
    """Publish TF, a PoseStamped per frame and end-effector twists from joint states."""

    def __init__(self, **kwargs):
        """Declare parameters, load the robot (may raise RobotDescriptionError), wire up."""
        super().__init__('dq_fk_node', **kwargs)
        # the input thread's updates and the executor's callbacks take turns on the state
        self._lock = threading.RLock()
        # every parameter, checked (ParameterError, one line): one object, replaced on change
        self._params = p = NodeParameters.from_values(declare(self, NODE_PARAMETERS))
        # where a robot file set at run time may be (a peer on the domain may set it)
        self._access = p.file_access(RUN_TIME_XACRO_LIMIT_S, lambda: not self.context.ok())
        self._packages = declare_package_paths(self)
        model = self._load_robot(p.robot_inputs)
        self._last_stamp_ns = None

        # the outputs' topics and QoS: one table (messages/outputs.py), the bag's too
        self._tf_pub = self.create_publisher(TFMessage, TF.topic, qos_profile(TF))
        self._tf_static_pub = self.create_publisher(TFMessage, TF_STATIC.topic,
                                                    qos_profile(TF_STATIC))
        self._tf_group = PublisherGroup([self._tf_pub])  # bytes through rcl, many a call
        self._diag_pub = self.create_publisher(DiagnosticArray, DIAGNOSTICS.topic,
                                               qos_profile(DIAGNOSTICS))
        # as robot_state_publisher: the URDF for RViz's RobotModel and Foxglove's 3D panel
        self._description_pub = self.create_publisher(String, ROBOT_DESCRIPTION.topic,
                                                      qos_profile(ROBOT_DESCRIPTION))
        self._outputs = self._merger = None
        self._last_publish_ns = None
        self._last_update_ns = None
        self._apply_model(model, NodeOutputs(self, model, p.frame_prefix, p.publish_dh_frames,
                                             self._tf_group))

        self._gaps = SequenceGaps()  # joint states lost before the node took them
        self._lost_reported = 0
        # who reads which pose topic, twice a second (a new subscriber waits at most that)
        self._readers_timer = self.create_timer(READERS_REFRESH_S, self._refresh_readers)
        self._diag_timer = self.create_timer(1.0, self._publish_diagnostics)
        self.add_on_set_parameters_callback(self._on_set_parameters)
        # whether ROS time follows /clock (use_sim_time): asked once per change, not per update
        self._sim_time = self.get_clock().ros_time_is_active
        self.add_post_set_parameters_callback(self._after_set_parameters)
        # serialized in, serialized out: the messages are read and written as bytes, by
        # default in a thread of their own (the executor's wake-up costs more than an update)
        qos = QoSProfile(depth=p.qos_depth, reliability=RELIABILITY[p.joint_states_reliability])
        self._input = None
        if p.input_thread:
            self._input = RawSubscriptionThread(self, JointState,
                                                self.resolve_topic_name('joint_states'), qos,
                                                self._on_joint_state, p.input_batch_ms / 1000.0,
                                                self._on_input_error)
            self._joint_state_sub = self._input.subscription
        else:
            self._joint_state_sub = self.create_subscription(
                JointState, 'joint_states', self._on_joint_state_drain, qos, raw=True)
        self.get_logger().info(
            f'dq_fk_node: {model.name} from {model.source}: {len(model.frame_names)} frames '
            f'under {model.fixed_frame!r}, joints {", ".join(model.joint_names)}')

    # -- parameters ----------------------------------------------------------------------
    def _load_robot(self, inputs, access=None):
        """Load the robot the parameters name (RobotDescriptionError: one line)."""
        return load_robot_of(inputs, self._packages, self.get_logger(), access)

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
            wanted = self._params.changed(new)
            if any(name in new for name in ROBOT_PARAMETERS):
                model = self._load_robot(wanted.robot_inputs, self._access)
        except Exception as exc:  # nothing a user sets may stop the node
            return self._refuse(exc)
        with self._lock:
            return self._set_parameters(new, model)

    def _refuse(self, exc, quote=False):
        """Refuse a parameter change for ``exc``: one line, in the log and the reply."""
        reason = refusal(exc, quote)
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
        old, p = self._params, self._params.changed(new)
        outputs = None
        try:
            if model is not None or p.frame_prefix != old.frame_prefix or \
                    p.publish_dh_frames != old.publish_dh_frames:
                outputs = NodeOutputs(self, model or self._model, p.frame_prefix,
                                      p.publish_dh_frames, self._tf_group)
        except Exception as exc:  # nothing a user sets may stop the node (a name too long...)
            return self._refuse(exc, quote=True)
        resend_static = p.publish_tf and not old.publish_tf
        resend_description = p.publish_robot_description and not old.publish_robot_description
        rebuild = model is not None or any(k in new for k in ('out_of_limits', 'frame_prefix',
                                                              'publish_dh_frames'))
        self._params = p
        if rebuild:
            self._apply_model(model or self._model, outputs)
            if model is not None:
                self.get_logger().info(f'reloaded robot {model.name} from {model.source}')
        else:
            if resend_static:
                self._tf_static_pub.publish(
                    self._outputs.messages.static_tf(self.get_clock().now().to_msg()))
            if resend_description:
                self._send_description()
        self._refresh_readers()
        return SetParametersResult(successful=True)

    def _apply_model(self, model, outputs=None):
        """(Re)build everything that depends on the robot: merger, input, outputs."""
        counts = self._merger.counts if self._merger is not None else None
        unknown = self._merger.unknown if self._merger is not None else set()
        self._model = model
        self._merger = JointStateMerger(
            model.joint_names, model.limits, self._params.out_of_limits, counts,
            {n for n in unknown if n not in model.joint_names}, len(model.required_joints))
        self._joint_states = JointStateInput(self._merger)
        if outputs is not None:
            if self._outputs is not None:
                self._outputs.close()
            self._outputs = outputs
            for line in outputs.describe():
                self.get_logger().info(line)
            self._refresh_readers()
        if self._params.publish_tf:
            self._tf_static_pub.publish(
                self._outputs.messages.static_tf(self.get_clock().now().to_msg()))
        self._send_description()

    def _send_description(self):
        """Publish the URDF of the robot (without frame_prefix, as robot_state_publisher)."""
        if not self._params.publish_robot_description:
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
            stamp_ns, q, qdot, result = self._joint_states.take(raw)
            if result is not None and not result.clean and not log_merge_result(
                    self.get_logger(), result, self._model.name, self._params.out_of_limits):
                return
            self._publish_merged(stamp_ns, q, qdot)
        except Exception as exc:  # nothing a user sends may stop the node
            if not self.context.ok():
                return  # shutting down: the publishers are gone
            self._merger.count_rejected('internal_error')
            self.get_logger().error(f'joint state not processed: {exc!r}',
                                    throttle_duration_sec=WARN_EVERY_S)

    def _publish_merged(self, stamp_ns, q, qdot):
        """Publish a merged joint vector unless a rate limit says not yet."""
        # ROS time is the system time unless /clock drives it (use_sim_time): skip the Time
        # object then (2.5 us of an update)
        now_ns = self.get_clock().now().nanoseconds if self._sim_time else time.time_ns()
        p = self._params
        self._last_update_ns = now_ns
        if p.max_publish_rate_hz > 0 and self._last_publish_ns is not None and \
                now_ns - self._last_publish_ns < 1e9 / p.max_publish_rate_hz:
            self._merger.counts['rate_limited'] += 1
            return
        stamp = stamp_ns or now_ns
        send_tf = True
        if p.publish_frequency > 0 and not p.ignore_timestamp:
            # robot_state_publisher's throttle of /tf: by the stamps, not the clock (bags
            # replay alike at any rate); a stamp back in time publishes and starts over
            last = self._last_stamp_ns
            if last is not None and last <= stamp < last + 1e9 / p.publish_frequency:
                self._merger.counts['rate_limited'] += 1
                send_tf = False
                if not self._outputs.wanted(p):
                    return  # nothing else to send: no FK either
        self._last_stamp_ns = stamp if send_tf else self._last_stamp_ns
        if self._model.optional_joints:
            self._show_branches()
        self._outputs.publish(p, stamp_ns if (p.use_joint_state_stamp and stamp_ns) else now_ns,
                              q, qdot, send_tf)
        self._last_publish_ns = now_ns
        self._merger.counts['published'] += 1

    def _show_branches(self):
        """Publish the links of the side-branch joints named so far (rare: a rebuild)."""
        seen = self._merger.seen_optional
        if seen != self._outputs.shown_optional:
            new = self._outputs.show_branches(seen)
            if new:
                self.get_logger().info(f'joint states name joints {listing(new, 10)}: '
                                       f'publishing the links that depend on them')

    def _refresh_readers(self):
        """
        Note which per-frame topics (poses, twists) have subscribers (nobody reads: not filled).

        Counted outside the node's lock (asking DDS for matched readers can take long
        enough to stall the input thread: 5 kHz input lost messages that way), then set
        under it if the outputs are still the same ones.
        """
        outputs = self._outputs
        readers = outputs.count_readers(self._params.publish_unread_topics)
        joint_states = getattr(self, '_joint_state_sub', None)
        publishers = joint_states.get_publisher_count() if joint_states is not None else 0
        with self._lock:
            if joint_states is not None:
                self._gaps.single_publisher(publishers == 1)
            if outputs is self._outputs:
                outputs.set_readers(readers)

    # -- diagnostics ---------------------------------------------------------------------
    def diagnostics(self) -> DiagnosticStatus:
        """Return the node's counters as one DiagnosticStatus."""
        age_s = None if self._last_update_ns is None else \
            (self.get_clock().now().nanoseconds - self._last_update_ns) / 1e9
        return joint_state_status(
            f'{self.get_name()}: joint states', self._model, self._merger, self._gaps.lost,
            self._gaps.lost - self._lost_reported,
            self._input.errors if self._input is not None else 0, age_s)

    def destroy_node(self) -> None:
        """Stop the input thread first, then destroy the node."""
        if getattr(self, '_input', None) is not None:
            self._input.close()
            self._input = None
        with self._lock:  # the groups hold their publishers' handles: let go
            getattr(self, '_tf_group', PublisherGroup([])).close()
            if getattr(self, '_outputs', None) is not None:
                self._outputs.close_groups()
        return super().destroy_node()

    def _publish_diagnostics(self):
        msg = DiagnosticArray()
        msg.header.stamp = self.get_clock().now().to_msg()
        with self._lock:
            msg.status = [self.diagnostics()]
            self._lost_reported = self._gaps.lost
        self._diag_pub.publish(msg)


def main(args=None) -> int:
    """Run dq_fk_node until SIGINT/SIGTERM (as ``ros2 run dq_fk_ros dq_fk_node``)."""
    usage = help_text('dq_fk_node', 'sensor_msgs/JointState in (joint_states), every link '
                      'frame out: /tf, /tf_static, ~/pose/<frame>, ~/twist/<frame>, the '
                      'robot_description; see the README, "dq_fk_node".', NODE_PARAMETERS)
    return spin_until_shutdown('dq_fk_node', DqFkNode, DqFkError, args, usage)


if __name__ == '__main__':
    sys.exit(run_main(main))
