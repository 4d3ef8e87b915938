"""
``dq_fk_bag``: joint states from rosbag2 files, without rosbag2 (bags via ``rosbags``).

* ``dq_fk_bag process IN_BAG OUT_BAG --robot FILE``: every JointState of the bag, through the
  same input rules as the node (:class:`~dq_fk_ros.joint_states.JointStateMerger`), then the
  batched FK in chunks, written as /tf, /tf_static and the pose topics of the node to a new
  bag (MCAP by default); ``--csv`` writes the end-effector pose per message.
* ``dq_fk_bag play BAG``: publishes the bag's JointState messages with their recorded timing
  (``--rate``, ``--loop``, ``--start``, ``--duration``, ``--clock``) into a running node.
"""

import argparse
import os
import re
import shutil
import sys
import time

from dq_fk_ros.cdr import (
    JointStateNames, JointStateRun, parse_joint_states, pose_stamped_template,
    tf_message_template)
from dq_fk_ros.dual_quaternion import dq_to_pose_xyzw
from dq_fk_ros.executables import MATCH_SETTLE_S
from dq_fk_ros.joint_states import JointStateMerger
from dq_fk_ros.robot_model import (
    load_robot_description, RobotDescriptionError, shipped_robot_path)
import numpy as np

JOINT_STATE = 'sensor_msgs/msg/JointState'
CHUNK = 4096
ACK_TIMEOUT_S = 5.0  # play: longest wait for reliable subscribers to acknowledge the end


class BagError(Exception):
    """A bag problem for the user; the message is one line."""


# -- reading -----------------------------------------------------------------------------
def open_reader(path):
    """
    Open a bag for reading: rosbags' ``Reader``, or its MCAP files record by record.

    A rosbag2 folder rosbags cannot open (no ``metadata.yaml``, no MCAP summary: a
    recording that did not stop cleanly) and a bare ``.mcap`` file are read with
    :class:`~dq_fk_ros.mcap_stream.McapStreamBag`, which keeps every complete record; its
    ``note`` says so and its ``damage`` where reading stops. Raises :class:`BagError`.
    """
    from rosbags.rosbag2 import Reader, ReaderError
    if not os.path.exists(path):
        raise BagError(f'{path}: no such bag')
    if os.path.isfile(path) and str(path).endswith('.mcap'):
        return _stream_bag([path], path, None)
    try:
        reader = Reader(path)
        reader.open()
    except (ReaderError, OSError, ValueError, KeyError) as exc:
        mcaps = _mcap_files(path)
        if not mcaps:
            raise BagError(f'{path}: not a readable rosbag2 ({exc})') from None
        if not os.path.exists(os.path.join(path, 'metadata.yaml')):
            exc = 'no metadata.yaml'
        return _stream_bag(mcaps, path, exc)
    reader.note = reader.damage = None
    return reader


def _mcap_files(folder):
    """List the MCAP files of a bag folder, splits in order (``x_2`` before ``x_10``)."""
    if not os.path.isdir(folder):
        return []
    names = [n for n in os.listdir(folder) if n.endswith('.mcap')]
    split = re.compile(r'^(.*?)(\d*)\.mcap$')
    return [os.path.join(folder, n) for n in sorted(
        names, key=lambda n: (split.match(n)[1], int(split.match(n)[2] or -1)))]


def _stream_bag(files, path, why):
    from dq_fk_ros.mcap_stream import McapStreamBag
    try:
        bag = McapStreamBag(files)
    except OSError as exc:
        raise BagError(f'{path}: cannot be read ({exc})') from None
    listing = ', '.join(os.path.basename(f) for f in files)
    bag.note = None if why is None else \
        f'{path}: not a complete rosbag2 ({why}); read {listing} record by record'
    return bag


def joint_state_connections(reader, path, topic=None):
    """Return the connections of the JointState topic (``topic``, or the only one)."""
    listing = ', '.join(f'{c.topic} ({c.msgtype})' for c in reader.connections) or 'none'
    if topic is not None:
        conns = [c for c in reader.connections if c.topic == topic]
        if not conns:
            raise BagError(f'{path} has no topic {topic!r}; its topics: {listing}')
        wrong = [c.msgtype for c in conns if c.msgtype != JOINT_STATE]
        if wrong:
            raise BagError(f'{path}: topic {topic!r} has type {wrong[0]}, not {JOINT_STATE}')
        return conns
    conns = [c for c in reader.connections if c.msgtype == JOINT_STATE]
    topics = sorted({c.topic for c in conns})
    if not topics:
        raise BagError(f'{path} has no {JOINT_STATE} topic; its topics: {listing}')
    if len(topics) > 1:
        raise BagError(f'{path} has several JointState topics ({", ".join(topics)}); '
                       f'pick one with --topic')
    return conns


# -- processing --------------------------------------------------------------------------
class Progress:
    """
    A progress bar on stderr: ``[#####.....] done/total pct, msg/s, time left``.

    Redrawn in place (a carriage return) at most once a second; :meth:`update` with
    ``force`` ends the line. Without a known total it shows the count and the rate only.
    """

    WIDTH = 30

    def __init__(self, total, label, stream=sys.stderr, enabled=True, clock=time.monotonic):
        """Start the clock."""
        self.total, self.label, self.stream, self.enabled = total, label, stream, enabled
        self.clock = clock
        self.start = self.last = clock()
        self.shown = 0  # length of the line on screen, to blank a longer one

    def line(self, done, now):
        """Return the progress line for ``done`` messages at time ``now``."""
        rate = done / max(now - self.start, 1e-9)
        text = f'{self.label}: {done:,}'
        if self.total:
            share = min(done / self.total, 1.0)
            filled = int(round(share * self.WIDTH))
            left = (self.total - done) / rate if rate > 0 else 0.0
            text = (f'{self.label}: [{"#" * filled}{"." * (self.WIDTH - filled)}] '
                    f'{done:,}/{self.total:,} {100.0 * share:5.1f} %')
            return f'{text}, {rate:,.0f} msg/s, {max(left, 0.0):.0f} s left'
        return f'{text}, {rate:,.0f} msg/s'

    def update(self, done, force=False):
        """Redraw for ``done`` messages if a second has passed (or ``force``: final line)."""
        now = self.clock()
        if not self.enabled or (not force and now - self.last < 1.0):
            return
        self.last = now
        text = self.line(done, now)
        self.stream.write(text.ljust(self.shown) + ('\n' if force else '\r'))
        self.shown = 0 if force else len(text)
        self.stream.flush()


class BagOutputs:
    """The output bag's connections and the chunked, vectorised writing of FK results."""

    def __init__(self, writer, model, typestore, pose_namespace, frame_prefix, copy_from,
                 poses='all'):
        """Register /tf, /tf_static, pose topics (all, end, none), copied input topics."""
        from rosbags.interfaces import (
            Qos, QosDurability, QosHistory, QosLiveliness, QosReliability, QosTime)

        def qos(depth, durability):
            never = QosTime(sec=0, nsec=0)
            return [Qos(QosHistory.KEEP_LAST, depth, QosReliability.RELIABLE, durability,
                        never, never, QosLiveliness.AUTOMATIC, never, False)]
        volatile, latched = QosDurability.VOLATILE, QosDurability.TRANSIENT_LOCAL
        self.model = model
        self.writer = writer
        self.typestore = typestore
        self.frame_ids = [frame_prefix + name for name in model.frame_names]
        parents = [model.fixed_frame] + self.frame_ids[:-1]
        n_rows = len(model.chain.joints)
        self.moving_rows = [k - 1 for k in range(1, n_rows + 1) if model.moving[k]]
        self.static_frames = [k for k in range(len(self.frame_ids)) if not model.moving[k]]
        add = writer.add_connection
        self.tf = add('/tf', 'tf2_msgs/msg/TFMessage', typestore=typestore,
                      offered_qos_profiles=qos(100, volatile))
        self.tf_static = add('/tf_static', 'tf2_msgs/msg/TFMessage', typestore=typestore,
                             offered_qos_profiles=qos(1, latched))
        n_frames = len(model.frame_names)
        self.pose_frames = {'all': list(range(n_frames)), 'end': [n_frames - 1],
                            'none': []}[poses]
        self.poses = [add(f'{pose_namespace}/pose/{model.frame_names[k]}',
                          'geometry_msgs/msg/PoseStamped', typestore=typestore,
                          offered_qos_profiles=qos(10, volatile)) for k in self.pose_frames]
        self.tf_template = tf_message_template(
            [(parents[row + 1], self.frame_ids[row + 1]) for row in self.moving_rows])
        self.pose_template = pose_stamped_template(model.fixed_frame)
        self.static_template = tf_message_template(
            [(parents[k], self.frame_ids[k]) for k in self.static_frames])
        self.copied = {}
        for conn in copy_from:
            self.copied[conn.id] = _copy_connection(writer, conn, typestore)
        self.static_written = False

    def write_static(self, time_ns):
        """Write /tf_static once: base, fixed rows and tool, stamped ``time_ns``."""
        chain = self.model.chain
        q0 = np.zeros((1, chain.dof))
        frames = dq_to_pose_xyzw(chain.forward_all_batch(q0)[0])
        # static transforms relative to their parent: base (absolute = relative), fixed
        # rows (the row operator), tool
        rel = dq_to_pose_xyzw(chain.relative_all_batch(q0)[0])
        values = []
        for k in self.static_frames:
            if k == 0:
                values.append(frames[0])
            elif k <= len(chain.joints):
                values.append(rel[k - 1])
            else:
                values.append(chain.tool.to_pose_xyzw())
        row = self.static_template.fill([time_ns], np.concatenate(values)[None, :])[0]
        self.writer.write(self.tf_static, time_ns, memoryview(row))
        self.static_written = True

    def write_chunk(self, q, stamps_ns, log_times_ns):
        """FK of a chunk of configurations, serialized and written as arrays."""
        chain = self.model.chain
        absolute = dq_to_pose_xyzw(chain.forward_all_batch(q))           # (N, frames, 7)
        relative = dq_to_pose_xyzw(chain.relative_all_batch(q)[:, self.moving_rows])
        n = len(q)
        tf_rows = self.tf_template.fill(stamps_ns, relative.reshape(n, -1))
        pose_rows = [self.pose_template.fill(stamps_ns, absolute[:, k])
                     for k in self.pose_frames]
        self.writer.write_rows([self.tf] + self.poses, log_times_ns, [tf_rows] + pose_rows)
        return absolute[:, -1]

    def copy(self, conn, time_ns, raw):
        """Copy an input message through unchanged."""
        out = self.copied.get(conn.id)
        if out is not None:
            self.writer.write(out, time_ns, raw)


def _copy_connection(writer, conn, typestore):
    """Add an input connection to the output: its own type definition, else Jazzy's."""
    from rosbags.typesys import TypesysError
    ext = getattr(conn, 'ext', None)
    qos = list(getattr(ext, 'offered_qos_profiles', None) or [])
    definition = getattr(getattr(conn, 'msgdef', None), 'data', '')
    if definition and conn.digest:
        return writer.add_connection(conn.topic, conn.msgtype, msgdef=definition,
                                     rihs01=conn.digest, offered_qos_profiles=qos)
    try:
        return writer.add_connection(conn.topic, conn.msgtype, typestore=typestore,
                                     offered_qos_profiles=qos)
    except TypesysError:
        raise BagError(f'cannot copy {conn.topic}: the bag carries no definition of '
                       f'{conn.msgtype} and ROS 2 Jazzy has none; leave out --copy-input'
                       ) from None


def process_bag(in_path, out_path, robot, topic=None, storage='mcap', overwrite=False,
                csv_path=None, csv_only=False, copy_input=False, pose_namespace='/dq_fk_node',
                frame_prefix='', out_of_limits='warn', progress=True, chunk=CHUNK,
                poses='all'):
    """
    Compute every frame for every JointState of ``in_path``; return a summary dict.

    Messages the node would reject are skipped and counted by reason; everything valid is
    written. Raises :class:`BagError` for problems with the bags themselves.
    """
    from dq_fk_ros.bag_writer import BagWriter
    from rosbags.typesys import get_typestore, Stores
    model = robot if not isinstance(robot, (str, os.PathLike)) else \
        load_robot_description(robot)
    reader = open_reader(in_path)
    try:
        conns = joint_state_connections(reader, in_path, topic)
        if csv_only and not csv_path:
            raise BagError('--csv-only needs --csv FILE')
        writer = None
        if not csv_only:
            if os.path.exists(out_path):
                if not overwrite:
                    raise BagError(f'{out_path} exists; use --overwrite to replace it')
                shutil.rmtree(out_path) if os.path.isdir(out_path) else os.remove(out_path)
            writer = BagWriter(out_path, storage)
            writer.open()
        typestore = get_typestore(Stores.ROS2_JAZZY)
        copy_from = list(reader.connections) if copy_input else []
        try:
            outputs = BagOutputs(writer, model, typestore, pose_namespace, frame_prefix,
                                 copy_from, poses) if writer is not None else None
        except BagError:  # refused before anything was written: leave no output behind
            writer.abort()
            shutil.rmtree(out_path, ignore_errors=True)
            raise
        try:
            summary = _process_messages(reader, conns, model, outputs, csv_path, copy_input,
                                        out_of_limits, progress, chunk, in_path)
        finally:
            if writer is not None:
                writer.close()
    finally:
        reader.close()
    summary['output'] = None if csv_only else out_path
    summary['note'] = reader.note
    summary['error'] = summary['error'] or reader.damage
    return summary


def _process_messages(reader, conns, model, outputs, csv_path, copy_input, out_of_limits,
                      progress, chunk, in_path):
    """Read, merge, compute and write chunk by chunk; return the summary dict."""
    merger = JointStateMerger(model.joint_names, model.limits, out_of_limits)
    cache = JointStateNames()
    ids = {c.id for c in conns}
    meter = Progress(sum(c.msgcount for c in conns), 'dq_fk_bag process', enabled=progress)
    csv = open(csv_path, 'w', encoding='utf-8') if csv_path else None
    if csv:
        csv.write('stamp_ns,x,y,z,qx,qy,qz,qw\n')
    raws, log_times = [], []
    seen = written = 0
    error = None

    def flush():
        """Parse, merge (the node's rules), compute and write the collected messages."""
        nonlocal written
        if not raws:
            return
        items = parse_joint_states(raws, cache)
        runs = [item for item in items if isinstance(item, JointStateRun)]
        malformed = len(items) - len(runs)
        merger.counts['received'] += malformed
        merger.count_rejected('malformed_cdr', malformed)
        published, q, _ = merger.merge_many(
            [(r.names, r.positions, r.velocities, r.stamps_ns) for r in runs])
        # message index in this batch of every run message, in merge order
        where = np.concatenate([r.first + np.arange(len(r.stamps_ns)) for r in runs] or [[]])
        where = where.astype(np.int64)[published]
        out_times = np.array(log_times, dtype=np.int64)[where]
        stamps = np.concatenate([r.stamps_ns for r in runs] or [[]]).astype(np.int64)[published]
        stamps = np.where(stamps != 0, stamps, out_times)  # output stamps are input stamps
        raws.clear()
        log_times.clear()
        if not len(q):
            return
        if outputs is not None:
            if not outputs.static_written:
                outputs.write_static(int(out_times[0]))
            ee = outputs.write_chunk(q, stamps, out_times)
        else:
            ee = dq_to_pose_xyzw(model.chain.forward_batch(q))
        if csv:
            line = '%d,' + ','.join(['%.17g'] * 7) + '\n'
            csv.writelines(line % (s, *p) for s, p in zip(stamps.tolist(), ee.tolist()))
        written += len(q)

    messages = reader.messages(connections=list(reader.connections) if copy_input else conns)
    try:
        for conn, log_time, raw in messages:
            if copy_input:
                outputs.copy(conn, log_time, raw)
            if conn.id not in ids:
                continue
            seen += 1
            raws.append(raw)
            log_times.append(log_time)
            if len(raws) == chunk:
                flush()
                meter.update(seen)
    except Exception as exc:  # a truncated or corrupt bag: keep everything read so far
        error = f'{in_path}: reading stopped after {seen} JointState messages: {exc}'
    flush()
    meter.update(seen, force=True)
    if csv:
        csv.close()
    counts = merger.counts
    rejected = {k[len('rejected_'):]: v for k, v in counts.items()
                if k.startswith('rejected_') and v}
    return {'read': seen, 'written': written, 'incomplete': counts['incomplete'],
            'rejected': rejected, 'unknown_joints': sorted(merger.unknown), 'error': error}


# -- playing -----------------------------------------------------------------------------
def play_bag(path, topic=None, rate=1.0, loop=False, start_s=0.0, duration_s=None,
             clock=False, output_topic=None, progress=True, node=None, wait_for=0,
             wait_timeout_s=30.0):
    """
    Publish the bag's JointState messages with their recorded timing; return a summary.

    The summary dict: ``sent`` (messages published), ``note`` and ``error`` (lines about a
    bag read record by record, see :func:`open_reader`; ``error`` if it is damaged).

    Serialized messages are published as they are (no conversion). ``clock`` publishes
    ``/clock`` with the bag time before each message, for nodes with ``use_sim_time``.
    ``wait_for``: first wait until that many subscriptions are matched (messages sent
    before discovery completes are lost otherwise).
    """
    from dq_fk_ros.ros_conversions import ns_to_stamp
    import rclpy
    from rclpy.duration import Duration
    from rclpy.qos import QoSProfile
    from rosgraph_msgs.msg import Clock
    from sensor_msgs.msg import JointState
    if rate <= 0:
        raise BagError(f'--rate must be positive, got {rate}')
    reader = open_reader(path)
    try:
        conns = joint_state_connections(reader, path, topic)
        own = node is None
        if own:
            rclpy.init(args=['--ros-args', '--log-level', 'warn'])
            node = rclpy.create_node('dq_fk_bag_play')
        pub = node.create_publisher(JointState, output_topic or conns[0].topic, 100)
        clock_pub = node.create_publisher(Clock, '/clock', QoSProfile(depth=10)) \
            if clock else None
        t_begin = reader.start_time + int(start_s * 1e9)
        t_end = None if duration_s is None else t_begin + int(duration_s * 1e9)
        total = sum(c.msgcount for c in conns)
        sent = 0
        deadline = time.monotonic() + wait_timeout_s
        while pub.get_subscription_count() < wait_for:
            if time.monotonic() > deadline:
                raise BagError(f'no {wait_for} subscribers on {pub.topic_name} within '
                               f'{wait_timeout_s:g} s')
            time.sleep(0.05)
        if wait_for:
            time.sleep(MATCH_SETTLE_S)  # the subscribers' side of the match may lag ours
        meter = Progress(total, 'dq_fk_bag play', enabled=progress)
        try:
            while True:
                wall0 = time.monotonic()
                for _, log_time, raw in reader.messages(connections=conns, start=t_begin,
                                                        stop=t_end):
                    delay = (log_time - t_begin) / 1e9 / rate - (time.monotonic() - wall0)
                    if delay > 0:
                        time.sleep(delay)
                    if clock_pub is not None:
                        clock_pub.publish(Clock(clock=ns_to_stamp(log_time)))
                    pub.publish(bytes(raw))
                    sent += 1
                    meter.update(sent)
                if not loop:
                    break
            # leaving at once would destroy the publishers before reliable subscribers
            # have the last messages (one was seen lost that way)
            for publisher in filter(None, (pub, clock_pub)):
                publisher.wait_for_all_acked(Duration(seconds=ACK_TIMEOUT_S))
        finally:
            meter.update(sent, force=True)
            if own:
                node.destroy_node()
                rclpy.try_shutdown()
    finally:
        reader.close()
    return {'sent': sent, 'note': reader.note, 'error': reader.damage}


# -- command line ------------------------------------------------------------------------
def summary_line(path, s):
    """One line saying what ``process`` read, wrote and skipped (with reasons)."""
    parts = [f"{path}: {s['read']} JointState messages, {s['written']} written"
             + (f" to {s['output']}" if s['output'] else '')]
    if s['incomplete']:
        parts.append(f"{s['incomplete']} incomplete (joints not all seen yet)")
    if s['rejected']:
        parts.append('rejected (' + ', '.join(f'{k}: {v}' for k, v in
                                              sorted(s['rejected'].items())) + ')')
    if s['unknown_joints']:
        parts.append('unknown joints ignored: ' + ', '.join(s['unknown_joints']))
    return ', '.join(parts)


def build_parser():
    parser = argparse.ArgumentParser(
        prog='dq_fk_bag', description='Joint-state bags: offline FK into a new bag, or replay.')
    sub = parser.add_subparsers(dest='command', required=True)
    p = sub.add_parser('process', help='compute every frame for every JointState of a bag')
    p.add_argument('in_bag', metavar='IN_BAG')
    p.add_argument('out_bag', metavar='OUT_BAG')
    p.add_argument('--robot', default='rl15',
                   help='robot description file or shipped robot name (default rl15)')
    p.add_argument('--topic', help='JointState topic (default: the only one in the bag)')
    p.add_argument('--storage', choices=('mcap', 'sqlite3'), default='mcap')
    p.add_argument('--overwrite', action='store_true', help='replace OUT_BAG if it exists')
    p.add_argument('--csv', metavar='FILE', help='also write the end-effector pose per message')
    p.add_argument('--csv-only', action='store_true', help='write the CSV and no bag')
    p.add_argument('--copy-input', action='store_true', help='copy the input topics through')
    p.add_argument('--pose-namespace', default='/dq_fk_node',
                   help='pose topics are <ns>/pose/<frame> (default /dq_fk_node, as the node)')
    p.add_argument('--frame-prefix', default='', help='as the node parameter frame_prefix')
    p.add_argument('--poses', choices=('all', 'end', 'none'), default='all',
                   help='pose topics written: every frame (default), the end effector, none')
    p.add_argument('--out-of-limits', choices=('warn', 'clamp', 'reject'), default='warn')
    p.add_argument('--quiet', action='store_true', help='no progress output')
    p = sub.add_parser('play', help='publish the JointState messages with recorded timing')
    p.add_argument('bag', metavar='BAG')
    p.add_argument('--topic', help='JointState topic (default: the only one in the bag)')
    p.add_argument('--rate', type=float, default=1.0, help='speed factor (default 1)')
    p.add_argument('--loop', action='store_true', help='start over at the end')
    p.add_argument('--start', type=float, default=0.0, help='skip this many seconds')
    p.add_argument('--duration', type=float, help='play this many seconds')
    p.add_argument('--clock', action='store_true', help='publish /clock (use_sim_time)')
    p.add_argument('--wait-for-subscribers', type=int, default=0, metavar='N',
                   help='start once N subscriptions are matched (default 0: at once)')
    p.add_argument('--quiet', action='store_true', help='no progress output')
    return parser


def main(argv=None):
    """Run ``dq_fk_bag``; exit 0 on success, 1 on a user error or a damaged bag."""
    args = build_parser().parse_args(argv)
    try:
        if args.command == 'process':
            robot = args.robot
            if not os.path.exists(robot) and os.sep not in robot:
                robot = shipped_robot_path(robot)
            s = process_bag(args.in_bag, args.out_bag, robot, topic=args.topic,
                            storage=args.storage, overwrite=args.overwrite, csv_path=args.csv,
                            csv_only=args.csv_only, copy_input=args.copy_input,
                            pose_namespace=args.pose_namespace, frame_prefix=args.frame_prefix,
                            out_of_limits=args.out_of_limits, progress=not args.quiet,
                            poses=args.poses)
            print(summary_line(args.in_bag, s))
        else:
            s = play_bag(args.bag, topic=args.topic, rate=args.rate, loop=args.loop,
                         start_s=args.start, duration_s=args.duration, clock=args.clock,
                         progress=not args.quiet, wait_for=args.wait_for_subscribers)
            print(f"{args.bag}: published {s['sent']} JointState messages")
        for line in (s['note'], s['error']):
            if line:
                print(f'dq_fk_bag: {line}', file=sys.stderr)
        if s['error']:
            return 1
    except (BagError, RobotDescriptionError, FileNotFoundError) as exc:
        print(f'dq_fk_bag: {exc}', file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        return 130
    return 0


if __name__ == '__main__':
    sys.exit(main())
