"""
Per-update cost of dq_fk_node (the RL15 by default), in-process, split into its parts.

One "update" is what the node does with a serialized JointState (its subscription is raw):
read it, merge it, compute every frame (FK), serialize /tf (6 transforms) and the pose
topics in place, and publish them as bytes (DDS included). Three cases: pose topics that
nobody reads are skipped (the default; only /tf goes out), every output published with no
subscriber (``publish_unread_topics``), and one subscriber on every topic (in this process:
DDS delivers to it, so its cost is partly counted here too). Prints median, 90th and 99th
percentile microseconds per update and per part, and the same for the message-object path
the node used before (for comparison).

Run with ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST and a private ROS_DOMAIN_ID
(``make bench`` sets both): ``python benchmarks/bench_node.py [--updates 20000] [--robot
ROBOT] [--urdf-tip LINK]`` (ROBOT: a DH file, a URDF, a shipped name).
"""

import argparse
import statistics
import sys
import time

from dq_fk_ros.messages.cdr import JointStateNames, parse_joint_state
from dq_fk_ros.ros.conversions import joint_state_fields
from dq_fk_ros.ros.node import DqFkNode
from geometry_msgs.msg import PoseStamped
import numpy as np
import rclpy
from rclpy.parameter import Parameter
from rclpy.serialization import serialize_message
from sensor_msgs.msg import JointState
from tf2_msgs.msg import TFMessage


def percentiles(samples_s):
    ordered = sorted(samples_s)
    pick = lambda f: ordered[min(len(ordered) - 1, int(f * len(ordered)))] * 1e6  # noqa: E731
    return statistics.median(ordered) * 1e6, pick(0.9), pick(0.99)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.strip().splitlines()[0])
    parser.add_argument('--updates', type=int, default=20000, help='updates timed per row')
    parser.add_argument('--robot', default='rl15', help='DH file, URDF or shipped name')
    parser.add_argument('--urdf-tip', default='', help="for a URDF: the chain's last link")
    args = parser.parse_args(argv)
    rclpy.init(args=['--ros-args', '--log-level', 'warn'])
    node = DqFkNode(parameter_overrides=[
        Parameter('robot_description_file', value=args.robot),
        Parameter('urdf_tip_link', value=args.urdf_tip)])
    probe = rclpy.create_node('dq_fk_bench_probe')
    rows = []
    try:
        names = list(node._model.joint_names)
        rng = np.random.default_rng(0)
        msgs, raws = [], []
        for q in rng.uniform(-1, 1, size=(args.updates, len(names))):
            msg = JointState(name=names, position=q.tolist())
            msg.header.stamp = node.get_clock().now().to_msg()
            msgs.append(msg)
            raws.append(serialize_message(msg))
        model, merger, out = node._model, node._merger, node._bytes
        n_frames = len(model.frame_names)

        def timed(label, fn, items):
            for item in items[:500]:  # warm up
                fn(item)
            samples = []
            for item in items:
                start = time.perf_counter()
                fn(item)
                samples.append(time.perf_counter() - start)
            rows.append((label, *percentiles(samples)))

        node._refresh_readers()
        timed('update, unread poses skipped (default)', node._on_joint_state, raws)
        node.set_parameters([Parameter('publish_unread_topics', value=True)])
        timed('update, all outputs, no subscribers', node._on_joint_state, raws)
        cache = JointStateNames()
        timed('  read + merge JointState', lambda raw: merger.merge(
            *_fields(parse_joint_state(raw, cache))), raws)
        qs = [np.array(m.position) for m in msgs]
        it = iter(qs * 2)
        timed('  FK, every frame (frame_poses)', lambda m: model.frame_poses(next(it)), msgs)
        poses = [model.frame_poses(q) for q in qs]
        it = iter(poses * 2)

        def serialize(_):
            absolute, relative = next(it)
            return [out.tf(1, 2, relative)] + [out.pose(1, 2, p) for p in absolute]
        timed(f'  serialize /tf + {n_frames} poses (bytes)', serialize, msgs)
        payloads = serialize(None)

        def publish_all(_):
            node._tf_pub.publish(payloads[0])
            for pub, payload in zip(node._pose_pubs, payloads[1:]):
                pub.publish(payload)
        timed(f'  publish /tf + {n_frames} poses (bytes)', publish_all, msgs)
        node.set_parameters([Parameter('publish_unread_topics', value=False)])

        probe.create_subscription(TFMessage, '/tf', lambda _: None, 10, raw=True)
        for name in node._model.frame_names:
            probe.create_subscription(PoseStamped, f'/dq_fk_node/pose/{name}',
                                      lambda _: None, 10, raw=True)
        deadline = time.monotonic() + 10
        while not all(p.get_subscription_count() for p in node._pose_pubs):
            if time.monotonic() > deadline:
                raise SystemExit('the probe subscriptions did not match within 10 s')
            time.sleep(0.05)
        node._refresh_readers()
        timed('update, one subscriber on every topic', node._on_joint_state, raws)

        # the message-object path the node used before, for comparison
        messages = node._messages
        tf, pose_msgs = messages.fill(msgs[0].header.stamp, *poses[0])

        def object_update(msg):
            result = merger.merge(*joint_state_fields(msg))
            absolute, relative = model.frame_poses(result.q)
            tf_msg, pose_list = messages.fill(msg.header.stamp, absolute, relative)
            node._tf_pub.publish(tf_msg)
            for pub, pm in zip(node._pose_pubs, pose_list):
                pub.publish(pm)
        timed('(before: message objects, subscribed)', object_update, msgs)
    finally:
        probe.destroy_node()
        node.destroy_node()
        rclpy.try_shutdown()

    print(f'# dq_fk_node per-update cost, {model.name} ({model.dof} joints, {n_frames} frames, '
          f'{len(model.links)} of them links), {args.updates} updates per row, in-process')
    print(f"| {'part':40s} | median us | p90 us | p99 us |")
    print('|---|---|---|---|')
    for label, p50, p90, p99 in rows:
        print(f'| {label:40s} | {p50:9.1f} | {p90:6.1f} | {p99:6.1f} |')
    return 0


def _fields(parsed):
    stamp_ns, names, positions, velocities = parsed
    return names, positions.tolist(), velocities.tolist(), stamp_ns


if __name__ == '__main__':
    sys.exit(main())
