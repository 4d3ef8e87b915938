"""
One per-frame output of one robot: the node publishes it for an update, the bag tool a batch.

A :class:`FrameStream` is a row of :data:`~dq_fk_ros.messages.outputs.FRAME_OUTPUTS` (the
pose topics, the twist topics) laid out for an
:class:`~dq_fk_ros.messages.output_plan.OutputPlan`: its frames, one message layout per
header frame id (the row's ``template``), its values (the row's ``values``, N messages at a
time) and the one rule for frames whose joints are not known yet: frame k's topic waits until
joint states have named the joints its pose needs (``model.frame_needs[k]``,
robot_state_publisher's rule for a link), :meth:`FrameStream.shown` for the node's named
joints, :meth:`FrameStream.waiting_groups` for a batch's mask of seen joints.

Serializing one message at a time (:meth:`FrameStream.serialize`): the C writer
(``CdrTemplate.compiled``) and its reference ``CdrPacker``; test_frame_bytes.py holds them
equal byte for byte, and both equal to rclpy's message objects.
"""

from typing import Callable, Optional

from dq_fk_ros.messages.outputs import pose_values
import numpy as np


class FrameStream:
    """One per-frame output row of ``plan`` (for its ``frames``: by default the plan's)."""

    def __init__(self, output, plan, frames=None, compiled=True):
        """
        Lay out ``output``'s messages for ``plan``'s frames (or ``frames``, a subset).

        :param output: an :class:`~dq_fk_ros.messages.outputs.Output` with a ``template``
            and ``values``.
        :param compiled: serialize with the C writer where it is built (False: the packer).
        """
        self.output, self.plan = output, plan
        self.frames = tuple(getattr(plan, output.plan) if frames is None else frames)
        fixed = plan.fixed_frame_id
        # a frame's header frame id: the root of its TF tree (the fixed frame, or the child
        # of the floating joint above it)
        ids = [plan.pose_frame_ids.get(k, fixed) for k in self.frames]
        layouts = {}
        for frame_id in ids:
            if frame_id not in layouts:
                layouts[frame_id] = output.template(frame_id)
        self.templates = [layouts[frame_id] for frame_id in ids]
        self.uniform = len(layouts) <= 1   # one layout for every frame
        self.width = sum(n for _, n in self.templates[0].floats) if ids else 0
        packers = {id(t): (t.packer().pack, t.compiled(self.width) if compiled else None)
                   for t in layouts.values()}
        self._writers = [packers[id(t)] for t in self.templates]
        self.needs = [plan.model.frame_needs[k] for k in self.frames]
        self._columns = self._picked = self._read = None
        # one layout and the C writer: one call writes every message of an update
        self._each = self._writers[0][1].each if self.uniform and self._writers and \
            self._writers[0][1] is not None else None

    def direct_writer(self) -> Optional[Callable[..., list]]:
        """
        Return the C writer's ``each`` where this row's values are the poses as they are.

        That is a pose row (``outputs.pose_values``) with no frame below a floating joint and
        one layout: ``each(sec, nanosec, absolute, frames)`` then gives :meth:`serialize`'s
        messages without the values call (the node's update; test_frame_bytes.py holds the
        two equal). None otherwise.
        """
        if self.output.values is pose_values and not self.plan.rooted:
            return self._each
        return None

    def values(self, q, qdot, absolute) -> tuple:
        """
        Return the row's ``values`` of N messages: ``(array, columns, rows)`` or None.

        :param q: ``(N, dof)`` joint values; ``qdot``: ``(N, dof)`` velocities or None;
            ``absolute``: ``(N, n_frames, 7)`` poses, as :func:`outputs.pose_values` says.
        """
        return self.output.values(self.plan, q, qdot, absolute, self.frames)

    def shown(self, named) -> list:
        """Return per frame whether the joints its pose needs are among ``named``."""
        named = frozenset(named)
        return [need <= named for need in self.needs]

    def waiting_groups(self, index) -> list:
        """
        Return ``[(joint columns, [frame position, ...])]``: the frames that wait alike.

        A message has frame i's value once its state has seen every joint column of i's
        group (no column: at once); groups in the order of their sorted joint names.

        :param index: joint name -> column of the seen mask.
        """
        groups = {}
        for i, need in enumerate(self.needs):
            groups.setdefault(need, []).append(i)
        return [([index[n] for n in sorted(need)], groups[need])
                for need in sorted(groups, key=sorted)]

    def serialize(self, sec, nanosec, array, columns, picked) -> list:
        """
        Return the messages (bytes) of the frames ``picked`` (positions) of one update.

        :param array: ``(M, width)`` float64 values, frame i's at ``array[columns[i]]`` (the
            first row of what :meth:`values` returned).
        """
        if columns is not self._columns or picked is not self._picked:
            self._columns, self._picked = columns, picked
            self._read = [columns[i] for i in picked]
        read = self._read
        if self._each is not None:
            try:
                return self._each(sec, nanosec, array, read)
            except ValueError:  # not C-contiguous float64 (a view of a row's values)
                return self._each(sec, nanosec, np.ascontiguousarray(array, dtype=float), read)
        if self.uniform:
            pack = self._writers[0][0] if self._writers else None
            rows = array.tolist()
            return [pack(sec, nanosec, (rows[c],)) for c in read]
        out = []
        array = np.ascontiguousarray(array, dtype=float)
        for i, c in zip(picked, read):
            pack, compiled = self._writers[i]
            out += compiled.each(sec, nanosec, array, (c,)) if compiled is not None else \
                [pack(sec, nanosec, (np.asarray(array[c], dtype=float).tolist(),))]
        return out


__all__ = ['FrameStream']
