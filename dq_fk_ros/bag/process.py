"""
Offline FK of a joint-state bag: ``dq_fk_bag process`` without its command line.

Every JointState of the bag goes through the node's own input rules
(:class:`~dq_fk_ros.messages.joint_states.JointStateMerger`), then the batched FK in chunks,
written as /tf, /tf_static and the node's pose topics to a new bag (MCAP by default);
``csv_path`` gets the end-effector pose per message.
"""

from contextlib import nullcontext
import os
import shutil

from dq_fk_ros.bag.progress import Progress
from dq_fk_ros.bag.reading import BagError, joint_state_connections, open_reader, Ros1Bag
from dq_fk_ros.bag.text import printable
from dq_fk_ros.description.loading import load_robot
from dq_fk_ros.description.urdf import description_urdf, HelperFrames
from dq_fk_ros.kinematics.dual_quaternion import dq_to_pose_xyzw
from dq_fk_ros.messages.cdr import (
    JointStateNames, JointStateRun, parse_joint_states, pose_stamped_template,
    tf_message_template)
from dq_fk_ros.messages.joint_states import JointStateMerger
import numpy as np

CHUNK = 4096


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
        self.prefix = frame_prefix
        self.frame_ids = [frame_prefix + name for name in model.frame_names]
        parents = [model.tf_frame_id(p, frame_prefix) for p in model.parent_frames]
        self.moving_edges = model.moving_edges
        self.static = model.static_transforms()
        add = writer.add_connection
        self.tf = add('/tf', 'tf2_msgs/msg/TFMessage', typestore=typestore,
                      offered_qos_profiles=qos(100, volatile))
        self.tf_static = add('/tf_static', 'tf2_msgs/msg/TFMessage', typestore=typestore,
                             offered_qos_profiles=qos(1, latched))
        n_frames = len(model.frame_names)
        self.end = model.end_effector_index
        self.pose_frames = {'all': list(range(n_frames)), 'end': [self.end],
                            'none': []}[poses]
        self.poses = [add(f'{pose_namespace}/pose/{model.topic_names[k]}',
                          'geometry_msgs/msg/PoseStamped', typestore=typestore,
                          offered_qos_profiles=qos(10, volatile)) for k in self.pose_frames]
        # the URDF's helper links, as the node publishes them (children of their DH frames)
        self.helpers = HelperFrames(model)
        # transforms and poses that depend on optional joints (side branches, every joint of
        # a tree) are written where the message's state has named those joints, as the node
        # does: each message's /tf holds the transforms whose joints are known
        edge_needs, frame_needs = model.edge_needs, model.frame_needs
        index = {name: i for i, name in enumerate(model.joint_names)}
        self.gated_edges = [(k, r) for k, r in self.moving_edges if edge_needs[k]]
        self._edge_columns = [[index[n] for n in edge_needs[k]] for k, _ in self.gated_edges]
        self._parents = parents
        self._tf_templates = {}
        self.base_poses = [i for i, k in enumerate(self.pose_frames) if not frame_needs[k]]
        self.pose_groups = []   # (joint columns, [pose index, ...]) per set of needs
        for group in sorted({frame_needs[self.pose_frames[i]] for i in
                             range(len(self.pose_frames))} - {frozenset()}, key=sorted):
            self.pose_groups.append(([index[n] for n in sorted(group)],
                                     [i for i, k in enumerate(self.pose_frames)
                                      if frame_needs[k] == group]))
        self.moving_edges = [(k, r) for k, r in self.moving_edges if not edge_needs[k]]
        self.tf_template = tf_message_template(
            [(parents[k], self.frame_ids[k]) for k, _ in self.moving_edges]
            + [(self.frame_ids[k], frame_prefix + name) for name, k in self.helpers.moving])
        self.pose_template = pose_stamped_template(model.tf_frame_id(model.fixed_frame,
                                                                     frame_prefix))
        self.static_template = tf_message_template(
            [(parents[k], self.frame_ids[k]) for k, _ in self.static]
            + [(self.frame_ids[k], frame_prefix + name) for name, k, _ in self.helpers.static])
        try:
            self.urdf = description_urdf(model)
        except ValueError:  # a robot URDF cannot express: no /robot_description
            self.urdf = None
        self.description = add('/robot_description', 'std_msgs/msg/String',
                               typestore=typestore, offered_qos_profiles=qos(1, latched)) \
            if self.urdf is not None else None
        self.copied = {}
        for conn in copy_from:
            self.copied[conn.id] = _copy_connection(writer, conn, typestore)
        self.static_written = False

    def write_static(self, time_ns):
        """Write /tf_static once: base, fixed rows, tool and links, stamped ``time_ns``."""
        values = [np.array(pose) for _, pose in self.static]
        values += [offset.to_pose_xyzw() for _, _, offset in self.helpers.static]
        row = self.static_template.fill([time_ns], np.concatenate(values)[None, :])[0]
        self.writer.write(self.tf_static, time_ns, memoryview(row))
        if self.description is not None:
            text = self.typestore.types['std_msgs/msg/String'](data=self.urdf)
            self.writer.write(self.description, time_ns,
                              self.typestore.serialize_cdr(text, 'std_msgs/msg/String'))
        self.static_written = True

    def write_chunk(self, q, stamps_ns, log_times_ns, seen=None):
        """
        FK of a chunk of configurations, serialized and written as arrays.

        ``seen``: ``(N, dof)`` mask of the joints each message's state had (the merger's
        ``last_seen``); side-branch links are written where their joints were seen.
        """
        model = self.model
        absolute = dq_to_pose_xyzw(model.forward_all_batch(q))           # (N, frames, 7)
        all_relative = model.relative_batch(q)   # (N, rows + links, 8): poses of those written
        relative = dq_to_pose_xyzw(all_relative[:, [k for _, k in self.moving_edges]])
        n = len(q)
        relative = relative.reshape(n, -1)
        if self.helpers.moving:  # (a cylindrical row's first motion: rare, per message)
            moving = np.array([np.concatenate(self.helpers.moving_poses(row)) for row in q])
            relative = np.concatenate([relative, moving], axis=1)
        stamps_ns, log_times_ns = np.asarray(stamps_ns), np.asarray(log_times_ns)
        pose_rows = [self.pose_template.fill(stamps_ns, absolute[:, self.pose_frames[i]])
                     for i in self.base_poses]
        channels = [self.poses[i] for i in self.base_poses]
        if self.gated_edges:
            self._write_gated_tf(all_relative, relative, stamps_ns, log_times_ns, seen)
        elif relative.shape[1]:  # a robot with nothing moving has no /tf (as the node)
            channels.insert(0, self.tf)
            pose_rows.insert(0, self.tf_template.fill(stamps_ns, relative))
        if channels:
            self.writer.write_rows(channels, log_times_ns, pose_rows)
        for columns, poses in self.pose_groups:
            rows = np.ones(n, bool) if seen is None else seen[:, columns].all(axis=1)
            if rows.any():
                self.writer.write_rows(
                    [self.poses[i] for i in poses], log_times_ns[rows],
                    [self.pose_template.fill(stamps_ns[rows], absolute[rows, self.pose_frames[i]])
                     for i in poses])
        return absolute[:, self.end]

    def _write_gated_tf(self, all_relative, relative, stamps_ns, log_times_ns, seen):
        """Write /tf where transforms need optional joints: one message per state, as the node."""
        n = len(stamps_ns)
        if seen is None:
            shown = np.ones((n, len(self.gated_edges)), bool)
        else:
            shown = np.stack([seen[:, cols].all(axis=1) for cols in self._edge_columns], axis=1)
        patterns, inverse = np.unique(shown, axis=0, return_inverse=True)
        inverse = inverse.reshape(-1)
        for p, pattern in enumerate(patterns):
            rows = inverse == p
            chosen = [edge for edge, on in zip(self.gated_edges, pattern) if on]
            if not relative.shape[1] and not chosen:
                continue  # nothing known to move yet: no /tf (as the node)
            key = pattern.tobytes()
            template = self._tf_templates.get(key)
            if template is None:
                template = self._tf_templates[key] = tf_message_template(
                    [(self._parents[k], self.frame_ids[k]) for k, _ in self.moving_edges]
                    + [(self.frame_ids[k], self.prefix + name) for name, k in self.helpers.moving]
                    + [(self._parents[k], self.frame_ids[k]) for k, _ in chosen])
            values = np.concatenate([relative[rows], dq_to_pose_xyzw(
                all_relative[rows][:, [r for _, r in chosen]]).reshape(int(rows.sum()), -1)],
                axis=1)
            self.writer.write_rows([self.tf], log_times_ns[rows],
                                   [template.fill(stamps_ns[rows], values)])

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


def check_output_paths(in_path, out_path, csv_path, overwrite, csv_only):
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


def process_bag(in_path, out_path, robot, topic=None, storage='mcap', overwrite=False,
                csv_path=None, csv_only=False, copy_input=False, pose_namespace='/dq_fk_node',
                frame_prefix='', out_of_limits='warn', progress=True, chunk=CHUNK,
                poses='all'):
    """
    Compute every frame for every JointState of ``in_path``; return a summary dict.

    Messages the node would reject are skipped and counted by reason; everything valid is
    written. A chunk that rosbags cannot read (damaged) makes the whole bag be read again
    record by record, skipping only the damaged chunks. The summary's ``error`` says what
    was damaged, or that no message could be used (the output is then removed). Raises
    :class:`BagError` for a command that cannot run (paths, topics, refused outputs).
    """
    model = robot if not isinstance(robot, (str, os.PathLike)) else load_robot(robot).model
    if csv_only and not csv_path:
        raise BagError('--csv-only needs --csv FILE')
    check_output_paths(in_path, out_path, csv_path, overwrite, csv_only)
    reader = open_reader(in_path)
    if copy_input and isinstance(reader, Ros1Bag):
        reader.close()
        raise BagError(f'{in_path}: --copy-input cannot copy ROS 1 messages; convert the bag '
                       f'first (rosbags-convert --src {in_path} --dst NEW_BAG)')
    args = (model, topic, storage, out_path, csv_path, csv_only, copy_input, pose_namespace,
            frame_prefix, out_of_limits, progress, chunk, poses, in_path)
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
                summary = _process_with(reader, *args, overwrite_own=True)
    except _ReadingStopped as stop:
        summary = stop.partial
    finally:
        reader.close()
    summary['output'] = None if csv_only else out_path
    summary['note'] = reader.note
    summary['error'] = summary['error'] or reader.damage
    if summary['written'] == 0:
        for path in ([] if csv_only else [out_path]) + ([csv_path] if csv_path else []):
            _remove(path)
        summary['output'] = None
        summary['error'] = '; '.join(filter(None, [
            summary['error'], nothing_usable(in_path, summary, model, robot)]))
    return summary


def nothing_usable(in_path, summary, model, robot):
    """One line: no message could be used, what the bag has and what the robot needs."""
    names = [printable(n, 40) for n in summary['joint_names_seen']]
    has = ('names joints ' + ', '.join(names[:12]) + (' ...' if len(names) > 12 else '')
           if names else 'names no joints')
    source = f' ({robot})' if isinstance(robot, (str, os.PathLike)) else ''
    return (f'{in_path}: no JointState message could be used (nothing written): '
            f"{printable(summary['topic'])} has {summary['read']} messages and {has}; robot "
            f"{model.name}{source} needs {', '.join(model.joint_names)}")


def _process_with(reader, model, topic, storage, out_path, csv_path, csv_only, copy_input,
                  pose_namespace, frame_prefix, out_of_limits, progress, chunk, poses,
                  in_path, overwrite_own=False):
    """Process the bag with one reader; raises ``_ReadingStopped`` if reading fails."""
    from dq_fk_ros.bag.writer import BagWriter
    from rosbags.typesys import get_typestore, Stores
    conns = joint_state_connections(reader, in_path, topic)
    writer = None
    if not csv_only:
        if os.path.lexists(out_path):  # checked: --overwrite given, or our own first try
            _remove(out_path)
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
    summary['topic'] = conns[0].topic
    if summary.pop('stopped'):
        raise _ReadingStopped(summary, summary['error'])
    return summary


def _process_messages(reader, conns, model, outputs, csv_path, copy_input, out_of_limits,
                      progress, chunk, in_path):
    """Read, merge, compute and write chunk by chunk; return the summary dict."""
    merger = JointStateMerger(model.joint_names, model.limits, out_of_limits,
                              required=len(model.required_joints))
    cache = JointStateNames()
    ids = {c.id for c in conns}
    meter = Progress(sum(c.msgcount for c in conns), 'dq_fk_bag process', enabled=progress)
    # the CSV file is closed whatever happens (an exception from a damaged bag included)
    with open(csv_path, 'w', encoding='utf-8') if csv_path else nullcontext() as csv:
        if csv:
            csv.write('stamp_ns,x,y,z,qx,qy,qz,qw\n')
        raws, log_times = [], []
        seen = written = 0
        error = None
        stopped = False
        names_seen = []  # the first joint names the bag's messages carry, for a closing message

        def flush():
            """Parse, merge (the node's rules), compute and write the collected messages."""
            nonlocal written
            if not raws:
                return
            items = parse_joint_states(raws, cache)
            runs = [item for item in items if isinstance(item, JointStateRun)]
            for run in runs:
                if len(names_seen) < 50:
                    names_seen.extend(n for n in run.names if n not in names_seen)
            malformed = len(items) - len(runs)
            merger.counts['received'] += malformed
            merger.count_rejected('malformed_cdr', malformed)
            published, q, _ = merger.merge_many(
                [(r.names, r.positions, r.velocities, r.stamps_ns) for r in runs])
            # message index in this batch of every run message, in merge order
            where = np.concatenate([r.first + np.arange(len(r.stamps_ns)) for r in runs] or [[]])
            where = where.astype(np.int64)[published]
            out_times = np.array(log_times, dtype=np.int64)[where]
            stamps = np.concatenate([r.stamps_ns for r in runs] or [[]])
            stamps = stamps.astype(np.int64)[published]
            stamps = np.where(stamps != 0, stamps, out_times)  # output stamps are input stamps
            raws.clear()
            log_times.clear()
            if not len(q):
                return
            if outputs is not None:
                if not outputs.static_written:
                    outputs.write_static(int(out_times[0]))
                ee = outputs.write_chunk(q, stamps, out_times, merger.last_seen)
            else:
                ee = dq_to_pose_xyzw(model.end_effector_batch(q))
            if csv:
                line = '%d,' + ','.join(['%.17g'] * 7) + '\n'
                csv.writelines(line % (s, *p) for s, p in zip(stamps.tolist(), ee.tolist()))
            written += len(q)

        messages = iter(reader.messages(
            connections=list(reader.connections) if copy_input else conns))
        while True:
            try:
                conn, log_time, raw = next(messages)
            except StopIteration:
                break
            except Exception as exc:  # a truncated or corrupt bag: keep everything read so far
                error = f'{in_path}: reading stopped after {seen} JointState messages: {exc}'
                stopped = True
                break
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
        flush()
        meter.update(seen, force=True)
        counts = merger.counts
        rejected = {k[len('rejected_'):]: v for k, v in counts.items()
                    if k.startswith('rejected_') and v}
        return {'read': seen, 'written': written, 'incomplete': counts['incomplete'],
                'rejected': rejected, 'unknown_joints': sorted(merger.unknown), 'error': error,
                'stopped': stopped, 'joint_names_seen': names_seen[:50]}
