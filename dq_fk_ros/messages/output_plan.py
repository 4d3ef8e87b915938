"""
What a robot publishes under a frame prefix: the one output plan of the node and the bag tool.

:class:`OutputPlan` names every frame id, each TF transform's parent and child, which
transforms are static (/tf_static, once) and which move (/tf, every update), which joints
each transform and pose waits for (a tree's branches appear when joint states name their
joints, as robot_state_publisher's), the frames with a pose topic and the frame each pose is
in, and the frames whose twist is published. :class:`~dq_fk_ros.ros.conversions.FrameMessages`
(the node) and :class:`~dq_fk_ros.bag.outputs.BagOutputs` (``dq_fk_bag process``) both lay
their messages out from it, so the two write the same frames in the same order.

Which frames are on TF (``dh_frames``, the node's ``publish_dh_frames``): for a URDF robot
(``model.publish_dh_frames`` false), robot_state_publisher's tree: one transform per URDF
joint, parent link -> child link, none for a floating joint (its child roots a tree of its
own); with ``dh_frames`` every frame of the model, the DH frames and the URDF helper links
too (a DH file's frames are its links: that is its default).
"""

from dq_fk_ros.description.to_urdf import HelperFrames
from dq_fk_ros.kinematics.dual_quaternion import pose_xyzw_in
import numpy as np


class OutputPlan:
    """
    The frame ids and TF transforms of one robot model under one ``frame_prefix``.

    ``frame_prefix`` is prepended to every frame id the model names, except a DH file's fixed
    frame (:meth:`RobotModel.tf_frame_id`). Poses are ``(x, y, z, qx, qy, qz, qw)``.
    """

    def __init__(self, model, frame_prefix='', dh_frames=None):
        """
        Plan the outputs of ``model`` (its helper frames take tens of ms for a big robot).

        :param dh_frames: whether TF carries the DH frames (and helper links); None: the
            model's default (``model.publish_dh_frames``: true for a DH file, not a URDF).
        """
        self.model = model
        self.prefix = frame_prefix
        self.dh_frames = model.publish_dh_frames if dh_frames is None else bool(dh_frames)
        self.fixed_frame_id = model.tf_frame_id(model.fixed_frame, frame_prefix)
        self.frame_ids = [frame_prefix + name for name in model.frame_names]
        self.parent_ids = [model.tf_frame_id(p, frame_prefix) for p in model.parent_frames]
        n_dh, n = model.n_dh_frames, len(model.frame_names)
        floating = {n_dh + j for j, link in enumerate(model.links) if link.floating}
        on_tf = set(range(n) if self.dh_frames else range(n_dh, n)) - floating
        # the frames with a TF transform (from parent_ids[k]), in frame order
        self.tf_frames = tuple(sorted(on_tf))
        self.helpers = HelperFrames(model, enabled=self.dh_frames)
        # /tf: ``(frame index, index in frame_poses' relative)`` of each moving transform
        self.moving_edges = tuple(e for e in model.moving_edges if e[0] in on_tf)
        # /tf_static: base, fixed rows, tool, fixed links, then the constant helpers
        self.static = [(k, pose) for k, pose in model.static_transforms() if k in on_tf]
        self.static_edges = (
            [(self.parent_ids[k], self.frame_ids[k]) for k, _ in self.static]
            + [(self.frame_ids[k], frame_prefix + name) for name, k, _ in self.helpers.static])
        # ~/pose/<frame>: the frames on TF, each in the root of its TF tree (the fixed
        # frame, or the child of the floating joint above it)
        self.pose_frames = self.tf_frames
        roots = model.tree_roots
        self.pose_root = {k: roots[k] for k in self.pose_frames}
        self.pose_frame_ids = {k: self.fixed_frame_id if r < 0 else self.frame_ids[r]
                               for k, r in self.pose_root.items()}
        self.rooted = tuple((k, r) for k, r in self.pose_root.items() if r >= 0)
        # twists: the chain's end and, if there is one, the tool; and the end effector if a
        # link; those on TF and in the fixed frame's tree (chain 0's twist is in it)
        n_chain = model.n_chain_frames
        twist = list(range(n_chain))[-1 - (model.chain.tool is not None):]
        if model.end_effector_index >= n_chain:
            twist.append(model.end_effector_index)
        self.twist_frames = [k for k in twist if k in on_tf and roots[k] < 0]

    def summary(self) -> str:
        """Say in one line what TF carries: the URDF's tree or every frame, and its roots."""
        urdf = self.model.urdf is not None
        what = ('every frame (the DH frames too)' if self.dh_frames and urdf
                else 'the URDF links, as robot_state_publisher' if urdf
                else 'the DH frames and links')
        roots = sorted({self.pose_frame_ids[k] for k in self.tf_frames})
        shown = ', '.join(roots[:5]) + (f' and {len(roots) - 5} more' if len(roots) > 5 else '')
        return (f'TF: {len(self.tf_frames)} transforms of {what} ({len(self.moving_edges)} '
                f'on /tf, {len(self.static_edges)} on /tf_static); tree roots: {shown}')

    def shown_edges(self, shown_optional=()) -> tuple:
        """Return the moving edges whose joints are known, given the optional ones named."""
        hidden = self.hidden(shown_optional, self.model.edge_needs)
        return tuple(e for e in self.moving_edges if e[0] not in hidden)

    def hidden(self, shown_optional=(), needs=None) -> frozenset:
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

    def tf_edges(self, edges) -> list:
        """Return ``[(parent id, child id)]`` of a /tf message: ``edges``, then moving helpers."""
        return ([(self.parent_ids[k], self.frame_ids[k]) for k, _ in edges]
                + [(self.frame_ids[k], self.prefix + name) for name, k in self.helpers.moving])

    def static_poses(self) -> np.ndarray:
        """Return the poses of :attr:`static_edges`, in order, as one flat float64 array."""
        values = [np.asarray(pose, float) for _, pose in self.static]
        values += [offset.to_pose_xyzw() for _, _, offset in self.helpers.static]
        return np.concatenate(values) if values else np.zeros(0)

    def rooted_poses(self, absolute) -> np.ndarray:
        """
        Return ``absolute`` (``(..., n_frames, 7)``, fixed frame) with rooted poses re-expressed.

        Each frame below a floating joint (:attr:`rooted`) is posed in that joint's child
        (:attr:`pose_frame_ids`), the frame its PoseStamped names; ``absolute`` itself when
        no frame is (no copy).
        """
        if not self.rooted:
            return absolute
        out = np.array(absolute, dtype=float)
        frames = [k for k, _ in self.rooted]
        roots = [r for _, r in self.rooted]
        out[..., frames, :] = pose_xyzw_in(out[..., roots, :], out[..., frames, :])
        return out


__all__ = ['OutputPlan']
