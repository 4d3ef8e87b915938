"""
Per-update cost of dq_fk_node for the 6-DoF RL15, in-process, split into its parts.

One "update" is what the node does for a complete JointState: merge it, compute every frame
(FK), fill 7 PoseStamped and one TFMessage of 6 transforms, and publish them all (DDS
serialisation included; nothing subscribes, as for a node with no listeners yet). Prints
median, 90th and 99th percentile microseconds per update and per part.

Run with ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST and a private ROS_DOMAIN_ID
(``make bench`` sets both): ``python benchmarks/bench_node.py [--updates 20000]``.
"""

import argparse
import statistics
import sys
import time

from dq_fk_ros.ros.conversions import joint_state_fields
from dq_fk_ros.ros.node import DqFkNode
import numpy as np
import rclpy
from sensor_msgs.msg import JointState


def percentiles(samples_s):
    ordered = sorted(samples_s)
    pick = lambda f: ordered[min(len(ordered) - 1, int(f * len(ordered)))] * 1e6  # noqa: E731
    return statistics.median(ordered) * 1e6, pick(0.9), pick(0.99)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.strip().splitlines()[0])
    parser.add_argument('--updates', type=int, default=20000, help='updates timed per row')
    args = parser.parse_args(argv)
    rclpy.init(args=['--ros-args', '--log-level', 'warn'])
    node = DqFkNode()
    try:
        names = list(node._model.joint_names)
        rng = np.random.default_rng(0)
        msgs = []
        for q in rng.uniform(-1, 1, size=(args.updates, len(names))):
            msg = JointState(name=names, position=q.tolist())
            msg.header.stamp = node.get_clock().now().to_msg()
            msgs.append(msg)
        chain, messages, merger = node._model.chain, node._messages, node._merger
        for msg in msgs[:500]:  # warm up
            node._handle(msg)

        rows = []

        def timed(label, fn):
            samples = []
            for msg in msgs:
                start = time.perf_counter()
                fn(msg)
                samples.append(time.perf_counter() - start)
            rows.append((label, *percentiles(samples)))

        timed('whole update (node._handle)', node._handle)
        timed('  merge JointState', lambda m: merger.merge(*joint_state_fields(m)))
        qs = [np.array(m.position) for m in msgs]
        it = iter(qs * 2)
        timed('  FK, every frame (frame_poses)', lambda m: chain.frame_poses(next(it)))
        poses = [chain.frame_poses(q) for q in qs]
        it = iter(poses * 2)
        timed('  fill 7 PoseStamped + TFMessage',
              lambda m: messages.fill(m.header.stamp, *next(it)))
        tf, pose_msgs = messages.fill(msgs[0].header.stamp, *poses[0])

        def publish_all(_):
            node._tf_pub.publish(tf)
            for pub, pm in zip(node._pose_pubs, pose_msgs):
                pub.publish(pm)
        timed('  publish 7 PoseStamped + TFMessage', publish_all)
    finally:
        node.destroy_node()
        rclpy.try_shutdown()

    print(f'# dq_fk_node per-update cost, RL15 (6 joints, 7 frames), {args.updates} updates '
          'per row, in-process, no subscribers')
    print(f"| {'part':36s} | median us | p90 us | p99 us |")
    print('|---|---|---|---|')
    for label, p50, p90, p99 in rows:
        print(f'| {label:36s} | {p50:9.1f} | {p90:6.1f} | {p99:6.1f} |')
    return 0


if __name__ == '__main__':
    sys.exit(main())
