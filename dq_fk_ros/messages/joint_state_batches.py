"""
Merging arrays of JointState messages at once: ``JointStateMerger.merge_many``'s engine.

The same outcome as one ``JointStateMerger.merge`` per message (the reference;
test_joint_states.py's ``test_merge_many_equals_merging_one_by_one``), for the bag tool's
chunks: runs of one layout checked together, each joint's last accepted value carried
forward with numpy, time jumps found in the stamps and the state reset there.
"""

from collections.abc import Sequence
import math

from dq_fk_ros.messages.joint_state_rules import INCOMPLETE, PUBLISH, TIME_JUMP_BACK_NS
from dq_fk_ros.messages.merge_state import MergeState
import numpy as np


def merge_many(state: MergeState, runs: Sequence[tuple]) -> tuple:
    """
    Merge runs of messages into ``state``, in order: the outcome of one ``merge`` per message.

    A run is ``(names, positions, velocities, stamps_ns)`` for k messages that share
    ``names``: ``(k, len(names))`` positions, ``(k, len(names))`` or ``(k, 0)``
    velocities, ``(k,)`` stamps (0: none). Runs may name different joints (several
    publishers): each joint keeps its last accepted value, carried forward with numpy.
    A run may end with ``order``, the ``(k,)`` places of its messages in the sequence
    merged (every run then has one; together they are each place once): several
    publishers' interleaved messages are then one run per layout, not one per message
    (the bag tool's batches; test_joint_states.py holds both ways equal).
    Returns ``(published, q, qdot)``: indices (into all the runs' messages, in order) of
    the messages that completed the joint vector, their ``(p, dof)`` joint values and
    ``(p, dof)`` velocities (a NaN row where ``merge`` gives no ``qdot``). Counts and
    the merged state are updated as ``merge`` would; ``last_seen`` is then the
    ``(p, dof)`` mask of joints that had a value at each published message.
    """
    n = len(state.joint_names)
    total = sum(len(run[3]) for run in runs)
    given = np.zeros((total, n), bool)      # joint values an accepted message sets
    values = np.zeros((total, n))
    rates = np.full((total, n), math.nan)
    accepted = np.zeros(total, bool)
    stamps = np.zeros(total, np.int64)
    # runs of one layout (several publishers interleave) are checked together
    layouts = {}
    at = 0
    _check_orders(runs, total)
    for names, positions, velocities, run_stamps, *order in runs:
        k = len(run_stamps)
        key = (tuple(names), np.shape(positions)[1], np.shape(velocities)[1])
        places = np.arange(at, at + k) if not order else np.asarray(order[0], np.int64)
        layouts.setdefault(key, []).append((places, positions, velocities))
        stamps[places] = run_stamps
        at += k
    state.counts['received'] += total
    for (names, _, n_vel), members in layouts.items():
        rows = np.concatenate([places for places, _, _ in members])
        columns, joints = _run_columns(state, names, members[0][1], members[0][2], len(rows))
        if columns is None:
            continue
        # (a range of columns or joints in order, the usual case, as a slice: no copies)
        columns, joints = _as_slice(columns), _as_slice(joints)
        q = np.concatenate([np.asarray(p, dtype=float) for _, p, _ in members])[:, columns]
        ok = _rows_all(np.isfinite(q))
        state.count_rejected('non_finite', len(rows) - int(ok.sum()))
        lower, upper = state.limits[joints, 0], state.limits[joints, 1]
        if state.out_of_limits == 'reject':
            inside = ((q >= lower) & (q <= upper)).all(axis=1)
            state.count_rejected('out_of_limits', int((ok & ~inside).sum()))
            ok &= inside
        elif state.out_of_limits == 'clamp':
            q = np.clip(q, lower, upper)
        accepted[rows] = ok
        if len(rows) == total and ok.all() and (rows[1:] > rows[:-1]).all():
            # one layout, every message taken, in order: slices
            taken = slice(None)
            given[:, joints] = True
            values[:, joints] = q
        else:
            taken = rows[ok] if isinstance(joints, slice) else rows[ok][:, None]
            given[taken, joints] = True
            values[taken, joints] = q[ok]
        if n_vel:
            qdot = np.concatenate([np.asarray(v, dtype=float) for _, _, v in members])
            qdot = qdot[:, columns]
            bad_rate = ~_rows_all(np.isfinite(qdot))  # dropped for the whole message
            state.counts['velocities_non_finite'] += int((ok & bad_rate).sum())
            rated = np.where(bad_rate[:, None], math.nan, qdot)
            rates[taken, joints] = rated if isinstance(taken, slice) else rated[ok]
    stamped = np.flatnonzero(accepted & (stamps != 0))
    jumps, last_stamp = _track_stamps(state, stamps[stamped])
    resets = stamped[jumps]
    q_out, qdot_out = np.empty((total, n)), np.empty((total, n))
    complete = np.zeros(total, bool)
    seen_rows = []
    bounds = zip(np.concatenate([[0], resets]), np.concatenate([resets, [total]]))
    for segment, (a, b) in enumerate(bounds):
        if segment:
            state.reset()  # a time jump: merge() forgets everything first
        _carry_forward(state, given[a:b], values[a:b], rates[a:b], q_out[a:b],
                       qdot_out[a:b], complete[a:b], seen_rows)
    state.last_stamp_ns = last_stamp
    published = np.flatnonzero(accepted & complete)
    state.counts[PUBLISH] += len(published)
    state.counts[INCOMPLETE] += int((accepted & ~complete).sum())
    every = slice(None) if len(published) == total else published  # (all: no copies)
    qdot = qdot_out[every]
    # as merge: every required joint's velocity, or none
    finite = np.isfinite(qdot[:, :state.required])
    if not finite.any():   # no message with them (no velocities at all: the usual case)
        qdot[:] = math.nan
    elif not finite.all():
        qdot[~finite.all(axis=1)] = math.nan
    seen_rows = np.concatenate(seen_rows) if seen_rows else \
        np.zeros((0, n), bool)
    state.last_seen = seen_rows[every]
    return published, q_out[every], qdot


def _rows_all(mask):
    """Return ``mask.all(axis=1)``; a whole ``True`` mask without the row-wise reduction."""
    if mask.all():   # (numpy's row-wise all on a few columns is ~10x slower)
        return np.ones(len(mask), bool)
    return mask.all(axis=1)


def _check_orders(runs, total):
    """Refuse orders given to some runs only, or not each place once."""
    given = [len(run) > 4 for run in runs]
    if not any(given):
        return
    if not all(given):
        raise ValueError('merge_many: an order for every run or for none')
    places = np.concatenate([np.asarray(run[4], np.int64) for run in runs])
    # each of 0..total-1 once: as many places, all in range, none twice (no sort)
    if len(places) != total or (total and (places.min() < 0 or places.max() >= total or
                                           np.bincount(places, minlength=total).max() > 1)):
        raise ValueError(f'merge_many: the orders must hold each of 0..{total - 1} once')


def _as_slice(indices):
    """Return ascending consecutive ``indices`` as a slice (basic indexing), else as they are."""
    first = indices[0] if len(indices) else 0
    if list(indices) == list(range(first, first + len(indices))):
        return slice(first, first + len(indices))
    return indices


def _run_columns(state, names, positions, velocities, k):
    """
    Columns of the chain's joints in k messages' arrays, and their chain indices.

    Returns ``(None, None)`` (and counts the k rejections) when ``JointStateMerger.merge`` rejects
    every message of this layout whatever its values; registers unknown joint names.
    """
    n_msg = len(names)
    reason = None
    if n_msg == 0:
        reason = 'empty'
    elif np.shape(positions)[1] != n_msg or np.shape(velocities)[1] not in (0, n_msg):
        reason = 'length_mismatch'
    elif len(set(names)) != n_msg:
        reason = 'duplicate_name'
    else:
        state.note_unknown(names, times=k)
        columns = [c for c, name in enumerate(names) if name in state.index]
        if not columns and state.index:  # (a robot without joints takes any message)
            reason = 'no_known_joint'
    if reason is not None:
        state.count_rejected(reason, k)
        return None, None
    return columns, [state.index[names[c]] for c in columns]


def _track_stamps(state, stamps):
    """
    Follow the last stamp through non-zero ``stamps`` as ``JointStateMerger.merge`` does.

    Returns the positions in ``stamps`` of time jumps back (where merge resets) and
    the last stamp after them all.
    """
    last = state.last_stamp_ns
    jumps = []
    at = 0
    while at < len(stamps):
        rest = stamps[at:]
        before = np.concatenate([[rest[0] if last is None else last],
                                 np.maximum.accumulate(rest)[:-1]])
        if last is not None:
            before = np.maximum(before, last)
        back = np.flatnonzero(rest < before - TIME_JUMP_BACK_NS)
        if not len(back):
            last = int(max(before[-1], rest[-1]))
            break
        state.counts['time_jumps'] += 1
        at += int(back[0])
        jumps.append(at)
        last = None
    return np.array(jumps, dtype=np.int64), last


def _carry_forward(state, given, values, rates, q_out, qdot_out, complete, seen_rows):
    """Fill each message's joint vector with the last given values, from the state."""
    if not len(given):
        return
    if given.all():   # every joint given by every message: nothing to carry forward
        q_out[:], qdot_out[:] = values, rates
        seen = np.ones(given.shape, bool)
        complete[:] = True
        seen_rows.append(seen)
        state.q, state.qdot, state.seen = q_out[-1].tolist(), qdot_out[-1].tolist(), \
            seen[-1].tolist()
        return
    steps = np.arange(len(given))[:, None]
    last = np.maximum.accumulate(np.where(given, steps, -1), axis=0)
    has = last >= 0
    pick = (np.where(has, last, 0), np.arange(given.shape[1]))
    q_out[:] = np.where(has, values[pick], state.q)
    qdot_out[:] = np.where(has, rates[pick], state.qdot)
    seen = has | np.array(state.seen, dtype=bool)
    complete[:] = seen[:, :state.required].all(axis=1)
    seen_rows.append(seen)
    state.q, state.qdot, state.seen = q_out[-1].tolist(), qdot_out[-1].tolist(), \
        seen[-1].tolist()
