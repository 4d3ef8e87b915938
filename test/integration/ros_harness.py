"""A test-side rclpy context: probe node, publishers, subscriptions and a spin loop."""

import contextlib
import itertools
import os
import time

from dq_fk_ros.ros.node import DqFkNode
import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState

# as tf2_ros's StaticListenerQoS: a reader depth of 1 would keep only one of several
# static broadcasters' latched messages
TF_STATIC_QOS = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE,
                           durability=DurabilityPolicy.TRANSIENT_LOCAL)


# the programs whose node a test may address by name: each started under a name of its own
# (another run's or another user's node of the same program never answers for it)
NODE_NAMES = {'dq_fk_node': 'dq_fk_node', 'fake_joint_publisher': 'fake_joint_publisher',
              'dq_fk_foxglove': 'dq_fk_foxglove'}
_started = itertools.count()


def unique_node_name(base):
    """Return a node name no other test, run or user on this machine has: base_pid_n."""
    return f'{base}_{os.getpid()}_{next(_started)}'


EVERY_UPDATE = 'publish_frequency:=0.0'


@contextlib.contextmanager
def own_node(name):
    """Yield an rclpy node in a context of its own; destroyed and shut down afterwards."""
    context = rclpy.Context()
    rclpy.init(context=context)
    node = rclpy.create_node(name, context=context)
    try:
        yield node
    finally:
        node.destroy_node()
        rclpy.shutdown(context=context)


def start(processes, name, *params, namespace=None, log_level='warn', options=(), env=None):
    """
    Start one of the package's programs with ``-p`` parameters, reaped by ``processes``.

    The plugin's ``dq_fk_processes.start_program`` with this suite's choices:

    ``options`` go before ``--ros-args`` (a program's own command line, dq_fk_foxglove's).
    dq_fk_node, fake_joint_publisher and dq_fk_foxglove run under a unique node name (the process's
    ``node_name``; its private topics are under it: :func:`node_topic`). dq_fk_node sends
    /tf at every update (``publish_frequency:=0.0``, :data:`EVERY_UPDATE`) unless ``params``
    set ``publish_frequency``: the tests count and compare updates; test_urdf_node.py
    checks the default (robot_state_publisher's 20 Hz). ``env``: variables set for it alone.
    """
    node_name = unique_node_name(NODE_NAMES[name]) if name in NODE_NAMES else None
    if name == 'dq_fk_node' and not any(p.startswith('publish_frequency:=') for p in params):
        params = (EVERY_UPDATE,) + params
    return processes.start_program(name, *params, node_name=node_name, namespace=namespace,
                                   log_level=log_level, options=options, env=env)


def node_topic(proc, relative):
    """Return the full name of a started node's private topic (``~/relative``)."""
    return f'{proc.namespace}/{proc.node_name}/{relative}'


class Harness:
    """One rclpy context with the node under test, a probe node and an executor."""

    def __init__(self, joint_states_topic='joint_states'):
        self.context = rclpy.Context()
        rclpy.init(context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.nodes = []
        self.probe = self.add(rclpy.create_node(unique_node_name('dq_fk_test_probe'),
                                                context=self.context))
        self.node_name = None
        self.joint_pub = self.probe.create_publisher(JointState, joint_states_topic, 10)
        self.received = {}

    def add(self, node):
        self.nodes.append(node)
        self.executor.add_node(node)
        return node

    def start_node(self, **params):
        """Start a DqFkNode in this context under a unique name; /tf at every update (as start)."""
        params.setdefault('publish_frequency', 0.0)
        if params['publish_frequency'] is None:  # the node's own default
            del params['publish_frequency']
        overrides = [Parameter(k, value=v) for k, v in params.items()]
        self.node_name = unique_node_name('dq_fk_node')
        return self.add(DqFkNode(context=self.context, parameter_overrides=overrides,
                                 cli_args=['--ros-args', '-r', f'__node:={self.node_name}']))

    def topic(self, relative):
        """Return the full name of ``~/relative`` for the last started node."""
        return f'/{self.node_name}/{relative}'

    def listen(self, msg_type, topic, qos=10):
        self.received[topic] = []
        self.probe.create_subscription(msg_type, topic, self.received[topic].append, qos)
        return self.received[topic]

    def joint_state(self, names, positions, velocities=(), stamp=None):
        msg = JointState()
        msg.name = list(names)
        msg.position = [float(v) for v in positions]
        msg.velocity = [float(v) for v in velocities]
        msg.header.stamp = stamp if stamp is not None else self.probe.get_clock().now().to_msg()
        return msg

    def spin_until(self, predicate, timeout_s=10.0, publish=None):
        """Spin (publishing ``publish`` every 50 ms if given) until ``predicate()`` holds."""
        deadline = time.monotonic() + timeout_s
        next_pub = 0.0
        while time.monotonic() < deadline:
            if publish is not None and time.monotonic() >= next_pub:
                self.joint_pub.publish(publish)
                next_pub = time.monotonic() + 0.05
            self.executor.spin_once(timeout_sec=0.01)
            if predicate():
                return True
        return False

    def close(self):
        for node in self.nodes:
            self.executor.remove_node(node)
            node.destroy_node()
        self.executor.shutdown()
        rclpy.shutdown(context=self.context)


def set_robot_file(harness, path, node):
    """Set a running node's ``robot_description_file`` through its parameter service."""
    from rclpy.parameter_client import AsyncParameterClient
    client = AsyncParameterClient(harness.probe, node)
    assert client.wait_for_services(timeout_sec=10.0)
    future = client.set_parameters([Parameter('robot_description_file', value=str(path))])
    harness.spin_until(future.done)
    assert future.result().results[0].successful
