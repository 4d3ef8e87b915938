"""
TF read back without tf2 (dq_fk_ros.tf): lookups, many stamps, a 1 kHz listener, a bag.

Prints each figure beside its target (issue "TF without tf2"):

(a) ``Buffer.lookup_transform`` between two leaves of a 130-frame tree (a binary tree, 100
    samples per edge) at an interpolated time, microseconds per call; beside it the floor of
    any Python lookup, rclpy constructing the empty ``TransformStamped`` it returns (target:
    within 2x of it), the real tf2_ros's 70-78 us measured when the issue was filed (target:
    at most 0.2x of it, 14 us; tf2_ros is not on PyPI, so not measured here), and, when
    ``.venv-bench`` has it, pytransform3d's ``TransformManager.get_transform`` on the same
    tree, static (its model has no time).
(b) ``Buffer.lookup_poses`` of 100 000 stamps on the same tree (target <= 0.1 s).
(c) a ``TransformListener`` process on tiago_dual's ``/tf`` at 1 kHz (bench_e2e's raw
    publisher -> dq_fk_node, ``publish_frequency:=0.0``): messages lost (target 0), its CPU
    as a share of one core (target <= 25 %) and its memory at the start and the end of the
    run after the 10 s cache filled (target: flat, less than 5 MiB more).
(d) ``dq_fk_bag tf`` (its function, in this process) over a bag of 300 000 RL15 ``/tf``
    messages beside rosbags' bare read of the same messages (target <= 1.5x).
(e) a hostile peer (issue "Nothing crashes, III"): 10 000 transforms of one frame at one
    stamp into ``Buffer.set_transform`` (51 s before; target <= 0.5 s), and 580 messages of
    200 such transforms stored as the listener stores them (``append_raw``) while another
    thread looks up an unrelated frame: the longest a lookup waited (2.8 s before; target
    <= 20 ms, a slice of 256 transforms and Python's 5 ms thread switch).
(f) tf2_sensor_msgs' ``do_transform_cloud`` of a 300 000-point cloud (x y z rgb intensity,
    float32): ours (``dq_fk_ros.ros.tf_cloud``) beside geometry2's with common_interfaces'
    sensor_msgs_py, from checkouts given by ``--geometry2`` and ``--common-interfaces``
    (target: at least 2x faster; not measured without them).
(g) with ``--real-tf2 ENV_LINE`` (the last line of ``../shared/tools/build_real_tf2.sh``): the
    real tf2_ros's ``lookup_transform`` on the tree of (a), measured beside ours through the
    compat path (target: ours at most 0.2x).

Run with ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST and a private ROS_DOMAIN_ID (``make bench``
sets both): ``python benchmarks/bench_tf.py [--seconds 60] [--skip-listener] [--geometry2
GEOMETRY2 --common-interfaces COMMON_INTERFACES] [--real-tf2 ENV_LINE]`` (bench_tf_peers.py
says where the peers come from).
"""

import argparse
import math
import os
import subprocess
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
from bench_e2e import start_node, start_publisher, stop  # noqa: E402
from bench_node import example_robot_data  # noqa: E402
from bench_results import figure  # noqa: E402
import numpy as np  # noqa: E402

S = 10**9
TF2_ROS_LOOKUP_US = (70.0, 78.0)   # the real tf2_ros, measured when the issue was filed
TREE_FRAMES = 130
WARM_S = 25.0   # the listener: its 10 s cache filled and its arrays at their size
QUIET_S = 3.0   # the listener stops once nothing came for this long
GROUP = 'TF without tf2'   # its heading in docs/performance.md


def tree_core():
    """Return a BufferCore of a 130-frame binary tree, 100 samples per edge at 100 Hz."""
    from dq_fk_ros.transforms.buffer_core import BufferCore
    core = BufferCore()
    for step in range(100):
        for k in range(1, TREE_FRAMES):
            a = 0.01 * step + k
            core.set_transform(f'f{(k - 1) // 2}', f'f{k}', S + step * 10_000_000,
                               (a, 0.1, 0.2, 0.0, 0.0, math.sin(a / 2), math.cos(a / 2)))
    return core


def per_call_us(call, seconds=1.0):
    """Return the best of 5 rounds' microseconds per call."""
    best = math.inf
    for _ in range(5):
        n, start = 0, time.perf_counter()
        while time.perf_counter() - start < seconds / 5:
            for _ in range(200):
                call()
            n += 200
        best = min(best, (time.perf_counter() - start) / n * 1e6)
    return best


def pytransform3d_us():
    """Return pytransform3d's get_transform on the same tree (static), from .venv-bench."""
    python = os.path.join(os.path.dirname(HERE), '.venv-bench', 'bin', 'python')
    code = f"""
import math, time
from pytransform3d.transform_manager import TransformManager
from pytransform3d.transformations import transform_from_pq
tm = TransformManager()
for k in range(1, {TREE_FRAMES}):
    a = k + 0.5
    tm.add_transform(f'f{{k}}', f'f{{(k - 1) // 2}}', transform_from_pq(
        [a, 0.1, 0.2, math.cos(a / 2), 0.0, 0.0, math.sin(a / 2)]))
best = 1e9
for _ in range(5):
    start = time.perf_counter()
    for _ in range(200):
        tm.get_transform('f100', 'f127')
    best = min(best, (time.perf_counter() - start) / 200 * 1e6)
print(best)
"""
    if not os.access(python, os.X_OK):
        return None
    done = subprocess.run([python, '-c', code], capture_output=True, text=True, timeout=300)
    return float(done.stdout) if done.returncode == 0 else None


def bench_lookups():
    """Print (a) and (b)."""
    from dq_fk_ros.ros.tf_buffer import Buffer
    from geometry_msgs.msg import TransformStamped
    from rclpy.time import Time
    buffer = Buffer()
    buffer.core = tree_core()
    when = Time(nanoseconds=S + 505_000_000 + 1234)
    lookup = per_call_us(lambda: buffer.lookup_transform('f127', 'f100', when))
    floor = per_call_us(TransformStamped)
    figure('lookup_transform, two leaves of 130 frames, interpolated', lookup, 'us',
           f'<= 2x the empty TransformStamped ({2 * floor:.1f} us)', lookup <= 2 * floor,
           group=GROUP)
    figure('the floor: rclpy constructs an empty TransformStamped', floor, 'us', group=GROUP)
    tf2 = 0.2 * TF2_ROS_LOOKUP_US[0]
    figure('lookup_transform against the real tf2_ros (70-78 us, issue)', lookup, 'us',
           f'<= 0.2x tf2_ros ({tf2:.0f} us)', lookup <= tf2, group=GROUP)
    peer = pytransform3d_us()
    if peer is not None:
        figure('pytransform3d TransformManager.get_transform, same tree, static', peer, 'us',
               group=GROUP)
    else:
        print('- pytransform3d: not in .venv-bench (make bench installs it)')
    stamps = np.linspace(S + 1, S + 99 * 10_000_000, 100_000).astype(np.int64)
    best = math.inf
    for _ in range(3):
        start = time.perf_counter()
        rows = buffer.lookup_poses('f127', 'f100', stamps)
        best = min(best, time.perf_counter() - start)
    assert not np.isnan(rows).any()
    figure('lookup_poses, 100 000 stamps, two leaves of 130 frames', best, 's', '<= 0.1 s',
           best <= 0.1, group=GROUP)


def bench_hostile_peer():
    """Print (e)."""
    import threading
    from dq_fk_ros.messages.cdr_tf import TfReader
    from dq_fk_ros.ros.tf_buffer import Buffer
    from geometry_msgs.msg import TransformStamped
    from rclpy.serialization import serialize_message
    from rclpy.time import Time
    from tf2_msgs.msg import TFMessage

    def transform(parent, child, sec, x):
        t = TransformStamped()
        t.header.frame_id, t.child_frame_id, t.header.stamp.sec = parent, child, sec
        t.transform.translation.x, t.transform.rotation.w = float(x), 1.0
        return t
    buffer = Buffer(log=lambda line: None)
    start = time.perf_counter()
    for k in range(10_000):
        buffer.set_transform(transform('world', 'peer', 7, k), 'peer')
    took = time.perf_counter() - start
    figure('10 000 transforms of one frame at one stamp, set_transform', took, 's',
           '<= 0.5 s (51 s before)', took <= 0.5, group=GROUP)
    buffer = Buffer(log=lambda line: None)
    buffer.set_transform(transform('world', 'other', 5, 0), 'rsp')
    raw = serialize_message(TFMessage(transforms=[transform('world', 'peer', 7, k)
                                                  for k in range(200)]))
    reader, plans, done, waits = TfReader(), {}, threading.Event(), []

    def peer():
        for _ in range(580):
            buffer.append_raw(raw, reader.layout(raw), plans, 'peer')
        done.set()
    thread = threading.Thread(target=peer)
    thread.start()
    while not done.is_set():
        begin = time.perf_counter()
        buffer.lookup_transform('world', 'other', Time())
        waits.append(time.perf_counter() - begin)
    thread.join()
    longest = max(waits) * 1e3
    figure('longest lookup of another frame while 580 x 200 repeated stamps are stored',
           longest, 'ms', '<= 20 ms (2.8 s before)', longest <= 20, group=GROUP)


def listen(seconds):
    """Run a TransformListener (this script with --listen); print received, CPU, memory."""
    import rclpy
    from dq_fk_ros.ros.tf_buffer import Buffer
    from dq_fk_ros.ros.tf_listener import TransformListener
    from rclpy.executors import SingleThreadedExecutor
    rclpy.init()
    node = rclpy.create_node(f'bench_tf_listener_{os.getpid()}')
    buffer = Buffer()
    listener = TransformListener(buffer, node, input_thread=True)   # the fast path (tf.md)
    # updates received: a new first-transform stamp (one per update; a counter, not a set,
    # so that the count itself takes no memory the figure would show)
    seen = {'count': 0, 'last': None}
    take = listener._take

    def counting(raw, reader, static):
        if not static and len(raw) >= 16 and raw[8:16] != seen['last']:
            seen['last'] = bytes(raw[8:16])
            seen['count'] += 1
        take(raw, reader, static)
    listener._take = counting
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    first, rss, last_count, last_change = None, [], 0, time.monotonic()
    while True:   # until the publisher is done: no message for QUIET_S
        executor.spin_once(timeout_sec=0.1)
        now = time.monotonic()
        if seen['count'] != last_count:
            last_count, last_change = seen['count'], now
        if first is None and seen['count']:
            first = now
        if first is not None and not rss and now > first + WARM_S:
            rss.append(_rss_mib())        # the 10 s cache has filled, its arrays grown
            cpu0, start = time.process_time(), now
        if rss and now - last_change > QUIET_S:
            break
        if first is not None and now > first + seconds + WARM_S + 60:
            break
    end = last_change
    cpu = 100 * (time.process_time() - cpu0) / (now - start)
    print(f'LISTENER {seen["count"]} {end - start:.1f} {cpu:.2f} {rss[0]:.1f} '
          f'{_rss_mib():.1f}', flush=True)
    listener.unregister()
    node.destroy_node()
    rclpy.try_shutdown()
    return 0


def _rss_mib():
    with open('/proc/self/status') as stream:
        for line in stream:
            if line.startswith('VmRSS:'):
                return int(line.split()[1]) / 1024
    return 0.0


def bench_listener(seconds):
    """Print (c)."""
    robot = example_robot_data('tiago_description/robots/tiago_dual.urdf')
    node = start_node([f'robot_description_file:={robot}'])
    listener = subprocess.Popen([sys.executable, os.path.abspath(__file__), '--listen',
                                 str(seconds)], stdout=subprocess.PIPE, text=True,
                                start_new_session=True)
    count = int(1000 * (seconds + WARM_S))
    publisher = None
    try:
        time.sleep(3.0)
        publisher = start_publisher(1000.0, count, False, robot)
        out, _ = listener.communicate(timeout=seconds + WARM_S + 120)
    finally:
        stop(publisher, listener, node)
    line = next((x for x in out.splitlines() if x.startswith('LISTENER ')), None)
    if line is None:
        print('- listener: no result (is DDS blocked on loopback?)')
        return
    received, _, cpu, rss_start, rss_end = line.split()[1:]
    lost = count - int(received)
    figure('TransformListener, tiago_dual /tf at 1 kHz: lost', lost, 'messages', '0',
           lost == 0, group=GROUP)
    figure('TransformListener, tiago_dual /tf at 1 kHz: CPU', float(cpu), '% of a core',
           '<= 25 %', float(cpu) <= 25, group=GROUP)
    growth = float(rss_end) - float(rss_start)
    figure(f'TransformListener memory over {seconds} s after the cache filled', growth,
           'MiB more', '< 5 MiB (flat)', growth < 5, group=GROUP)


def bench_bag(folder):
    """Print (d)."""
    from dq_fk_ros.bag.tf_export import export_tf
    from rosbags.rosbag2 import Reader
    bag = os.path.join(folder, 'tf_300k')
    if not os.path.exists(bag):
        tools = os.path.dirname(sys.executable)
        subprocess.run([os.path.join(tools, 'dq_fk_bag'), 'example', bag + '_in', '--robot',
                        'rl15', '--seconds', '3000', '--rate', '100'], check=True,
                       stdout=subprocess.DEVNULL)
        subprocess.run([os.path.join(tools, 'dq_fk_bag'), 'process', bag + '_in', bag,
                        '--robot', 'rl15', '--quiet'], check=True, stdout=subprocess.DEVNULL)
    bare, ours = math.inf, math.inf
    for k in range(3):
        start = time.perf_counter()
        with Reader(bag) as reader:
            conns = [c for c in reader.connections if c.topic == '/tf']
            n = sum(1 for _ in reader.messages(connections=conns))
        bare = min(bare, time.perf_counter() - start)
        out = os.path.join(folder, f'ee_{k}.csv')
        if os.path.exists(out):
            os.remove(out)
        start = time.perf_counter()
        done = export_tf(bag, 'world', 'eeCarry_seg6', out, rate_hz=100)
        ours = min(ours, time.perf_counter() - start)
        os.remove(out)
    print(f'- rosbags bare read of {n} /tf messages: {bare:.2f} s; dq_fk_bag tf '
          f'({done.rows} rows): {ours:.2f} s')
    figure(f"dq_fk_bag tf over {n} /tf messages against rosbags' bare read", ours / bare,
           'x', '<= 1.5x', ours / bare <= 1.5, group=GROUP)


def bench_peers(args):
    """Print (f) and (g)."""
    from bench_tf_peers import cloud_ms, lookup_us, real_cloud_ms
    from dq_fk_ros.cli.compat_path import compat_folders
    compat = compat_folders()
    ours = cloud_ms(compat)
    figure('do_transform_cloud, 300 000 points (x y z rgb intensity), ours', ours, 'ms',
           group=GROUP)
    if args.geometry2 and args.common_interfaces:
        real = real_cloud_ms(args.geometry2, args.common_interfaces, compat)
        if real is not None and ours is not None:
            figure("the same cloud, geometry2's tf2_sensor_msgs (sensor_msgs_py)", real, 'ms',
                   group=GROUP)
            figure('do_transform_cloud: how much faster than tf2_sensor_msgs', real / ours,
                   'x', '>= 2x', real / ours >= 2.0, group=GROUP)
    else:
        print('- tf2_sensor_msgs: not measured (give --geometry2 and --common-interfaces)')
    if args.real_tf2:
        real = lookup_us(args.real_tf2, compat, TREE_FRAMES)
        mine = lookup_us(None, compat, TREE_FRAMES)
        if real is not None and mine is not None:
            figure('the real tf2_ros lookup_transform, the tree of (a)', real, 'us', group=GROUP)
            figure('the same through the compat path (dq_fk_ros.tf.Buffer)', mine, 'us',
                   group=GROUP)
            figure('lookup_transform through the compat path, against the real tf2_ros',
                   mine / real, 'x', '<= 0.2x', mine / real <= 0.2, group=GROUP)
    else:
        print('- the real tf2_ros: not measured (give --real-tf2; 70-78 us in (a))')


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.strip().splitlines()[0])
    parser.add_argument('--seconds', type=float, default=60.0,
                        help='the listener run after its cache filled (default 60)')
    parser.add_argument('--skip-listener', action='store_true')
    parser.add_argument('--geometry2', help='a checkout of ros2/geometry2 (jazzy), for (f)')
    parser.add_argument('--common-interfaces', help='a checkout of ros2/common_interfaces')
    parser.add_argument('--real-tf2', metavar='ENV_LINE', help="build_real_tf2.sh's last line")
    parser.add_argument('--only-peers', action='store_true', help='(f) and (g) alone')
    parser.add_argument('--listen', type=float, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.listen is not None:
        return listen(args.listen)
    print('TF without tf2 (dq_fk_ros.tf)')
    if args.only_peers:
        bench_peers(args)
        return 0
    bench_lookups()
    bench_hostile_peer()
    folder = os.path.join(os.path.dirname(HERE), 'build', 'bench')
    os.makedirs(folder, exist_ok=True)
    bench_bag(folder)
    bench_peers(args)
    if not args.skip_listener:
        bench_listener(args.seconds)
    return 0


if __name__ == '__main__':
    sys.exit(main())
