"""
dq_fk_foxglove's CPU with a 1 kHz robot: raw JointStates -> dq_fk_node -> dq_fk_foxglove.

Four processes on loopback: ``bench_e2e.py``'s raw publisher (1 kHz, pinned to CPU 0), the
node (``publish_frequency:=0.0``: ``/tf`` at every update, pinned to CPU 1), dq_fk_foxglove
(unpinned) and, in this script, one Foxglove client (the tests' own, written from the
protocol's spec) subscribed to what a 3D panel reads (``/tf``, ``/tf_static``,
``/robot_description``), then to every channel (``/joint_states`` and the end effector's
pose topic too: dq_fk_foxglove subscribes to those only while a client does). For each
robot and case it prints the messages a second the client received per channel and
dq_fk_foxglove's CPU (share of one core, from /proc) over the run, beside the target (issue
"Foxglove live on a pip-only ROS": at most 10 % of a core). The floor, measured in the same
run in place of dq_fk_foxglove: a bare rclpy process with the same raw subscriptions (``/tf``
and, for every channel, ``/joint_states`` and the pose topic), taking what is queued 30 times
a second and discarding it: what receiving the streams from DDS costs before any Foxglove
work.

Run with ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST and a private ROS_DOMAIN_ID (``make bench``
sets both): ``python benchmarks/bench_foxglove.py [--seconds 10] [--robots rl15 tiago_dual]``.
"""

import argparse
import os
import select
import subprocess
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(os.path.dirname(HERE), 'test', 'integration'))
sys.path.insert(0, HERE)
from bench_e2e import cpu_seconds, start_node, start_publisher, stop  # noqa: E402
from bench_node import example_robot_data  # noqa: E402
from bench_results import figure  # noqa: E402
from dq_fk_ros.ros.executables import executable  # noqa: E402, I100
from foxglove_client import FoxgloveClient  # noqa: E402 (the tests' spec-written client)

ROBOTS = {'rl15': ('rl15', 'eeCarry_seg6'),
          'tiago_dual': ('tiago_description/robots/tiago_dual.urdf', 'arm_left_tool_link')}
TARGET_CPU = 10.0


def start_foxglove():
    """Start dq_fk_foxglove on a free port; return ``(process, ws:// URL)``."""
    proc = subprocess.Popen(executable('dq_fk_foxglove') + ['--port', '0'],
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                            start_new_session=True)
    deadline = time.monotonic() + 30
    while time.monotonic() < deadline:
        ready, _, _ = select.select([proc.stdout], [], [], 0.2)
        if ready:
            line = proc.stdout.readline()
            if 'Foxglove WebSocket > ' in line:
                return proc, line.rsplit('> ', 1)[1].strip()
        if proc.poll() is not None:
            break
    stop(proc)
    raise SystemExit('bench_foxglove: dq_fk_foxglove did not start')


def floor_subscriber(topics):
    """Take ``topics`` raw as dq_fk_foxglove does (30 times a second), discard, until SIGINT."""
    import rclpy
    from geometry_msgs.msg import PoseStamped
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from sensor_msgs.msg import JointState
    from tf2_msgs.msg import TFMessage
    from dq_fk_ros.viewers.foxglove_live import DEFAULT_RATE_HZ, QUEUE_DEPTH
    from dq_fk_ros.ros.raw_input import take_queued
    rclpy.init()
    node = rclpy.create_node('bench_foxglove_floor', start_parameter_services=False,
                             enable_rosout=False)
    subscriptions = []
    for topic in topics:
        kind = {'/tf': TFMessage, '/joint_states': JointState}.get(topic, PoseStamped)
        depth = QUEUE_DEPTH if topic == '/tf' else 1
        subscriptions.append(node.create_subscription(
            kind, topic, lambda _: None,
            QoSProfile(depth=depth, reliability=ReliabilityPolicy.BEST_EFFORT), raw=True))
    try:
        while True:
            time.sleep(1.0 / DEFAULT_RATE_HZ)
            for subscription in subscriptions:
                take_queued(subscription, lambda raw: None)
    except KeyboardInterrupt:
        pass
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
    return 0


def run_floor(robot, end_effector, seconds, everything, rate_hz=1000.0):
    """Return the floor subscriber's CPU % of a core in place of dq_fk_foxglove."""
    node = start_node([f'robot_description_file:={robot}'])
    topics = ['/tf'] + (['/joint_states', f'/dq_fk_node/pose/{end_effector}']
                        if everything else [])
    floor = subprocess.Popen([sys.executable, os.path.abspath(__file__), '--floor', *topics],
                             start_new_session=True)
    publisher = None
    try:
        publisher = start_publisher(rate_hz, int(rate_hz * (seconds + 6)), False, robot)
        time.sleep(4.0)  # matched, and past the start-up
        start, cpu0 = time.monotonic(), cpu_seconds(floor.pid)
        time.sleep(seconds)
        return 100.0 * (cpu_seconds(floor.pid) - cpu0) / (time.monotonic() - start)
    finally:
        stop(publisher, floor, node)


def run(robot, end_effector, seconds, everything, rate_hz=1000.0):
    """Return ``{channel: messages/s}`` and dq_fk_foxglove's CPU % of a core, for one robot."""
    node = start_node([f'robot_description_file:={robot}'])
    fox, url = start_foxglove()
    publisher = client = None
    try:
        client = FoxgloveClient(url)
        pose = next(c['topic'] for c in _wait_channels(client, end_effector))
        client.subscribe('/tf', '/tf_static', '/robot_description',
                         *(['/joint_states', pose] if everything else []))
        publisher = start_publisher(rate_hz, int(rate_hz * (seconds + 6)), False, robot)
        _wait(lambda: client.messages.get('/tf'), 30)
        time.sleep(2.0)  # past the start-up
        counts = {topic: len(client.messages.get(topic, [])) for topic in
                  ('/tf', '/joint_states', pose)}
        start, cpu0 = time.monotonic(), cpu_seconds(fox.pid)
        time.sleep(seconds)
        elapsed, cpu = time.monotonic() - start, cpu_seconds(fox.pid) - cpu0
        rates = {topic: (len(client.messages.get(topic, [])) - n) / elapsed
                 for topic, n in counts.items()}
        return rates, 100.0 * cpu / elapsed
    finally:
        if client is not None:
            client.close()
        stop(publisher, fox, node)


def _wait(predicate, timeout_s):
    deadline = time.monotonic() + timeout_s
    while not predicate():
        if time.monotonic() > deadline:
            raise SystemExit('bench_foxglove: nothing arrived')
        time.sleep(0.05)


def _wait_channels(client, frame):
    """Return the advertised pose channel of ``frame`` (once the node's topics are seen)."""
    _wait(lambda: any(c['topic'].endswith(f'/pose/{frame}') for c in
                      list(client.channels.values())), 30)
    return [c for c in list(client.channels.values()) if c['topic'].endswith(f'/pose/{frame}')]


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.strip().splitlines()[0])
    parser.add_argument('--seconds', type=float, default=10.0)
    parser.add_argument('--robots', nargs='+', default=list(ROBOTS), choices=list(ROBOTS))
    parser.add_argument('--floor', nargs='+', metavar='TOPIC', help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.floor:
        return floor_subscriber(args.floor)
    print(f'# dq_fk_foxglove at 1 kHz in: raw publisher (CPU 0) -> dq_fk_node (CPU 1) -> '
          f'dq_fk_foxglove --rate 30 (unpinned) -> one client; {args.seconds:g} s per robot, '
          f'{os.cpu_count()} CPUs')
    print('| robot | client subscribed to | /tf msg/s | /joint_states msg/s | end-effector '
          'pose msg/s | dq_fk_foxglove CPU % of a core | target | floor: bare rclpy '
          'subscriber CPU % |')
    print('|---|---|---|---|---|---|---|---|')
    for name in args.robots:
        path, end_effector = ROBOTS[name]
        robot = path if name == 'rl15' else example_robot_data(path)
        for everything in (False, True):
            rates, cpu = run(robot, end_effector, args.seconds, everything)
            floor = run_floor(robot, end_effector, args.seconds, everything)
            tf, joints, pose = rates.values()
            verdict = 'met' if cpu <= TARGET_CPU else 'NOT met'
            what = 'every channel' if everything else "a 3D panel's"
            print(f'| {name} | {what} | {tf:.1f} | {joints:.1f} | {pose:.1f} | {cpu:.1f} '
                  f'| <= {TARGET_CPU:g} %: {verdict} | {floor:.1f} |', flush=True)
            figure(f'{name}, {what}: dq_fk_foxglove CPU at 1 kHz', round(cpu, 1),
                   '% of a core', f'<= {TARGET_CPU:g} %', cpu <= TARGET_CPU,
                   group='dq_fk_foxglove', show=False)
            figure(f'{name}, {what}: the floor (a bare rclpy subscriber)', round(floor, 1),
                   '% of a core', group='dq_fk_foxglove', show=False)
    return 0


if __name__ == '__main__':
    sys.exit(main())
