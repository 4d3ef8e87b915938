"""
The outputs of a robot's forward kinematics: one table that every writer and reader uses.

Each :class:`Output` is a topic, its message type, the QoS it is published with and which
frames it carries (the :class:`~dq_fk_ros.messages.output_plan.OutputPlan` attribute that
lists them for a robot: one plan for the node and the bag alike). ``dq_fk_node`` publishes
every row, ``dq_fk_bag process`` writes them as a bag's connections (with the same QoS as
offered profiles), ``dq_fk_view`` and ``dq_fk_foxglove`` subscribe to the TF rows and the
description by these names. Adding an output is a row here plus its writer. No ROS here:
QoS is plain data, turned into an rclpy ``QoSProfile`` by
:func:`dq_fk_ros.ros.conversions.qos_profile`.
"""

from dataclasses import dataclass


@dataclass(frozen=True)
class Output:
    """One output: a topic, its message type, its QoS (reliable, keep last) and its frames."""

    topic: str          # a name: absolute '/tf', relative 'robot_description', private '~/...'
    msgtype: str        # 'tf2_msgs/msg/TFMessage'
    depth: int          # history: keep the last ``depth``
    latched: bool       # durability transient local (a late subscriber gets the last ones)
    frames: str         # which frames it carries (docs/node.md says it in full)
    plan: str = ''      # the OutputPlan attribute that lists them ('': no frame)

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


TF = Output('/tf', 'tf2_msgs/msg/TFMessage', 100, False,
            'the moving transforms: every revolute, prismatic, continuous and mimic joint',
            'moving_edges')
TF_STATIC = Output('/tf_static', 'tf2_msgs/msg/TFMessage', 1, True,
                   'the fixed transforms (fixed and planar joints), once', 'static_edges')
ROBOT_DESCRIPTION = Output('robot_description', 'std_msgs/msg/String', 1, True,
                           'the URDF (none: no frame)')
POSE = Output('~/pose/{frame}', 'geometry_msgs/msg/PoseStamped', 10, False,
              'one frame on TF, in the root of its TF tree', 'pose_frames')
TWIST = Output('~/twist/{frame}', 'geometry_msgs/msg/TwistStamped', 10, False,
               "the last DH frame's, the tool's and a link end effector's velocity, in the "
               'fixed frame', 'twist_frames')
DIAGNOSTICS = Output('/diagnostics', 'diagnostic_msgs/msg/DiagnosticArray', 10, False,
                     "the node's status (no frame)")
OUTPUTS = (TF, TF_STATIC, ROBOT_DESCRIPTION, POSE, TWIST, DIAGNOSTICS)

__all__ = ['DIAGNOSTICS', 'Output', 'OUTPUTS', 'POSE', 'ROBOT_DESCRIPTION', 'TF',
           'TF_STATIC', 'TWIST']
