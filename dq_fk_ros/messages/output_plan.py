"""
What a robot publishes under a frame prefix: the one output plan of the node and the bag tool.

:class:`OutputPlan` names every frame id, each TF transform's parent and child, which
transforms are static (/tf_static, once) and which move (/tf, every update), the URDF's
helper links among them, which joints each transform and pose waits for (a tree's branches
appear when joint states name their joints, as robot_state_publisher's), and the frames
whose twist is published. :class:`~dq_fk_ros.ros.conversions.FrameMessages` (the node) and
:class:`~dq_fk_ros.bag.outputs.BagOutputs` (``dq_fk_bag process``) both lay their messages
out from it, so the two write the same frames in the same order.
"""

from dq_fk_ros.description.to_urdf import HelperFrames
import numpy as np


class OutputPlan:
    """
    The frame ids and TF transforms of one robot model under one ``frame_prefix``.

    ``frame_prefix`` is prepended to every frame id the model names, except a DH file's fixed
    frame (:meth:`RobotModel.tf_frame_id`). Poses are ``(x, y, z, qx, qy, qz, qw)``.
    """

    def __init__(self, model, frame_prefix=''):
        """Plan the outputs of ``model`` (its helper frames take tens of ms for a big robot)."""
        self.model = model
        self.prefix = frame_prefix
        self.fixed_frame_id = model.tf_frame_id(model.fixed_frame, frame_prefix)
        self.frame_ids = [frame_prefix + name for name in model.frame_names]
        self.parent_ids = [model.tf_frame_id(p, frame_prefix) for p in model.parent_frames]
        self.helpers = HelperFrames(model)
        # /tf: ``(frame index, index in frame_poses' relative)`` of each moving transform
        self.moving_edges = model.moving_edges
        # /tf_static: base, fixed rows, tool, fixed links, then the constant helpers
        self.static = model.static_transforms()
        self.static_edges = (
            [(self.parent_ids[k], self.frame_ids[k]) for k, _ in self.static]
            + [(self.frame_ids[k], frame_prefix + name) for name, k, _ in self.helpers.static])
        # the chain's end and, if there is one, the tool; and the end effector if a link
        n_chain = model.n_chain_frames
        self.twist_frames = list(range(n_chain))[-1 - (model.chain.tool is not None):]
        if model.end_effector_index >= n_chain:
            self.twist_frames.append(model.end_effector_index)

    def shown_edges(self, shown_optional=()):
        """Return the moving edges whose joints are known, given the optional ones named."""
        hidden = self.hidden(shown_optional, self.model.edge_needs)
        return tuple(e for e in self.moving_edges if e[0] not in hidden)

    def hidden(self, shown_optional=(), needs=None):
        """
        Return the indices of the frames that need an optional joint not in ``shown_optional``.

        :param needs: per frame, the joints it needs: ``model.frame_needs`` (default: its pose
            in the fixed frame) or ``model.edge_needs`` (its TF transform).
        """
        model = self.model
        if not model.optional_joints:
            return frozenset()
        shown = frozenset(shown_optional)
        needs = model.frame_needs if needs is None else needs
        return frozenset(k for k, need in enumerate(needs) if not need <= shown)

    def tf_edges(self, edges):
        """Return ``[(parent id, child id)]`` of a /tf message: ``edges``, then moving helpers."""
        return ([(self.parent_ids[k], self.frame_ids[k]) for k, _ in edges]
                + [(self.frame_ids[k], self.prefix + name) for name, k in self.helpers.moving])

    def static_poses(self):
        """Return the poses of :attr:`static_edges`, in order, as one flat float64 array."""
        values = [np.asarray(pose, float) for _, pose in self.static]
        values += [offset.to_pose_xyzw() for _, _, offset in self.helpers.static]
        return np.concatenate(values) if values else np.zeros(0)


__all__ = ['OutputPlan']
