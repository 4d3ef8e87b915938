"""
Measured poses paired with joint values: from a CSV file, or from a bag's topics.

A CSV file has a header row naming a column per joint of the chain (radians or metres),
``x, y, z`` (metres, the measurement frame) and, where orientation is measured, ``qx, qy,
qz, qw`` (a unit quaternion, (x, y, z, w) as ROS writes it; other columns are ignored).
A bag pairs each ``geometry_msgs/PoseStamped`` of a topic with the joint states at its
header stamp: linearly interpolated between the JointStates before and after it (their
header stamps; the log time where a stamp is zero), left out and counted when no
JointState naming every joint of the chain lies within ``max_gap_s`` on either side or
when the joints moved more than ``max_motion`` (rad or m) between the two. Everything read
is bounded (file size, rows, messages); errors are one line and never repeat the file's
values.
"""

import csv
import io
import math
import os

from dq_fk_ros.calibration.identify import Measurements
from dq_fk_ros.errors import BagError, CdrError, DqFkError, listing
from dq_fk_ros.messages.cdr import parse_joint_state
from dq_fk_ros.messages.cdr_tf import parse_pose_stamped
from dq_fk_ros.storage.reading import joint_state_connections, open_reader
from dq_fk_ros.storage.text import printable
import numpy as np

MAX_CSV_BYTES = 256 * 1024 * 1024
MAX_ROWS = 100_000      # measurements: the Jacobian is 6 x 8 bytes a parameter for each
MAX_COLUMNS = 4096
MAX_JOINT_STATES = 20_000_000
POSE_STAMPED = 'geometry_msgs/msg/PoseStamped'
POSITION = ('x', 'y', 'z')
ORIENTATION = ('qx', 'qy', 'qz', 'qw')


class DataError(DqFkError, ValueError):
    """Measurements that do not fit the robot (a one-line message)."""


def read_csv(path, joint_names) -> Measurements:
    """
    Return the measurements of a CSV file (module doc) for the joints ``joint_names``.

    :raises DataError: a missing column, a value that is not a finite number, a quaternion
        that is not of unit length, too few rows, a file too big.
    """
    path = os.fspath(path)
    if os.path.exists(path) and not os.path.isfile(path):
        raise DataError(f'{path}: not a regular file')   # (a FIFO would never end)
    try:
        size = os.path.getsize(path)
        if size > MAX_CSV_BYTES:
            raise DataError(f'{path}: {size} bytes; at most {MAX_CSV_BYTES} are read')
        # (utf-8-sig: a spreadsheet's "CSV UTF-8" starts with a byte-order mark)
        with open(path, encoding='utf-8-sig', newline='') as stream:
            text = stream.read(MAX_CSV_BYTES + 1)
    except UnicodeDecodeError:
        raise DataError(f'{path}: not UTF-8 text') from None
    except OSError as exc:
        raise DataError(f'{path}: cannot read it ({exc.strerror or type(exc).__name__})') \
            from None
    rows = csv.reader(io.StringIO(text))
    try:
        header = [name.strip() for name in next(rows)]
    except (StopIteration, csv.Error):
        raise DataError(f'{path}: no header row') from None
    if len(header) > MAX_COLUMNS:
        raise DataError(f'{path}: {len(header)} columns; at most {MAX_COLUMNS}')
    at = {name: i for i, name in reversed(list(enumerate(header)))}
    missing = [n for n in list(joint_names) + list(POSITION) if n not in at]
    if missing:
        raise DataError(f'{path}: no column {listing(missing, 8)}; a column per joint '
                        f'({listing(joint_names, 8)}) and x, y, z (m) are needed, '
                        f'qx, qy, qz, qw with orientations')
    given = [n for n in ORIENTATION if n in at]
    if given and len(given) != 4:
        raise DataError(f'{path}: orientation columns {", ".join(given)} without the others; '
                        f'give all of qx, qy, qz, qw or none')
    wanted = list(joint_names) + list(POSITION) + (list(ORIENTATION) if given else [])
    columns = [at[n] for n in wanted]
    values = []
    try:
        for line, row in enumerate(rows, start=2):
            if not row or all(not cell.strip() for cell in row):
                continue
            if len(values) >= MAX_ROWS:
                raise DataError(f'{path}: more than {MAX_ROWS} rows')
            out = []
            for name, c in zip(wanted, columns):
                try:
                    v = float(row[c])
                except (IndexError, ValueError):
                    v = math.nan
                if not math.isfinite(v):
                    raise DataError(f'{path} line {line}: column {name}: not a finite number')
                out.append(v)
            values.append(out)
    except csv.Error as exc:
        raise DataError(f'{path}: not a CSV file ({type(exc).__name__})') from None
    values = np.array(values, dtype=float).reshape(-1, len(wanted))
    n = len(joint_names)
    quaternions = None
    if given:
        xyzw = values[:, n + 3:]
        norms = np.linalg.norm(xyzw, axis=1)
        bad = np.flatnonzero(np.abs(norms - 1.0) > 1e-3)
        if len(bad):
            raise DataError(f'{path}: row {int(bad[0]) + 1} of data: qx, qy, qz, qw is not a '
                            f'unit quaternion (norm {norms[bad[0]]:.4g})')
        quaternions = np.concatenate([xyzw[:, 3:], xyzw[:, :3]], axis=1) / norms[:, None]
    return _enough(path, Measurements(values[:, :n], values[:, n:n + 3], quaternions))


def _enough(path, data: Measurements) -> Measurements:
    if len(data) < 3:
        raise DataError(f'{path}: {len(data)} measurements; at least 3 are needed (tens to '
                        f'hundreds for a calibration)')
    return data


def read_bag(path, joint_names, pose_topic, joint_topic=None, max_gap_s=0.05,
             max_motion=1e-3, orientation=True) -> tuple:
    """
    Return ``(Measurements, counts)`` of the poses on ``pose_topic`` paired with the joints.

    ``counts``: ``poses`` read, ``paired``, and those left out: ``no_joint_state`` (none
    within ``max_gap_s`` on a side), ``moving`` (the joints moved more than
    ``max_motion`` between the two), ``malformed`` (messages that could not be read).

    :param orientation: use the poses' orientations (False: their positions only).
    :raises BagError: no such topic, a topic of another type, too many messages.
    :raises DataError: too few measurements, or poses in more than one frame.
    """
    path = os.fspath(path)
    reader = open_reader(path)
    try:
        poses = [c for c in reader.connections if c.topic == pose_topic]
        if not poses:
            topics = ', '.join(f'{printable(t)} ({printable(m)})'
                               for t, m in reader.all_topics[:20]) or 'none'
            raise BagError(f'{path} has no topic {printable(pose_topic)}; its topics: {topics}')
        if any(c.msgtype != POSE_STAMPED for c in poses):
            raise BagError(f'{path}: topic {printable(pose_topic)} has type '
                           f'{printable(poses[0].msgtype)}, not {POSE_STAMPED}')
        joints = joint_state_connections(reader, path, joint_topic)
        stamps, q, counts = _joint_states(reader, joints, list(joint_names))
        measured, frames = [], set()
        for _, log_time, raw in reader.messages(poses):
            counts['poses'] += 1
            if counts['poses'] > MAX_ROWS:
                raise BagError(f'{path}: more than {MAX_ROWS} poses on {printable(pose_topic)}')
            try:
                stamp, frame_id, pose = parse_pose_stamped(bytes(raw))
            except CdrError:
                counts['malformed'] += 1
                continue
            if not all(map(math.isfinite, pose)) or \
                    abs(math.sqrt(sum(v * v for v in pose[3:])) - 1.0) > 1e-3:
                counts['malformed'] += 1   # (not a number, or not a unit quaternion)
                continue
            frames.add(frame_id)
            measured.append((stamp or log_time, pose))
    finally:
        reader.close()
    if len(frames) > 1:
        raise DataError(f'{path}: the poses on {printable(pose_topic)} are in '
                        f'{len(frames)} frames; one measurement frame is needed')
    rows, positions, quaternions = [], [], []
    for stamp, pose in measured:
        k = int(np.searchsorted(stamps, stamp, side='right'))
        if k == 0 or stamp - stamps[k - 1] > max_gap_s * 1e9 or (
                stamp != stamps[k - 1] and (k == len(stamps) or
                                            stamps[k] - stamp > max_gap_s * 1e9)):
            counts['no_joint_state'] += 1
            continue
        if stamp == stamps[k - 1]:
            value = q[k - 1]
        else:
            before, after = q[k - 1], q[k]
            if np.abs(after - before).max() > max_motion:
                counts['moving'] += 1
                continue
            w = (stamp - stamps[k - 1]) / (stamps[k] - stamps[k - 1])
            value = before + w * (after - before)
        rows.append(value)
        positions.append(pose[:3])
        x, y, z, w_ = pose[3:]
        quaternions.append((w_, x, y, z))
    counts['paired'] = len(rows)
    if not rows:
        data = Measurements(np.zeros((0, len(joint_names))), np.zeros((0, 3)))
    else:
        quat = np.array(quaternions)
        norms = np.linalg.norm(quat, axis=1)
        data = Measurements(np.array(rows), np.array(positions),
                            quat / norms[:, None] if orientation else None)
    return _enough(path, data), counts


def _joint_states(reader, connections, names) -> tuple:
    """Return the stamps and joint values of the JointStates that name every joint."""
    counts = {'poses': 0, 'paired': 0, 'no_joint_state': 0, 'moving': 0, 'malformed': 0,
              'joint_states': 0, 'joint_states_without_the_joints': 0}
    stamps, values = [], []
    wanted = set(names)
    for _, log_time, raw in reader.messages(connections):
        counts['joint_states'] += 1
        if counts['joint_states'] > MAX_JOINT_STATES:
            raise BagError(f'more than {MAX_JOINT_STATES} JointStates; cut the bag '
                           f'(dq_fk_bag, --start/--end) around the measurements')
        try:
            stamp, got, position, _ = parse_joint_state(bytes(raw))
        except CdrError:
            counts['malformed'] += 1
            continue
        if not wanted <= set(got) or len(position) != len(got):
            counts['joint_states_without_the_joints'] += 1
            continue
        at = {n: i for i, n in enumerate(got)}
        row = [float(position[at[n]]) for n in names]
        if not all(map(math.isfinite, row)):
            counts['malformed'] += 1
            continue
        stamps.append(stamp or log_time)
        values.append(row)
    order = np.argsort(np.array(stamps, dtype=np.int64), kind='stable')
    return (np.array(stamps, dtype=np.int64)[order],
            np.array(values, dtype=float).reshape(-1, len(names))[order], counts)


__all__ = ['DataError', 'read_bag', 'read_csv']
