"""
Merging ``JointState`` content into one joint vector: the node's input logic, without ROS.

:class:`JointStateMerger` takes the fields of a message (names, positions, velocities, stamp
in nanoseconds) and decides whether it is valid, keeps the last value of each joint
(several publishers may each send some joints), and says when the set is complete. It
never raises on bad input: it returns a :class:`MergeResult` saying what happened, and
counts every outcome for diagnostics.

The merge's three forms: a message (:meth:`JointStateMerger.merge`, the reference, with its
short path for a repeated complete layout beside it), the compiled short path
(:mod:`.joint_state_raw`) and arrays of messages (:mod:`.joint_state_batches`); their rules
as constants in :mod:`.joint_state_rules`.
"""

from collections import Counter
from dataclasses import dataclass
import math
import operator
from typing import Optional

from dq_fk_ros.messages.joint_state_batches import merge_many
from dq_fk_ros.messages.joint_state_raw import learn_layout, merge_raw
from dq_fk_ros.messages.joint_state_rules import (  # noqa: F401 (the module's surface too)
    INCOMPLETE, MAX_UNKNOWN_LISTED, OUT_OF_LIMITS_POLICIES, PUBLISH, REJECT_REASONS, REJECTED,
    TIME_JUMP_BACK_NS)
from dq_fk_ros.messages.merge_state import MergeState
import numpy as np


@dataclass
class MergeResult:
    """What one message led to."""

    status: str
    reason: str = ''                     # why it was rejected (a key of REJECT_REASONS)
    detail: str = ''                     # one line for a log message
    q: np.ndarray = None                 # joint values in chain order (status PUBLISH)
    qdot: np.ndarray = None              # joint velocities, when every joint has one
    stamp_ns: int = 0                    # the message stamp (0: none given)
    new_unknown: tuple = ()              # joint names seen for the first time, not ours
    unknown_overflow: bool = False       # first message with unknown names beyond the list
    missing: tuple = ()                  # joints never seen (status INCOMPLETE)
    out_of_limits: tuple = ()            # joints outside their limits (warn/clamp)
    time_jump: bool = False              # the stamp jumped back; state was reset first

    @property
    def clean(self) -> bool:
        """Say whether it is a ``PUBLISH`` with nothing to report (nothing to log)."""
        return self.status == PUBLISH and not (self.new_unknown or self.time_jump or
                                               self.out_of_limits or self.unknown_overflow)


class JointStateMerger:
    """
    Keep the latest value of every joint of a chain, from partial or complete messages.

    Velocities that are NaN or infinite are dropped (the message has no velocities then)
    and counted in ``counts['velocities_non_finite']``; positions decide acceptance.
    ``unknown`` holds at most :data:`MAX_UNKNOWN_LISTED` names not of this robot. What it
    knows between messages is one :class:`~.merge_state.MergeState` (``state``), which
    :meth:`merge`, :meth:`merge_many` and :meth:`merge_raw` share.

    :param joint_names: the robot's joint names, in the order ``q`` is returned.
    :param limits: ``(dof, 2)`` lower/upper limits (+-inf for none).
    :param out_of_limits: ``'warn'`` (publish as is), ``'clamp'`` or ``'reject'``.
    :param required: how many of the first ``joint_names`` must have a value before a
        message completes the vector (default: all); the others are optional (side-branch
        joints): 0.0 until given, see :attr:`seen_optional`.
    :param counts: the counter to count into (default: a new one).
    :param unknown: names known not to be joints of this robot (default: none).
    """

    def __init__(self, joint_names: tuple, limits: np.ndarray, out_of_limits: str = 'warn',
                 counts: Counter = None, unknown: set = None, required: int = None):
        """Set up the per-joint state."""
        if out_of_limits not in OUT_OF_LIMITS_POLICIES:
            raise ValueError(f'out_of_limits must be one of {OUT_OF_LIMITS_POLICIES}, '
                             f'got {out_of_limits!r}')
        joint_names = tuple(joint_names)
        limits = np.asarray(limits, dtype=float).reshape(len(joint_names), 2)
        self.state = MergeState(joint_names, limits, out_of_limits,
                                len(joint_names) if required is None else required,
                                Counter() if counts is None else counts,
                                set() if unknown is None else unknown)
        self.joint_names, self.limits, self.out_of_limits = joint_names, limits, out_of_limits
        self.required = self.state.required
        self._nan = [math.nan] * len(joint_names)
        self._true = [True] * len(joint_names)

    counts = property(lambda self: self.state.counts, doc='What happened, by outcome.')
    unknown = property(lambda self: self.state.unknown, doc='Names not of this robot.')
    raw_reader = property(lambda self: self.state.raw_reader,
                          doc='The compiled reader of the learnt layout (None: none).')
    last_seen = property(lambda self: self.state.last_seen,
                         doc="``merge_many``'s mask of joints with a value, per message.")

    def reset(self) -> None:
        """Forget all joint values and the last stamp (after a time jump)."""
        self.state.reset()

    def clear_counts(self) -> None:
        """Start the counts and the unknown names afresh; the merged state is kept."""
        self.state.counts, self.state.unknown = Counter(), set()

    def learn_layout(self, layout) -> None:
        """Take messages of ``layout`` by the compiled short path (``joint_state_raw``)."""
        learn_layout(self.state, layout)

    def merge_raw(self, raw) -> Optional[tuple]:
        """
        Merge a serialized JointState of the learnt layout: ``(stamp_ns, q, qdot)`` or None.

        The compiled short path of :meth:`merge` (:func:`.joint_state_raw.merge_raw`; None:
        nothing was done, call :meth:`merge`).
        """
        return merge_raw(self.state, raw)

    @property
    def never_seen(self) -> tuple:
        """Name the required joints that no accepted message has given a value yet."""
        return tuple(n for n, s in zip(self.joint_names[:self.required], self.state.seen)
                     if not s)

    @property
    def never_seen_any(self) -> tuple:
        """Name every joint, required or optional, that no accepted message has given yet."""
        return tuple(n for n, s in zip(self.joint_names, self.state.seen) if not s)

    @property
    def seen_optional(self) -> tuple:
        """Name the optional joints an accepted message gave a value (since the last reset)."""
        state, n = self.state, self.required
        mask = state.seen[n:]  # a copy; asked at every update: the tuple only when it changed
        if mask != state.seen_optional_mask:
            state.seen_optional = tuple(name for name, s in zip(self.joint_names[n:], mask)
                                        if s)
            state.seen_optional_mask = mask
        return state.seen_optional

    def merge(self, names, positions, velocities=(), stamp_ns=0) -> 'MergeResult':
        """
        Merge one message's content; returns a :class:`MergeResult` (never raises).

        The reference path (:meth:`_merge`) beside its fast one for a repeated complete
        layout (:meth:`_merge_complete`; held equal by test_joint_states.py's
        ``test_the_short_path_for_complete_messages_changes_nothing``); :meth:`merge_many`
        is the array version (``test_merge_many_equals_merging_one_by_one``).
        """
        counts = self.state.counts
        counts['received'] += 1
        complete = self.state.complete
        if complete is not None and (names is complete.names or tuple(names) == complete.names):
            result = self._merge_complete(complete, positions, velocities, stamp_ns)
        else:
            result = self._merge(names, positions, velocities, stamp_ns)
        if result.status == REJECTED:
            counts['rejected'] += 1
            counts['rejected_' + result.reason] += 1
        else:
            counts[result.status] += 1
        return result

    def merge_many(self, runs) -> tuple:
        """
        Merge runs of messages, in order: the same outcome as one :meth:`merge` per message.

        The array version of :meth:`merge` (:func:`.joint_state_batches.merge_many`, held
        equal by test_joint_states.py's ``test_merge_many_equals_merging_one_by_one``).
        Returns ``(published, q, qdot)``; ``last_seen`` is then the ``(p, dof)`` mask of
        joints that had a value at each published message.
        """
        return merge_many(self.state, runs)

    def count_rejected(self, reason, count=1) -> None:
        """Count ``count`` messages rejected for ``reason`` (also ones rejected elsewhere)."""
        self.state.count_rejected(reason, count)

    def _reject(self, reason, detail=''):
        return MergeResult(REJECTED, reason=reason,
                           detail=detail or REJECT_REASONS[reason])

    def _merge_complete(self, complete, positions, velocities, stamp_ns):
        """
        Merge a message of the cached complete layout: the outcome :meth:`_merge` gives.

        Fast path; the reference is :meth:`_merge` (see :meth:`merge` for the test).

        Every required joint is named once (optional ones may be) and nothing else, so there
        are no unknown names, no duplicates, and a valid message always completes the joint
        vector. The checks run over whole lists first (a sum is finite only if every value
        is; ``map(le, ...)`` for the limits) and look value by value only to say which failed.
        """
        state = self.state
        order = complete.order          # chain index of each message column
        n = len(order)
        if len(positions) != n or len(velocities) not in (0, n):
            return self._reject('length_mismatch', f'{n} names, {len(positions)} '
                                f'positions, {len(velocities)} velocities')
        values = [float(v) for v in positions]
        if not math.isfinite(sum(values)):  # (or finite values too large to add up)
            for k, value in enumerate(values):
                if not math.isfinite(value):
                    name = self.joint_names[order[k]]
                    return self._reject('non_finite', f'position of {name!r} is {value}')
        outside = ()
        lower, upper = complete.lower, complete.upper
        if lower is not None and not (all(map(operator.le, lower, values)) and
                                      all(map(operator.le, values, upper))):
            outside = []
            for k, value in enumerate(values):
                if value < lower[k] or value > upper[k]:
                    name = self.joint_names[order[k]]
                    outside.append(name)
                    if self.out_of_limits == 'reject':
                        return self._reject('out_of_limits',
                                            f'{name} = {value:.6g} outside '
                                            f'[{lower[k]:.6g}, {upper[k]:.6g}]')
                    if self.out_of_limits == 'clamp':
                        values[k] = min(max(value, lower[k]), upper[k])
            outside = tuple(outside)
        rates = [float(v) for v in velocities] if len(velocities) else None
        if rates is not None and not all(map(math.isfinite, rates)):
            state.counts['velocities_non_finite'] += 1  # dropped: no velocities this time
            rates = None
        time_jump = state.track_stamp(stamp_ns)   # (False without a stamp)
        q, qdot = state.q, state.qdot
        if complete.in_order:  # the message lists the joints in chain order
            q[:n] = values
            qdot[:n] = rates if rates is not None else self._nan[:n]
            state.seen[:n] = self._true[:n]
        else:
            seen = state.seen
            for k, i in enumerate(order):
                q[i] = values[k]
                qdot[i] = rates[k] if rates is not None else math.nan
                seen[i] = True
        return MergeResult(PUBLISH, q=np.array(q),
                           qdot=np.array(qdot) if rates is not None else None,
                           stamp_ns=stamp_ns, out_of_limits=outside, time_jump=time_jump)

    def _merge(self, names, positions, velocities, stamp_ns):
        state = self.state
        n_msg = len(names)
        if n_msg == 0:
            return self._reject('empty')
        if len(positions) != n_msg or (len(velocities) not in (0, n_msg)):
            return self._reject('length_mismatch', f'{n_msg} names, {len(positions)} '
                                f'positions, {len(velocities)} velocities')
        if len(set(names)) != n_msg:
            return self._reject('duplicate_name')
        index = state.index
        new_unknown, overflow = state.note_unknown(names)
        ours = []  # (chain index, position, velocity)
        for k, name in enumerate(names):
            i = index.get(name)
            if i is None:
                continue
            position = float(positions[k])
            if not math.isfinite(position):
                result = self._reject('non_finite', f'position of {name!r} is {position}')
                result.new_unknown = tuple(new_unknown)
                result.unknown_overflow = overflow
                return result
            ours.append((i, position, float(velocities[k]) if len(velocities) else math.nan))
        if not ours and self.joint_names:  # (a robot without joints takes any message)
            result = self._reject('no_known_joint', 'none of ' + ', '.join(map(repr, names[:5]))
                                  + (' ...' if n_msg > 5 else '') + ' is a joint of this robot')
            result.new_unknown = tuple(new_unknown)
            result.unknown_overflow = overflow
            return result

        outside = []
        for j, (i, position, velocity) in enumerate(ours):
            lower, upper = self.limits[i]
            if position < lower or position > upper:
                outside.append(self.joint_names[i])
                if self.out_of_limits == 'reject':
                    result = self._reject('out_of_limits', f'{self.joint_names[i]} = '
                                          f'{position:.6g} outside [{lower:.6g}, {upper:.6g}]')
                    result.new_unknown = tuple(new_unknown)
                    result.unknown_overflow = overflow
                    return result
                if self.out_of_limits == 'clamp':
                    ours[j] = (i, min(max(position, lower), upper), velocity)

        if len(velocities) and not all(math.isfinite(v) for _, _, v in ours):
            state.counts['velocities_non_finite'] += 1  # dropped: no velocities this time
            ours = [(i, position, math.nan) for i, position, _ in ours]

        time_jump = state.track_stamp(stamp_ns)

        q, qdot, seen = state.q, state.qdot, state.seen
        for i, position, velocity in ours:
            q[i] = position
            qdot[i] = velocity
            seen[i] = True
        base = {'stamp_ns': stamp_ns, 'new_unknown': tuple(new_unknown),
                'unknown_overflow': overflow,
                'out_of_limits': tuple(outside), 'time_jump': time_jump}
        required = self.required
        if not all(seen[:required]):
            return MergeResult(INCOMPLETE, missing=self.never_seen, **base)
        order = tuple(i for i, _, _ in ours)
        if len(ours) == n_msg and sum(i < required for i in order) == required:
            # every required joint once, nothing unknown: the short path from now on
            state.learn_complete(names, order)
        has_velocity = all(math.isfinite(v) for v in qdot[:required])
        return MergeResult(PUBLISH, q=np.array(q), qdot=np.array(qdot) if has_velocity else None,
                           **base)


class SequenceGaps:
    """
    Count the messages of one publisher that were lost before they were taken.

    DDS numbers each publisher's messages 1, 2, 3, ... (``publication_sequence_number`` of a
    taken message's info); a jump forward between two taken messages means the ones in
    between were lost: a full subscription queue under overload, or loss on the wire.
    Counting holds only while one publisher is matched (:meth:`single_publisher`): the
    numbers of several publishers interleave. A number at or below the last one (a second
    publisher not yet noticed, or a restarted one) starts over without counting, and
    counting waits until the next :meth:`single_publisher` call confirms one publisher.
    """

    def __init__(self):
        """Count nothing until one publisher is confirmed."""
        self.lost = 0
        self._last = None
        self._counting = False

    def single_publisher(self, single) -> None:
        """Say whether exactly one publisher is matched now (from a periodic check)."""
        if not (single and self._counting):
            self._last = None  # (re)start: the next message is the stream's first
        self._counting = single

    def note(self, sequence) -> int:
        """Note a taken message's sequence number (None: not known); return the count lost."""
        if sequence is None or not self._counting:
            return 0
        last, self._last = self._last, sequence
        if last is None:
            return 0
        if sequence <= last:  # another publisher's numbers, or a restart
            self._counting = False
            self._last = None
            return 0
        gap = sequence - last - 1
        self.lost += gap
        return gap
