"""
Offline FK of a joint-state bag: ``dq_fk_bag process`` without its command line.

Every JointState of the bag goes through the node's own input rules
(:class:`~dq_fk_ros.messages.joint_states.JointStateMerger`), then the batched FK in chunks,
written as /tf, /tf_static and the node's pose topics to a new bag (MCAP by default);
``csv_path`` gets the end-effector pose per message.
"""

from contextlib import nullcontext
from dataclasses import dataclass, field, replace
import os
import shutil

from dq_fk_ros.bag.outputs import BagOutputs
from dq_fk_ros.bag.progress import Progress
from dq_fk_ros.description.loading import load_robot
from dq_fk_ros.errors import BagError
from dq_fk_ros.kinematics.dual_quaternion import dq_to_pose_xyzw
from dq_fk_ros.messages.joint_state_input import JointStateInput
from dq_fk_ros.messages.joint_states import JointStateMerger
from dq_fk_ros.storage.reading import joint_state_connections, open_reader
from dq_fk_ros.storage.text import printable
import numpy as np

CHUNK = 4096
# the fleet's progress: a shared counter of JointStates read (set in its workers), or None
_progress_counter = None


def set_progress_counter(counter) -> None:
    """
    Count the JointStates every processing in this process reads into ``counter``.

    ``counter``: a ``multiprocessing.Value`` (or None: no counting); a fleet's pool sets it
    in each worker, so the parent shows one progress bar for all of them.
    """
    global _progress_counter
    _progress_counter = counter


def check_output_paths(in_path, out_path, csv_path, overwrite, csv_only) -> None:
    """
    Refuse output paths that would destroy the input or write somewhere unexpected.

    An output may not be, contain or lie inside the input (paths resolved), nor be a
    symbolic link (never followed, also with ``overwrite``); an existing output needs
    ``overwrite``; its folder must exist. Nothing is written or removed here: every
    refusal is a :class:`BagError` before any output exists.
    """
    inp = os.path.realpath(in_path)
    outputs = [] if csv_only else [('OUT_BAG', out_path)]
    if csv_path:
        outputs.append(('--csv', csv_path))
    if len(outputs) == 2 and (os.path.realpath(csv_path) == os.path.realpath(out_path)
                              or _inside(os.path.realpath(csv_path),
                                         os.path.realpath(out_path))):
        raise BagError(f'--csv {csv_path} would be inside OUT_BAG {out_path}; '
                       f'choose another path')
    for what, path in outputs:
        path = os.fspath(path)
        real = os.path.realpath(path)
        if real == inp or _inside(real, inp):
            raise BagError(f'{what} {path} would overwrite the input bag {in_path}; '
                           f'choose another path')
        if _inside(inp, real):
            raise BagError(f'{what} {path} contains the input bag {in_path}; '
                           f'choose another path')
        if os.path.islink(path):
            raise BagError(f'{what} {path} is a symbolic link; not following it '
                           f'(give the real path)')
        parent = os.path.dirname(os.path.abspath(path))
        if not os.path.isdir(parent):
            raise BagError(f'{what} {path}: folder {parent} does not exist')
        if what == '--csv' and os.path.isdir(path):
            raise BagError(f'--csv {path} is a directory; give a file name')
        if os.path.lexists(path) and not overwrite:
            raise BagError(f'{path} exists; use --overwrite to replace it')
    # what the input really is: its files after symlinks, and their inodes (hard links)
    reals, inodes = _files_of(in_path, follow=True)
    for what, path in outputs:
        real = os.path.realpath(path)
        inside = [r for r in reals if r == real or _inside(r, real)]
        if inside:
            raise BagError(f'{what} {path} holds {inside[0]}, a file the input bag {in_path} '
                           f'reads (through a symbolic link); choose another path')
        _, theirs = _files_of(path, follow=False)
        if theirs & inodes:
            raise BagError(f'{what} {path} is (or holds) a hard link to a file of the input '
                           f'bag {in_path}; choose another path')


def _files_of(path, follow):
    """
    Return ``(real paths, {(device, inode)})`` of the files at or under ``path``.

    ``follow``: symbolic links count as the files they point to (what reading follows);
    else as themselves (what removing or writing touches).
    """
    path = os.fspath(path)
    if not os.path.lexists(path):
        return set(), set()
    names = [path]
    if os.path.isdir(path) and (follow or not os.path.islink(path)):
        names = []
        for folder, dirs, files in os.walk(path, followlinks=False):
            names += [os.path.join(folder, n) for n in files + dirs
                      if n in files or os.path.islink(os.path.join(folder, n))]
    reals, inodes = set(), set()
    for name in names:
        try:
            st = os.stat(name) if follow else os.lstat(name)
        except OSError:  # a dangling link: nothing to protect or clobber
            continue
        reals.add(os.path.realpath(name) if follow else os.path.abspath(name))
        inodes.add((st.st_dev, st.st_ino))
    return reals, inodes


def _inside(path, folder):
    """Whether ``path`` lies strictly inside ``folder`` (both resolved)."""
    return path != folder and os.path.commonpath([path, folder]) == folder


def _remove(path):
    if os.path.isdir(path) and not os.path.islink(path):
        shutil.rmtree(path)
    elif os.path.lexists(path):
        os.remove(path)


class _ReadingStopped(Exception):
    """The reader raised inside the bag; ``partial`` is the summary of what was written."""

    def __init__(self, partial, why):
        super().__init__(why)
        self.partial = partial


@dataclass
class ProcessSummary:
    """
    What :func:`process_bag` did with one bag.

    ``read``: JointState messages on the topic; ``written``: those computed and written (one
    /tf each); ``incomplete``: skipped until every required joint was seen; ``rejected``:
    ``{reason: count}`` as the node's /diagnostics; ``unknown_joints``: names the robot
    does not have; ``error``: one line if part of the bag was damaged or nothing could be
    used (else None); ``note``: one line about how the bag was read (else None);
    ``output``: the bag written (None: nothing, or ``csv_only``); ``topic``: the topic read;
    ``joint_names_seen``: the first 50 joint names the messages carried; ``time_jumps``: the
    times the stamps jumped back and the joint state was reset.
    """

    read: int = 0
    written: int = 0
    incomplete: int = 0
    rejected: dict = field(default_factory=dict)
    unknown_joints: list = field(default_factory=list)
    error: str = None
    note: str = None
    output: object = None
    topic: str = None
    joint_names_seen: list = field(default_factory=list)
    time_jumps: int = 0


@dataclass(frozen=True)
class ProcessOptions:
    """
    How :func:`process_bag` reads and writes (the ``dq_fk_bag process`` options).

    ``topic``: the JointState topic (None: the only one); ``storage``: ``mcap`` or
    ``sqlite3``; ``csv_path``: also the end effector's pose per message (``csv_only``: no
    bag); ``copy_input``: the input topics copied through; ``pose_namespace``,
    ``frame_prefix``, ``out_of_limits``: as the node's; ``poses``: ``all``, ``end`` or
    ``none``; ``chunk``: messages computed at once; ``dh_frames``: whether /tf and the pose
    topics carry the DH frames (None: the robot's default, as the node's
    ``publish_dh_frames``); ``compression``: MCAP chunks ``none``, ``zstd`` or ``lz4``;
    ``reference_reader``: read with rosbags' reader, the reference (else an intact MCAP
    folder a chunk at a time).
    """

    topic: str = None
    storage: str = 'mcap'
    overwrite: bool = False
    csv_path: str = None
    csv_only: bool = False
    copy_input: bool = False
    pose_namespace: str = '/dq_fk_node'
    frame_prefix: str = ''
    out_of_limits: str = 'warn'
    progress: bool = True
    chunk: int = CHUNK
    poses: str = 'end'
    dh_frames: bool = None
    compression: str = 'none'
    reference_reader: bool = False


def process_bag(in_path, out_path, robot, options=None, **changes) -> ProcessSummary:
    """
    Compute every frame for every JointState of ``in_path``; return a :class:`ProcessSummary`.

    :param options: a :class:`ProcessOptions` (default: its defaults); ``changes`` are
        fields of it given by name (``process_bag(a, b, 'rl15', csv_path='ee.csv')``).

    Messages the node would reject are skipped and counted by reason; everything valid is
    written. A chunk that rosbags cannot read (damaged) makes the whole bag be read again
    record by record, skipping only the damaged chunks. The summary's ``error`` says what
    was damaged, or that no message could be used (the output is then removed). Raises
    :class:`BagError` for a command that cannot run (paths, topics, refused outputs).
    """
    o = replace(options or ProcessOptions(), **changes)
    model = robot if not isinstance(robot, (str, os.PathLike)) else load_robot(robot).model
    if o.csv_only and not o.csv_path:
        raise BagError('--csv-only needs --csv FILE')
    check_compression(o)
    check_output_paths(in_path, out_path, o.csv_path, o.overwrite, o.csv_only)
    reader = open_reader(in_path, reference=o.reference_reader)
    if o.copy_input and not reader.copies_messages:
        reader.close()
        raise BagError(f'{in_path}: --copy-input cannot copy ROS 1 messages; convert the bag '
                       f'first (rosbags-convert --src {in_path} --dst NEW_BAG)')
    args = (model, in_path, out_path, o)
    try:
        try:
            summary = _process_with(reader, *args)
        except _ReadingStopped as stop:
            retry = reader.fallback()
            if retry is None:
                summary = stop.partial
            else:
                reader.close()
                reader = retry
                summary = _process_with(reader, *args)
    except _ReadingStopped as stop:
        summary = stop.partial
    finally:
        reader.close()
    summary.output = None if o.csv_only else out_path
    summary.note = reader.note
    summary.error = summary.error or reader.damage
    if summary.written == 0:
        for path in ([] if o.csv_only else [out_path]) + ([o.csv_path] if o.csv_path else []):
            _remove(path)
        summary.output = None
        summary.error = '; '.join(filter(None, [
            summary.error, nothing_usable(in_path, summary, model, robot)]))
    return summary


def process_window(in_path, out_path, model, options, window) -> ProcessSummary:
    """
    Process one window of a bag (see :mod:`dq_fk_ros.bag.windows`) into its own bag.

    As :func:`process_bag` on the messages of the window, after merging those of the
    window's look-back (not written) so it starts from the joint values the bag held there;
    /tf_static and /robot_description only in the first window. No CSV, and no record-by-
    record fallback for a damaged chunk: its ``error`` says where reading stopped, and the
    fleet reports the bag (as it reports a damaged bag the one-bag way). Returns a
    :class:`ProcessSummary` of the window's messages alone.
    """
    o = replace(options, csv_path=None, csv_only=False)
    check_compression(o)
    reader = open_reader(in_path, reference=o.reference_reader)
    try:
        summary = _process_with(reader, model, in_path, out_path, o, window)
    except _ReadingStopped as stop:
        summary = stop.partial
    finally:
        reader.close()
    summary.output = out_path
    return summary


def check_compression(options) -> None:
    """Refuse a compression that is not one, or one for a storage that has none."""
    from dq_fk_ros.storage.mcap_writer import COMPRESSIONS
    if options.compression not in COMPRESSIONS:
        raise BagError(f'--compression {printable(str(options.compression), 20)}: one of '
                       f'{", ".join(COMPRESSIONS)}')
    if options.compression != 'none' and options.storage != 'mcap':
        raise BagError(f'--compression {options.compression} is for MCAP output; '
                       f'--storage {options.storage} is written uncompressed')


def nothing_usable(in_path, summary, model, robot) -> str:
    """One line: no message could be used, what the bag has and what the robot needs."""
    names = [printable(n, 40) for n in summary.joint_names_seen]
    has = ('names joints ' + ', '.join(names[:12]) + (' ...' if len(names) > 12 else '')
           if names else 'names no joints')
    source = f' ({robot})' if isinstance(robot, (str, os.PathLike)) else ''
    return (f'{in_path}: no JointState message could be used (nothing written): '
            f'{printable(summary.topic)} has {summary.read} messages and {has}; robot '
            f"{model.name}{source} needs {', '.join(model.joint_names)}")


def _process_with(reader, model, in_path, out_path, o, window=None):
    """
    Process the bag with one reader (options ``o``); raises ``_ReadingStopped`` if it fails.

    :param window: a :class:`~dq_fk_ros.bag.windows.Window`: only its messages (None: all).
    """
    topic, storage, csv_path, csv_only = o.topic, o.storage, o.csv_path, o.csv_only
    copy_input, pose_namespace, frame_prefix = o.copy_input, o.pose_namespace, o.frame_prefix
    out_of_limits, progress, chunk, poses = o.out_of_limits, o.progress, o.chunk, o.poses
    conns = joint_state_connections(reader, in_path, topic)
    writer = None
    if not csv_only:
        if os.path.lexists(out_path):  # checked: --overwrite given, or our own first try
            _remove(out_path)
        from dq_fk_ros.storage.formats import open_bag_writer
        writer = open_bag_writer(out_path, storage, o.compression)
    copy_from = list(reader.connections) if copy_input else []
    try:
        outputs = BagOutputs(writer, model, pose_namespace, frame_prefix,
                             copy_from, poses, o.dh_frames) if writer is not None else None
    except BagError:  # refused before anything was written: leave no output behind
        writer.abort()
        shutil.rmtree(out_path, ignore_errors=True)
        raise
    try:
        if outputs is not None and window is not None and window.index:
            outputs.static_written = True  # the first window writes /tf_static
        summary, stopped = _process_messages(reader, conns, model, outputs, csv_path,
                                             copy_input, out_of_limits, progress, chunk,
                                             in_path, window)
    finally:
        if writer is not None:
            writer.close()
    summary.topic = conns[0].topic
    if stopped:
        raise _ReadingStopped(summary, summary.error)
    return summary


class _Pending:
    """JointStates read and not yet computed: pieces of batches, joined when flushed."""

    def __init__(self):
        self.pieces, self.count = [], 0

    def add(self, batch, rows) -> None:
        """Add the messages ``rows`` (a mask or None: all) of a :class:`MessageBatch`."""
        if rows is None:
            self.pieces.append((batch.data, batch.starts, batch.lengths, batch.log_times))
            self.count += len(batch)
            return
        self.pieces.append((batch.data, batch.starts[rows], batch.lengths[rows],
                            batch.log_times[rows]))
        self.count += int(np.count_nonzero(rows))

    def take(self) -> tuple:
        """Return ``(data, starts, lengths, log_times)`` of everything pending, and forget it."""
        pieces, self.pieces, self.count = self.pieces, [], 0
        if len(pieces) == 1:
            return pieces[0]
        data = b''.join(bytes(d) for d, _, _, _ in pieces)
        shift = np.cumsum([0] + [len(d) for d, _, _, _ in pieces[:-1]])
        return (data, np.concatenate([s + k for (_, s, _, _), k in zip(pieces, shift)]),
                np.concatenate([n for _, _, n, _ in pieces]),
                np.concatenate([t for _, _, _, t in pieces]))


def _look_back(reader, conns, model, out_of_limits, chunk, window):
    """
    Return a merger holding the joint values the bag held at the window's start.

    Merges the messages of the look-back spans (one chunk before the window, then two,
    four... back to the bag's start) until every joint has been named; its counts are then
    cleared (those messages belong to earlier windows), the time jumps seen kept.
    """
    for start in window.lookback_ns:
        merger = JointStateMerger(model.joint_names, model.limits, out_of_limits,
                                  required=len(model.required_joints))
        taken = JointStateInput(merger)
        for batch in reader.message_batches(connections=conns, start=start,
                                            stop=window.start_ns, size=chunk):
            taken.take_many(batch.data, batch.starts, batch.lengths)
        if not merger.never_seen_any:
            break
    jumps = merger.counts['time_jumps']
    merger.clear_counts()
    return merger, jumps


def _process_messages(reader, conns, model, outputs, csv_path, copy_input, out_of_limits,
                      progress, chunk, in_path, window=None):
    """Read, merge, compute and write chunk by chunk; return the summary and if it stopped."""
    jumps_before = 0
    if window is not None and window.start_ns is not None:
        merger, jumps_before = _look_back(reader, conns, model, out_of_limits, chunk, window)
    else:
        merger = JointStateMerger(model.joint_names, model.limits, out_of_limits,
                                  required=len(model.required_joints))
    taken = JointStateInput(merger)
    ids = np.array(sorted(c.id for c in conns), np.int64)
    meter = Progress(sum(c.msgcount for c in conns), 'dq_fk_bag process', enabled=progress)
    # the CSV file is closed whatever happens (an exception from a damaged bag included)
    with open(csv_path, 'w', encoding='utf-8') if csv_path else nullcontext() as csv:
        if csv:
            csv.write('stamp_ns,x,y,z,qx,qy,qz,qw\n')
        pending = _Pending()
        seen = written = 0
        error = None
        stopped = False
        names_seen = []  # the first joint names the bag's messages carry, for a closing message

        def flush():
            """Parse, merge (the node's rules), compute and write the collected messages."""
            nonlocal written
            if not pending.count:
                return
            counted = pending.count
            data, starts, lengths, log_times = pending.take()
            merged = taken.take_many(data, starts, lengths)
            groups, valid, stamps = merged.groups, merged.valid, merged.stamps
            published, q, qdot = merged.published, merged.q, merged.qdot
            for group in groups:
                if len(names_seen) < 50:
                    names_seen.extend(n for n in group.names if n not in names_seen)
            where = valid[published]   # the batch index of every published message
            out_times = np.asarray(log_times, dtype=np.int64)[where]
            stamps = stamps[published]
            stamps = np.where(stamps != 0, stamps, out_times)  # output stamps are input stamps
            if _progress_counter is not None:
                with _progress_counter.get_lock():
                    _progress_counter.value += counted
            if not len(q):
                return
            if outputs is not None:
                if not outputs.static_written:
                    outputs.write_static(int(out_times[0]))
                ee = outputs.write_chunk(q, stamps, out_times, merger.last_seen, qdot)
            else:
                ee = dq_to_pose_xyzw(model.end_effector_batch(q))
            if csv:
                line = '%d,' + ','.join(['%.17g'] * 7) + '\n'
                csv.writelines(line % (s, *p) for s, p in zip(stamps.tolist(), ee.tolist()))
            written += len(q)

        span = {} if window is None else {'start': window.start_ns, 'stop': window.stop_ns}
        by_id = {c.id: c for c in reader.connections}   # (--copy-input's connections)
        batches = iter(reader.message_batches(
            connections=list(reader.connections) if copy_input else conns, size=chunk, **span))
        while True:
            try:
                batch = next(batches)
            except StopIteration:
                break
            except Exception as exc:  # a truncated or corrupt bag: keep everything read so far
                error = f'{in_path}: reading stopped after {seen} JointState messages: {exc}'
                stopped = True
                break
            rows = None
            if copy_input:
                for i, cid in enumerate(batch.connection_ids.tolist()):
                    outputs.copy(by_id[cid], int(batch.log_times[i]), batch.raw(i))
                rows = np.isin(batch.connection_ids, ids)
            pending.add(batch, rows)
            seen += len(batch) if rows is None else int(np.count_nonzero(rows))
            if pending.count >= chunk:
                flush()
                meter.update(seen)
        flush()
        meter.update(seen, force=True)
        counts = merger.counts
        rejected = {k[len('rejected_'):]: v for k, v in counts.items()
                    if k.startswith('rejected_') and v}
        return ProcessSummary(read=seen, written=written, incomplete=counts['incomplete'],
                              rejected=rejected, unknown_joints=sorted(merger.unknown),
                              error=error, joint_names_seen=names_seen[:50],
                              time_jumps=jumps_before + counts['time_jumps']), stopped
