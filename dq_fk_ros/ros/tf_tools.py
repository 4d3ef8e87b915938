"""
``dq_fk tf echo | frames | monitor``: tf2_ros's tf2_echo, tf2_tools' view_frames, tf2_monitor.

* ``echo TARGET SOURCE [--rate HZ]``: SOURCE's pose in TARGET at the latest common time,
  printed as tf2_echo prints it (At time, translation with three decimals, the quaternion
  x y z w, RPY in radians and degrees, the 4x4 matrix) ``rate`` times a second until
  Ctrl-C; a lookup that fails prints tf2_echo's "Failure at" lines.
* ``frames [--bag BAG] [-o frames.pdf] [--seconds 5]``: listens ``seconds`` (or reads a bag's
  TF) and writes ``frames.gv`` and, with Graphviz's ``dot``, ``frames.pdf``: one edge per
  child frame with its broadcaster, average rate, most recent transform and buffer length
  (tf2's ``_allFramesAsDot``).
* ``monitor [TARGET SOURCE] [--seconds S]``: per frame, how often its transform comes and
  how old it is on arrival (average and maximum delay), per broadcaster the same; with two
  frames, the chain between them. Printed every second, as tf2_monitor.

Frame names come from any peer on the domain: printed with unprintable characters as
``?``, at most :data:`MAX_LISTED` per list, and escaped in the DOT text.
"""

import math
import os
import shutil
import subprocess
import sys
import threading
import time

from dq_fk_ros.errors import printable_line
from dq_fk_ros.messages.cdr_tf import TfReader
from dq_fk_ros.transforms.exceptions import TransformException

MAX_LISTED = 200          # frames printed in one list
DOT_TIMEOUT_S = 60.0      # Graphviz's time to draw frames.pdf
MAX_DOT_BYTES = 4 << 20   # a DOT text larger than this is not drawn (a peer's 10^4 frames)


def rpy(qx, qy, qz, qw) -> tuple:
    """Return roll, pitch, yaw (rad) of a unit quaternion, as tf2's ``Matrix3x3::getRPY``."""
    m20 = 2 * (qx * qz - qy * qw)
    m21 = 2 * (qy * qz + qx * qw)
    m22 = 1 - 2 * (qx * qx + qy * qy)
    m10 = 2 * (qx * qy + qz * qw)
    m00 = 1 - 2 * (qy * qy + qz * qz)
    if abs(m20) >= 1:   # gimbal lock: tf2's getEulerYPR sets yaw 0
        roll = math.atan2(m21, m22)
        return roll, (math.pi / 2 if m20 < 0 else -math.pi / 2), 0.0
    pitch = -math.asin(m20)
    c = math.cos(pitch)
    return math.atan2(m21 / c, m22 / c), pitch, math.atan2(m10 / c, m00 / c)


def matrix_rows(pose) -> list:
    """Return the 4x4 matrix of a pose (x y z qx qy qz qw) as four rows."""
    x, y, z, qx, qy, qz, qw = pose
    return [[1 - 2 * (qy * qy + qz * qz), 2 * (qx * qy - qz * qw), 2 * (qx * qz + qy * qw), x],
            [2 * (qx * qy + qz * qw), 1 - 2 * (qx * qx + qz * qz), 2 * (qy * qz - qx * qw), y],
            [2 * (qx * qz - qy * qw), 2 * (qy * qz + qx * qw), 1 - 2 * (qx * qx + qy * qy), z],
            [0.0, 0.0, 0.0, 1.0]]


def format_echo(stamp_ns: int, pose) -> str:
    """Return tf2_echo's lines for one transform (``pose``: x y z qx qy qz qw)."""
    sec, nanosec = divmod(stamp_ns, 1_000_000_000)
    x, y, z, qx, qy, qz, qw = pose
    r = rpy(qx, qy, qz, qw)
    lines = [f'At time {sec}.{nanosec:09d}',
             f'- Translation: [{x:.3f}, {y:.3f}, {z:.3f}]',
             f'- Rotation: in Quaternion (xyzw) [{qx:.3f}, {qy:.3f}, {qz:.3f}, {qw:.3f}]',
             f'- Rotation: in RPY (radian) [{r[0]:.3f}, {r[1]:.3f}, {r[2]:.3f}]',
             '- Rotation: in RPY (degree) [' + ', '.join(f'{math.degrees(a):.3f}' for a in r)
             + ']', '- Matrix:']
    lines += [''.join(f'{v:7.3f}' for v in row) for row in matrix_rows(pose)]
    return '\n'.join(lines) + '\n'


def listing(buffer) -> str:
    """Return the buffer's frames as tf2's allFramesAsString, at most MAX_LISTED lines."""
    lines = buffer.all_frames_as_string().splitlines()
    shown = [printable_line(line, 300) for line in lines[:MAX_LISTED]]
    if len(lines) > MAX_LISTED:
        shown.append(f'... and {len(lines) - MAX_LISTED} more frames')
    return '\n'.join(shown)


class _Ros:
    """An rclpy context and node of a tool, and a Buffer with its listener; closed on exit."""

    def __init__(self, name):
        import rclpy
        from rclpy.signals import SignalHandlerOptions
        from dq_fk_ros.ros.tf_buffer import Buffer
        from dq_fk_ros.ros.tf_listener import TransformListener
        self.context = rclpy.Context()
        rclpy.init(context=self.context, signal_handler_options=SignalHandlerOptions.NO)
        self.node = rclpy.create_node(f'{name}_{os.getpid()}', context=self.context)
        self.buffer = Buffer()
        self.listener = TransformListener(self.buffer, self.node, spin_thread=True)

    def now_ns(self):
        return self.node.get_clock().now().nanoseconds

    def close(self):
        import rclpy
        self.listener.unregister()
        self.node.destroy_node()
        rclpy.try_shutdown(context=self.context)


def echo(target: str, source: str, rate_hz: float = 1.0, count: int | None = None,
         out=sys.stdout) -> int:
    """Print SOURCE in TARGET (module doc) until Ctrl-C, or ``count`` times; return 0."""
    from rclpy.duration import Duration
    from rclpy.time import Time
    ros = _Ros('dq_fk_tf_echo')
    try:
        ros.buffer.can_transform(target, source, Time(), timeout=Duration(seconds=1.0))
        printed = 0
        while count is None or printed < count:
            try:
                msg = ros.buffer.lookup_transform(target, source, Time())
                t, r = msg.transform.translation, msg.transform.rotation
                stamp = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
                out.write(format_echo(stamp, (t.x, t.y, t.z, r.x, r.y, r.z, r.w)))
            except TransformException as exc:
                out.write(f'Failure at {ros.now_ns() / 1e9:.6f}\n'
                          f'Exception thrown:{printable_line(exc, 500)}\n'
                          f'The current list of frames is:\n{listing(ros.buffer)}\n')
            out.flush()
            printed += 1
            time.sleep(1.0 / rate_hz)
        return 0
    finally:
        ros.close()


def write_frames(core, output_pdf: str, now_ns: int = 0) -> tuple:
    """
    Write ``<output>.gv`` and, with Graphviz's ``dot``, the PDF; return ``(gv, pdf or None)``.

    :raises RuntimeError: one line: ``dot`` missing, failing or too slow (the .gv is kept).
    """
    base = output_pdf[:-4] if output_pdf.endswith('.pdf') else output_pdf
    gv = base + '.gv'
    text = core.all_frames_as_dot(now_ns)
    with open(gv, 'w', encoding='utf-8') as stream:
        stream.write(text)
    dot = shutil.which('dot')
    if dot is None:
        raise RuntimeError(f"{gv} written; Graphviz's dot is not installed, so no PDF "
                           '(apt-get install graphviz)')
    if len(text) > MAX_DOT_BYTES:
        raise RuntimeError(f'{gv} written; {len(text) >> 20} MiB of DOT text is more than '
                           'dot is given here, so no PDF')
    try:
        done = subprocess.run([dot, '-Tpdf', gv, '-o', base + '.pdf'], capture_output=True,
                              timeout=DOT_TIMEOUT_S)
    except subprocess.TimeoutExpired:
        raise RuntimeError(f'{gv} written; dot took more than {DOT_TIMEOUT_S:g} s') from None
    if done.returncode:
        raise RuntimeError(f'{gv} written; dot failed: '
                           f'{printable_line(done.stderr.decode(errors="replace"), 300)}')
    return gv, base + '.pdf'


def frames(output: str = 'frames.pdf', bag: str | None = None, seconds: float = 5.0,
           out=sys.stdout) -> int:
    """Write view_frames' files from ``seconds`` of live TF or from a bag; return 0."""
    if bag is not None:
        from dq_fk_ros.bag.tf_bag import core_from_bag
        core, summary = core_from_bag(bag)
        newest = max((c.newest_stamp() for c in core.caches if c is not None), default=0)
        gv, pdf = write_frames(core, output, newest)
        if summary.dropped_line():
            print(f'dq_fk tf frames: {bag}: {summary.dropped_line()}', file=sys.stderr)
    else:
        ros = _Ros('dq_fk_tf_frames')
        try:
            out.write(f'Listening to tf data for {seconds:g} seconds...\n')
            out.flush()
            time.sleep(seconds)
            with ros.buffer.lock:
                gv, pdf = write_frames(ros.buffer.core, output, ros.now_ns())
        finally:
            ros.close()
    out.write(f'{gv} and {pdf} written\n')
    return 0


class Monitor:
    """Per child frame and per broadcaster: messages, average and maximum delay (s)."""

    def __init__(self):
        """Start with nothing seen."""
        self.lock = threading.Lock()
        self.frames = {}   # child -> [count, delay sum, delay max, parent]
        self.start = time.monotonic()

    def take(self, transforms, now_ns) -> None:
        """Count ``[(parent, child, stamp_ns, pose)]`` received at ``now_ns``."""
        with self.lock:
            for parent, child, stamp, _ in transforms:
                if child not in self.frames and len(self.frames) >= 10 * MAX_LISTED:
                    continue
                delay = (now_ns - stamp) / 1e9 if stamp else 0.0
                seen = self.frames.setdefault(child, [0, 0.0, -math.inf, parent])
                seen[0] += 1
                seen[1] += delay
                seen[2] = max(seen[2], delay)
                seen[3] = parent

    def report(self, chain=None) -> str:
        """Return tf2_monitor's block: the chain's frames (or all), rate and delays."""
        with self.lock:
            elapsed = max(time.monotonic() - self.start, 1e-9)
            names = chain if chain is not None else sorted(self.frames)
            lines = ['RESULTS: for ' + (f'{chain[0]} to {chain[-1]}' if chain else 'all Frames'),
                     '', 'Frames:']
            for name in names[:MAX_LISTED]:
                seen = self.frames.get(name)
                if seen is None:
                    continue
                lines.append(f'Frame: {printable_line(name, 100)}, parent '
                             f'{printable_line(seen[3], 100)}, {seen[0] / elapsed:.3f} Hz, '
                             f'Average Delay: {seen[1] / seen[0]:.6f}, '
                             f'Max Delay: {seen[2]:.6f}')
            return '\n'.join(lines) + '\n'


def monitor(target: str | None = None, source: str | None = None,
            seconds: float | None = None, out=sys.stdout) -> int:
    """Print :class:`Monitor` reports every second until Ctrl-C or ``seconds``; return 0."""
    from dq_fk_ros.ros.tf_listener import DYNAMIC_QOS, STATIC_QOS
    from tf2_msgs.msg import TFMessage
    ros = _Ros('dq_fk_tf_monitor')
    watch = Monitor()
    readers = (TfReader(), TfReader())

    def take(raw, reader):
        try:
            transforms = reader.read(raw)
        except ValueError:
            return
        watch.take(transforms, ros.now_ns())
    from rclpy.callback_groups import ReentrantCallbackGroup
    group = ReentrantCallbackGroup()
    ros.node.create_subscription(TFMessage, '/tf', lambda raw: take(raw, readers[0]),
                                 DYNAMIC_QOS, callback_group=group, raw=True)
    ros.node.create_subscription(TFMessage, '/tf_static', lambda raw: take(raw, readers[1]),
                                 STATIC_QOS, callback_group=group, raw=True)
    try:
        deadline = None if seconds is None else time.monotonic() + seconds
        while deadline is None or time.monotonic() < deadline:
            time.sleep(1.0)
            chain = None
            if target is not None:
                try:
                    up, down = ros.buffer.core.path(target, source, 0)
                    names = ros.buffer.core.names
                    chain = [names[c] for c, _ in up] + [names[c] for c, _ in reversed(down)]
                    out.write(f'Chain is: {" -> ".join(printable_line(n, 100) for n in chain)}'
                              '\n')
                except TransformException as exc:
                    out.write(f'{printable_line(exc, 300)}\n')
                    chain = []
            out.write(watch.report(chain))
            out.flush()
        return 0
    finally:
        ros.close()


__all__ = ['echo', 'format_echo', 'frames', 'monitor', 'Monitor', 'rpy', 'write_frames']
