"""
tf2's lookup rules (dq_fk_ros.transforms.buffer_core) against a reference written here.

The reference follows tf2's documented behaviour (the tf2 design page, tf2's "Errors
explained", the BufferCore API docs), not the code: an edge at a time is its sample at that
stamp, or the interpolation of the two samples around it (linear in translation, the
shortest-arc rotation in between, computed here by axis and angle with 4x4 matrices), or
the older sample when they name different parents; a time outside an edge's samples is an
ExtrapolationException; time 0 is the newest time every moving edge of the path has; two
frames with no common ancestor are a ConnectivityException.
"""

import math

from dq_fk_ros.transforms.buffer_core import BufferCore, MAX_FRAME_ID
from dq_fk_ros.transforms.exceptions import (ConnectivityException, ExtrapolationException,
                                             InvalidArgumentException, LookupException,
                                             TransformException)
from dq_fk_ros.transforms.pose_math import compose, inverse
from hypothesis import given, settings, strategies as st
import numpy as np
import pytest

S = 1_000_000_000


def matrix(pose):
    """Return the 4x4 matrix of a pose (x y z qx qy qz qw), from the unit quaternion."""
    x, y, z, qx, qy, qz, qw = pose
    n = math.sqrt(qx * qx + qy * qy + qz * qz + qw * qw)
    qx, qy, qz, qw = qx / n, qy / n, qz / n, qw / n
    m = np.eye(4)
    m[:3, :3] = [[1 - 2 * (qy * qy + qz * qz), 2 * (qx * qy - qz * qw), 2 * (qx * qz + qy * qw)],
                 [2 * (qx * qy + qz * qw), 1 - 2 * (qx * qx + qz * qz), 2 * (qy * qz - qx * qw)],
                 [2 * (qx * qz - qy * qw), 2 * (qy * qz + qx * qw), 1 - 2 * (qx * qx + qy * qy)]]
    m[:3, 3] = (x, y, z)
    return m


def rotation_between(q0, q1, ratio):
    """
    Return the rotation matrix ``ratio`` of the way from q0 to q1 (x y z w), the shorter arc.

    Geodesic interpolation in axis-angle form: the relative rotation ``conj(q0) q1``
    (``q1`` negated when the dot product is negative, only then: tf2's rule, which also
    settles a half turn), its angle by ``atan2`` (exact near a half turn), ``ratio`` of it
    turned about its axis after q0.
    """
    q0, q1 = np.array(q0, dtype=float), np.array(q1, dtype=float)
    if np.dot(q0, q1) < 0:
        q1 = -q1
    v0, v1, w0, w1 = q0[:3], q1[:3], q0[3], q1[3]
    v = w0 * v1 - w1 * v0 - np.cross(v0, v1)          # conj(q0) q1, vector part
    w = w0 * w1 + np.dot(v0, v1)                      # and its scalar part
    half = math.atan2(np.linalg.norm(v), w) * ratio
    axis = v / np.linalg.norm(v) if np.linalg.norm(v) > 0 else np.zeros(3)
    step = np.concatenate([axis * math.sin(half), [math.cos(half)]])
    x, y, z, qw = (w0 * step[:3] + step[3] * v0 + np.cross(v0, step[:3])).tolist() + \
        [w0 * step[3] - np.dot(v0, step[:3])]
    return matrix((0, 0, 0, x, y, z, qw))[:3, :3]


class Reference:
    """Samples per child frame, looked up by the rules of the module doc."""

    def __init__(self):
        self.static = {}     # child -> (parent, pose)
        self.samples = {}    # child -> [(stamp, insert order, parent, pose)]
        self.named = set()   # parents of refused samples

    def add(self, parent, child, stamp, pose, static=False):
        """Store a sample; return whether it was taken (False: refused, a repeated stamp)."""
        if static:
            self.static[child] = (parent, pose)
            self.samples.pop(child, None)
            return True
        if child in self.static:
            del self.static[child]
        samples = self.samples.setdefault(child, [])
        held = [s for s in samples if s[0] == stamp]
        if held:   # one sample a stamp: an exact duplicate is taken once, another refused
            self.named.add(parent)   # (its name is known, as tf2 names it before storing)
            return held[0][2] == parent and held[0][3] == pose
        samples.append((stamp, len(samples), parent, pose))
        return True

    def edge(self, child, t):
        """Return ``(parent, 4x4)`` at t, None for a root, or raise ExtrapolationException."""
        if child in self.static:
            parent, pose = self.static[child]
            return parent, matrix(pose)
        if child not in self.samples:
            return None
        samples = sorted(self.samples[child])
        if t == 0:
            return samples[-1][2], matrix(samples[-1][3])
        if len(samples) == 1 or not samples[0][0] <= t <= samples[-1][0]:
            if samples[0][0] == t == samples[-1][0]:
                return samples[-1][2], matrix(samples[-1][3])
            raise ExtrapolationException('outside')
        if t == samples[-1][0]:
            return samples[-1][2], matrix(samples[-1][3])
        if t == samples[0][0]:
            return samples[0][2], matrix(samples[0][3])
        older = [s for s in samples if s[0] <= t][-1]
        newer = samples[samples.index(older) + 1]
        if older[2] != newer[2]:
            return older[2], matrix(older[3])
        ratio = (t - older[0]) / (newer[0] - older[0])
        m0, m1 = matrix(older[3]), matrix(newer[3])
        m = np.eye(4)
        m[:3, :3] = rotation_between(older[3][3:], newer[3][3:], ratio)
        m[:3, 3] = (1 - ratio) * m0[:3, 3] + ratio * m1[:3, 3]
        return older[2], m

    def ancestors(self, frame, t):
        """Return ``({frame: its pose in the top one}, top, failed)`` walking up at t."""
        chain, failed = {frame: np.eye(4)}, False
        while True:
            try:
                found = self.edge(frame, t)
            except ExtrapolationException:
                failed = True
                break
            if found is None:
                break
            parent, m = found
            chain = {f: m @ p for f, p in chain.items()}
            chain[parent] = np.eye(4)
            frame = parent
        return chain, frame, failed

    def latest_time(self, target, source):
        chain_s, _, _ = self.ancestors(source, 0)
        chain_t, _, _ = self.ancestors(target, 0)
        common = [f for f in chain_s if f in chain_t]
        if not common:
            raise ConnectivityException('apart')
        lca = common[0]
        stamps = []
        for start in (source, target):
            frame = start
            while frame != lca:
                if frame in self.samples:
                    stamps.append(max(s[0] for s in self.samples[frame]))
                frame = self.edge(frame, 0)[0]
        return min(stamps) if stamps else 0

    def lookup(self, target, source, t):
        if target == source:
            return np.eye(4)
        known = set(self.static) | set(self.samples) | self.named | \
            {p for p, _ in self.static.values()} | \
            {s[2] for v in self.samples.values() for s in v}
        for name in (target, source):
            if name not in known:
                raise LookupException(name)
        if t == 0:
            t = self.latest_time(target, source)
        chain_s, _, failed_s = self.ancestors(source, t)
        chain_t, _, failed_t = self.ancestors(target, t)
        common = [f for f in chain_s if f in chain_t]
        if not common:
            if failed_s or failed_t:
                raise ExtrapolationException('apart or outside')
            raise ConnectivityException('apart')
        lca = common[0]
        # each side's pose in the common ancestor: re-walk up to it only
        return np.linalg.inv(self.up_to(target, lca, t)) @ self.up_to(source, lca, t)

    def up_to(self, frame, top, t):
        pose = np.eye(4)
        while frame != top:
            parent, m = self.edge(frame, t)
            pose = m @ pose
            frame = parent
        return pose


def random_pose(draw):
    x, y, z = (draw(st.floats(-2, 2)) for _ in range(3))
    q = np.array([draw(st.floats(-1, 1)) for _ in range(4)])
    if np.linalg.norm(q) < 0.1:
        q = np.array([0.0, 0.0, 0.0, 1.0])
    q /= np.linalg.norm(q)
    return (x, y, z) + tuple(float(v) for v in q)


@st.composite
def scenes(draw):
    """Draw a tree of up to 7 frames (a parent always an earlier one), static and moving edges."""
    n = draw(st.integers(2, 7))
    frames = [f'f{k}' for k in range(n)]
    inserts = []
    for k in range(1, n):
        kind = draw(st.sampled_from(('static', 'moving', 'moving', 'none')))
        if kind == 'static':
            inserts.append((frames[draw(st.integers(0, k - 1))], frames[k], 0, random_pose(draw),
                            True))
        elif kind == 'moving':
            for _ in range(draw(st.integers(1, 4))):
                parent = frames[draw(st.integers(0, k - 1))]   # parents may change over time
                stamp = draw(st.integers(1, 10)) * S // 2
                inserts.append((parent, frames[k], stamp, random_pose(draw), False))
    order = draw(st.permutations(range(len(inserts))))
    queries = [(draw(st.sampled_from(frames)), draw(st.sampled_from(frames)),
                draw(st.one_of(st.just(0), st.sampled_from([k * S // 4 for k in range(1, 22)]))))
               for _ in range(6)]
    return [inserts[i] for i in order], queries


@settings(max_examples=300, deadline=None)
@given(scenes())
def test_lookups_follow_tf2s_rules_on_random_trees(scene):
    inserts, queries = scene
    core, reference = BufferCore(cache_time_ns=100 * S), Reference()
    for parent, child, stamp, pose, static in inserts:
        assert core.set_transform(parent, child, stamp, pose, 'test', static) == \
            reference.add(parent, child, stamp, pose, static)
    for target, source, t in queries:
        try:
            expected = reference.lookup(target, source, t)
        except TransformException as exc:
            with pytest.raises(type(exc)):
                core.lookup(target, source, t)
            assert not core.can_transform(target, source, t)[0]
            continue
        pose, _ = core.lookup(target, source, t)
        np.testing.assert_allclose(matrix(pose), expected, atol=1e-9, err_msg=str((target,
                                                                                  source, t)))
        assert core.can_transform(target, source, t) == (True, '')


def test_one_sample_answers_its_own_stamp_only_and_statics_answer_every_time():
    core = BufferCore()
    core.set_transform('map', 'odom', 0, (1, 2, 3, 0, 0, 0, 1), static=True)
    core.set_transform('odom', 'base', 5 * S, (1, 0, 0, 0, 0, 0, 1))
    assert core.lookup('map', 'base', 5 * S)[0][:3] == (2.0, 2.0, 3.0)
    assert core.lookup('map', 'base', 0) == ((2.0, 2.0, 3.0, 0.0, 0.0, 0.0, 1.0), 5 * S)
    with pytest.raises(ExtrapolationException, match='only time 5.000000 is in the buffer'):
        core.lookup('map', 'base', 5 * S + 1)
    assert core.lookup('map', 'odom', 123)[1] == 123   # a static edge: any time
    assert core.lookup('map', 'odom', 0)[1] == 0        # only static edges: time 0


def test_the_future_and_the_past_raise_with_tf2s_words():
    core = BufferCore()
    core.set_transform('a', 'b', 1 * S, (0, 0, 0, 0, 0, 0, 1))
    core.set_transform('a', 'b', 2 * S, (1, 0, 0, 0, 0, 0, 1))
    with pytest.raises(ExtrapolationException, match='extrapolation into the future'):
        core.lookup('a', 'b', 3 * S)
    with pytest.raises(ExtrapolationException, match='extrapolation into the past'):
        core.lookup('a', 'b', S // 2)
    # nanoseconds count: at 1.5 s + 1 ns the translation is 0.5 + 1e-9
    assert core.lookup('a', 'b', 3 * S // 2 + 1)[0][0] == pytest.approx(0.5 + 1e-9, abs=1e-15)


def test_old_samples_are_pruned_and_older_ones_refused():
    lines = []
    core = BufferCore(cache_time_ns=10 * S, log=lines.append)
    for k in range(30):
        assert core.set_transform('a', 'b', k * S, (k, 0, 0, 0, 0, 0, 1))
    with pytest.raises(ExtrapolationException, match='into the past'):
        core.lookup('a', 'b', 5 * S)   # pruned: older than 10 s before the newest
    assert core.lookup('a', 'b', 19 * S)[0][0] == 19.0
    assert not core.set_transform('a', 'b', 3 * S, (0, 0, 0, 0, 0, 0, 1))
    assert lines and lines[-1].startswith('TF_OLD_DATA')


def test_frame_names_as_tf2_takes_them():
    core = BufferCore()
    assert core.set_transform('/world', '/base', 0, (0, 0, 1, 0, 0, 0, 1), static=True)
    assert core.lookup('world', 'base', 0)[0][2] == 1.0      # the slash stripped on the way in
    with pytest.raises(InvalidArgumentException, match="cannot start with a '/'"):
        core.lookup('/world', 'base', 0)
    with pytest.raises(InvalidArgumentException, match='cannot be empty'):
        core.lookup('', 'base', 0)
    with pytest.raises(LookupException, match='does not exist'):
        core.lookup('world', 'nowhere', 0)
    assert core.lookup('nowhere', 'nowhere', 7)[1] == 7      # the same frame: identity, any name
    assert not core.can_transform('world', '/base', 0)[0]


def test_nan_denormalised_self_and_unnamed_transforms_are_refused_with_one_line_each():
    lines = []
    core = BufferCore(log=lines.append, log_every_s=0)
    for parent, child, pose in (('a', 'b', (math.nan, 0, 0, 0, 0, 0, 1)),
                                ('a', 'b', (0, 0, 0, 0, 0, 0, 2.0)),
                                ('a', 'b', (0, 0, 0, 0, 0, 0, 0)),
                                ('a', 'a', (0, 0, 0, 0, 0, 0, 1)),
                                ('', 'b', (0, 0, 0, 0, 0, 0, 1)),
                                ('a', '/', (0, 0, 0, 0, 0, 0, 1)),
                                ('a', 'b', (math.inf, 0, 0, 0, 0, 0, 1))):
        assert not core.set_transform(parent, child, S, pose)
    assert [line.split(':')[0] for line in lines] == [
        'TF_NAN_INPUT', 'TF_DENORMALIZED_QUATERNION', 'TF_DENORMALIZED_QUATERNION',
        'TF_SELF_TRANSFORM', 'TF_NO_FRAME_ID', 'TF_NO_CHILD_FRAME_ID', 'TF_INF_INPUT']
    assert all('\n' not in line for line in lines)


def test_a_loop_is_tf2s_lookup_error_never_a_hang():
    core = BufferCore()
    core.set_transform('a', 'b', 0, (1, 0, 0, 0, 0, 0, 1), static=True)
    core.set_transform('b', 'c', 0, (1, 0, 0, 0, 0, 0, 1), static=True)
    core.set_transform('c', 'a', 0, (1, 0, 0, 0, 0, 0, 1), static=True)
    core.set_transform('x', 'y', 0, (1, 0, 0, 0, 0, 0, 1), static=True)
    with pytest.raises(LookupException, match='contains a loop'):
        core.lookup('y', 'a', 0)
    with pytest.raises(LookupException, match='contains a loop'):
        core.lookup('y', 'a', 5 * S)


def test_a_peer_naming_a_million_frames_is_held_to_the_cap():
    lines = []
    core = BufferCore(max_frames=1000, log=lines.append)
    for k in range(100_000):
        core.set_transform('world', f'frame_{k}', S, (0, 0, 0, 0, 0, 0, 1))
    assert len(core.frame_names()) <= 1000 and len(lines) == 1
    assert 'TF_TOO_MANY_FRAMES' in lines[0]
    # every refused transform counted (the count had stayed at 1)
    assert core.refused_frames == 100_000 - 999 == core.refused['TF_TOO_MANY_FRAMES']


def test_a_repeated_stamp_is_refused_and_an_exact_duplicate_stored_once():
    lines = []
    core = BufferCore(log=lines.append)
    assert core.set_transform('a', 'b', S, (1, 0, 0, 0, 0, 0, 1))
    assert not core.set_transform('a', 'b', S, (2, 0, 0, 0, 0, 0, 1))
    assert not core.set_transform('c', 'b', S, (1, 0, 0, 0, 0, 0, 1))   # another parent
    assert core.set_transform('a', 'b', S, (1, 0, 0, 0, 0, 0, 1))       # the same: taken once
    assert core.lookup('a', 'b', S)[0][0] == 1.0
    assert len(core.caches[core.ids['b']]) == 1
    assert core.refused == {'TF_REPEATED_DATA': 2}
    assert len(lines) == 1 and lines[0].startswith(
        'TF_REPEATED_DATA ignoring data with redundant timestamp for frame b (parent a)')


def test_a_peer_repeating_one_stamp_costs_no_scan_and_is_logged_at_a_bounded_rate():
    # 10 000 transforms of one frame at one stamp took 51 s (each insert scanned every
    # sample of the stamp) and logged nothing; now one sample is held, the rest counted
    lines = []
    core = BufferCore(log=lines.append)
    core.set_transform('world', 'other', S, (0, 0, 0, 0, 0, 0, 1))
    steps = []
    for k in range(10_000):
        steps.append(core.set_transform('world', 'peer', S, (k, 0, 0, 0, 0, 0, 1)))
    assert steps[0] and not any(steps[1:])
    assert len(core.caches[core.ids['peer']]) == 1
    assert core.refused['TF_REPEATED_DATA'] == 9999 and len(lines) == 1
    # (the bound on time is the benchmark's: bench_tf.py prints the inserts a second)


def test_refusals_are_logged_once_a_code_per_interval_with_their_count(monkeypatch):
    clock = [100.0]
    monkeypatch.setattr('dq_fk_ros.transforms.buffer_core._time.monotonic', lambda: clock[0])
    lines = []
    core = BufferCore(log=lines.append, log_every_s=10.0)
    for k in range(5):
        core.set_transform('a', 'a', S, (0, 0, 0, 0, 0, 0, 1))
        core.set_transform('a', 'b', S, (0, 0, 0, 0, 0, 0, 3))
    assert [line.split(':')[0] for line in lines] == ['TF_SELF_TRANSFORM',
                                                      'TF_DENORMALIZED_QUATERNION']
    clock[0] += 10.0
    core.set_transform('a', 'a', S, (0, 0, 0, 0, 0, 0, 1))
    assert lines[-1].startswith('TF_SELF_TRANSFORM') and lines[-1].endswith(
        '(6 refused so far)')
    assert core.refused == {'TF_SELF_TRANSFORM': 6, 'TF_DENORMALIZED_QUATERNION': 5}


def test_frame_ids_longer_than_the_bound_are_refused_and_not_held():
    lines = []
    core = BufferCore(log=lines.append)
    long_name = 'x' * (MAX_FRAME_ID + 1)
    for k in range(100):
        assert not core.set_transform('world', long_name + str(k), S, (0, 0, 0, 0, 0, 0, 1))
        assert not core.set_transform(long_name + str(k), 'base', S, (0, 0, 0, 0, 0, 0, 1))
    assert core.set_transform('world', 'y' * MAX_FRAME_ID, S, (0, 0, 0, 0, 0, 0, 1))
    assert core.frame_names() == ['y' * MAX_FRAME_ID, 'world']
    assert core.refused == {'TF_LONG_FRAME_ID': 200} and len(lines) == 1
    assert len(lines[0]) < 400


def test_interpolation_takes_the_short_way_round_and_sclerp_moves_along_the_screw():
    half = math.sqrt(0.5)
    for interpolation in ('slerp', 'sclerp'):
        core = BufferCore(interpolation=interpolation)
        core.set_transform('a', 'b', 0 * S + 1, (0, 0, 0, 0, 0, half, half))        # +90 deg z
        core.set_transform('a', 'b', 2 * S + 1, (0, 0, 0, 0, 0, -half, -half))      # same, -q
        pose, _ = core.lookup('a', 'b', S + 1)
        np.testing.assert_allclose(matrix(pose), matrix((0, 0, 0, 0, 0, half, half)),
                                   atol=1e-12)
    # a quarter turn about z, moving 1 m along z: the screw's midpoint is half of each
    core = BufferCore(interpolation='sclerp')
    core.set_transform('a', 'b', 1, (1, 0, 0, 0, 0, 0, 1))
    core.set_transform('a', 'b', 2 * S + 1, (0, 1, 1, 0, 0, half, half))
    pose, _ = core.lookup('a', 'b', S + 1)
    c, s = math.cos(math.pi / 8), math.sin(math.pi / 8)
    np.testing.assert_allclose(pose, (math.cos(math.pi / 4), math.sin(math.pi / 4), 0.5,
                                      0, 0, s, c), atol=1e-12)
    with pytest.raises(ValueError, match='interpolation must be one of'):
        BufferCore(interpolation='cubic')


def test_compose_and_inverse_agree_with_matrices():
    a, b = (1, 2, 3, 0.1, 0.2, 0.3, 0.9), (-1, 0.5, 2, -0.3, 0.1, 0.0, 0.8)
    na = np.linalg.norm(a[3:])
    nb = np.linalg.norm(b[3:])
    a = a[:3] + tuple(v / na for v in a[3:])
    b = b[:3] + tuple(v / nb for v in b[3:])
    np.testing.assert_allclose(matrix(compose(a, b)), matrix(a) @ matrix(b), atol=1e-12)
    np.testing.assert_allclose(matrix(inverse(a)), np.linalg.inv(matrix(a)), atol=1e-12)


def test_yaml_and_string_say_what_tf2s_say():
    core = BufferCore()
    core.set_transform('world', 'base', 0, (0, 0, 0, 0, 0, 0, 1), 'rsp', static=True)
    core.set_transform('base', 'arm', S, (0, 0, 0, 0, 0, 0, 1), 'node')
    core.set_transform('base', 'arm', 3 * S, (0, 0, 0, 0, 0, 0, 1), 'node')
    assert core.all_frames_as_string() == ('Frame base exists with parent world.\n'
                                           'Frame arm exists with parent base.\n')
    text = core.all_frames_as_yaml()
    assert "arm: \n  parent: 'base'\n  broadcaster: 'node'\n  rate: 1.000\n" in text
    assert 'most_recent_transform: 3.000000\n  oldest_transform: 1.000000\n' \
        '  buffer_length: 2.000' in text
    assert BufferCore().all_frames_as_yaml() == '[]'


@settings(max_examples=300, deadline=None)
@given(scenes())
def test_the_compiled_walk_is_the_reference(scene):
    """_tf.lookup (C) answers as BufferCore._walk, to the last bit, and fails where it fails."""
    from dq_fk_ros.transforms.buffer_core import COMPILED
    if COMPILED is None:
        pytest.fail('the C walk is not built (make setup builds it): nothing to compare')
    inserts, queries = scene
    core = BufferCore(cache_time_ns=100 * S)
    for parent, child, stamp, pose, static in inserts:
        core.set_transform(parent, child, stamp, pose, 'test', static)
    for target, source, t in queries:
        if target == source or target not in core.ids or source not in core.ids:
            continue
        ids = core.ids[target], core.ids[source]
        error, pose, used = core._walk(t if t else core.latest_common_time(*ids)[1],
                                       ids[0], ids[1], True)
        if t == 0 and core.latest_common_time(*ids)[0] is not None:
            error = core.latest_common_time(*ids)[0]
        found = COMPILED.lookup(core.caches, ids[0], ids[1], t)
        if error is not None:
            assert found is None, (target, source, t, found)
        else:
            assert found == (used,) + pose, (target, source, t)


def test_stamps_out_of_range_are_refused_and_times_out_of_range_are_tf2s_invalid_argument():
    lines = []
    core = BufferCore(log=lines.append, log_every_s=0)
    core.set_transform('a', 'b', S, (0, 0, 0, 0, 0, 0, 1))
    for stamp in (1 << 63, -(1 << 63) - 1, 2**200, 1.5):
        assert not core.set_transform('a', 'b', stamp, (0, 0, 0, 0, 0, 0, 1))
    assert len(lines) == 4 and all(line.startswith('TF_BAD_STAMP') for line in lines)
    assert core.set_transform('a', 'b', -5 * S, (0, 0, 0, 0, 0, 0, 1))   # negative: a time
    assert not core.set_transform('a', 'b', -10 * S, (0, 0, 0, 0, 0, 0, 1))   # 11 s old
    for time in (1 << 63, 2**100, -(1 << 64), 0.5):
        with pytest.raises(InvalidArgumentException, match='int64 nanoseconds'):
            core.lookup('a', 'b', time)
    assert core.lookup('a', 'b', S)[1] == S
