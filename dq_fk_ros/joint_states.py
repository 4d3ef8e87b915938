"""
Merging ``JointState`` content into one joint vector: the node's input logic, without ROS.

:class:`JointStateMerger` takes the fields of a message (names, positions, velocities, stamp
in nanoseconds) and decides whether it is valid, keeps the last value of each joint
(several publishers may each send some joints), and says when the set is complete. It
never raises on bad input: it returns a :class:`MergeResult` saying what happened, and
counts every outcome for diagnostics.
"""

from collections import Counter
from dataclasses import dataclass, field
import math

import numpy as np

OUT_OF_LIMITS_POLICIES = ('warn', 'clamp', 'reject')
# A stamp this far before the last accepted one is a time jump (a looping bag, a restarted
# simulation): the merger resets. Smaller steps back are out-of-order messages and merge.
TIME_JUMP_BACK_NS = 1_000_000_000

# Outcomes of a message, as counted in MergeResult.status / JointStateMerger.counts
PUBLISH = 'publish'          # complete joint vector, to be published
INCOMPLETE = 'incomplete'    # valid, but some joints were never seen yet
REJECTED = 'rejected'        # malformed or refused; nothing of it was kept


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
    missing: tuple = ()                  # joints never seen (status INCOMPLETE)
    out_of_limits: tuple = ()            # joints outside their limits (warn/clamp)
    time_jump: bool = False              # the stamp jumped back; state was reset first


REJECT_REASONS = {
    'empty': 'the message names no joints',
    'length_mismatch': 'name, position and velocity arrays differ in length',
    'duplicate_name': 'a joint is named twice',
    'non_finite': 'a position is NaN or infinite',
    'no_known_joint': 'none of its joints belong to this robot',
    'out_of_limits': 'a joint is outside its limits (out_of_limits: reject)',
}


@dataclass
class JointStateMerger:
    """
    Keep the latest value of every joint of a chain, from partial or complete messages.

    :param joint_names: the chain's joint names, in the order ``q`` is returned.
    :param limits: ``(dof, 2)`` lower/upper limits (+-inf for none).
    :param out_of_limits: ``'warn'`` (publish as is), ``'clamp'`` or ``'reject'``.
    """

    joint_names: tuple
    limits: np.ndarray
    out_of_limits: str = 'warn'
    counts: Counter = field(default_factory=Counter)
    unknown: set = field(default_factory=set)

    def __post_init__(self):
        """Set up the per-joint state."""
        if self.out_of_limits not in OUT_OF_LIMITS_POLICIES:
            raise ValueError(f'out_of_limits must be one of {OUT_OF_LIMITS_POLICIES}, '
                             f'got {self.out_of_limits!r}')
        self._index = {name: k for k, name in enumerate(self.joint_names)}
        self.limits = np.asarray(self.limits, dtype=float).reshape(len(self.joint_names), 2)
        self.reset()

    def reset(self):
        """Forget all joint values and the last stamp (after a time jump)."""
        n = len(self.joint_names)
        self._q = [0.0] * n
        self._qdot = [math.nan] * n
        self._seen = [False] * n
        self._last_stamp_ns = None

    @property
    def never_seen(self):
        """Joints that no accepted message has given a value yet."""
        return tuple(n for n, s in zip(self.joint_names, self._seen) if not s)

    def merge(self, names, positions, velocities=(), stamp_ns=0):
        """Merge one message's content; returns a :class:`MergeResult` (never raises)."""
        self.counts['received'] += 1
        result = self._merge(names, positions, velocities, stamp_ns)
        if result.status == REJECTED:
            self.counts['rejected'] += 1
            self.counts['rejected_' + result.reason] += 1
        else:
            self.counts[result.status] += 1
        return result

    def merge_batch(self, names, positions, velocities, stamps_ns):
        """
        Merge k messages that share ``names``, in order; the same outcome as k :meth:`merge`.

        Returns ``(published, q, qdot)``: indices of the messages that completed the joint
        vector, their ``(p, dof)`` joint values and ``(p, dof)`` velocities (a NaN row where
        :meth:`merge` gives no ``qdot``). Counts are updated as :meth:`merge` would. When the
        names cover every joint of the chain, each message is decided on its own
        (vectorised); otherwise (partial messages build on earlier ones) the messages go
        through :meth:`merge`.

        :param names: the joint names of every message.
        :param positions: ``(k, len(names))`` positions.
        :param velocities: ``(k, len(names))`` or ``(k, 0)`` velocities.
        :param stamps_ns: ``(k,)`` stamps in nanoseconds (0: none).
        """
        positions = np.asarray(positions, dtype=float)
        velocities = np.asarray(velocities, dtype=float)
        k, n = len(stamps_ns), len(self.joint_names)
        columns = self._full_columns(names, positions, velocities)
        if columns is None:
            return self._merge_each(names, positions, velocities, stamps_ns)
        self.counts['received'] += k
        q = positions[:, columns]
        qdot = velocities[:, columns] if velocities.shape[1] else np.full((k, n), math.nan)
        lower, upper = self.limits[:, 0], self.limits[:, 1]
        accepted = np.isfinite(q).all(axis=1)
        self._count_rejected('non_finite', k - int(accepted.sum()))
        if self.out_of_limits == 'reject':
            inside = ((q >= lower) & (q <= upper)).all(axis=1)
            self._count_rejected('out_of_limits', int((accepted & ~inside).sum()))
            accepted &= inside
        elif self.out_of_limits == 'clamp':
            q = np.clip(q, lower, upper)
        published = np.flatnonzero(accepted)
        stamps = np.asarray(stamps_ns, dtype=np.int64)[published]
        self._track_stamps(stamps[stamps != 0])
        if len(published):
            self._q = q[published[-1]].tolist()
            self._qdot = qdot[published[-1]].tolist()
            self._seen = [True] * n
            self.counts[PUBLISH] += len(published)
        qdot = qdot[published]
        qdot[~np.isfinite(qdot).all(axis=1)] = math.nan  # as merge: all joints, or none
        return published, q[published], qdot

    def _full_columns(self, names, positions, velocities):
        """Column of each chain joint in messages that name all of them, else None."""
        n_msg = len(names)
        if (positions.ndim != 2 or positions.shape[1] != n_msg or velocities.ndim != 2
                or velocities.shape[1] not in (0, n_msg) or len(set(names)) != n_msg):
            return None
        where = {name: k for k, name in enumerate(names)}
        columns = [where.get(name) for name in self.joint_names]
        if None in columns:
            return None
        for name in names:
            if name not in self._index and name not in self.unknown:
                self.unknown.add(name)
        return columns

    def _count_rejected(self, reason, count):
        if count:
            self.counts['rejected'] += count
            self.counts['rejected_' + reason] += count

    def _track_stamps(self, stamps):
        """Follow the last stamp through non-zero ``stamps`` as :meth:`merge` does."""
        last = self._last_stamp_ns
        at = 0
        while at < len(stamps):
            rest = stamps[at:]
            before = np.maximum.accumulate(rest)
            before = np.concatenate([[last if last is not None else rest[0]], before[:-1]])
            if last is not None:
                before = np.maximum(before, last)
            jumps = np.flatnonzero(rest < before - TIME_JUMP_BACK_NS)
            if not len(jumps):
                last = int(before[-1] if before[-1] > rest[-1] else rest[-1])
                break
            self.counts['time_jumps'] += 1
            last = None
            at += int(jumps[0])
        self._last_stamp_ns = last

    def _merge_each(self, names, positions, velocities, stamps_ns):
        published, qs, qdots = [], [], []
        for i, stamp in enumerate(stamps_ns):
            result = self.merge(names, positions[i], velocities[i], int(stamp))
            if result.status == PUBLISH:
                published.append(i)
                qs.append(result.q)
                qdots.append(result.qdot if result.qdot is not None
                             else np.full(len(self.joint_names), math.nan))
        n = len(self.joint_names)
        return (np.array(published, dtype=np.int64), np.array(qs).reshape(-1, n),
                np.array(qdots).reshape(-1, n))

    def _reject(self, reason, detail=''):
        return MergeResult(REJECTED, reason=reason,
                           detail=detail or REJECT_REASONS[reason])

    def _merge(self, names, positions, velocities, stamp_ns):
        n_msg = len(names)
        if n_msg == 0:
            return self._reject('empty')
        if len(positions) != n_msg or (len(velocities) not in (0, n_msg)):
            return self._reject('length_mismatch', f'{n_msg} names, {len(positions)} '
                                f'positions, {len(velocities)} velocities')
        if len(set(names)) != n_msg:
            return self._reject('duplicate_name')
        index = self._index
        ours = []  # (chain index, position, velocity)
        new_unknown = []
        for k, name in enumerate(names):
            i = index.get(name)
            if i is None:
                if name not in self.unknown:
                    self.unknown.add(name)
                    new_unknown.append(name)
                continue
            position = float(positions[k])
            if not math.isfinite(position):
                return self._reject('non_finite', f'position of {name!r} is {position}')
            ours.append((i, position, float(velocities[k]) if len(velocities) else math.nan))
        if not ours:
            result = self._reject('no_known_joint', 'none of ' + ', '.join(map(repr, names[:5]))
                                  + (' ...' if n_msg > 5 else '') + ' is a joint of this robot')
            result.new_unknown = tuple(new_unknown)
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
                    return result
                if self.out_of_limits == 'clamp':
                    ours[j] = (i, min(max(position, lower), upper), velocity)

        time_jump = False
        if stamp_ns:
            last = self._last_stamp_ns
            if last is not None and stamp_ns < last - TIME_JUMP_BACK_NS:
                self.reset()
                self.counts['time_jumps'] += 1
                time_jump, last = True, None
            self._last_stamp_ns = stamp_ns if last is None else max(stamp_ns, last)

        q, qdot, seen = self._q, self._qdot, self._seen
        for i, position, velocity in ours:
            q[i] = position
            qdot[i] = velocity
            seen[i] = True
        base = {'stamp_ns': stamp_ns, 'new_unknown': tuple(new_unknown),
                'out_of_limits': tuple(outside), 'time_jump': time_jump}
        if not all(seen):
            return MergeResult(INCOMPLETE, missing=self.never_seen, **base)
        has_velocity = all(math.isfinite(v) for v in qdot)
        return MergeResult(PUBLISH, q=np.array(q), qdot=np.array(qdot) if has_velocity else None,
                           **base)
