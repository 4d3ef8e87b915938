"""
The joint source of a test robot: ``sensor_msgs/JointState`` from a child process.

``python -m dq_fk_ros.testing.joint_source ROBOT --topic T [--rate HZ] [--csv FILE]``

Publishes every joint of ROBOT (a shipped name, a DH file or a URDF/xacro) on ``T`` at
``--rate`` with fresh stamps (the ROS clock), each position 0 until told otherwise. Told on
its standard input, one JSON object a line (``{"joint_2": 0.5}``): the positions change,
a message carrying them goes out at once, and the program prints ``stamp NS`` (the header
stamp of that first message) on its standard output, so the test knows from which stamp on
TF shows them. A line that is not such an object is answered ``error ...`` (one line) and
changes nothing. ``--csv FILE`` instead replays the rows of a CSV (a column per joint named
in its header, rad or m) at ``--rate``, once, prints ``done NS`` (the stamp of the last
row's message) and goes on publishing the last row.
It prints ``ready`` once its publisher exists; it ends at the end of its input (or of the
CSV), on SIGINT or SIGTERM.
"""

import argparse
import csv
import json
import math
import os
import select
import sys
import time

MAX_LINE = 1 << 16   # bytes of one line of input read at most
MAX_ROWS = 1_000_000


def parse_update(line: str, names) -> dict:
    """Return ``{joint: position}`` of one input line; ValueError (one line) if it is not."""
    if len(line) > MAX_LINE:
        raise ValueError(f'a line of more than {MAX_LINE} bytes')
    try:
        update = json.loads(line)
    except ValueError:
        raise ValueError('not JSON') from None
    if not isinstance(update, dict):
        raise ValueError('not a JSON object of joint names and positions')
    for name, value in update.items():
        if name not in names:
            raise ValueError(f'no joint {name[:80]!r} in this robot')
        if isinstance(value, bool) or not isinstance(value, (int, float)) or \
                not math.isfinite(value):
            raise ValueError(f'joint {name[:80]!r}: not a finite number')
    return {name: float(value) for name, value in update.items()}


def read_csv_rows(path, names) -> list:
    """Return the rows of a CSV as position lists in ``names``' order (ValueError: one line)."""
    with open(path, encoding='utf-8-sig', newline='') as stream:
        rows = csv.reader(stream)
        header = [h.strip() for h in next(rows, [])]
        missing = [n for n in header if n not in names]
        if missing:
            raise ValueError(f'{path}: column {missing[0][:80]!r} is no joint of this robot')
        out = []
        for k, row in enumerate(rows):
            if len(out) >= MAX_ROWS:
                raise ValueError(f'{path}: more than {MAX_ROWS} rows')
            values = dict(zip(header, (float(v) for v in row)))
            out.append([values.get(n, 0.0) for n in names])
        return out


def main(argv=None) -> int:
    """Run the joint source (module doc)."""
    parser = argparse.ArgumentParser(description=__doc__.strip().splitlines()[0])
    parser.add_argument('robot')
    parser.add_argument('--topic', default='joint_states')
    parser.add_argument('--rate', type=float, default=50.0)
    parser.add_argument('--csv')
    parser.add_argument('--set', default='{}', help='initial positions, a JSON object')
    args = parser.parse_args(argv)
    from dq_fk_ros.description.loading import load_robot
    names = list(load_robot(args.robot).model.joint_names)
    positions = dict.fromkeys(names, 0.0)
    positions.update(parse_update(args.set, names))
    rows = read_csv_rows(args.csv, names) if args.csv else None
    import rclpy
    from sensor_msgs.msg import JointState
    rclpy.init(args=['--ros-args'])
    node = rclpy.create_node(f'dq_fk_test_joints_{os.getpid()}', enable_rosout=False,
                             start_parameter_services=False)
    try:
        publisher = node.create_publisher(JointState, args.topic, 10)
        period = 1.0 / args.rate if args.rate > 0 else 0.02

        def publish(values):
            msg = JointState()
            msg.header.stamp = node.get_clock().now().to_msg()
            msg.name = names
            msg.position = [values[n] for n in names] if isinstance(values, dict) else values
            publisher.publish(msg)
            return msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
        print('ready', flush=True)
        next_at, row = time.monotonic(), 0
        while True:
            wait = max(0.0, next_at - time.monotonic())
            readable = rows is None and select.select([sys.stdin], [], [], wait)[0]
            if rows is not None:
                time.sleep(wait)
            if readable:
                line = sys.stdin.readline(MAX_LINE + 1)
                if not line:
                    return 0
                try:
                    positions.update(parse_update(line, names))
                except ValueError as exc:
                    print(f'error {exc}', flush=True)
                    continue
                print(f'stamp {publish(positions)}', flush=True)
                next_at = time.monotonic() + period
                continue
            if time.monotonic() < next_at:
                continue
            if rows is not None and row < len(rows):
                positions.update(zip(names, rows[row]))
                row += 1
                if row == len(rows):
                    print(f'done {publish(positions)}', flush=True)
                    next_at += period
                    continue
            publish(positions)
            next_at += period
            if next_at < time.monotonic() - period:   # (a pause: no burst to catch up)
                next_at = time.monotonic() + period
    except KeyboardInterrupt:
        return 0
    finally:
        node.destroy_node()
        rclpy.try_shutdown()


if __name__ == '__main__':
    from dq_fk_ros.ros.executables import run_main
    sys.exit(run_main(main))
