"""JointStateMerger: the node's input logic, fed message fields directly (no DDS)."""

from collections import Counter
import math
import struct

from dq_fk_ros.messages.cdr import (_joint_state_spans, CdrError, COMPILED, JointStateNames,
                                    parse_joint_state)
from dq_fk_ros.messages.joint_states import (
    INCOMPLETE, JointStateMerger, MAX_UNKNOWN_LISTED, PUBLISH, REJECTED, SequenceGaps,
    TIME_JUMP_BACK_NS)
from hypothesis import given, settings, strategies as st
import numpy as np
import pytest
from rclpy.serialization import serialize_message
from sensor_msgs.msg import JointState

needs_compiled = pytest.mark.skipif(COMPILED is None, reason='the Python path is active: '
                                    'nothing to compare')

NAMES = ('a', 'b', 'c')
LIMITS = [[-1.0, 1.0], [-math.inf, math.inf], [0.0, 2.0]]


@pytest.fixture
def merger():
    return JointStateMerger(NAMES, LIMITS)


def test_matches_by_name_not_position(merger):
    r = merger.merge(['c', 'a', 'b'], [1.5, 0.5, -3.0], stamp_ns=10)
    assert r.status == PUBLISH
    np.testing.assert_array_equal(r.q, [0.5, -3.0, 1.5])
    assert r.qdot is None and r.stamp_ns == 10


def test_partial_messages_merge_and_keep_the_last_value(merger):
    r = merger.merge(['a'], [0.1])
    assert r.status == INCOMPLETE and r.missing == ('b', 'c')
    assert merger.merge(['b'], [0.2]).missing == ('c',)
    r = merger.merge(['c', 'a'], [0.3, 0.4])
    assert r.status == PUBLISH
    np.testing.assert_array_equal(r.q, [0.4, 0.2, 0.3])
    r = merger.merge(['b'], [0.9])
    np.testing.assert_array_equal(r.q, [0.4, 0.9, 0.3])


def test_velocities_only_when_every_joint_has_one(merger):
    assert merger.merge(NAMES, [0, 0, 0], [1, 2, 3]).qdot.tolist() == [1, 2, 3]
    merger.reset()
    merger.merge(['a', 'b'], [0, 0], [1, 2])
    assert merger.merge(['c'], [0]).qdot is None
    assert merger.merge(['c'], [0], [3]).qdot.tolist() == [1, 2, 3]


@pytest.mark.parametrize('names, positions, velocities, reason', [
    ([], [], [], 'empty'),
    (['a', 'b', 'c'], [0.0, 0.0], [], 'length_mismatch'),
    (['a', 'b', 'c'], [0.0, 0.0, 0.0], [1.0], 'length_mismatch'),
    (['a', 'a', 'b', 'c'], [0.0] * 4, [], 'duplicate_name'),
    (['a', 'b', 'c'], [0.0, math.nan, 0.0], [], 'non_finite'),
    (['a', 'b', 'c'], [0.0, math.inf, 0.0], [], 'non_finite'),
    (['x', 'y'], [0.0, 0.0], [], 'no_known_joint'),
])
def test_malformed_messages_are_rejected_and_change_nothing(merger, names, positions,
                                                            velocities, reason):
    merger.merge(NAMES, [0.1, 0.2, 0.3])
    r = merger.merge(names, positions, velocities)
    assert r.status == REJECTED and r.reason == reason and r.detail
    assert merger.counts['rejected_' + reason] == 1 and merger.counts['rejected'] == 1
    np.testing.assert_array_equal(merger.merge(['a'], [0.5]).q, [0.5, 0.2, 0.3])


def test_unknown_joints_are_ignored_and_reported_once(merger):
    r = merger.merge(['a', 'b', 'c', 'gripper'], [0, 0, 0, 5])
    assert r.status == PUBLISH and r.new_unknown == ('gripper',)
    assert merger.merge(['a', 'gripper'], [0, 5]).new_unknown == ()
    assert merger.unknown == {'gripper'}


def test_nan_velocity_drops_only_the_twist(merger):
    r = merger.merge(NAMES, [0, 0, 0], [1, math.nan, 3])
    assert r.status == PUBLISH and r.qdot is None


@pytest.mark.parametrize('policy, status, q_a', [
    ('warn', PUBLISH, 1.5), ('clamp', PUBLISH, 1.0), ('reject', REJECTED, None)])
def test_out_of_limits_policies(policy, status, q_a):
    merger = JointStateMerger(NAMES, LIMITS, policy)
    r = merger.merge(NAMES, [1.5, 0.0, 1.0])
    assert r.status == status
    if status == PUBLISH:
        assert r.q[0] == q_a and r.out_of_limits == ('a',)
    else:
        assert r.reason == 'out_of_limits' and 'a = 1.5' in r.detail


def test_unknown_policy_is_refused():
    with pytest.raises(ValueError, match='out_of_limits'):
        JointStateMerger(NAMES, LIMITS, 'ignore')


def test_time_jump_back_resets_instead_of_stalling(merger):
    t0 = 50 * TIME_JUMP_BACK_NS
    assert merger.merge(NAMES, [0, 0, 0], stamp_ns=t0).status == PUBLISH
    # a little out of order: merged
    assert merger.merge(['a'], [0.2], stamp_ns=t0 - 1000).status == PUBLISH
    # a bag loops: the state is reset, then the message is taken
    r = merger.merge(['a', 'b'], [0.3, 0.3], stamp_ns=TIME_JUMP_BACK_NS)
    assert r.time_jump and r.status == INCOMPLETE and r.missing == ('c',)
    assert merger.merge(NAMES, [1, 1, 1], stamp_ns=TIME_JUMP_BACK_NS + 1).status == PUBLISH
    assert merger.counts['time_jumps'] == 1


def test_counts(merger):
    merger.merge(['a'], [0])
    merger.merge(NAMES, [0, 0, 0])
    merger.merge([], [])
    assert merger.counts['received'] == 3
    assert merger.counts['incomplete'] == 1 and merger.counts['publish'] == 1
    assert merger.counts['rejected'] == 1


# -- merge_batch: the same outcome as one merge per message -------------------------------
NAME_SETS = [
    ('a', 'b', 'c'), ('c', 'a', 'b'), ('b', 'x', 'c', 'a'),  # full, reordered, plus unknown
    ('a', 'c'), ('y',), ('a', 'a', 'b'), (),                  # partial, foreign, duplicate
]


def random_batch(rng, names, k):
    """K messages with ``names``: some NaN, some out of limits, stamps with jumps and zeros."""
    n = len(names)
    positions = rng.uniform(-1.5, 2.5, size=(k, n))
    positions[rng.random((k, n)) < 0.03] = np.nan
    velocities = rng.normal(size=(k, n)) if rng.random() < 0.5 else np.zeros((k, 0))
    if velocities.size:
        velocities[rng.random((k, n)) < 0.05] = np.nan
    steps = rng.choice([0, 1_000_000, 5_000_000, -300_000_000, -3_000_000_000], size=k,
                       p=[0.1, 0.6, 0.2, 0.05, 0.05])
    stamps = 5_000_000_000 + np.cumsum(steps)
    stamps[rng.random(k) < 0.1] = 0
    return positions, velocities, stamps


def merge_one_by_one(merger, runs):
    published, qs, qdots, optional = [], [], [], []
    at = 0
    for names, positions, velocities, stamps in runs:
        for i in range(len(stamps)):
            r = merger.merge(names, positions[i], velocities[i], int(stamps[i]))
            if r.status == PUBLISH:
                published.append(at + i)
                qs.append(r.q)
                qdots.append(r.qdot if r.qdot is not None else np.full(3, np.nan))
                optional.append('c' in merger.seen_optional)
        at += len(stamps)
    return published, np.array(qs).reshape(-1, 3), np.array(qdots).reshape(-1, 3), optional


def by_layout(runs):
    """Return the runs' messages as one run per layout (names and array lengths), placed."""
    groups, at = {}, 0
    for names, positions, velocities, stamps in runs:
        k = len(stamps)
        key = (tuple(names), np.shape(positions)[1], np.shape(velocities)[1])
        groups.setdefault(key, []).append((positions, velocities, stamps, np.arange(at, at + k)))
        at += k
    return [(key[0], *(np.concatenate([np.asarray(m[i]) for m in members]) for i in range(4)))
            for key, members in groups.items()]


def test_a_run_in_any_order_merges_as_its_messages_in_that_order():
    rng = np.random.default_rng(3)
    positions, velocities, stamps = random_batch(rng, NAMES, 9)
    order = rng.permutation(9)
    placed = JointStateMerger(NAMES, LIMITS, 'warn')
    plain = JointStateMerger(NAMES, LIMITS, 'warn')
    got = placed.merge_many([(NAMES, positions, velocities, stamps, order)])
    back = np.argsort(order)   # the message at place i
    expected = plain.merge_many([(NAMES, positions[back], velocities[back], stamps[back])])
    assert got[0].tolist() == expected[0].tolist()
    np.testing.assert_array_equal(got[1], expected[1])
    np.testing.assert_array_equal(got[2], expected[2])


def test_merge_many_refuses_orders_that_do_not_cover_each_place_once(merger):
    run = (NAMES, np.zeros((2, 3)), np.zeros((2, 0)), [0, 0])
    for bad in ([run + ([0, 0],)], [run + ([0, 1],), run], [run + ([0, 2],)],
                [run + ([1, -1],)], [run + ([1],)]):
        with pytest.raises(ValueError, match='merge_many: '):
            merger.merge_many(bad)


@pytest.mark.parametrize('required', [3, 2])  # 2: joint c is optional (a side branch)
@pytest.mark.parametrize('policy', ['warn', 'clamp', 'reject'])
@pytest.mark.parametrize('seed', range(6))
def test_merge_many_equals_merging_one_by_one(policy, seed, required):
    rng = np.random.default_rng(seed)
    batched = JointStateMerger(NAMES, LIMITS, policy, required=required)
    single = JointStateMerger(NAMES, LIMITS, policy, required=required)
    grouped = JointStateMerger(NAMES, LIMITS, policy, required=required)
    for _ in range(25):
        runs = []
        for _ in range(int(rng.integers(1, 8))):  # several publishers, interleaved
            names = NAME_SETS[rng.integers(len(NAME_SETS))]
            positions, velocities, stamps = random_batch(rng, names, int(rng.integers(1, 30)))
            if names == ('a', 'a', 'b') and rng.random() < 0.5:
                positions = positions[:, :2]  # and a length mismatch
            runs.append((names, positions, velocities, stamps))
        published, q, qdot = batched.merge_many(runs)
        expected = merge_one_by_one(single, runs)
        # the same messages as one run per layout, each message's place given
        in_order = grouped.merge_many(by_layout(runs))
        assert in_order[0].tolist() == expected[0]
        np.testing.assert_array_equal(in_order[1], expected[1])
        np.testing.assert_array_equal(in_order[2], expected[2])
        np.testing.assert_array_equal(grouped.last_seen, batched.last_seen)
        assert grouped.counts == single.counts
        assert published.tolist() == expected[0]
        np.testing.assert_array_equal(q, expected[1])
        np.testing.assert_array_equal(qdot, expected[2])
        if required == 2:
            assert batched.last_seen[:, 2].tolist() == expected[3]
            assert batched.last_seen[:, :2].all()
        assert batched.counts == single.counts
        assert batched.unknown == single.unknown
        # the state left behind is the same: a partial message completes alike
        probe_b = batched.merge(['b'], [0.25], [0.5], stamp_ns=0)
        probe_s = single.merge(['b'], [0.25], [0.5], stamp_ns=0)
        probe_g = grouped.merge(['b'], [0.25], [0.5], stamp_ns=0)
        assert (probe_g.status, str(probe_g.q)) == (probe_s.status, str(probe_s.q))
        assert (probe_b.status, str(probe_b.q), str(probe_b.qdot)) == \
            (probe_s.status, str(probe_s.q), str(probe_s.qdot))
    for outcome in ('time_jumps', 'rejected_non_finite', 'incomplete', 'publish'):
        assert single.counts[outcome] > 0, outcome


def test_merge_many_tracks_time_jumps_across_calls(merger):
    merger.merge_many([(NAMES, np.zeros((1, 3)), np.zeros((1, 0)), [10 * TIME_JUMP_BACK_NS])])
    # 8.9 s is a jump back from the 10 s of the call before, not from the 9.5 s before it
    merger.merge_many([(NAMES, np.zeros((3, 3)), np.zeros((3, 0)),
                        [9.5 * TIME_JUMP_BACK_NS, 8.9 * TIME_JUMP_BACK_NS, 0])])
    assert merger.counts['time_jumps'] == 1
    assert merger.counts['publish'] == 4


def test_merge_many_resets_partial_state_at_a_time_jump(merger):
    late, early = 10 * TIME_JUMP_BACK_NS, 2 * TIME_JUMP_BACK_NS
    published, q, _ = merger.merge_many([
        (('a', 'b'), [[0.5, 0.5]], np.zeros((1, 0)), [late]),
        (('c',), [[1.0]], np.zeros((1, 0)), [late]),          # complete: a, b, c
        (('a', 'b'), [[0.1, 0.2]], np.zeros((1, 0)), [early]),  # jump back: c forgotten
        (('c',), [[1.5]], np.zeros((1, 0)), [early])])
    assert published.tolist() == [1, 3]
    np.testing.assert_array_equal(q, [[0.5, 0.5, 1.0], [0.1, 0.2, 1.5]])
    assert merger.counts['incomplete'] == 2 and merger.counts['time_jumps'] == 1


# -- hostile input: bounded memory, counted velocities, never an exception -----------------
def test_a_flood_of_new_unknown_names_stays_bounded(merger):
    """Each message with new made-up names used to grow the unknown set without bound."""
    overflow_at = []
    for k in range(5000):
        r = merger.merge(['a', 'b', 'c', f'ghost_{k}', f'phantom_{k}'], [0, 0, 0, 0, 0])
        assert r.status == PUBLISH
        if r.unknown_overflow:
            overflow_at.append(k)
    assert len(merger.unknown) == MAX_UNKNOWN_LISTED == 20
    assert merger.unknown == {f'{p}_{k}' for k in range(10) for p in ('ghost', 'phantom')}
    assert overflow_at == [10]  # reported once, when the list is full
    assert merger.counts['unknown_names_unlisted'] == 2 * (5000 - 10)


def test_merge_many_bounds_unknown_names_as_merge_does():
    rng = np.random.default_rng(4)
    runs = [(('a', 'b', 'c', f'u{k}'), rng.normal(size=(3, 4)) * 0.1, np.zeros((3, 0)),
             np.arange(3) + 100 * k + 1) for k in range(40)]
    batched = JointStateMerger(NAMES, LIMITS)
    single = JointStateMerger(NAMES, LIMITS)
    batched.merge_many(runs)
    merge_one_by_one(single, runs)
    assert batched.unknown == single.unknown and len(single.unknown) == MAX_UNKNOWN_LISTED
    assert batched.counts == single.counts
    assert single.counts['unknown_names_unlisted'] == 3 * 20


@pytest.mark.parametrize('bad', [math.nan, math.inf, -math.inf])
def test_non_finite_velocities_are_dropped_and_counted(merger, bad):
    r = merger.merge(NAMES, [0.1, 0.2, 0.3], [1.0, bad, 2.0])
    assert r.status == PUBLISH and r.qdot is None
    np.testing.assert_array_equal(r.q, [0.1, 0.2, 0.3])
    assert merger.counts['velocities_non_finite'] == 1
    r = merger.merge(NAMES, [0.1, 0.2, 0.3], [1.0, 1.5, 2.0])
    np.testing.assert_array_equal(r.qdot, [1.0, 1.5, 2.0])  # the next message has them again
    assert merger.counts['velocities_non_finite'] == 1


ANY_NUMBER = st.one_of(st.floats(allow_nan=True, allow_infinity=True),
                       st.integers(-2**63, 2**63 - 1))
ANY_NAME = st.one_of(st.sampled_from(['a', 'b', 'c', 'x', '']), st.text(max_size=12))


@given(st.lists(st.tuples(st.lists(ANY_NAME, max_size=6), st.lists(ANY_NUMBER, max_size=6),
                          st.lists(ANY_NUMBER, max_size=6), st.integers(0, 2**63 - 1)),
                max_size=12),
       st.sampled_from(['warn', 'clamp', 'reject']))
def test_random_joint_state_contents_never_raise(messages, policy):
    merger = JointStateMerger(NAMES, LIMITS, policy)
    for names, positions, velocities, stamp in messages:
        r = merger.merge(names, positions, velocities, stamp)
        assert r.status in (PUBLISH, INCOMPLETE, REJECTED)
        if r.status == PUBLISH:
            assert np.isfinite(r.q).all()
            assert r.qdot is None or np.isfinite(r.qdot).all()
    assert merger.counts['received'] == len(messages)
    assert len(merger.unknown) <= MAX_UNKNOWN_LISTED


class NoShortPath(JointStateMerger):
    """The merger with its short path for complete layouts switched off."""

    def _merge_complete(self, complete, positions, velocities, stamp_ns):
        raise AssertionError('not used')

    def merge(self, names, positions, velocities=(), stamp_ns=0):
        self.state.complete = None
        return super().merge(names, positions, velocities, stamp_ns)


@given(st.lists(st.tuples(st.sampled_from([('a', 'b', 'c'), ('c', 'a', 'b'), ('a', 'b'),
                                           ('a', 'b', 'c', 'x'), ('b', 'c', 'a')]),
                          st.lists(st.one_of(st.floats(-3, 3), st.sampled_from(
                              [math.nan, math.inf, 2.5, -1.5, 1e308, -1e308])),
                                   min_size=2, max_size=4),
                          st.lists(st.one_of(st.floats(-3, 3), st.just(math.nan)),
                                   max_size=4),
                          st.sampled_from([0, 1, 2, 5, -3])),
                max_size=30),
       st.sampled_from(['warn', 'clamp', 'reject']), st.sampled_from([3, 2]),
       st.sampled_from([LIMITS, [[-math.inf, math.inf]] * 3]))
def test_the_short_path_for_complete_messages_changes_nothing(messages, policy, required,
                                                              limits):
    fast = JointStateMerger(NAMES, limits, policy, required=required)
    slow = NoShortPath(NAMES, limits, policy, required=required)
    stamp = 10 * TIME_JUMP_BACK_NS
    for names, positions, velocities, step in messages:
        stamp += step * TIME_JUMP_BACK_NS // 2
        a = fast.merge(list(names), positions, velocities, stamp)
        b = slow.merge(list(names), positions, velocities, stamp)
        assert (a.status, a.reason, a.detail, a.out_of_limits, a.time_jump, a.missing) == \
            (b.status, b.reason, b.detail, b.out_of_limits, b.time_jump, b.missing)
        assert str(a.q) == str(b.q) and str(a.qdot) == str(b.qdot)
        assert fast.seen_optional == slow.seen_optional
    assert fast.counts == slow.counts


def test_a_message_of_foreign_joints_says_which_names_it_had(merger):
    r = merger.merge(['x', 'y'], [0.0, 0.0])
    assert r.detail == "none of 'x', 'y' is a joint of this robot"
    r = merger.merge([f'u{k}' for k in range(7)], [0.0] * 7)
    assert r.detail == "none of 'u0', 'u1', 'u2', 'u3', 'u4' ... is a joint of this robot"


def test_optional_joints_never_hold_back_an_update():
    merger = JointStateMerger(NAMES, LIMITS, required=2)  # c: a gripper on another topic
    r = merger.merge(['b', 'a'], [0.5, 0.25], [1.0, 2.0])
    assert r.status == PUBLISH and r.q.tolist() == [0.25, 0.5, 0.0]
    assert r.qdot[:2].tolist() == [2.0, 1.0] and math.isnan(r.qdot[2])
    assert merger.never_seen == () and merger.seen_optional == ()
    r = merger.merge(['c'], [1.5])
    assert r.status == PUBLISH and r.q.tolist() == [0.25, 0.5, 1.5]
    assert merger.seen_optional == ('c',)
    r = merger.merge(['b', 'a'], [0.0, 0.0], [1.0, 2.0])  # the short path keeps c
    assert r.q.tolist() == [0.0, 0.0, 1.5] and merger.seen_optional == ('c',)
    merger.reset()
    assert merger.seen_optional == () and merger.never_seen == ('a', 'b')
    assert merger.merge(['c'], [0.1]).status == INCOMPLETE


def test_a_value_exactly_at_a_limit_is_inside_on_both_paths():
    merger = JointStateMerger(NAMES, LIMITS, 'reject')
    for _ in range(3):  # the first message takes the general path, the next the short one
        r = merger.merge(['a', 'b', 'c'], [-1.0, 5.0, 2.0])
        assert r.status == PUBLISH and r.out_of_limits == ()
        r = merger.merge(['a', 'b', 'c'], [1.0, 5.0, 0.0])
        assert r.status == PUBLISH and r.out_of_limits == ()


def test_a_stamp_exactly_one_jump_back_is_not_a_jump_on_both_paths():
    t = 10 * TIME_JUMP_BACK_NS
    single, batched = JointStateMerger(NAMES, LIMITS), JointStateMerger(NAMES, LIMITS)
    stamps = [t, t - TIME_JUMP_BACK_NS, t - TIME_JUMP_BACK_NS - 1 - TIME_JUMP_BACK_NS]
    for stamp in stamps:
        single.merge(NAMES, [0.0, 0.0, 1.0], stamp_ns=stamp)
    batched.merge_many([(NAMES, np.tile([0.0, 0.0, 1.0], (3, 1)), np.zeros((3, 0)),
                         np.array(stamps))])
    # t - 1 s merges; 1 s and 1 ns before the latest stamp (t) is a jump
    assert single.counts['time_jumps'] == batched.counts['time_jumps'] == 1


def test_counting_a_rejection_counts_one_by_default():
    merger = JointStateMerger(NAMES, LIMITS)
    merger.count_rejected('malformed_cdr')
    assert merger.counts['rejected'] == merger.counts['rejected_malformed_cdr'] == 1
    merger.count_rejected('malformed_cdr', 40)   # a batch's malformed messages at once
    assert merger.counts['rejected'] == merger.counts['rejected_malformed_cdr'] == 41


def test_values_exactly_at_the_limits_are_inside_in_batches_too():
    merger = JointStateMerger(NAMES, LIMITS, 'reject')
    published, q, _ = merger.merge_many([(NAMES, np.array([[-1.0, 5.0, 2.0], [1.0, 0.0, 0.0]]),
                                          np.zeros((2, 0)), np.array([0, 0]))])
    assert published.tolist() == [0, 1] and merger.counts['rejected'] == 0


def test_a_rejected_message_has_no_stamp():
    assert JointStateMerger(NAMES, LIMITS).merge([], [], (), 5).stamp_ns == 0


def test_sequence_gaps_count_what_one_publisher_lost():
    gaps = SequenceGaps()
    assert [gaps.note(s) for s in (1, 5)] == [0, 0] and gaps.lost == 0  # not confirmed yet
    gaps.single_publisher(True)
    assert [gaps.note(s) for s in (3, 4, 7, 8, 18, None, 19)] == [0, 0, 2, 0, 9, 0, 0]
    assert gaps.lost == 11
    gaps.single_publisher(True)  # confirmed again: the stream goes on
    assert gaps.note(21) == 1 and gaps.lost == 12


def test_sequence_gaps_stop_at_a_second_publisher_or_a_restart():
    gaps = SequenceGaps()
    gaps.single_publisher(True)
    gaps.note(100)
    assert gaps.note(5) == 0  # another publisher's number (or a restart): stop counting
    assert gaps.note(1000) == 0 and gaps.note(2000) == 0 and gaps.lost == 0
    gaps.single_publisher(True)  # one publisher again: counting restarts from its next
    assert gaps.note(3000) == 0 and gaps.note(3002) == 1 and gaps.lost == 1
    gaps.single_publisher(False)  # two publishers: nothing is counted
    assert gaps.note(3010) == 0 and gaps.lost == 1
    gaps.single_publisher(True)
    assert gaps.note(3020) == 0 and gaps.note(3021) == 0 and gaps.lost == 1
    gaps.note(3021)  # the same number twice: not counted, counting stops
    assert gaps.note(3030) == 0 and gaps.lost == 1


def test_a_message_of_six_foreign_joints_lists_five_and_says_there_are_more(merger):
    names = [f'x{k}' for k in range(6)]
    r = merger.merge(names, [0.0] * 6)
    assert r.reason == 'no_known_joint'
    assert r.detail == "none of 'x0', 'x1', 'x2', 'x3', 'x4' ... is a joint of this robot"
    five = merger.merge(names[:5], [0.0] * 5)
    assert five.detail == "none of 'x0', 'x1', 'x2', 'x3', 'x4' is a joint of this robot"


def test_a_robot_without_joints_takes_any_message_in_both_paths():
    """A fixed rig (no moving joint): every message is an update, none 'no_known_joint'."""
    merger = JointStateMerger((), np.zeros((0, 2)), required=0)
    result = merger.merge(('other',), (1.0,), (), 7)
    assert result.status == PUBLISH and result.q.shape == (0,) and result.stamp_ns == 7
    published, q, _ = JointStateMerger((), np.zeros((0, 2)), required=0).merge_many(
        [(('a', 'b'), np.zeros((3, 2)), np.zeros((3, 0)), np.array([1, 2, 3]))])
    assert published.tolist() == [0, 1, 2] and q.shape == (3, 0)


def node_like_merge(merger, raw, cache):
    """Merge ``raw`` as the node does: the compiled short path, else parse and merge."""
    fast = merger.merge_raw(raw)
    if fast is not None:
        return fast
    stamp_ns, names, positions, velocities = parse_joint_state(raw, cache, as_tuples=True)
    result = merger.merge(names, positions, velocities, stamp_ns)
    if result.status == PUBLISH and not (result.new_unknown or result.time_jump or
                                         result.out_of_limits or result.unknown_overflow):
        if merger.raw_reader is None:
            merger.learn_layout(cache.layout)
    return result


def reader_arguments():
    """
    Return ``(arguments, raw)``: a JointStateReader's keyword arguments, and its message.

    The layout a node-like merge learns from ``raw`` (NAMES at 0.1, 0.2, 0.3, stamp 10 ns),
    bounds [0, 1] for each joint.
    """
    merger, cache = JointStateMerger(NAMES, LIMITS, 'clamp'), JointStateNames()
    raw = serialized_joint_state(NAMES, [0.1, 0.2, 0.3], [], 10, '', 0)
    node_like_merge(merger, raw, cache)
    layout = cache.layout
    return {'size': layout.size, 'fixed': layout.fixed, 'mask': bytes(len(layout.fixed)),
            'counts_at': layout.count_offsets, 'counts': layout.expected_counts,
            'positions_at': layout.positions[0], 'velocities_at': layout.velocities[0],
            'order': [0, 1, 2], 'lower': [0.0] * 3, 'upper': [1.0] * 3,
            'jump_back_ns': 1}, raw


def serialized_joint_state(names, positions, velocities, stamp_ns, frame_id, padding):
    msg = JointState(name=list(names), position=list(positions), velocity=list(velocities))
    msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(stamp_ns, 1_000_000_000)
    msg.header.frame_id = frame_id
    raw = bytearray(serialize_message(msg))
    spans = _joint_state_spans(bytes(raw))
    # CDR leaves the alignment padding undefined: any byte after a string's end and before
    # the next 4-aligned field may differ between two messages of the same names
    at = 12
    for _ in range(len(names) + 1):
        (length,) = struct.unpack_from('<I', raw, at)
        end = at + 4 + length
        pad = (-(end - 4)) % 4
        raw[end:end + pad] = bytes([padding]) * pad
        at = end + pad
        if at == spans[0][0] - 4:  # the name count after the frame id
            at += 4
    return bytes(raw)


@needs_compiled
@settings(max_examples=150, deadline=None)
@given(st.lists(st.tuples(st.sampled_from([('a', 'b', 'c'), ('c', 'a', 'b'), ('a', 'b'),
                                           ('a', 'b', 'c', 'x')]),
                          st.lists(st.one_of(st.floats(-3, 3), st.sampled_from(
                              [math.nan, math.inf, 2.5, -1.5, 1e308])),
                                   min_size=4, max_size=4),
                          st.sampled_from([0, 4]),
                          st.one_of(st.just(math.nan), st.floats(-3, 3)),
                          st.sampled_from([0, 1, 2, 5, -3]),
                          st.sampled_from(['', 'base']), st.sampled_from([0, 0xAB])),
                max_size=30),
       st.sampled_from(['warn', 'clamp', 'reject']), st.sampled_from([3, 2]),
       st.sampled_from([LIMITS, [[-math.inf, math.inf]] * 3]))
def test_the_compiled_path_merges_as_merge_does(messages, policy, required, limits):
    fast = JointStateMerger(NAMES, limits, policy, required=required)
    slow = NoShortPath(NAMES, limits, policy, required=required)
    fast_cache, slow_cache = JointStateNames(), JointStateNames()
    stamp = 10 * TIME_JUMP_BACK_NS
    taken = 0
    for names, values, n_vel, velocity, step, frame_id, padding in messages:
        stamp += step * TIME_JUMP_BACK_NS // 2
        positions = values[:len(names)]
        velocities = [velocity] + [0.5] * (len(names) - 1) if n_vel else []
        raw = serialized_joint_state(names, positions, velocities, stamp, frame_id, padding)
        a = node_like_merge(fast, raw, fast_cache)
        b = slow.merge(*_fields(parse_joint_state(raw, slow_cache, as_tuples=True)))
        if isinstance(a, tuple):  # the compiled path took it: what merge publishes
            taken += 1
            stamp_ns, q, qdot = a
            assert b.status == PUBLISH and not (b.out_of_limits or b.time_jump or
                                                b.new_unknown)
            assert stamp_ns == b.stamp_ns
            assert str(q) == str(b.q) and str(qdot) == str(b.qdot)
        else:
            assert (a.status, a.reason, a.detail, a.out_of_limits, a.time_jump, a.missing) == \
                (b.status, b.reason, b.detail, b.out_of_limits, b.time_jump, b.missing)
            assert str(a.q) == str(b.q) and str(a.qdot) == str(b.qdot)
        assert fast.seen_optional == slow.seen_optional
        assert fast.state.q == slow.state.q and str(fast.state.qdot) == str(slow.state.qdot)
    assert fast.counts == slow.counts


@needs_compiled
def test_a_repeated_complete_layout_takes_the_compiled_path():
    merger, cache = JointStateMerger(NAMES, LIMITS), JointStateNames()
    raws = [serialized_joint_state(('c', 'a', 'b'), [0.5, 0.1 * k, 1.0], [1.0, 2.0, 3.0],
                                   (5 + k) * 1_000_000_000, 'base', k % 2 * 0xAB)
            for k in range(4)]
    assert not isinstance(node_like_merge(merger, raws[0], cache), tuple)
    assert merger.raw_reader is not None
    for k, raw in enumerate(raws[1:], 1):  # padding bytes differ: still the same layout
        stamp_ns, q, qdot = node_like_merge(merger, raw, cache)
        assert stamp_ns == (5 + k) * 1_000_000_000
        assert q.tolist() == [0.1 * k, 1.0, 0.5] and qdot.tolist() == [2.0, 3.0, 1.0]
    # a longer frame id, a truncated message, garbage: not taken (merge decides)
    other = serialized_joint_state(('c', 'a', 'b'), [0.5, 0.1, 1.0], [], 9, 'base_link', 0)
    for raw in (other, raws[1][:-8], b'', b'\x00\x01\x00\x00' + bytes(100)):
        assert merger.merge_raw(raw) is None
    merger.reset()  # forgets the layout with everything else
    assert merger.raw_reader is None and merger.merge_raw(raws[1]) is None


@needs_compiled
def test_the_compiled_reader_refuses_what_it_cannot_use():
    from dq_fk_ros.messages import _cdr
    merger, cache = JointStateMerger(NAMES, LIMITS), JointStateNames()
    raw = serialized_joint_state(NAMES, [0.1, 0.2, 0.3], [], 10, '', 0)
    node_like_merge(merger, raw, cache)
    reader = merger.raw_reader
    out = np.empty(3)
    for args in ((raw, None, [0.0] * 3, [0.0] * 2, out, out),           # lists differ
                 (raw, None, [0.0, 1, 0.0], [0.0] * 3, out, out),       # not floats
                 (raw, None, (0.0,) * 3, [0.0] * 3, out, out),          # not lists
                 (raw, 'x', [0.0] * 3, [0.0] * 3, out, out),            # a stamp not an int
                 (raw, None, [0.0] * 3, [0.0] * 3, np.empty(2), out),   # q_out too short
                 (raw, None, [0.0] * 3, [0.0] * 3, out, np.empty(3, np.float32)),
                 (raw, None, [0.0] * 2, [0.0] * 2, np.empty(2), np.empty(2)),  # order past q
                 (raw,)):
        with pytest.raises((TypeError, ValueError)):
            reader.read(*args)
    good, _ = reader_arguments()
    _cdr.JointStateReader(**good)
    for field, value in (('mask', b'\xff'), ('size', 8), ('counts_at', (0, 1, 2)),
                         ('counts', (3, 2, 0)), ('positions_at', 10 ** 6),
                         ('order', [0, -1, 2]), ('order', [0, 1]), ('lower', [0.0]),
                         ('upper', ['x'] * 3)):
        with pytest.raises((TypeError, ValueError)):
            _cdr.JointStateReader(**{**good, field: value})
    with pytest.raises(TypeError):
        _cdr.JointStateReader.__new__(_cdr.JointStateReader)  # nothing without arguments
    made = _cdr.JointStateReader(**good)
    with pytest.raises(TypeError, match='set once'):  # a second __init__ changes nothing
        made.__init__(**{**good, 'size': 8})
    q, qdot = [0.0] * 3, [0.0] * 3
    assert made.read(raw, None, q, qdot, out, np.empty(3)) == 10
    assert q == [0.1, 0.2, 0.3]


def _fields(parsed):
    stamp_ns, names, positions, velocities = parsed
    return names, positions, velocities, stamp_ns


@needs_compiled
def test_the_compiled_path_takes_over_after_a_clamped_value():
    merger, cache = JointStateMerger(NAMES, LIMITS, 'clamp'), JointStateNames()
    first = serialized_joint_state(NAMES, [2.5, 0.0, 0.5], [], 10, '', 0)
    assert node_like_merge(merger, first, cache).out_of_limits == ('a',)  # clamped to 1.0
    merger.learn_layout(cache.layout)  # (the node learns from clean messages only)
    again = serialized_joint_state(NAMES, [0.5, 0.25, 0.5], [], 11, '', 0)
    stamp_ns, q, qdot = node_like_merge(merger, again, cache)
    assert (stamp_ns, q.tolist(), qdot) == (11, [0.5, 0.25, 0.5], None)


@needs_compiled
@settings(max_examples=300, deadline=None)
@given(st.lists(st.lists(st.tuples(st.integers(0, 123), st.integers(0, 255)), min_size=1,
                         max_size=3), max_size=20))
def test_damaged_bytes_get_the_same_outcome_on_both_paths(damages):
    fast, slow = JointStateMerger(NAMES, LIMITS), NoShortPath(NAMES, LIMITS)
    fast_cache, slow_cache = JointStateNames(), JointStateNames()
    good = serialized_joint_state(('c', 'a', 'b'), [0.5, 0.1, 1.0], [1.0, 2.0, 3.0],
                                  5 * 1_000_000_000, 'base', 0)
    assert len(good) == 124
    for raw in [good] + [bytes(b if k not in dict(d) else dict(d)[k] for k, b in
                               enumerate(good)) for d in damages]:
        try:
            a = node_like_merge(fast, raw, fast_cache)
        except CdrError:
            a = 'malformed'
        try:
            b = slow.merge(*_fields(parse_joint_state(raw, slow_cache, as_tuples=True)))
        except CdrError:
            b = 'malformed'
        if isinstance(a, tuple):  # taken from the bytes: what merge publishes silently
            assert b.status == PUBLISH and not (b.out_of_limits or b.time_jump)
            assert (a[0], str(a[1]), str(a[2])) == (b.stamp_ns, str(b.q), str(b.qdot))
        elif a == 'malformed' or b == 'malformed':
            assert a == b
        else:
            assert (a.status, a.reason, str(a.q), str(a.qdot)) == \
                (b.status, b.reason, str(b.q), str(b.qdot))
    assert fast.counts == slow.counts


def test_a_rejections_detail_says_what_was_wrong(merger):
    from dq_fk_ros.messages.joint_states import REJECT_REASONS
    merger.merge(NAMES, [0.1, 0.2, 0.3])   # the complete layout, then its short path
    assert merger.merge(NAMES, [0.0, 0.0], [1.0]).detail == \
        '3 names, 2 positions, 1 velocities'
    assert merger.merge(['a', 'b'], [0.0], []).detail == '2 names, 1 positions, 0 velocities'
    assert merger.merge([], [], []).detail == REJECT_REASONS['empty']
    assert merger.merge(['a', 'a'], [0.0, 0.0]).detail == REJECT_REASONS['duplicate_name']


def test_clear_counts_starts_the_counts_and_unknown_names_afresh_and_keeps_the_state(merger):
    merger.merge(['a', 'b', 'c', 'gripper'], [0.1, 0.2, 0.3, 5.0])
    merger.merge([], [], [])
    merger.clear_counts()
    assert merger.counts['received'] == 0 and merger.counts['rejected'] == 0
    assert merger.unknown == set()
    np.testing.assert_array_equal(merger.merge(['a'], [0.5]).q, [0.5, 0.2, 0.3])
    assert merger.counts['received'] == 1


@pytest.mark.parametrize('policy, bad, reason', [('warn', math.nan, 'non_finite'),
                                                 ('reject', 5.0, 'out_of_limits')])
def test_a_rejected_message_still_says_the_unknown_names_it_brought(policy, bad, reason):
    merger = JointStateMerger(NAMES, LIMITS, policy)
    r = merger.merge(['a', 'gripper'], [bad, 0.0])
    assert (r.status, r.reason, r.new_unknown, r.unknown_overflow) == \
        (REJECTED, reason, ('gripper',), False)
    r = merger.merge(['x1', 'x2'], [0.0, 0.0])
    assert (r.reason, r.new_unknown, r.unknown_overflow) == ('no_known_joint', ('x1', 'x2'),
                                                             False)
    many = [f'u{k}' for k in range(25)]   # past the list's room: the overflow said once
    r = merger.merge(['a'] + many, [bad] + [0.0] * 25)
    assert r.reason == reason and r.unknown_overflow is True
    assert r.new_unknown == tuple(many[:MAX_UNKNOWN_LISTED - 3])   # 3 names listed before
    assert len(merger.unknown) == MAX_UNKNOWN_LISTED


def test_the_short_path_says_what_the_reference_says_case_by_case():
    """Each outcome of a repeated complete layout, beside the merger without the short path."""
    t = 10 * TIME_JUMP_BACK_NS
    cases = [  # (names, positions, velocities, stamp) after a first message at t
        (NAMES, [-1.0, 0.0, 2.5], [], t + 1),        # c above; a exactly at its lower limit
        (NAMES, [1.5, 0.0, 2.0], [], t + 2),         # a above; c exactly at its upper limit
        (NAMES, [0.5, 0.0, -0.5], [0.1, 0.2, 0.3], t + 3),   # c below
        (NAMES, [0.5, 0.0, 1.0], [], 0),             # no stamp: never a time jump
        (NAMES, [0.5, 0.0, 1.0], [], t - 5 * TIME_JUMP_BACK_NS),   # a jump back
        (('c', 'a', 'b'), [2.5, 0.5, 0.0], [], t + 4),   # another order, c above
    ]
    for policy in ('warn', 'clamp', 'reject'):
        for case in cases:
            fast = JointStateMerger(NAMES, LIMITS, policy)
            slow = NoShortPath(NAMES, LIMITS, policy)
            for merger in (fast, slow):
                merger.merge(case[0], [0.0, 0.0, 1.0], [], t)   # learns the layout
            assert fast.state.complete is not None
            a, b = fast.merge(*case), slow.merge(*case)
            assert (a.status, a.reason, a.detail, a.out_of_limits, a.time_jump, a.stamp_ns) \
                == (b.status, b.reason, b.detail, b.out_of_limits, b.time_jump, b.stamp_ns), \
                (policy, case)
            assert str(a.q) == str(b.q) and fast.counts == slow.counts, (policy, case)
    merger = JointStateMerger(NAMES, LIMITS, 'reject')
    merger.merge(NAMES, [0.0, 0.0, 1.0], [], t)
    r = merger.merge(NAMES, [-1.0, 0.0, 2.5], [], t + 1)
    assert r.detail == 'c = 2.5 outside [0, 2]'
    r = JointStateMerger(NAMES, LIMITS, 'warn')
    r.merge(NAMES, [0.0, 0.0, 1.0], [], t)
    assert r.merge(NAMES, [-1.0, 0.0, 2.5], [], t + 1).out_of_limits == ('c',)
    assert r.merge(NAMES, [0.0, 0.0, 1.0], [], 0).time_jump is False
    jump = r.merge(NAMES, [0.0, 0.0, 1.0], [], t - 5 * TIME_JUMP_BACK_NS)
    assert jump.time_jump is True and jump.stamp_ns == t - 5 * TIME_JUMP_BACK_NS


def test_counts_and_unknown_names_given_are_the_ones_kept():
    """The node carries both across a reload: the merger keeps the objects it is given."""
    counts, unknown = Counter({'publish': 7}), {'old'}
    merger = JointStateMerger(NAMES, LIMITS, counts=counts, unknown=unknown)
    merger.merge(('a', 'b', 'c', 'x'), [0.0, 0.0, 1.0, 0.0])
    assert merger.counts is counts and counts['publish'] == 8
    assert merger.unknown is unknown and unknown == {'old', 'x'}


def test_a_message_without_a_stamp_has_stamp_zero():
    merger = JointStateMerger(NAMES, LIMITS)
    assert merger.merge(NAMES, [0.0, 0.0, 1.0]).stamp_ns == 0
    assert merger.merge(NAMES, [0.0, 0.0, 1.0], (), 5).stamp_ns == 5
