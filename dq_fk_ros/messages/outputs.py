"""
The outputs of a robot's forward kinematics: one table that every writer and reader uses.

Each :class:`Output` is a topic, its message type, the QoS it is published with and which
frames it carries (the :class:`~dq_fk_ros.messages.output_plan.OutputPlan` attribute that
lists them for a robot: one plan for the node and the bag alike). ``dq_fk_node`` publishes
every row, ``dq_fk_bag process`` writes them as a bag's connections (with the same QoS as
offered profiles), ``dq_fk_view`` and ``dq_fk_foxglove`` subscribe to the TF rows and the
description by these names.

A row with a topic per frame (:data:`FRAME_OUTPUTS`: the poses, the twists) also carries its
message layout (``template``, a function of the header's frame id) and its values
(``values``, a function of the poses and velocities of N messages): the node publishes it for
one update and the bag tool writes it for a batch through
:class:`~dq_fk_ros.messages.frame_streams.FrameStream`, which holds one rule for frames
whose joints are not known yet. Adding such an output is a row here, its values (computed in
``kinematics/`` when more than a pose) and, for the bag tool, its type's definition in
``bag/output_types.py``. No ROS here: QoS is plain data, turned into an rclpy
``QoSProfile`` by :func:`dq_fk_ros.ros.conversions.qos_profile`.
"""

from dataclasses import dataclass
import math
from typing import Callable, Optional

from dq_fk_ros.kinematics.twists import frame_twists, frame_twists_batch
from dq_fk_ros.messages.cdr_templates import (
    CdrTemplate, pose_stamped_template, tf_message_template, twist_stamped_template)
import numpy as np


@dataclass(frozen=True)
class Output:
    """One output: a topic, its message type, its QoS (reliable, keep last) and its frames."""

    topic: str          # a name: absolute '/tf', relative 'robot_description', private '~/...'
    msgtype: str        # 'tf2_msgs/msg/TFMessage'
    depth: int          # history: keep the last ``depth``
    latched: bool       # durability transient local (a late subscriber gets the last ones)
    frames: str         # which frames it carries (docs/node.md says it in full)
    plan: str = ''      # the OutputPlan attribute that lists them ('': no frame)
    # the node's bool parameter that turns it on ('': always), the message layout (a
    # CdrTemplate) and its values: for a topic per frame, of the header's frame id and
    # pose_values' signature; for /tf, tf_template and tf_values; for /tf_static, of the plan
    switch: str = ''
    template: Optional[Callable] = None
    values: Optional[Callable] = None
    velocities: bool = False   # its values need joint velocities (its topics come with them)

    def topic_for(self, frame: str = '', namespace: str = '~') -> str:
        """
        Return the topic name: a per-frame row's for ``frame``, under ``namespace``.

        :param namespace: what ``~`` stands for (the node: ``~`` itself, rclpy resolves
            it; a bag: its pose namespace, ``/dq_fk_node``). Outside a node a relative name
            is made absolute at the root, as a node in the root namespace resolves it.
        """
        name = self.topic.format(frame=frame)
        if namespace == '~':
            return name
        if name.startswith('~/'):
            return f'{namespace}/{name[2:]}'
        return name if name.startswith('/') else f'/{name}'


def pose_values(plan, q, qdot, absolute, frames) -> tuple:
    """
    Return the values of N messages of a per-frame output: here each frame's pose.

    Every per-frame row's ``values`` has this signature (N = 1 for one node update).

    :param plan: the robot's :class:`~dq_fk_ros.messages.output_plan.OutputPlan`.
    :param q: ``(N, dof)`` joint values; ``qdot``: their velocities (None: none given).
    :param absolute: ``(N, n_frames, 7)`` poses in the fixed frame, ``(x, y, z, qx, qy,
        qz, qw)``; ``frames``: the frame indices of the row's topics.
    :returns: ``(array, columns, rows)``: ``array[:, columns[i]]`` are frame i's values
        (float64, the template's width), for the messages ``rows`` (a bool mask; None:
        all N, and ``array`` has N rows; else ``array`` has a row per True); or None when
        no message has them.
    """
    # a frame below a floating joint in that joint's child: the frame its PoseStamped names
    return (plan.rooted_poses(absolute) if plan.rooted else absolute), frames, None


def twist_values(plan, q, qdot, absolute, frames) -> Optional[tuple]:
    """
    Return :func:`pose_values`' tuple for the frames' twists ``(v, w)`` in the fixed frame.

    The messages whose first chain's velocities are all known (finite) have one
    (``kinematics.twists``: one configuration for the node, a batch for the bag tool).
    """
    if qdot is None:
        return None
    model = plan.model
    dof = model.chain.dof
    end = model.n_chain_frames - 1
    if len(q) == 1:  # the node's update
        if not all(map(math.isfinite, qdot[0, :dof])):
            return None
        twists = frame_twists(model.chain, q[0, :dof], qdot[0, :dof], absolute[0, end, :3],
                              absolute[0, frames, :3])
        return twists[None], range(len(frames)), None
    rows = np.isfinite(qdot[:, :dof]).all(axis=1)
    if not rows.any():
        return None
    poses = absolute[rows]
    twists = frame_twists_batch(model.chain, q[rows, :dof], qdot[rows, :dof],
                                poses[:, end, :3], poses[:, frames, :3])
    return twists, range(len(frames)), None if rows.all() else rows


def tf_template(plan, edges) -> CdrTemplate:
    """
    Return the layout of a ``/tf`` message carrying the moving ``edges`` and moving helpers.

    ``edges``: ``(frame index, transform index)`` of the moving transforms whose joints are
    known (``OutputPlan.shown_edges``; the bag tool per message: the same rule).
    """
    return tf_message_template(plan.tf_edges(edges))


def tf_values(plan, q, relative, edges) -> np.ndarray:
    """
    Return the ``(N, 7 k)`` values of N ``/tf`` messages of :func:`tf_template`'s layout.

    The transforms of ``edges``, rows of ``relative`` (``(N, n_transforms, 7)``, each in its
    TF parent), then the moving helper frames at the joint values ``q`` ``(N, dof)``. The
    node's update writes the same from the transforms' rows directly
    (``FrameBytes.tf_writer``; test_frame_bytes.py holds it to this).
    """
    n = len(relative)
    columns = [r for _, r in edges]
    if columns and columns == list(range(columns[0], columns[0] + len(columns))):
        # a run of transforms: a view, rows at the array's stride (no copy)
        values = relative[:, columns[0]:columns[0] + len(columns)].reshape(n, -1)
    else:
        values = relative[:, columns].reshape(n, -1)
    if plan.helpers.moving:  # (a cylindrical row's first motion: rare, per message)
        moving = np.array([np.concatenate(plan.helpers.moving_poses(row)) for row in q])
        values = np.concatenate([values, moving.reshape(n, -1)], axis=1)
    return values


def static_template(plan) -> CdrTemplate:
    """Return the layout of the one ``/tf_static`` message: every static transform."""
    return tf_message_template(plan.static_edges)


def static_values(plan) -> np.ndarray:
    """Return the ``(1, 7 k)`` values of :func:`static_template`'s message."""
    return plan.static_poses()[None, :]


TF = Output('/tf', 'tf2_msgs/msg/TFMessage', 100, False,
            'the moving transforms: every revolute, prismatic, continuous and mimic joint',
            'moving_edges', 'publish_tf', tf_template, tf_values)
TF_STATIC = Output('/tf_static', 'tf2_msgs/msg/TFMessage', 1, True,
                   'the fixed transforms (fixed and planar joints), once', 'static_edges',
                   '', static_template, static_values)
ROBOT_DESCRIPTION = Output('robot_description', 'std_msgs/msg/String', 1, True,
                           'the URDF (none: no frame)')
POSE = Output('~/pose/{frame}', 'geometry_msgs/msg/PoseStamped', 10, False,
              'one frame on TF, in the root of its TF tree', 'pose_frames',
              'publish_poses', pose_stamped_template, pose_values)
TWIST = Output('~/twist/{frame}', 'geometry_msgs/msg/TwistStamped', 10, False,
               "the last DH frame's, the tool's and a link end effector's velocity, in the "
               'fixed frame', 'twist_frames',
               'publish_twist', twist_stamped_template, twist_values, velocities=True)
DIAGNOSTICS = Output('/diagnostics', 'diagnostic_msgs/msg/DiagnosticArray', 10, False,
                     "the node's status (no frame)")
OUTPUTS = (TF, TF_STATIC, ROBOT_DESCRIPTION, POSE, TWIST, DIAGNOSTICS)
FRAME_OUTPUTS = tuple(o for o in OUTPUTS if '{frame}' in o.topic)  # a topic per frame

__all__ = ['DIAGNOSTICS', 'FRAME_OUTPUTS', 'Output', 'OUTPUTS', 'POSE', 'pose_values',
           'ROBOT_DESCRIPTION', 'TF', 'TF_STATIC', 'tf_template', 'tf_values', 'TWIST',
           'twist_values']
