"""
The node's memory under a flood of oversized JointStates (docs/security.md).

Starts dq_fk_node (RL15) with each ``qos_depth``, then publishes, as fast as one process can,
JointStates of ``names`` joints for ``--seconds`` per kind: kinds the node refuses (more
than 1024 names, more than 64 KiB) and the largest kind it takes. Prints the node's resident
memory (VmRSS) before and after each flood. DDS holds up to ``qos_depth`` messages for the
subscription, of any size, before the node takes (and refuses) them, and keeps that memory:
the figure to compare is RSS against qos_depth x message size.

Run with ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST and a private ROS_DOMAIN_ID (``make bench``
sets both): ``python benchmarks/bench_flood_memory.py [--depths 1000 100] [--seconds 5]``.
"""

import argparse
import time

from dq_fk_ros.ros.executables import executable
import rclpy
from sensor_msgs.msg import JointState

KINDS = (  # (what, names, characters per name)
    ('10 000 names (refused: > 1024 names)', 10_000, 30),
    ('1000 names of 200 characters (refused: > 64 KiB)', 1000, 200),
    ('1000 names of 50 characters (taken: 58 KiB, none of them joints of the robot)',
     1000, 50),
)


def rss_mib(pid):
    """Return the resident memory of a process in MiB (Linux /proc)."""
    with open(f'/proc/{pid}/status', encoding='ascii') as status:
        line = next(line for line in status if line.startswith('VmRSS'))
    return int(line.split()[1]) / 1024


def flood(pid, depth, seconds):
    rclpy.init()
    node = rclpy.create_node('bench_flood')
    try:
        pub = node.create_publisher(JointState, 'joint_states', 1000)
        deadline = time.monotonic() + 10
        while pub.get_subscription_count() < 1 and time.monotonic() < deadline:
            time.sleep(0.05)
        time.sleep(1.0)
        print(f'qos_depth {depth}: node at start {rss_mib(pid):.0f} MiB')
        for what, count, chars in KINDS:
            msg = JointState()
            msg.name = [f'joint_{k:05d}'.ljust(chars, 'x') for k in range(count)]
            msg.position = [0.0] * count
            sent, end = 0, time.monotonic() + seconds
            while time.monotonic() < end:
                pub.publish(msg)
                sent += 1
            time.sleep(1.0)
            print(f'  after {sent} messages of {what}: {rss_mib(pid):.0f} MiB')
    finally:
        node.destroy_node()
        rclpy.shutdown()


def main():
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--depths', type=int, nargs='+', default=[1000, 100])
    parser.add_argument('--seconds', type=float, default=5.0)
    args = parser.parse_args()
    import subprocess
    print('dq_fk_node memory under a flood of oversized JointStates (VmRSS; no target: the '
          'docs/security.md states the bound qos_depth x message size)')
    for depth in args.depths:
        proc = subprocess.Popen(executable('dq_fk_node') + ['--ros-args', '-p',
                                                            f'qos_depth:={depth}'],
                                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        try:
            time.sleep(2.0)
            flood(proc.pid, depth, args.seconds)
        finally:
            proc.terminate()
            proc.wait(timeout=10)


if __name__ == '__main__':
    main()
