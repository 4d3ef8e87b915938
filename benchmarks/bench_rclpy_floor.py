"""
rclpy's own floor: the CPU of a node whose raw JointState subscription does nothing.

A separate process (this script with ``--node MODE``) spins a node with two timers and the
parameter services, as dq_fk_node, and one raw subscription that does nothing, taken:

- ``executor``: by rclpy's SingleThreadedExecutor (a callback of the node);
- ``thread``: by dq_fk_node's input thread (``dq_fk_ros.ros.raw_input``), at once;
- ``thread-batch``: by that thread with dq_fk_node's default window (``input_batch_ms``).

bench_e2e's raw publisher sends it 1 kHz for 5 s (node on CPU 1, publisher on CPU 0 where
taskset exists). Prints per mode the node's CPU share of a core and CPU microseconds per
message while messages flow: what any rclpy node pays per wake-up before it does any work.

Then the sending side (``--send-tf``): a process on CPU 1 that only publishes the RL15's
serialized /tf message (7 transforms) at 1 kHz for 3 s, reliable as dq_fk_node's /tf, to a
reliable subscriber in this script's process; it prints its CPU and how often Fast DDS's
event thread woke per message.

Run with ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST and a private ROS_DOMAIN_ID
(``make bench`` sets both): ``python benchmarks/bench_rclpy_floor.py``.
"""

import os
import signal
import subprocess
import sys
import time

from bench_e2e import pinned  # a sibling script: python puts benchmarks/ on sys.path
from dq_fk_ros.ros.node_parameters import INPUT_BATCH_MS_DEFAULT
from dq_fk_ros.ros.raw_input import RawSubscriptionThread
from geometry_msgs.msg import TransformStamped
import rclpy
from rclpy.executors import ExternalShutdownException
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rclpy.serialization import serialize_message
from sensor_msgs.msg import JointState
from tf2_msgs.msg import TFMessage

HERE = os.path.dirname(os.path.abspath(__file__))

MODES = ('executor', 'thread', 'thread-batch')
BATCH_S = INPUT_BATCH_MS_DEFAULT / 1000.0  # dq_fk_node's input_batch_ms


def node_main(mode):
    rclpy.init(args=['--ros-args', '--log-level', 'warn'])
    node = rclpy.create_node('dq_fk_bench_floor')
    count = [0]
    first = [None]  # time, CPU times and count at the first message

    def on_message(*_):
        if first[0] is None:
            first[0] = (time.monotonic(), os.times(), count[0])
        count[0] += 1
    qos = QoSProfile(depth=100, reliability=ReliabilityPolicy.BEST_EFFORT)
    if mode == 'executor':
        node.create_subscription(JointState, 'joint_states', on_message, qos, raw=True)
    else:
        RawSubscriptionThread(node, JointState, '/joint_states', qos, on_message,
                              BATCH_S if mode == 'thread-batch' else 0.0)
    node.create_timer(1.0, lambda: None)
    node.create_timer(0.5, lambda: None)
    try:
        rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    t1, c1 = time.monotonic(), os.times()  # (0.3 s idle after the last message included)
    t0, c0, n0 = first[0]
    cpu = (c1.user + c1.system) - (c0.user + c0.system)
    print(f'| {mode} | {count[0] - n0} | {t1 - t0:.1f} | {100 * cpu / (t1 - t0):.1f} '
          f'| {1e6 * cpu / max(count[0] - n0, 1):.0f} |', flush=True)
    os._exit(0)  # the input thread's helper node needs no orderly teardown here


def voluntary_switches(prefix):
    """Voluntary context switches so far of this process's threads whose names start so."""
    total = 0
    for task in os.listdir('/proc/self/task'):
        with open(f'/proc/self/task/{task}/comm') as stream:
            if not stream.read().startswith(prefix):
                continue
        with open(f'/proc/self/task/{task}/status') as stream:
            total += int(stream.read().split('voluntary_ctxt_switches:')[1].split()[0])
    return total


def send_tf_main(count=3000, rate_hz=1000.0):
    """Publish a serialized 7-transform TFMessage at ``rate_hz``; print CPU and DDS wakes."""
    rclpy.init(args=['--ros-args', '--log-level', 'warn'])
    node = rclpy.create_node('dq_fk_bench_send_tf')
    pub = node.create_publisher(TFMessage, '/tf',
                                QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE))
    raw = serialize_message(TFMessage(transforms=[TransformStamped()] * 7))
    deadline = time.monotonic() + 20
    while pub.get_subscription_count() < 1 and time.monotonic() < deadline:
        time.sleep(0.01)
    time.sleep(0.5)  # the subscriber's side of the match
    wakes, c0, start = voluntary_switches('dds.ev'), os.times(), time.monotonic()
    for k in range(count):
        delay = start + k / rate_hz - time.monotonic()
        if delay > 0:
            time.sleep(delay)
        pub.publish(raw)
    c1, wakes = os.times(), voluntary_switches('dds.ev') - wakes
    seconds = time.monotonic() - start
    cpu = (c1.user + c1.system) - (c0.user + c0.system)
    print(f'| send /tf only | {count} | {seconds:.1f} | {100 * cpu / seconds:.1f} '
          f'| {1e6 * cpu / count:.0f} | {wakes / count:.1f} |', flush=True)
    os._exit(0)


def send_tf_row():
    """Run :func:`send_tf_main` in a process of its own against a subscriber here."""
    rclpy.init(args=['--ros-args', '--log-level', 'warn'])
    node = rclpy.create_node('dq_fk_bench_tf_sink')
    node.create_subscription(TFMessage, '/tf', lambda _: None,
                             QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE),
                             raw=True)
    sender = subprocess.Popen(pinned([sys.executable, __file__, '--send-tf'], 1))
    try:
        while sender.poll() is None:
            rclpy.spin_once(node, timeout_sec=0.05)
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
    return sender.returncode


def main():
    if sys.argv[1:2] == ['--node']:
        return node_main(sys.argv[2])
    if sys.argv[1:2] == ['--send-tf']:
        return send_tf_main()
    print('# rclpy floor: a node with one raw subscription that does nothing, at 1 kHz')
    print('| taken by | messages | seconds | CPU % of a core | CPU us per message |')
    print('|---|---|---|---|---|')
    for mode in MODES:
        node = subprocess.Popen(pinned([sys.executable, __file__, '--node', mode], 1))
        time.sleep(2.0)
        subprocess.run(pinned([sys.executable, os.path.join(HERE, 'bench_e2e.py'),
                               '--publish', '1000', '5000', '0'], 0), check=True)
        time.sleep(0.3)
        node.send_signal(signal.SIGINT)
        node.wait(timeout=10)
    print('\n# the sending side: a process that only publishes /tf (7 transforms, reliable) at '
          '1 kHz to a subscriber in another process')
    print('| what | messages | seconds | CPU % of a core | CPU us per message '
          '| DDS event thread wake-ups per message |')
    print('|---|---|---|---|---|---|')
    return send_tf_row()


if __name__ == '__main__':
    sys.exit(main())
