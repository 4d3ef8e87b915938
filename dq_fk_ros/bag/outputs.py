"""
What ``dq_fk_bag process`` writes for a robot: the output bag's topics and their messages.

:class:`BagOutputs` adds the connections (``/tf``, ``/tf_static``, ``/robot_description``,
the pose topics, copied inputs) and writes a chunk of computed frames as rows of serialized
messages, as the node publishes them (the same frame ids, TF parents, helper frames, and a
transform only where the message's state has named its joints).
"""

from dq_fk_ros.bag.reading import BagError
from dq_fk_ros.description.to_urdf import description_urdf, HelperFrames
from dq_fk_ros.kinematics.dual_quaternion import dq_to_pose_xyzw
from dq_fk_ros.messages.cdr import pose_stamped_template, tf_message_template
import numpy as np


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


__all__ = ['BagOutputs']
