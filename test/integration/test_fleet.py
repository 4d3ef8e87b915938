"""
dq_fk_bag on a fleet of bags: every output is the one-bag command's, message for message.

On a pool of processes, in windows of one large MCAP, and on a Dask LocalCluster; complete
outputs are skipped, a killed run is completed by the next, a bad bag stops none.
"""

import json
import os
import shutil
import signal
import subprocess
import sys
import time

from dq_fk_ros.bag.fleet import process_fleet
from dq_fk_ros.bag.process import process_bag, ProcessOptions
from dq_fk_ros.cli.dq_fk_bag import main as bag_main
from dq_fk_ros.description.schema import load_robot_description
from dq_fk_ros.description.shipped import shipped_robot_path
from dq_fk_ros.ros.executables import executable
from dq_fk_ros.testing import wait_until
import numpy as np
from proc_table import in_session, listening, proc_file, proc_stat, processes
import pytest
from rosbags.rosbag2 import Reader
from test_bag import js_bytes, NAMES, T0, trajectory, write_bag
from test_bag_hostile import write_ros1_bag

QUIET = ProcessOptions(progress=False)
DUAL_ARM = load_robot_description(shipped_robot_path('dual_arm'))


def messages(path):
    """Every message of a bag as read: (topic, log time, bytes), in order."""
    with Reader(path) as reader:
        return [(c.topic, t, bytes(raw)) for c, t, raw in reader.messages()]


def file_order(folder):
    """Every message of a bag's MCAP files in the order the files hold them (not by time)."""
    from mcap.reader import make_reader
    out = []
    for name in sorted(n for n in os.listdir(folder) if n.endswith('.mcap')):
        with open(os.path.join(folder, name), 'rb') as stream:
            out += [(channel.topic, message.log_time, message.data) for _, channel, message
                    in make_reader(stream).iter_messages(log_time_order=False)]
    return out


def rl15_bag(path, n, storage='mcap', offset=0.0):
    q = trajectory(n) + offset
    stamps = [T0 + k * 10_000_000 for k in range(n)]
    write_bag(path, [(s, js_bytes(NAMES, row, s)) for s, row in zip(stamps, q)], storage)


def serial(in_path, out_path, robot='rl15', **options):
    """Return the one-bag command's output, the reference of every fleet test."""
    os.makedirs(os.path.dirname(out_path), exist_ok=True)
    summary = process_bag(in_path, out_path, robot, progress=False, **options)
    assert summary.error is None
    return messages(out_path)


@pytest.fixture(scope='module')
def small_fleet(tmp_path_factory):
    """Five RL15 bags in nested folders, MCAP and sqlite3, and a ROS 1 bag file."""
    root = tmp_path_factory.mktemp('fleet') / 'in'
    for k, (rel, storage) in enumerate([('site_a/run_1', 'mcap'), ('site_a/run_2', 'sqlite3'),
                                        ('site_b/day_1/run_1', 'mcap'), ('site_b/run_9', 'mcap'),
                                        ('lone', 'sqlite3')]):
        (root / rel).parent.mkdir(parents=True, exist_ok=True)
        rl15_bag(root / rel, 200 + 50 * k, storage, offset=0.01 * k)
    write_ros1_bag(root / 'site_b' / 'old.bag', 120)
    return root


def test_many_bags_on_two_workers_equal_the_one_bag_command(small_fleet, tmp_path):
    summary = process_fleet([small_fleet], tmp_path / 'out', 'rl15', QUIET, jobs=2,
                            progress=False)
    names = [b.bag for b in summary.bags]
    assert names == ['lone', 'site_a/run_1', 'site_a/run_2', 'site_b/day_1/run_1',
                     'site_b/old', 'site_b/run_9']
    assert summary.failed == 0 and summary.workers == 2
    for bag in summary.bags:
        source = small_fleet / (bag.bag + '.bag' if bag.bag == 'site_b/old' else bag.bag)
        expected = serial(source, tmp_path / 'serial' / bag.bag)
        assert messages(tmp_path / 'out' / bag.bag) == expected, bag.bag
        assert bag.messages_in == sum(t == '/tf' for t, _, _ in expected) == bag.tf_out


def tree_bag(path, n=30_000):
    """
    Write a dual-arm MCAP of several publishers, large enough for several chunks.

    Torso and left arm every message; the right arm every third; the gripper once, near the
    start: every window after the first starts from a joint value only the look-back sees.
    """
    rng = np.random.default_rng(3)
    left = ['waist', 'left_shoulder_pitch', 'left_elbow', 'left_wrist_roll']
    right = ['right_shoulder_pitch', 'right_elbow', 'right_wrist_roll']
    out = []
    for k in range(n):
        stamp = T0 + k * 1_000_000
        out.append((stamp, js_bytes(left, 0.3 * np.sin(k * 1e-3 + np.arange(4)), stamp)))
        if k % 3 == 0:
            out.append((stamp + 1, js_bytes(right, rng.uniform(-0.5, 0.5, 3), stamp + 1)))
        if k == 5:
            out.append((stamp + 2, js_bytes(['left_gripper'], [0.02], stamp + 2)))
    write_bag(path, out)
    return out


def test_one_large_mcap_in_windows_equals_the_serial_run(tmp_path):
    """Windows: the tree's gated /tf, a joint only seen before a window, the boundaries."""
    tree_bag(tmp_path / 'in' / 'big')
    expected = serial(tmp_path / 'in' / 'big', tmp_path / 'serial', str(
        shipped_robot_path('dual_arm')), frame_prefix='r1/')
    options = ProcessOptions(progress=False, frame_prefix='r1/')
    summary = process_fleet([tmp_path / 'in' / 'big'], tmp_path / 'out',
                            str(shipped_robot_path('dual_arm')), options, jobs=2,
                            progress=False, window_messages=5_000)
    bag = summary.bags[0]
    assert summary.failed == 0 and bag.units >= 4, bag
    out = tmp_path / 'out' / 'big'
    files = sorted(n for n in os.listdir(out) if n.endswith('.mcap'))
    assert len(files) == bag.units
    got = messages(out)
    assert len(got) == len(expected) and got == expected
    # the same, read with Foxglove's mcap library (an independent reader) file by file
    serial_order = file_order(tmp_path / 'serial')
    assert sorted(file_order(out), key=lambda m: m[1]) == sorted(serial_order,
                                                                 key=lambda m: m[1])
    # every window after the first starts exactly at the first message of a file, and the
    # gripper finger's transform is in the first /tf of every window
    starts = []
    for name in files:
        with Reader(out / name) as reader:  # one file of the split bag, alone
            first = next(iter(reader.messages()))
            starts.append(first[1])
    assert starts == sorted(starts) and len(set(starts)) == len(starts)
    tf_times = [t for topic, t, _ in expected if topic == '/tf']
    assert all(s in tf_times for s in starts)
    from rosbags.typesys import get_typestore, Stores
    ts = get_typestore(Stores.ROS2_JAZZY)
    for s in starts[1:]:
        raw = next(r for topic, t, r in got if topic == '/tf' and t == s)
        children = [t.child_frame_id for t in ts.deserialize_cdr(
            raw, 'tf2_msgs/msg/TFMessage').transforms]
        assert 'r1/left_finger_b' in children and 'r1/right_forearm' in children


def test_a_dask_local_cluster_gives_what_the_pool_gives(small_fleet, tmp_path):
    pool = process_fleet([small_fleet], tmp_path / 'pool', 'rl15', QUIET, jobs=2,
                         progress=False)
    dask = process_fleet([small_fleet], tmp_path / 'dask', 'rl15', QUIET, jobs=2,
                         scheduler='local', progress=False)
    assert dask.failed == pool.failed == 0 and dask.workers == 2
    for bag in pool.bags:
        assert messages(tmp_path / 'dask' / bag.bag) == messages(tmp_path / 'pool' / bag.bag)


def test_complete_outputs_are_skipped_and_changed_or_missing_ones_redone(tmp_path):
    for k in range(3):
        rl15_bag(tmp_path / 'in' / f'b{k}', 100 + k)
    out = tmp_path / 'out'
    first = process_fleet([tmp_path / 'in'], out, 'rl15', QUIET, jobs=1, progress=False)
    assert [b.status for b in first.bags] == ['done'] * 3
    again = process_fleet([tmp_path / 'in'], out, 'rl15', QUIET, jobs=1, progress=False)
    assert [b.status for b in again.bags] == ['skipped'] * 3
    shutil.rmtree(out / 'b1')
    shutil.rmtree(tmp_path / 'in' / 'b2')
    rl15_bag(tmp_path / 'in' / 'b2', 140, offset=0.2)  # a changed input
    third = process_fleet([tmp_path / 'in'], out, 'rl15', QUIET, jobs=1, progress=False)
    assert [b.status for b in third.bags] == ['skipped', 'done', 'done']
    assert third.bags[2].messages_in == 140
    assert messages(out / 'b2') == serial(tmp_path / 'in' / 'b2', tmp_path / 's2')
    forced = process_fleet([tmp_path / 'in'], out, 'rl15', QUIET, jobs=1, progress=False,
                           force=True)
    assert [b.status for b in forced.bags] == ['done'] * 3
    other = process_fleet([tmp_path / 'in'], out, 'rl15', ProcessOptions(
        progress=False, poses='none'), jobs=1, progress=False)  # other options: redone
    assert [b.status for b in other.bags] == ['done'] * 3


def _processes_marked(mark):
    """Return the pids of the processes whose environment holds ``mark`` (left behind)."""
    return processes(lambda pid: mark.encode() in proc_file(pid, 'environ'))


def _spawned_by(parent):
    """Return the pids of the processes ``parent`` started with multiprocessing's spawn."""
    return processes(lambda pid: b'spawn_main' in proc_file(pid, 'cmdline') and int(
        proc_stat(pid)[1]) == parent)


def _kill_all_but_the_tracker(pgid):
    """
    SIGKILL the process group ``pgid`` but multiprocessing's resource tracker.

    The tracker outlives them and removes the pool's semaphores (``/dev/shm/sem.mp-*``);
    killed too, it would leave them there, six a run.
    """
    for pid in processes(lambda pid: os.getpgid(pid) == pgid and (
            b'resource_tracker import main' not in proc_file(pid, 'cmdline'))):
        try:
            os.kill(pid, signal.SIGKILL)
        except ProcessLookupError:
            pass


def _wait_for_work(out, timeout_s=60):
    """Wait until a fleet writing ``out`` has an output bag under way (an MCAP in its work)."""
    wait_until(lambda: _has_work(out), timeout_s)


def test_a_local_cluster_listens_on_loopback_only_and_on_no_fixed_port(tmp_path):
    """Dask's scheduler serves HTTP on 8787 unless told: held here, that printed a warning."""
    import socket
    for k in range(2):
        rl15_bag(tmp_path / 'in' / f'b{k}', 40_000, offset=0.1 * k)
    holder = socket.socket()
    try:
        holder.bind(('127.0.0.1', 8787))  # (if another program has it: taken all the same)
        holder.listen()
    except OSError:
        pass
    child = subprocess.Popen(
        executable('dq_fk_bag') + ['process', str(tmp_path / 'in'), '--output-dir',
                                   str(tmp_path / 'out'), '--robot', 'rl15', '--jobs', '2',
                                   '--scheduler', 'local', '--quiet'],
        start_new_session=True, stdout=subprocess.PIPE, stderr=subprocess.STDOUT)
    seen, deadline = set(), time.monotonic() + 120
    try:
        while child.poll() is None and time.monotonic() < deadline:
            seen |= listening(in_session(child.pid))
            time.sleep(0.05)
    finally:
        holder.close()
        if child.poll() is None:
            os.killpg(child.pid, signal.SIGKILL)
        output = child.communicate()[0].decode()
    assert child.returncode == 0 and 'Warning' not in output, output
    assert seen and all(address == '0100007F' for address, _ in seen), seen
    assert 8787 not in {port for _, port in seen}


def test_a_run_killed_mid_bag_is_completed_by_the_next(tmp_path):
    for k in range(2):
        rl15_bag(tmp_path / 'in' / f'b{k}', 40_000, offset=0.1 * k)
    out = tmp_path / 'out'
    argv = executable('dq_fk_bag') + ['process', str(tmp_path / 'in'), '--output-dir',
                                      str(out), '--robot', 'rl15', '--jobs', '2', '--quiet']
    child = subprocess.Popen(argv, start_new_session=True, stdout=subprocess.DEVNULL,
                             stderr=subprocess.DEVNULL)
    _wait_for_work(out)
    _kill_all_but_the_tracker(child.pid)  # the command and its workers, mid-bag
    child.wait()
    assert not (out / 'b0').exists() or not (out / 'b1').exists()
    summary = process_fleet([tmp_path / 'in'], out, 'rl15', QUIET, jobs=2, progress=False)
    assert summary.failed == 0
    for k in range(2):
        assert messages(out / f'b{k}') == serial(tmp_path / 'in' / f'b{k}', tmp_path / f's{k}')


@pytest.mark.parametrize('how', ['pool', 'local'])
def test_the_command_killed_alone_leaves_no_worker_behind(tmp_path, how):
    """
    SIGKILL to the command only (the OOM killer's choice, say): its workers follow it.

    A pool worker waiting for work holds both ends of its queue's pipe, so it would wait for
    ever; each watches its parent instead, and exits within a second of it.
    """
    rl15_bag(tmp_path / 'in' / 'b0', 40_000)
    rl15_bag(tmp_path / 'in' / 'b1', 40_000, offset=0.1)
    mark = f'dq_fk_orphan_test_{os.getpid()}_{how}'
    out = tmp_path / 'out'
    argv = executable('dq_fk_bag') + ['process', str(tmp_path / 'in'), '--output-dir',
                                      str(out), '--robot', 'rl15', '--jobs', '2', '--quiet']
    argv += ['--scheduler', 'local'] if how == 'local' else []
    child = subprocess.Popen(argv, start_new_session=True, stdout=subprocess.DEVNULL,
                             stderr=subprocess.DEVNULL, env=dict(os.environ, DQ_FK_MARK=mark))
    try:
        _wait_for_work(out)
        workers = [pid for pid in _processes_marked(mark) if pid != child.pid]
        os.kill(child.pid, signal.SIGKILL)
        child.wait()
        assert workers, 'no worker process seen'
        wait_until(lambda: not _processes_marked(mark), 3.0)
        left = _processes_marked(mark)
    finally:
        for pid in _processes_marked(mark):
            os.kill(pid, signal.SIGKILL)
    assert left == [], left


def test_a_worker_killed_mid_bag_is_run_again(tmp_path, monkeypatch):
    """The pool loses a worker (the OOM killer, say): its unit runs once more."""
    from dq_fk_ros.bag import fleet
    for k in range(2):
        rl15_bag(tmp_path / 'in' / f'b{k}', 300)
    monkeypatch.setattr(fleet, 'run_unit', _die_once)
    monkeypatch.setenv('DQ_FK_TEST_DIE_ONCE', str(tmp_path / 'died'))
    summary = process_fleet([tmp_path / 'in'], tmp_path / 'out', 'rl15', QUIET, jobs=2,
                            progress=False)
    assert (tmp_path / 'died').exists() and summary.failed == 0
    for k in range(2):
        assert messages(tmp_path / 'out' / f'b{k}') == serial(tmp_path / 'in' / f'b{k}',
                                                              tmp_path / f's{k}')


def _die_once(unit):
    """Kill this worker process the first time any unit is run (a file marks it)."""
    from dq_fk_ros.bag.fleet import run_unit
    marker = os.environ['DQ_FK_TEST_DIE_ONCE']
    if not os.path.exists(marker):
        open(marker, 'w').close()
        os.kill(os.getpid(), signal.SIGKILL)
    return run_unit(unit)


def test_bad_bags_stop_none_of_the_others(tmp_path, capsys):
    """Damaged, empty, misnamed, another robot's: each reported; the rest done; exit 1."""
    fleet = tmp_path / 'in'
    rl15_bag(fleet / 'good', 150)
    write_ros1_bag(fleet / 'old.bag', 80)
    rl15_bag(fleet / 'damaged', 3000)
    mcap = fleet / 'damaged' / 'damaged.mcap'
    data = bytearray(mcap.read_bytes())
    data[len(data) // 3:len(data) // 3 + 4000] = b'\xff' * 4000
    mcap.write_bytes(bytes(data))
    write_bag(fleet / 'empty', [])
    (fleet / 'misnamed').mkdir()
    (fleet / 'misnamed' / 'misnamed.mcap').write_text('a text file, not an MCAP')
    write_bag(fleet / 'other_robot', [(T0 + k, js_bytes(['wheel_left', 'wheel_right'],
                                                        [0.1, 0.2], T0 + k)) for k in range(20)])
    report = tmp_path / 'report.json'
    rc = bag_main(['process', str(fleet), '--output-dir', str(tmp_path / 'out'), '--robot',
                   'rl15', '--jobs', '2', '--report', str(report), '--quiet'])
    out = capsys.readouterr().out
    assert rc == 1
    data = json.loads(report.read_text())
    bags = {b['bag']: b for b in data['bags']}
    assert {k: b['status'] for k, b in bags.items()} == {
        'damaged': 'failed', 'empty': 'failed', 'good': 'done', 'misnamed': 'failed',
        'old': 'done', 'other_robot': 'failed'}
    assert 'is damaged' in bags['damaged']['problems'][0]
    assert 'has 0 messages' in bags['empty']['problems'][0]
    assert 'wheel_left' in bags['other_robot']['problems'][0]
    assert 'misnamed' in bags['misnamed']['problems'][0]
    for name in ('damaged', 'empty', 'misnamed', 'other_robot'):
        assert not (tmp_path / 'out' / name).exists()  # partial output removed
    assert messages(tmp_path / 'out' / 'good') == serial(fleet / 'good', tmp_path / 's')
    for line in out.splitlines()[1:7]:
        name = line.split()[0]
        assert name in bags
    assert '6 bags: 2 done, 0 skipped, 4 failed' in out


def test_fleet_usage_errors_are_one_line_and_exit_2(tmp_path, capsys):
    rl15_bag(tmp_path / 'in' / 'a', 20)
    cases = [
        (['process', str(tmp_path / 'in'), '--output-dir', str(tmp_path / 'in' / 'o'),
          '--robot', 'rl15'], 'inside the input'),
        (['process', str(tmp_path / 'in'), '--output-dir', str(tmp_path / 'o'), '--robot',
          'rl15', '--csv', 'x.csv'], '--csv is for one bag'),
        (['process', str(tmp_path / 'in'), '--output-dir', str(tmp_path / 'o'), '--robot',
          'rl15', '--jobs', '0'], '--jobs must be at least 1'),
        (['process', str(tmp_path / 'in'), str(tmp_path / 'x'), str(tmp_path / 'y'),
          '--robot', 'rl15'], 'process takes IN_BAG OUT_BAG'),
        (['process', str(tmp_path / 'in' / 'a'), str(tmp_path / 'x'), '--robot', 'rl15',
          '--jobs', '2'], '--jobs is for a fleet of bags'),
        (['process', str(tmp_path / 'nowhere'), '--output-dir', str(tmp_path / 'o'),
          '--robot', 'rl15'], 'no such bag or folder'),
        (['process', str(tmp_path / 'in'), '--output-dir', str(tmp_path / 'o'), '--robot',
          'no_such_robot'], 'no_such_robot'),
        (['process', str(tmp_path / 'in'), '--output-dir', str(tmp_path / 'o'), '--robot',
          'rl15', '--scheduler', 'not-an-address'], 'cannot reach the scheduler'),
    ]
    for argv, says in cases:
        rc = bag_main(argv)
        err = capsys.readouterr().err
        assert rc == 2 and says in err and err.count('\n') == 1, (argv, err)


def test_without_dask_the_message_says_how_to_get_it(tmp_path, monkeypatch, capsys):
    rl15_bag(tmp_path / 'in' / 'a', 20)
    monkeypatch.setitem(sys.modules, 'distributed', None)  # as if not installed
    rc = bag_main(['process', str(tmp_path / 'in'), '--output-dir', str(tmp_path / 'o'),
                   '--robot', 'rl15', '--scheduler', 'local'])
    err = capsys.readouterr().err
    assert rc == 2 and "pip install 'dq_fk_ros[cluster]'" in err


def test_a_bag_named_as_the_fleet_state_is_refused_and_the_state_kept(tmp_path, capsys):
    rl15_bag(tmp_path / 'in' / 'run', 30)
    out = tmp_path / 'out'
    assert bag_main(['process', str(tmp_path / 'in'), '--output-dir', str(out), '--robot',
                     'rl15', '--jobs', '1', '--quiet']) == 0
    manifest = (out / '.dq_fk_fleet' / 'manifest.json').read_bytes()
    rl15_bag(tmp_path / 'in' / '.dq_fk_fleet', 30)  # would be written over the state folder
    capsys.readouterr()
    for argv in ([str(tmp_path / 'in')], [str(tmp_path / 'in' / '.dq_fk_fleet')]):
        rc = bag_main(['process', *argv, '--output-dir', str(out), '--robot', 'rl15',
                       '--jobs', '1', '--quiet'])
        err = capsys.readouterr().err
        assert rc == 2 and err.count('\n') == 1 and 'state folder' in err, err
        assert (out / '.dq_fk_fleet' / 'manifest.json').read_bytes() == manifest
    assert messages(out / 'run') == serial(tmp_path / 'in' / 'run', tmp_path / 's')


@pytest.mark.parametrize('content', [
    b'{"version":1,"bags":{"run":"x"}}', b'[1,2]', b'null', b'[' * 100_000, b'\xff\xfe\x00',
    b'{"version":1,"bags":{"run":{"input":{},"options":"","output":{}}}}',
    b'{"version":2,"bags":{}}', b''],
    ids=['entry', 'list', 'null', 'nested', 'binary', 'hollow', 'version', 'empty'])
def test_a_manifest_the_fleet_did_not_write_is_set_aside_and_the_work_redone(
        tmp_path, capsys, content):
    rl15_bag(tmp_path / 'in' / 'run', 30)
    out = tmp_path / 'out'
    args = ['process', str(tmp_path / 'in'), '--output-dir', str(out), '--robot', 'rl15',
            '--jobs', '1', '--quiet']
    assert bag_main(args) == 0
    state = out / '.dq_fk_fleet'
    (state / 'manifest.json').write_bytes(content)
    capsys.readouterr()
    assert bag_main(args) == 0
    captured = capsys.readouterr()
    notes = [line for line in captured.err.splitlines() if 'set aside' in line]
    assert len(notes) == 1 and 'Traceback' not in captured.err, captured.err
    aside = [p.name for p in state.iterdir() if p.name.startswith('manifest.json.set-aside-')]
    assert len(aside) == 1 and (state / aside[0]).read_bytes() == content
    assert ' 1 done, 0 skipped' in captured.out  # redone, not taken as complete
    assert messages(out / 'run') == serial(tmp_path / 'in' / 'run', tmp_path / 's')
    assert bag_main(args) == 0  # and the manifest written again is the fleet's own
    assert ' 0 done, 1 skipped' in capsys.readouterr().out


def test_a_bag_named_twice_is_processed_once(tmp_path, capsys):
    rl15_bag(tmp_path / 'in' / 'run', 30)
    out = tmp_path / 'out'
    for argv in ([str(tmp_path / 'in' / 'run')] * 2,
                 [str(tmp_path / 'in'), str(tmp_path / 'in' / 'run')],
                 [str(tmp_path / 'in' / 'run'), str(tmp_path / 'in' / '..' / 'in' / 'run')]):
        rc = bag_main(['process', *argv, '--output-dir', str(out), '--robot', 'rl15',
                       '--jobs', '2', '--quiet', '--force'])
        captured = capsys.readouterr()
        assert rc == 0 and captured.err == '', captured.err
        assert '1 bags: 1 done' in captured.out
    assert messages(out / 'run') == serial(tmp_path / 'in' / 'run', tmp_path / 's')


def _mcap_bytes(folder):
    return {p.name: p.read_bytes() for p in sorted(folder.rglob('*.mcap'))}


@pytest.fixture(scope='module')
def signal_fleet(tmp_path_factory):
    """Two RL15 bags large enough that a run takes seconds, and their uninterrupted output."""
    root = tmp_path_factory.mktemp('signals')
    for k in range(2):
        rl15_bag(root / 'in' / f'b{k}', 60_000, offset=0.1 * k)
    assert bag_main(['process', str(root / 'in'), '--output-dir', str(root / 'reference'),
                     '--robot', 'rl15', '--jobs', '1', '--quiet']) == 0
    return root


def _has_work(out):
    return any(name.endswith('.mcap') for _, _, names in os.walk(out / '.dq_fk_fleet' / 'work')
               for name in names)


def _importing_the_package(pid):
    """Whether ``pid`` has mapped one of the package's C extensions (its imports under way)."""
    try:
        maps = proc_file(pid, 'maps')
    except OSError:   # it has ended
        return False
    return any(b'/dq_fk_ros/' in line and b'.so' in line for line in maps.splitlines())


# the moments a signal is sent at, each an event seen from outside (never a delay): while
# the package is imported (Python itself started: a Ctrl-C while CPython starts is a "Fatal
# Python error" of CPython's own, whatever the program), once the output folder is made,
# once a worker process exists (not in a serial run), once an output bag is under way, once
# a bag is done
MOMENTS = {
    'importing': lambda child, out: _importing_the_package(child.pid),
    'planned': lambda child, out: (out / '.dq_fk_fleet').is_dir(),
    'workers': lambda child, out: bool(_spawned_by(child.pid)),
    'writing': lambda child, out: _has_work(out),
    'one-done': lambda child, out: any((out / f'b{k}' / 'metadata.yaml').exists()
                                       for k in range(2)),
}


@pytest.mark.parametrize('how', ['pool', 'serial', 'local'])
@pytest.mark.parametrize('signum', [signal.SIGINT, signal.SIGTERM], ids=['SIGINT', 'SIGTERM'])
def test_a_signal_at_any_moment_exits_quietly_and_a_new_run_resumes(signal_fleet, tmp_path,
                                                                    how, signum):
    """
    Exit quietly on Ctrl-C or SIGTERM before, while and after the workers start.

    Ctrl-C goes to the whole process group (as a terminal sends it), SIGTERM to the command
    alone (as a supervisor does): exit 130 (143) or 0 if it was done, no traceback, no process
    left; the next run's outputs are byte-identical. Each signal is sent when an event of
    :data:`MOMENTS` is seen; the run that had ended first (exit 0) has nothing to check.
    """
    out = tmp_path / 'out'
    extra = {'pool': ['--jobs', '2'], 'serial': ['--jobs', '1'],
             'local': ['--scheduler', 'local', '--jobs', '2']}[how]
    argv = executable('dq_fk_bag') + ['process', str(signal_fleet / 'in'), '--output-dir',
                                      str(out), '--robot', 'rl15', '--quiet'] + extra
    for moment, reached in MOMENTS.items():
        if moment == 'workers' and how == 'serial':
            continue
        mark = f'dq_fk_signal_test_{os.getpid()}_{how}_{signum}_{moment}'
        child = subprocess.Popen(argv, start_new_session=True, stdout=subprocess.PIPE,
                                 stderr=subprocess.PIPE, env=dict(os.environ, DQ_FK_MARK=mark))
        try:
            assert wait_until(lambda: reached(child, out) or child.poll() is not None, 60,
                              every_s=0.002), f'{moment}: not reached in 60 s'
            try:   # (the run may have ended meanwhile)
                if signum == signal.SIGINT:
                    os.killpg(child.pid, signum)
                else:
                    os.kill(child.pid, signum)
            except ProcessLookupError:
                pass
            _, err = child.communicate(timeout=20)   # the deadline: a hang fails here
        finally:
            if child.poll() is None:
                os.killpg(child.pid, signal.SIGKILL)
        wait_until(lambda: not _processes_marked(mark), 10)
        left = _processes_marked(mark)
        for pid in left:
            os.kill(pid, signal.SIGKILL)
        err = err.decode(errors='replace')
        if child.returncode == 0:  # the run was over before the signal: nothing to check
            continue
        # while importing, SIGTERM may come before the program's handler is set, when the
        # system's default ends the process by the signal (no output: nothing ran yet)
        early = moment == 'importing' and signum == signal.SIGTERM
        allowed = {128 + signum} | ({-signum} if early else set())
        assert child.returncode in allowed, (moment, child.returncode, err[-2000:])
        assert left == [], (moment, left)
        assert 'Traceback' not in err and 'Warning' not in err, (moment, err[-2000:])
        assert err.count('\n') <= 1, (moment, err[-2000:])  # the one line, if any
    assert bag_main(['process', str(signal_fleet / 'in'), '--output-dir', str(out),
                     '--robot', 'rl15', '--jobs', '2', '--quiet']) == 0
    for k in range(2):
        assert _mcap_bytes(out / f'b{k}') == _mcap_bytes(signal_fleet / 'reference' / f'b{k}')


# Put on PYTHONPATH for the command alone (DQ_FK_SLOW_START set): every spawned worker's
# process starts 0.3 s before its start-up data is written to it (a busy machine's
# scheduling, made certain), so a signal lands in that gap
SLOW_START = """
import os
import time
if os.environ.pop('DQ_FK_SLOW_START', None):
    from multiprocessing import util
    spawnv_passfds = util.spawnv_passfds

    def slow_spawnv_passfds(path, args, passfds):
        pid = spawnv_passfds(path, args, passfds)
        if any('spawn_main' in str(arg) for arg in args):
            time.sleep(0.3)
        return pid
    util.spawnv_passfds = slow_spawnv_passfds
"""


@pytest.mark.parametrize('how', ['pool', 'local'])
def test_a_signal_while_a_worker_starts_leaves_no_traceback(signal_fleet, tmp_path, how):
    """
    SIGTERM between a worker's process starting and its start-up data being written.

    Dask starts its workers from its own threads: the command exiting there left the worker
    reading a closed pipe, which printed an ``EOFError`` traceback (seen once in CI).
    """
    (tmp_path / 'site').mkdir()
    (tmp_path / 'site' / 'sitecustomize.py').write_text(SLOW_START)
    mark = f'dq_fk_slow_start_test_{os.getpid()}_{how}'
    env = dict(os.environ, DQ_FK_MARK=mark, DQ_FK_SLOW_START='1',
               PYTHONPATH=os.pathsep.join([str(tmp_path / 'site')]
                                          + os.environ.get('PYTHONPATH', '').split(os.pathsep)))
    extra = {'pool': ['--jobs', '2'], 'local': ['--scheduler', 'local', '--jobs', '2']}[how]
    argv = executable('dq_fk_bag') + ['process', str(signal_fleet / 'in'), '--output-dir',
                                      str(tmp_path / 'out'), '--robot', 'rl15', '--quiet'] + extra
    child = subprocess.Popen(argv, start_new_session=True, stdout=subprocess.PIPE,
                             stderr=subprocess.PIPE, env=env)
    try:
        assert wait_until(lambda: _spawned_by(child.pid) or child.poll() is not None, 30,
                          every_s=0.002), 'no worker started within 30 s'
        try:
            os.kill(child.pid, signal.SIGTERM)
        except ProcessLookupError:   # it ended first: checked below (its exit code)
            pass
        _, err = child.communicate(timeout=20)   # the deadline: a hang fails here
    finally:
        if child.poll() is None:
            os.killpg(child.pid, signal.SIGKILL)
    wait_until(lambda: not _processes_marked(mark), 10)
    left = _processes_marked(mark)
    for pid in left:
        os.kill(pid, signal.SIGKILL)
    err = err.decode(errors='replace')
    assert child.returncode == 128 + signal.SIGTERM, (child.returncode, err[-2000:])
    assert 'Traceback' not in err and err.count('\n') <= 1, err[-2000:]
    assert left == [], left


@pytest.mark.parametrize('metadata', [
    b'rosbag2_bagfile_information: {topics_with_message_count: [',  # not YAML
    b'rosbag2_bagfile_information:\n' + b'  ' + b'[' * 2000 + b']' * 2000 + b'\n',  # deep
    b'# ' + b'x' * (17 << 20) + b'\n',  # the same, but larger than any rosbag2 writes
], ids=['not-yaml', 'nested', 'huge'])
def test_a_damaged_earlier_output_is_redone_not_a_crash(tmp_path, metadata):
    rl15_bag(tmp_path / 'in' / 'b0', 100)
    out = tmp_path / 'out'
    first = process_fleet([tmp_path / 'in'], out, 'rl15', QUIET, jobs=1, progress=False)
    assert [b.status for b in first.bags] == ['done']
    path = out / 'b0' / 'metadata.yaml'
    path.write_bytes(path.read_bytes() + metadata if metadata.startswith(b'#') else metadata)
    again = process_fleet([tmp_path / 'in'], out, 'rl15', QUIET, jobs=1, progress=False)
    assert [b.status for b in again.bags] == ['done']
    assert messages(out / 'b0') == serial(tmp_path / 'in' / 'b0', tmp_path / 's0')
