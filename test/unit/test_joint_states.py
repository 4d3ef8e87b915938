"""JointStateMerger: the node's input logic, fed message fields directly (no DDS)."""

import math

from dq_fk_ros.joint_states import (
    INCOMPLETE, JointStateMerger, PUBLISH, REJECTED, TIME_JUMP_BACK_NS)
import numpy as np
import pytest

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
