"""
Serialized JointStates in, merged joint vectors out: one way for the node and the bag tool.

:class:`JointStateInput` owns the steps between the wire and the merge, in the node's order:
the compiled short path of the learnt layout (:meth:`JointStateMerger.merge_raw`), else the
message parsed (:func:`~.cdr.parse_joint_state`; unreadable bytes rejected as
``malformed_cdr``) and merged by the reference (:meth:`JointStateMerger.merge`), after which
a clean complete message teaches the short path its layout. :meth:`JointStateInput.take`
takes one message (the node); :meth:`JointStateInput.take_many` a batch, parsed per layout
and merged at once (the bag tool's chunks, ``JointStateMerger.merge_many``).
"""

from dataclasses import dataclass
from typing import Optional

from dq_fk_ros.errors import CdrError
from dq_fk_ros.messages.cdr import group_joint_state_spans, JointStateNames, parse_joint_state
from dq_fk_ros.messages.joint_state_raw import merge_raw
from dq_fk_ros.messages.joint_state_rules import REJECTED
from dq_fk_ros.messages.joint_states import JointStateMerger, MergeResult
import numpy as np


@dataclass
class MergedBatch:
    """
    A batch merged.

    ``groups``: its layouts, as parsed; ``valid``: the batch indices of the readable
    messages, in order; ``stamps``: theirs (ns); ``published``, ``q``, ``qdot``: as
    ``merge_many`` returns them (``published`` indexes ``valid``).
    """

    groups: list
    valid: np.ndarray
    stamps: np.ndarray
    published: np.ndarray
    q: np.ndarray
    qdot: np.ndarray


class JointStateInput:
    """The input steps of one merger (see the module); ``names``: the parse cache."""

    def __init__(self, merger: JointStateMerger):
        """Take messages into ``merger``."""
        self.merger = merger
        self.names = JointStateNames()

    def take(self, raw) -> tuple[int, Optional[np.ndarray], Optional[np.ndarray],
                                 Optional[MergeResult]]:
        """
        Merge one serialized JointState: ``(stamp_ns, q, qdot, result)``.

        ``result`` None: a clean message of the compiled short path (publish ``q``, the
        merger's buffer, valid until the next merge); else what :meth:`~.merge` said
        (publish only a ``PUBLISH``; report what it carries unless it is ``clean``).
        """
        merger = self.merger
        fast = merge_raw(merger.state, raw)  # the compiled short path, or None
        if fast is not None:
            return fast + (None,)
        try:
            stamp_ns, names, positions, velocities = parse_joint_state(
                raw, self.names, as_tuples=True)
        except CdrError as exc:
            merger.counts['received'] += 1
            merger.count_rejected('malformed_cdr')
            return 0, None, None, MergeResult(REJECTED, reason='malformed_cdr', detail=str(exc))
        result = merger.merge(names, positions, velocities, stamp_ns)
        if result.clean and merger.raw_reader is None:  # the short path learns its layout
            merger.learn_layout(self.names.layout)
        return stamp_ns, result.q, result.qdot, result

    def take_many(self, data, starts: np.ndarray, lengths: np.ndarray) -> MergedBatch:
        """
        Parse and merge the serialized JointStates of one buffer, one group per layout.

        :param data: the bytes holding them; ``starts``/``lengths``: ``(m,)`` int64 spans.
        """
        merger = self.merger
        groups, malformed = group_joint_state_spans(data, starts, lengths, self.names)
        merger.counts['received'] += len(malformed)
        merger.count_rejected('malformed_cdr', len(malformed))
        if len(groups) == 1:   # one layout (the usual bag): its rows ascend, in order
            g = groups[0]
            merged = merger.merge_many([(g.names, g.positions, g.velocities, g.stamps_ns)])
            return MergedBatch(groups, g.rows, g.stamps_ns, *merged)
        valid = np.sort(np.concatenate([g.rows for g in groups])) if groups else \
            np.zeros(0, np.int64)
        places = [np.searchsorted(valid, g.rows) for g in groups]
        stamps = np.zeros(len(valid), np.int64)
        for g, at in zip(groups, places):
            stamps[at] = g.stamps_ns
        merged = merger.merge_many([(g.names, g.positions, g.velocities, g.stamps_ns, at)
                                    for g, at in zip(groups, places)])
        return MergedBatch(groups, valid, stamps, *merged)


__all__ = ['JointStateInput', 'MergedBatch']
