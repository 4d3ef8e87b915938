"""
What ``dq_fk_bag process`` writes for a robot: the output bag's topics and their messages.

:class:`BagOutputs` adds the connections (``/tf``, ``/tf_static``, ``/robot_description``,
the pose topics, the twist topics, copied inputs) and writes a chunk of computed frames as
rows of serialized messages, as the node publishes them: both lay their messages out from one
:class:`~dq_fk_ros.messages.output_plan.OutputPlan` (the same frame ids, TF parents, helper
frames, order, and a transform only where the message's state has named its joints), and the
per-frame topics (poses, twists) of both are the output table's rows through one
:class:`~dq_fk_ros.messages.frame_streams.FrameStream` each.
"""

from dq_fk_ros.bag.output_types import OUTPUT_TYPES, string_cdr
from dq_fk_ros.description.to_urdf import description_urdf
from dq_fk_ros.errors import BagError
from dq_fk_ros.messages import outputs as output_table
from dq_fk_ros.messages.frame_streams import FrameStream
from dq_fk_ros.messages.output_plan import OutputPlan
from dq_fk_ros.messages.outputs import POSE, ROBOT_DESCRIPTION, TF, TF_STATIC
import numpy as np


class BagOutputs:
    """The output bag's connections and the chunked, vectorised writing of FK results."""

    def __init__(self, writer, model, pose_namespace, frame_prefix, copy_from, poses='all',
                 dh_frames=None):
        """
        Register /tf, /tf_static, pose topics (all, end, none), copied input topics.

        The outputs' definitions and hashes are :data:`~dq_fk_ros.bag.output_types.OUTPUT_TYPES`
        (rosbags' Jazzy type store's, without building it).

        :param dh_frames: whether TF and the pose topics carry the DH frames (None: the
            model's default, as the node's ``publish_dh_frames``).
        """
        from rosbags.interfaces import (
            Qos, QosDurability, QosHistory, QosLiveliness, QosReliability, QosTime)

        def add(output, frame=''):
            """Add the connection of an output (its topic, type and the node's QoS)."""
            never = QosTime(sec=0, nsec=0)
            durability = QosDurability.TRANSIENT_LOCAL if output.latched else \
                QosDurability.VOLATILE
            offered = [Qos(QosHistory.KEEP_LAST, output.depth, QosReliability.RELIABLE,
                           durability, never, never, QosLiveliness.AUTOMATIC, never, False)]
            definition, digest = OUTPUT_TYPES[output.msgtype]
            return writer.add_connection(output.topic_for(frame, pose_namespace),
                                         output.msgtype, msgdef=definition, rihs01=digest,
                                         offered_qos_profiles=offered)
        self.model = model
        self.writer = writer
        # frame ids, TF parents, static and moving transforms, helpers: as the node's
        self.plan = plan = OutputPlan(model, frame_prefix, dh_frames)
        # topics, types and QoS: the node's table (messages/outputs.py)
        self.tf = add(TF)
        self.tf_static = add(TF_STATIC)
        self.end = model.end_effector_index
        # the per-frame outputs (poses, twists: the node's rows, frames and messages):
        # ``--poses end`` keeps the end effector's pose topic, ``none`` no per-frame topic
        self.streams = []
        for output in output_table.FRAME_OUTPUTS:  # (read at each use: tests add rows)
            frames = [] if poses == 'none' else [self.end] if (
                poses == 'end' and output is POSE) else getattr(plan, output.plan)
            self.streams.append(FrameStream(output, plan, frames))
        # their connections: now, or for a row that needs velocities at the first message
        # that has them (a bag without velocities stays as it was)
        self._add_stream = lambda stream: [add(stream.output, model.topic_names[k])
                                           for k in stream.frames]
        self.channels = [None if stream.output.velocities else self._add_stream(stream)
                         for stream in self.streams]
        # transforms and per-frame topics that depend on optional joints (side branches,
        # every joint of a tree) are written where the message's state has named those
        # joints, as the node does: each message's /tf holds the transforms whose joints are
        # known, each frame's topic waits for the joints its pose needs
        edge_needs = model.edge_needs
        index = {name: i for i, name in enumerate(model.joint_names)}
        self._gated = [i for i, (k, _) in enumerate(plan.moving_edges) if edge_needs[k]]
        self._gate_columns = [[index[n] for n in edge_needs[plan.moving_edges[i][0]]]
                              for i in self._gated]
        self._tf_templates = {}
        self._waiting = [stream.waiting_groups(index) for stream in self.streams]
        self.static_template = TF_STATIC.template(plan)
        try:
            self.urdf = description_urdf(model)
        except ValueError:  # a robot URDF cannot express: no /robot_description
            self.urdf = None
        self.description = add(ROBOT_DESCRIPTION) if self.urdf is not None else None
        self.copied = {}
        for conn in copy_from:
            self.copied[conn.id] = _copy_connection(writer, conn)
        self.static_written = False
        self._fk_out = None     # write_chunk's FK arrays, reused

    def write_static(self, time_ns) -> None:
        """Write /tf_static once: base, fixed rows, tool and links, stamped ``time_ns``."""
        row = self.static_template.fill([time_ns], TF_STATIC.values(self.plan))[0]
        self.writer.write(self.tf_static, time_ns, memoryview(row))
        if self.description is not None:
            self.writer.write(self.description, time_ns, string_cdr(self.urdf))
        self.static_written = True

    def write_chunk(self, q, stamps_ns, log_times_ns, seen=None, qdot=None) -> np.ndarray:
        """
        FK of a chunk of configurations, serialized and written as arrays.

        ``seen``: ``(N, dof)`` mask of the joints each message's state had (the merger's
        ``last_seen``); side-branch links are written where their joints were seen.
        ``qdot``: ``(N, dof)`` joint velocities (a NaN row: none), for the twist topics.
        Returns the end effector's ``(N, 7)`` poses, ``(x, y, z, qx, qy, qz, qw)``.
        """
        model = self.model
        # (N, frames, 7) and (N, transforms, 7): the compiled kernel, as the node's, into
        # arrays kept from chunk to chunk (fresh ones fault their pages in at every chunk)
        if self._fk_out is None or len(self._fk_out[0]) < len(q):
            self._fk_out = tuple(np.ascontiguousarray(a) for a in
                                 model.frame_pose_arrays_batch(q))
            absolute, relative = self._fk_out
        else:
            absolute, relative = model.frame_pose_arrays_batch(q, self._fk_out)
        end = absolute[:, self.end].copy()
        stamps_ns, log_times_ns = np.asarray(stamps_ns), np.asarray(log_times_ns)
        every, later = self._frame_values(q, qdot, absolute, seen)
        channels, templates, values = every
        tf = list(self._tf_values(relative, q, seen))
        if len(tf) == 1 and tf[0][0] is None:  # every message the same transforms
            channels.insert(0, self.tf)  # interleaved: each message's /tf, then its topics
            templates.insert(0, tf[0][1])
            values.insert(0, tf[0][2])
        else:
            for rows, template, tf_values in tf:
                self.writer.write_templates([self.tf], log_times_ns[rows], stamps_ns[rows],
                                            [template], [tf_values])
        if channels:
            self.writer.write_templates(channels, log_times_ns, stamps_ns, templates, values)
        for rows, s, positions, values in later:
            if self.channels[s] is None:  # its first message: its topics from now on
                self.channels[s] = self._add_stream(self.streams[s])
            templates = self.streams[s].templates
            self.writer.write_templates([self.channels[s][i] for i in positions],
                                        log_times_ns[rows], stamps_ns[rows],
                                        [templates[i] for i in positions], values)
        return end

    def _frame_values(self, q, qdot, absolute, seen):
        """
        Return the per-frame topics' values: those of every message, and those of some.

        ``(channels, templates, values)`` of the topics every message has (written with its
        /tf), then ``[(rows, stream, frame positions, values)]`` of the others: the rows
        where a stream's values exist (twists: where the velocities are known) and the
        frames' joints were seen (:meth:`FrameStream.waiting_groups`). A stream that needs
        velocities is always of the others (its topics are added at its first message).
        """
        n = len(q)
        every, later = ([], [], []), []
        for s, stream in enumerate(self.streams):
            got = stream.values(q, qdot, absolute) if stream.frames else None
            if got is None:
                continue
            array, columns, rows = got
            for joints, positions in self._waiting[s]:
                if rows is None and (not joints or seen is None) and \
                        not stream.output.velocities:
                    every[0].extend(self.channels[s][i] for i in positions)
                    every[1].extend(stream.templates[i] for i in positions)
                    every[2].extend(array[:, columns[i]] for i in positions)
                    continue
                known = np.ones(n, bool) if rows is None else rows.copy()
                if joints and seen is not None:
                    known &= seen[:, joints].all(axis=1)
                if known.any():
                    picked = known if rows is None else known[rows]
                    later.append((known, s, positions,
                                  [array[picked, columns[i]] for i in positions]))
        return every, later

    def _tf_values(self, relative, q, seen):
        """
        Yield ``(rows, template, values)``: the moving transforms whose joints are known.

        The node's rule and order (:meth:`OutputPlan.shown_edges`, the /tf row's
        ``tf_template`` and ``tf_values``): messages whose states know the same joints share
        one template; ``rows`` is None when that is every message of the chunk.
        """
        plan = self.plan
        if not self._gated or seen is None:
            patterns, inverse = [np.ones(len(self._gated), bool)], None
        else:
            shown = np.stack([seen[:, cols].all(axis=1) for cols in self._gate_columns], axis=1)
            patterns, inverse = np.unique(shown, axis=0, return_inverse=True)
            inverse = inverse.reshape(-1)
            if len(patterns) == 1:
                inverse = None
        for p, pattern in enumerate(patterns):
            rows = None if inverse is None else inverse == p
            hidden = {i for i, on in zip(self._gated, pattern) if not on}
            edges = [e for i, e in enumerate(plan.moving_edges) if i not in hidden]
            if not edges and not plan.helpers.moving:
                continue  # nothing known to move: no /tf (as the node)
            key = pattern.tobytes()
            template = self._tf_templates.get(key)
            if template is None:
                template = self._tf_templates[key] = TF.template(plan, edges)
            picked = slice(None) if rows is None else rows
            yield rows, template, TF.values(plan, q[picked], relative[picked], edges)

    def copy(self, conn, time_ns, raw) -> None:
        """Copy an input message through unchanged."""
        out = self.copied.get(conn.id)
        if out is not None:
            self.writer.write(out, time_ns, raw)


def _copy_connection(writer, conn):
    """Add an input connection to the output: its own type definition, else Jazzy's."""
    from rosbags.typesys import get_typestore, Stores, TypesysError
    ext = getattr(conn, 'ext', None)
    qos = list(getattr(ext, 'offered_qos_profiles', None) or [])
    definition = getattr(getattr(conn, 'msgdef', None), 'data', '')
    if definition and conn.digest:
        return writer.add_connection(conn.topic, conn.msgtype, msgdef=definition,
                                     rihs01=conn.digest, offered_qos_profiles=qos)
    try:
        return writer.add_connection(conn.topic, conn.msgtype,
                                     typestore=get_typestore(Stores.ROS2_JAZZY),
                                     offered_qos_profiles=qos)
    except TypesysError:
        raise BagError(f'cannot copy {conn.topic}: the bag carries no definition of '
                       f'{conn.msgtype} and ROS 2 Jazzy has none; leave out --copy-input'
                       ) from None


__all__ = ['BagOutputs']
