"""
What a JointState merger knows between messages (:class:`MergeState`), shared by its paths.

One object holds the robot's joints and rules and the merged state: each joint's last
value, velocity and whether it was ever given, the last stamp, the counts, the unknown
names, the complete layout learnt for the short paths and the compiled reader of it.
``JointStateMerger.merge`` (the reference, and its short path), ``merge_many``
(:mod:`.joint_state_batches`) and ``merge_raw`` (:mod:`.joint_state_raw`) read and write it
through its fields and methods; none of them reaches into another object.
"""

from collections import Counter
from dataclasses import dataclass, field
import math

from dq_fk_ros.messages.joint_state_rules import MAX_UNKNOWN_LISTED, TIME_JUMP_BACK_NS
import numpy as np


@dataclass(frozen=True)
class CompleteLayout:
    """
    A message layout naming every required joint once and nothing else: the short paths'.

    ``names``: the message's names; ``order``: the joint index of each message column;
    ``lower``/``upper``: the limits of each column (None: no joint has one);
    ``in_order``: the columns are the joints 0..n-1 in order.
    """

    names: tuple
    order: tuple
    lower: list | None
    upper: list | None
    in_order: bool


@dataclass
class MergeState:
    """
    The rules (joints, limits, policy, how many are required) and the merged state.

    ``q``, ``qdot``, ``seen``: per joint, lists (the float path's); ``q_out``, ``qdot_out``:
    arrays the compiled path writes; ``complete``: the learnt :class:`CompleteLayout`;
    ``raw_reader``: its compiled reader (None: none learnt); ``last_seen``: the ``(p, dof)``
    mask of joints with a value at each message ``merge_many`` published.
    """

    joint_names: tuple
    limits: np.ndarray
    out_of_limits: str
    required: int
    counts: Counter = field(default_factory=Counter)
    unknown: set = field(default_factory=set)

    def __post_init__(self):
        """Index the joints and start with nothing merged."""
        self.index = {name: k for k, name in enumerate(self.joint_names)}
        self.limit_list = self.limits.tolist()
        self.complete = None
        self.last_seen = None
        self.reset()

    def reset(self) -> None:
        """Forget all joint values and the last stamp (after a time jump)."""
        n = len(self.joint_names)
        self.q, self.qdot, self.seen = [0.0] * n, [math.nan] * n, [False] * n
        self.seen_optional_mask, self.seen_optional = None, ()
        self.last_stamp_ns = None
        self.raw_reader, self.raw_velocities = None, False  # learnt again from the next one
        self.q_out, self.qdot_out = np.empty(n), np.empty(n)

    def note_unknown(self, names, times: int = 1) -> tuple:
        """
        Record names that are not joints of this robot, up to the listing limit.

        Returns ``(new names listed, True the first time the list overflows)``; names beyond
        the list are counted ``times`` each (once per message that carries them).
        """
        index, unknown = self.index, self.unknown
        fresh = [n for n in dict.fromkeys(names) if n not in index and n not in unknown]
        room = max(MAX_UNKNOWN_LISTED - len(unknown), 0)
        listed, unlisted = fresh[:room], len(fresh) - min(len(fresh), room)
        unknown.update(listed)
        overflow = False
        if unlisted:
            overflow = not self.counts['unknown_names_unlisted']
            self.counts['unknown_names_unlisted'] += unlisted * times
        return listed, overflow

    def track_stamp(self, stamp_ns: int) -> bool:
        """Follow the last stamp; on a jump back, reset first. Return whether it jumped."""
        if not stamp_ns:
            return False
        last = self.last_stamp_ns
        jumped = last is not None and stamp_ns < last - TIME_JUMP_BACK_NS
        if jumped:
            self.reset()
            self.counts['time_jumps'] += 1
            last = None
        self.last_stamp_ns = stamp_ns if last is None else max(stamp_ns, last)
        return jumped

    def count_rejected(self, reason: str, count: int = 1) -> None:
        """Count ``count`` messages rejected for ``reason`` (also ones rejected elsewhere)."""
        if count:
            self.counts['rejected'] += count
            self.counts['rejected_' + reason] += count

    def learn_complete(self, names, order: tuple) -> None:
        """Take ``names`` (joint index ``order`` per column) as the short paths' layout."""
        lower = [self.limit_list[i][0] for i in order]
        upper = [self.limit_list[i][1] for i in order]
        if all(math.isinf(v) for v in lower + upper):
            lower = upper = None   # no limits: nothing to check
        self.complete = CompleteLayout(tuple(names), order, lower, upper,
                                       order == tuple(range(len(order))))
        self.raw_reader = None  # the compiled short path: learnt for this layout


__all__ = ['CompleteLayout', 'MergeState']
