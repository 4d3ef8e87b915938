"""
End to end over DDS: fake_joint_publisher -> dq_fk_node -> a /tf subscriber, three processes.

For each rate (default 100, 500 and 1000 Hz, 10 s each) the publisher sends
``rate * seconds`` RL15 joint states (sine mode, default QoS); this script subscribes to /tf
as a tf2 listener would (reliable, depth 100) and prints: updates sent, /tf messages
received, lost, the latency from the JointState stamp to arrival here (p50, p99, max), the
rate actually achieved, and the node's CPU use (share of one core, from /proc).

Run with ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST and a private ROS_DOMAIN_ID
(``make bench`` sets both): ``python benchmarks/bench_e2e.py [--rates 100 500 1000]``.
"""

import argparse
import os
import signal
import subprocess
import sys
import time

from dq_fk_ros.ros.executables import executable
import numpy as np
import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import QoSProfile, ReliabilityPolicy
from tf2_msgs.msg import TFMessage


def cpu_seconds(pid):
    """User + system CPU seconds of a process so far (Linux /proc)."""
    with open(f'/proc/{pid}/stat') as stream:
        fields = stream.read().rsplit(')', 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf('SC_CLK_TCK')


def run_rate(rate_hz, seconds):
    """One measurement; returns a dict of figures."""
    log = ['--ros-args', '--log-level', 'warn']
    node_proc = subprocess.Popen(executable('dq_fk_node') + log, start_new_session=True)
    rclpy.init(args=log)
    probe = rclpy.create_node('dq_fk_bench_e2e')
    executor = SingleThreadedExecutor()
    executor.add_node(probe)
    latencies_ns, stamps = [], set()

    def on_tf(msg):
        arrival = time.time_ns()
        stamp = msg.transforms[0].header.stamp
        ns = stamp.sec * 1_000_000_000 + stamp.nanosec
        latencies_ns.append(arrival - ns)
        stamps.add(ns)
    probe.create_subscription(TFMessage, '/tf', on_tf,
                              QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE))
    pub_proc = None
    try:
        deadline = time.monotonic() + 20
        while probe.count_publishers('/tf') < 1 or probe.count_subscribers('/tf') < 1:
            if time.monotonic() > deadline:
                raise RuntimeError('dq_fk_node did not come up within 20 s')
            executor.spin_once(timeout_sec=0.05)
        total = int(rate_hz * seconds)
        pub_proc = subprocess.Popen(executable('fake_joint_publisher') + log + [
            '-p', 'mode:=sine', '-p', f'rate_hz:={float(rate_hz)}', '-p',
            f'max_messages:={total}', '-p', 'wait_for_subscribers:=1'],
            start_new_session=True)
        cpu_start, wall_start = cpu_seconds(node_proc.pid), time.monotonic()
        deadline = time.monotonic() + seconds * 3 + 20
        last_count, quiet_since = -1, time.monotonic()
        while len(stamps) < total and time.monotonic() < deadline:
            executor.spin_once(timeout_sec=0.05)
            if len(stamps) != last_count:
                last_count, quiet_since = len(stamps), time.monotonic()
            elif stamps and time.monotonic() - quiet_since > 3.0:
                break  # nothing more is coming
        cpu = cpu_seconds(node_proc.pid) - cpu_start
        wall = time.monotonic() - wall_start
    finally:
        for proc in (pub_proc, node_proc):
            if proc is not None:
                proc.send_signal(signal.SIGINT)
        for proc in (pub_proc, node_proc):
            if proc is not None:
                try:
                    proc.wait(timeout=10)
                except subprocess.TimeoutExpired:
                    proc.kill()
        probe.destroy_node()
        rclpy.try_shutdown()
    lat_ms = np.array(latencies_ns) / 1e6
    span_s = (max(stamps) - min(stamps)) / 1e9 if len(stamps) > 1 else float('nan')
    return {'rate': rate_hz, 'sent': total, 'received': len(stamps),
            'lost': total - len(stamps),
            'achieved_hz': (len(stamps) - 1) / span_s if span_s else float('nan'),
            'p50': np.percentile(lat_ms, 50) if len(lat_ms) else float('nan'),
            'p99': np.percentile(lat_ms, 99) if len(lat_ms) else float('nan'),
            'max': lat_ms.max() if len(lat_ms) else float('nan'),
            'cpu': 100.0 * cpu / wall}


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.strip().splitlines()[0])
    parser.add_argument('--rates', type=float, nargs='+', default=[100, 500, 1000])
    parser.add_argument('--seconds', type=float, default=10.0)
    args = parser.parse_args(argv)
    rows = [run_rate(rate, args.seconds) for rate in args.rates]
    print(f'# end to end: fake_joint_publisher -> dq_fk_node -> /tf subscriber, RL15, '
          f'{args.seconds:g} s per rate, {os.cpu_count()} CPUs, loopback')
    print('| rate Hz | sent | received on /tf | lost | achieved Hz | latency p50 ms '
          '| p99 ms | max ms | node CPU % of a core |')
    print('|---|---|---|---|---|---|---|---|---|')
    for r in rows:
        print(f"| {r['rate']:g} | {r['sent']} | {r['received']} | {r['lost']} "
              f"| {r['achieved_hz']:.0f} | {r['p50']:.3f} | {r['p99']:.3f} | {r['max']:.3f} "
              f"| {r['cpu']:.0f} |")
    return 0


if __name__ == '__main__':
    sys.exit(main())
