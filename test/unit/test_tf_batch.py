"""Many lookups at once (dq_fk_ros.transforms.batch) equal to one lookup per stamp."""

from dq_fk_ros.transforms.batch import lookup_poses
from dq_fk_ros.transforms.buffer_core import BufferCore
from dq_fk_ros.transforms.exceptions import TransformException
from hypothesis import given, settings, strategies as st
import numpy as np
from test_tf_buffer_core import matrix, S, scenes


@settings(max_examples=200, deadline=None)
@given(scenes(), st.lists(st.integers(0, 6 * S), min_size=1, max_size=40))
def test_lookup_poses_answers_what_lookup_answers_at_each_stamp(scene, stamps):
    inserts, queries = scene
    core = BufferCore(cache_time_ns=100 * S)
    for parent, child, stamp, pose, static in inserts:
        core.set_transform(parent, child, stamp, pose, 'test', static)
    stamps = stamps + [k * S // 2 for k in range(1, 11)]   # every sample's own stamp too
    for target, source, _ in queries:
        rows = lookup_poses(core, target, source, stamps)
        assert rows.shape == (len(stamps), 7)
        for row, stamp in zip(rows, stamps):
            try:
                expected = core.lookup(target, source, stamp)[0]
            except TransformException:
                assert np.isnan(row).all(), (target, source, stamp, row)
                continue
            np.testing.assert_allclose(matrix(row), matrix(expected), atol=1e-12,
                                       err_msg=str((target, source, stamp)))


def test_a_hundred_thousand_stamps_of_a_moving_chain():
    core = BufferCore(cache_time_ns=1000 * S)
    for k in range(1001):
        a = k * 0.01
        core.set_transform('world', 'base', k * S // 10, (a, 0, 0, 0, 0, np.sin(a / 2),
                                                          np.cos(a / 2)))
        core.set_transform('base', 'tool', k * S // 10, (0, 1, 0, np.sin(a / 2), 0, 0,
                                                         np.cos(a / 2)))
    stamps = np.linspace(0, 100 * S, 100_000).astype(np.int64)
    rows = lookup_poses(core, 'world', 'tool', stamps)
    assert not np.isnan(rows).any()
    for at in (0, 1, 50_000, 99_999):
        np.testing.assert_allclose(matrix(rows[at]),
                                   matrix(core.lookup('world', 'tool', int(stamps[at]))[0]),
                                   atol=1e-12)
    assert np.isnan(lookup_poses(core, 'world', 'tool', [101 * S])).all()
