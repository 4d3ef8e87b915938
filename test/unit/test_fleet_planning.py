"""A fleet's planning without running it: which bags, where their outputs go, the windows."""

import os

from dq_fk_ros.bag.discover import find_bags
from dq_fk_ros.bag.windows import ChunkCounts, plan_windows
from dq_fk_ros.storage.reading import BagError
import numpy as np
import pytest


def bag_folder(path, storage='x.mcap'):
    os.makedirs(path)
    open(os.path.join(path, storage), 'w').close()


def test_bags_are_found_at_any_depth_and_keep_their_place(tmp_path):
    bag_folder(tmp_path / 'in' / 'site_a' / 'run_1')
    bag_folder(tmp_path / 'in' / 'site_a' / 'run_2', 'run_2.db3')
    bag_folder(tmp_path / 'in' / 'site_b' / 'deep' / 'run_1')
    (tmp_path / 'in' / 'site_b' / 'old.bag').write_bytes(b'#ROSBAG V2.0\n')
    (tmp_path / 'in' / 'notes.txt').write_text('not a bag')
    (tmp_path / 'in' / 'empty_folder').mkdir()
    bag_folder(tmp_path / 'single')
    found = find_bags([tmp_path / 'in', tmp_path / 'single'])
    assert [(b.name, os.path.relpath(b.path, tmp_path)) for b in found] == [
        ('single', 'single'),
        ('site_a/run_1', 'in/site_a/run_1'),
        ('site_a/run_2', 'in/site_a/run_2'),
        ('site_b/deep/run_1', 'in/site_b/deep/run_1'),
        ('site_b/old', 'in/site_b/old.bag')]


def test_a_bag_s_own_folders_are_not_bags_and_folder_links_are_not_followed(tmp_path):
    bag_folder(tmp_path / 'in' / 'run')
    bag_folder(tmp_path / 'in' / 'run' / 'inner')  # inside a bag: part of it
    os.symlink(tmp_path / 'in', tmp_path / 'in' / 'loop')  # a loop, not walked
    bag_folder(tmp_path / 'elsewhere' / 'secret')
    os.symlink(tmp_path / 'elsewhere', tmp_path / 'in' / 'out_of_tree')
    assert [b.name for b in find_bags([tmp_path / 'in'])] == ['run']


def test_two_bags_with_one_output_name_and_missing_paths_are_refused(tmp_path):
    bag_folder(tmp_path / 'a' / 'run')
    bag_folder(tmp_path / 'b' / 'run')
    with pytest.raises(BagError, match='would both be written to run'):
        find_bags([tmp_path / 'a' / 'run', tmp_path / 'b' / 'run'])
    with pytest.raises(BagError, match='no such bag or folder'):
        find_bags([tmp_path / 'nowhere'])


def counts(times, starts):
    times, starts = np.sort(np.array(times)), np.array(starts)
    return ChunkCounts(starts, np.searchsorted(times, starts), len(times))


def test_windows_start_at_chunk_starts_and_cover_every_message_once():
    times = np.arange(0, 1000, 1)                 # 1000 messages, one per ns
    starts = np.arange(0, 1000, 100)              # ten chunks of 100
    windows = plan_windows(counts(times, starts), 4)
    assert [(w.start_ns, w.stop_ns) for w in windows] == [
        (None, 200), (200, 500), (500, 700), (700, None)]  # nearest chunk starts to 250..
    assert [w.first_message for w in windows] == [0, 200, 500, 700]
    taken = [t for w in windows for t in times
             if (w.start_ns is None or t >= w.start_ns) and (w.stop_ns is None or t < w.stop_ns)]
    assert taken == list(times)                   # half-open: every message exactly once
    # the look-back: one chunk back, then two, four, eight... then the bag's start
    assert windows[3].lookback_ns == (600, 500, 300, None)
    assert windows[0].lookback_ns == (None,)


def test_a_bag_of_one_chunk_or_asked_for_one_window_is_whole():
    one = plan_windows(counts(range(50), [0]), 4)
    assert [(w.start_ns, w.stop_ns) for w in one] == [(None, None)]
    assert len(plan_windows(counts(range(1000), range(0, 1000, 100)), 1)) == 1
