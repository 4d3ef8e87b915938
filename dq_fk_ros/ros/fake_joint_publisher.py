"""
fake_joint_publisher: ``sensor_msgs/JointState`` for a robot description, for demos and tests.

Modes: ``zeros``; ``fixed`` (the ``positions`` parameter); ``sine`` (each joint sweeps
within its limits with a period of its own); ``random_walk`` (seeded, reproducible).

The robot comes, as joint_state_publisher takes it, from the ``robot_description``
parameter (URDF XML), else from ``robot_description_file``, else, with ``from_topic:=true``,
from the ``robot_description`` topic (transient local: the node's, robot_state_publisher's;
a new description replaces the robot, nothing is published before the first), else rl15.
``fault_fraction`` mixes malformed messages (wrong lengths, NaN, unknown names) into the
stream, for robustness tests. The motion itself is plain Python (:class:`JointMotion`).
"""

import math
import sys

from dq_fk_ros.description.from_urdf import NODE_OPTIONS
from dq_fk_ros.description.loading import load_robot, robot_from_urdf_text
from dq_fk_ros.errors import DqFkError
from dq_fk_ros.ros.executables import MATCH_SETTLE_S, run_main, spin_until_shutdown
from dq_fk_ros.ros.package_paths import declare_package_paths
from dq_fk_ros.ros.parameters import declare, help_text, Param
import numpy as np
import rclpy
from rclpy.duration import Duration
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState
from std_msgs.msg import String

MODES = ('zeros', 'fixed', 'sine', 'random_walk')
FAULTS = ('wrong_length', 'nan', 'unknown_names')
# range swept by joints without limits: +-1 rad (revolute) or +-0.1 m (prismatic)
UNBOUNDED_HALF_RANGE = 1.0
ACK_TIMEOUT_S = 5.0  # max_messages: longest wait for reliable subscribers before exiting


# the publisher's parameters (declared from this table; `fake_joint_publisher --help`)
FAKE_PARAMETERS = (
    Param('robot_description_file', '',
          'the robot whose joints to publish (every joint of a tree): DH YAML, URDF/xacro or '
          'a shipped name; empty: rl15'),
    Param('robot_description', '',
          'URDF XML, as joint_state_publisher takes it; if set, used instead of '
          'robot_description_file'),
    Param('from_topic', False,
          'with neither parameter set: take the robot from the robot_description topic, as '
          'joint_state_publisher does (a new description replaces it)'),
    Param('urdf_base_link', '', 'for a URDF: the link the robot starts at'),
    Param('urdf_tip_link', '', 'for a URDF: the link the first DH chain ends at'),
    Param('mode', 'sine', f'one of {", ".join(MODES)}'),
    Param('rate_hz', 50.0, 'messages per second'),
    Param('positions', [0.0], "joint positions for fixed mode (rad, m), in the robot's joint "
          'order'),
    Param('publish_velocities', True, 'fill JointState.velocity'),
    Param('amplitude', 0.8, 'sine: fraction of each half range swept'),
    Param('seed', 0, 'random_walk and fault injection seed'),
    Param('fault_fraction', 0.0, 'fraction of messages sent malformed (0..1)'),
    Param('max_messages', 0, 'stop publishing after this many; 0: never'),
    Param('wait_for_subscribers', 0, 'start publishing once this many subscriptions matched'),
)


class JointMotion:
    """
    Joint positions and velocities over time for one of :data:`MODES`; no ROS.

    :param limits: ``(dof, 2)`` joint limits (+-inf for none).
    :param fixed: positions for ``fixed`` mode.
    :param amplitude: fraction of each joint's half range that ``sine`` sweeps.
    :param seed: seed of ``random_walk``.
    """

    def __init__(self, mode, limits, fixed=None, amplitude=0.8, seed=0):
        """Prepare centres, ranges and periods of every joint."""
        if mode not in MODES:
            raise ValueError(f'mode {mode!r} is not one of {", ".join(MODES)}')
        self.mode = mode
        limits = np.asarray(limits, dtype=float)
        dof = len(limits)
        bounded = np.isfinite(limits).all(axis=1)
        lower = np.where(bounded, limits[:, 0], -UNBOUNDED_HALF_RANGE)
        upper = np.where(bounded, limits[:, 1], UNBOUNDED_HALF_RANGE)
        self.center = 0.5 * (lower + upper)
        self.half_range = 0.5 * (upper - lower)
        self.amplitude = amplitude * self.half_range
        self.period_s = 4.0 + 1.5 * np.arange(dof)  # a period of its own per joint
        self.limits = limits
        if fixed is not None and len(fixed) != dof:
            raise ValueError(f'fixed mode needs {dof} positions, got {len(fixed)}')
        self.fixed = np.zeros(dof) if fixed is None else np.asarray(fixed, dtype=float)
        self._rng = np.random.default_rng(seed)
        self._walk = self.center.copy()
        self._walk_t = None

    def sample(self, t_s) -> tuple:
        """Return positions and velocities at ``t_s`` (seconds since the start)."""
        if self.mode == 'zeros':
            return np.zeros_like(self.center), np.zeros_like(self.center)
        if self.mode == 'fixed':
            return self.fixed.copy(), np.zeros_like(self.center)
        if self.mode == 'sine':
            omega = 2.0 * math.pi / self.period_s
            return (self.center + self.amplitude * np.sin(omega * t_s),
                    self.amplitude * omega * np.cos(omega * t_s))
        dt = 0.0 if self._walk_t is None else max(0.0, t_s - self._walk_t)
        self._walk_t = t_s
        step = self._rng.normal(scale=0.5 * self.half_range * math.sqrt(dt))
        previous = self._walk.copy()
        self._walk = np.clip(self._walk + step, self.limits[:, 0], self.limits[:, 1])
        velocity = (self._walk - previous) / dt if dt > 0 else np.zeros_like(previous)
        return self._walk.copy(), velocity


def malformed(names, positions, kind) -> tuple:
    """Return a broken copy ``(names, positions)`` of a joint state, fault ``kind``."""
    names, positions = list(names), list(positions)
    if kind == 'wrong_length':
        return names, positions[:-1]
    if kind == 'nan':
        positions[len(positions) // 2] = math.nan
        return names, positions
    return [f'not_a_joint_{k}' for k in range(len(names))], positions


class FakeJointPublisher(Node):
    """Publish joint states of a robot description at ``rate_hz``."""

    def __init__(self, **kwargs):
        """Declare parameters, load the robot and start the timer."""
        super().__init__('fake_joint_publisher', **kwargs)

        value = declare(self, FAKE_PARAMETERS)
        path, base, tip = (value[k] for k in ('robot_description_file', 'urdf_base_link',
                                              'urdf_tip_link'))
        mode, rate_hz, positions = value['mode'], value['rate_hz'], value['positions']
        amplitude, seed = value['amplitude'], value['seed']
        self._with_velocity = value['publish_velocities']
        self._fault_fraction = value['fault_fraction']
        self._max_messages = value['max_messages']
        self._wait_for = value['wait_for_subscribers']
        if not 0.0 <= self._fault_fraction <= 1.0:
            raise ValueError(f'fault_fraction must be in [0, 1], got {self._fault_fraction}')
        if not rate_hz > 0.0:
            raise ValueError(f'rate_hz must be positive, got {rate_hz}')
        packages = declare_package_paths(self)
        self._mode, self._positions = mode, positions
        self._amplitude, self._seed, self._base, self._tip = amplitude, seed, base, tip
        self._names, self._motion = None, None
        self._rng = np.random.default_rng(seed + 1)
        self._pub = self.create_publisher(JointState, 'joint_states', 10)
        self._start = self.get_clock().now()
        self.sent = {'valid': 0, 'malformed': 0}
        if value['robot_description']:
            self._use(robot_from_urdf_text(value['robot_description'], 'robot_description',
                                           base or None, tip or None,
                                           options=NODE_OPTIONS).model)
        elif path or not value['from_topic']:
            self._use(load_robot(path or 'rl15', base or None, tip or None,
                                 packages=packages, options=NODE_OPTIONS).model)
        else:
            latched = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                                 durability=DurabilityPolicy.TRANSIENT_LOCAL)
            self.create_subscription(String, 'robot_description', self._on_description,
                                     latched)
            self.get_logger().info('waiting for robot_description')
        self._timer = self.create_timer(1.0 / rate_hz, self._tick)

    def _use(self, model):
        """Publish ``model``'s joints from now on."""
        self._names = list(model.joint_names)
        self._motion = JointMotion(self._mode, model.limits,
                                   fixed=self._positions if self._mode == 'fixed' else None,
                                   amplitude=self._amplitude, seed=self._seed)
        self.get_logger().info(f'publishing {self._mode} joint states of {model.name} on '
                               f'{self._pub.topic_name}')

    def _on_description(self, msg):
        """Take a robot_description from the topic as the robot from now on (a bad one: logged)."""
        try:
            self._use(robot_from_urdf_text(msg.data, 'robot_description',
                                           self._base or None, self._tip or None,
                                           options=NODE_OPTIONS).model)
        except (DqFkError, ValueError) as exc:
            self.get_logger().error(str(exc)[:300])

    def _tick(self):
        if self._motion is None:
            return  # no robot yet (from_topic)
        if self._wait_for:
            if self._pub.get_subscription_count() < self._wait_for:
                return
            # our side has matched; give the subscribers' side time to match us too
            self._wait_for = 0
            self._start = self.get_clock().now() + Duration(seconds=MATCH_SETTLE_S)
        if self.get_clock().now() < self._start:
            return
        if self._max_messages and sum(self.sent.values()) >= self._max_messages:
            self._timer.cancel()
            # reliable subscribers get the last messages before we leave; then end the
            # process (exit code 0), as a finite publisher should
            self._pub.wait_for_all_acked(Duration(seconds=ACK_TIMEOUT_S))
            self.get_logger().info(f'sent {self.sent}; done (max_messages)')
            rclpy.try_shutdown(context=self.context)
            return
        now = self.get_clock().now()
        q, qdot = self._motion.sample((now - self._start).nanoseconds * 1e-9)
        msg = JointState()
        msg.header.stamp = now.to_msg()
        names, positions = self._names, q.tolist()
        if self._fault_fraction and self._rng.random() < self._fault_fraction:
            names, positions = malformed(names, positions, FAULTS[self._rng.integers(3)])
            self.sent['malformed'] += 1
        else:
            self.sent['valid'] += 1
        msg.name = names
        msg.position = positions
        if self._with_velocity:
            msg.velocity = qdot.tolist()[:len(positions)]
        self._pub.publish(msg)


def main(args=None) -> int:
    """Run fake_joint_publisher until SIGINT/SIGTERM."""
    usage = help_text('fake_joint_publisher', "sensor_msgs/JointState of a robot's joints on "
                      'joint_states, for demos and tests (zeros, fixed, sine, random_walk; '
                      'malformed messages mixed in on request).', FAKE_PARAMETERS)
    return spin_until_shutdown('fake_joint_publisher', FakeJointPublisher,
                               (DqFkError, ValueError), args, usage)


if __name__ == '__main__':
    sys.exit(run_main(main))
