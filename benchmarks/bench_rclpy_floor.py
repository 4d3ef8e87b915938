"""
rclpy's own floor: the CPU of a node whose raw JointState subscription does nothing.

A separate process (this script with ``--node``) spins a node with one raw subscription
(and, like dq_fk_node, two timers and the parameter services) under rclpy's
SingleThreadedExecutor; bench_e2e's raw publisher sends it 1 kHz for 5 s. Prints the
node's CPU share of a core and CPU microseconds per message while messages flow: what any
rclpy node pays per wake-up before it does any work.

Run with ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST and a private ROS_DOMAIN_ID
(``make bench`` sets both): ``python benchmarks/bench_rclpy_floor.py``.
"""

import os
import signal
import subprocess
import sys
import time

import rclpy
from rclpy.executors import ExternalShutdownException
from rclpy.qos import QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState

HERE = os.path.dirname(os.path.abspath(__file__))


def node_main():
    rclpy.init(args=['--ros-args', '--log-level', 'warn'])
    node = rclpy.create_node('dq_fk_bench_floor')
    count = [0]
    first = [None]  # time, CPU times and count at the first message

    def on_message(_):
        if first[0] is None:
            first[0] = (time.monotonic(), os.times(), count[0])
        count[0] += 1
    node.create_subscription(JointState, 'joint_states', on_message,
                             QoSProfile(depth=100, reliability=ReliabilityPolicy.BEST_EFFORT),
                             raw=True)
    node.create_timer(1.0, lambda: None)
    node.create_timer(0.5, lambda: None)
    try:
        rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    t1, c1 = time.monotonic(), os.times()  # (0.3 s idle after the last message included)
    t0, c0, n0 = first[0]
    cpu = (c1.user + c1.system) - (c0.user + c0.system)
    print(f'{count[0] - n0} messages in {t1 - t0:.1f} s: {100 * cpu / (t1 - t0):.0f} % of a '
          f'core, {1e6 * cpu / max(count[0] - n0, 1):.0f} us of CPU per message')


def main():
    if sys.argv[1:] == ['--node']:
        return node_main()
    node = subprocess.Popen([sys.executable, __file__, '--node'], stdout=subprocess.PIPE,
                            text=True)
    time.sleep(2.0)
    subprocess.run([sys.executable, os.path.join(HERE, 'bench_e2e.py'), '--publish', '1000',
                    '5000', '0'], check=True)
    time.sleep(0.3)
    node.send_signal(signal.SIGINT)
    out, _ = node.communicate(timeout=10)
    print('# rclpy floor: a node with one raw subscription that does nothing, at 1 kHz')
    print(out.strip())
    return 0


if __name__ == '__main__':
    sys.exit(main())
