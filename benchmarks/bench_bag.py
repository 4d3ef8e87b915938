"""
Offline bag processing speed and memory: ``dq_fk_bag process`` end to end (read, FK, write).

Writes a 6-DoF RL15 JointState bag of N messages (MCAP) into a temporary folder, then runs
``dq_fk_bag process`` on it in a child process for each case and prints messages per second
and the child's peak resident memory. A case is ``STORAGE:POSES:INPUT[:COMPRESSION]``: the
output storage (mcap, sqlite3), the pose topics written (all frames, the end effector only,
none: /tf only), the input (``full``: every message names all six joints; ``split``: two
publishers alternate, three joints each, so every message merges with the one before) and
the output's chunk compression (none by default; zstd, lz4). Several bag lengths show whether
memory grows with the bag.

The floor, in the same run on the same input (issue "Bags at the reading floor"): rosbags'
bare read (``AnyReader.messages()``, every message, nothing done with it) and the ``mcap``
library's bare ``iter_messages``, each a whole command as ``dq_fk_bag process`` is. The
two reads and the three ``dq_fk_bag process`` cases run in ``--repeat`` rounds (at least
5), every command once a round (round robin: a slow minute of this machine slows them
alike), each its best round taken; the ratios of ``dq_fk_bag process`` (every pose topic,
MCAP out) to both are printed with their targets (<= 0.7x and <= 0.3x), and the reference
reader's (``--reference-reader``) beside it.

Each child runs on one CPU (its affinity set to the first this process may use); an output
left by the previous case is removed before the clock starts. The package's modules are
compiled to bytecode first, as pip does when it installs a package (an editable install
leaves that to the first import, which skips writing them under PYTHONDONTWRITEBYTECODE:
then every command would compile ~40 modules, ~80 ms, that no installed copy compiles).

Run: ``python benchmarks/bench_bag.py [--messages 100000 300000 1000000] [--cases ...]``.
"""

import argparse
import compileall
import os
import shutil
import subprocess
import sys
import tempfile
import time

from bench_results import figure
import dq_fk_ros
from dq_fk_ros.ros.executables import executable
import numpy as np
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import get_typestore, Stores

CASES = ['mcap:all:full', 'mcap:end:full', 'mcap:none:full', 'sqlite3:all:full',
         'mcap:all:split', 'mcap:all:full:zstd', 'mcap:all:full:lz4']
RATIO_MESSAGES = 300_000     # the figure: a bag of this many JointStates
FLOOR_ROUNDS = 5             # rounds of the floor and the ratios, at least
# the floor's commands: the same input read and nothing done with it
ROSBAGS_READ = """
import sys
from pathlib import Path
from rosbags.highlevel import AnyReader
n = 0
with AnyReader([Path(sys.argv[1])]) as reader:
    for _ in reader.messages():
        n += 1
print(n)
"""
# what writing the output costs before anything is computed: its bytes, from one 1 MiB
# block, written and CRC-32ed as the writer does a chunk
WRITE_FLOOR = """
import sys
from dq_fk_ros.storage.crc import crc32   # the writer's (zlib-ng's where installed)
block, left = bytes(range(256)) * 4096, int(sys.argv[2])
with open(sys.argv[1], 'wb') as f:
    while left > 0:
        part = block[:left]
        crc32(part)
        f.write(part)
        left -= len(part)
"""
MCAP_READ = """
import glob, sys
from mcap.reader import make_reader
n = 0
for path in sorted(glob.glob(sys.argv[1] + '/*.mcap')):
    with open(path, 'rb') as f:
        for _ in make_reader(f).iter_messages():
            n += 1
print(n)
"""


def write_joint_state_bag(path, n, split=False):
    """
    Write a bag of ``n`` RL15 joint states at 1 kHz along a smooth trajectory.

    ``split``: messages alternate between joints 1-3 and joints 4-6 (two publishers).
    """
    ts = get_typestore(Stores.ROS2_JAZZY)
    js = ts.types['sensor_msgs/msg/JointState']
    header = ts.types['std_msgs/msg/Header']
    stamp = ts.types['builtin_interfaces/msg/Time']
    names = [f'joint_{i}' for i in range(1, 7)]
    t0 = 1_700_000_000_000_000_000
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        conn = writer.add_connection('/joint_states', 'sensor_msgs/msg/JointState', typestore=ts)
        for k in range(n):
            t = t0 + k * 1_000_000
            q = 0.8 * np.sin(np.arange(1, 7) * k * 1e-4)
            part = slice(3 * (k % 2), 3 * (k % 2) + 3) if split else slice(0, 6)
            msg = js(header=header(stamp=stamp(sec=t // 10**9, nanosec=t % 10**9), frame_id=''),
                     name=names[part], position=q[part], velocity=np.zeros(0),
                     effort=np.zeros(0))
            writer.write(conn, t, ts.serialize_cdr(msg, 'sensor_msgs/msg/JointState'))


def _one_cpu():
    """Pin the calling process (a child before exec) to the first CPU it may use."""
    os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})


def run_child(argv):
    """Run a command as a child on one CPU; return (seconds, peak RSS MiB, its output)."""
    start = time.perf_counter()
    proc = subprocess.Popen(argv, stdout=subprocess.PIPE, text=True, preexec_fn=_one_cpu)
    _, status, usage = os.wait4(proc.pid, 0)
    elapsed = time.perf_counter() - start
    out = proc.stdout.read().strip()
    proc.stdout.close()
    if os.waitstatus_to_exitcode(status) != 0:
        raise SystemExit(f'{argv[0]} failed: {out}')
    return elapsed, usage.ru_maxrss / 1024.0, out


def run_process(in_bag, out_bag, storage, poses, compression='none', extra=()):
    """Run ``dq_fk_bag process`` as a child; return (seconds, peak RSS MiB, summary line)."""
    shutil.rmtree(out_bag, ignore_errors=True)   # not part of the clock
    argv = executable('dq_fk_bag') + ['process', in_bag, out_bag, '--robot', 'rl15',
                                      '--poses', poses, '--storage', storage,
                                      '--compression', compression, '--quiet', *extra]
    return run_child(argv)


def best(runs):
    """Return the run with the least time of ``runs`` ((seconds, RSS, output) each)."""
    return min(runs, key=lambda r: r[0])


def floor_and_ratios(in_bag, out_bag, n, repeat):
    """Time the floor's reads and dq_fk_bag process on one input; print and record ratios."""
    # round robin: each round runs every command once, so that a minute in which this
    # machine runs slow (it varies up to 2x) slows all of them alike; each its best round
    commands = {
        ('read', 'rosbags'): lambda: run_child([sys.executable, '-c', ROSBAGS_READ, in_bag]),
        ('read', 'mcap'): lambda: run_child([sys.executable, '-c', MCAP_READ, in_bag])}
    for poses in ('none', 'end', 'all'):   # the every-topic output the last one left
        commands[('ours', poses)] = lambda poses=poses: run_process(in_bag, out_bag, 'mcap',
                                                                    poses)
    times = {key: [] for key in commands}
    for _ in range(repeat):
        for key, command in commands.items():
            times[key].append(command()[0])
    reads = {name: min(times[('read', name)]) for name in ('rosbags', 'mcap')}
    ours = {poses: min(times[('ours', poses)]) for poses in ('none', 'end', 'all')}
    size = sum(os.path.getsize(os.path.join(out_bag, f)) for f in os.listdir(out_bag))
    writing = best([run_child([sys.executable, '-c', WRITE_FLOOR, out_bag + '_floor',
                               str(size)]) for _ in range(repeat)])[0]
    os.remove(out_bag + '_floor')
    reference = best([run_process(in_bag, out_bag, 'mcap', 'all', extra=['--reference-reader'])
                      for _ in range(repeat)])[0]
    group = 'dq_fk_bag process'
    print(f'# dq_fk_bag process and the reading floor ({n:,} RL15 JointStates, one CPU), '
          f'best of {repeat} rounds, each round every command once')
    shown = {'all': 'every pose topic', 'end': "the end effector's pose topic",
             'none': '/tf only'}
    for what, seconds in (("rosbags' bare read (AnyReader.messages())", reads['rosbags']),
                          ("the mcap library's bare iter_messages", reads['mcap']),
                          *[(f'dq_fk_bag process, {shown[p]}, MCAP out', ours[p])
                            for p in ours],
                          ('dq_fk_bag process, every pose topic, --reference-reader (rosbags '
                           'reads)', reference),
                          (f'the writing floor: {size / 2**20:,.0f} MiB (the every-topic '
                           f'output) written and CRC-32ed in 1 MiB blocks', writing)):
        figure(f'{n:,} messages: {what}', round(seconds, 3), 's', group=group, show=False)
        print(f'- {what}: {seconds:.3f} s, {n / seconds:,.0f} messages/s')
    for poses, seconds in ours.items():
        ratio_rosbags = seconds / reads['rosbags']
        ratio_mcap = seconds / reads['mcap']
        figure(f"{n:,} messages, {shown[poses]}: process / rosbags' bare read",
               round(ratio_rosbags, 2), 'x', '<= 0.7x', ratio_rosbags <= 0.7, group=group)
        figure(f"{n:,} messages, {shown[poses]}: process / the mcap library's bare read",
               round(ratio_mcap, 2), 'x', '<= 0.3x', ratio_mcap <= 0.3, group=group)
    figure(f'{n:,} messages, every topic to MCAP, one core', round(n / ours['all']),
           'JointStates/s', '>= 400,000', n / ours['all'] >= 400_000, group=group)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.strip().splitlines()[0])
    parser.add_argument('--messages', type=int, nargs='+',
                        default=[100_000, RATIO_MESSAGES, 1_000_000])
    parser.add_argument('--cases', nargs='+', default=CASES,
                        metavar='STORAGE:POSES:INPUT[:COMPRESSION]')
    parser.add_argument('--repeat', type=int, default=3, help='runs of each timed command')
    args = parser.parse_args(argv)
    compileall.compile_dir(os.path.dirname(dq_fk_ros.__file__), quiet=1)  # as pip install
    cases = [tuple(c.split(':')) + (('none',) if c.count(':') == 2 else ()) for c in args.cases]
    rows = []
    work = tempfile.mkdtemp(prefix='dq_fk_bench_bag_')
    try:
        for n in args.messages:
            for shape in sorted({c[2] for c in cases}):
                in_bag = os.path.join(work, f'in_{n}_{shape}')
                start = time.perf_counter()
                write_joint_state_bag(in_bag, n, split=shape == 'split')
                print(f'wrote a {n}-message {shape} input bag in '
                      f'{time.perf_counter() - start:.1f} s', file=sys.stderr)
                out_bag = os.path.join(work, 'out')
                if n == RATIO_MESSAGES and shape == 'full':
                    floor_and_ratios(in_bag, out_bag, n, max(args.repeat, FLOOR_ROUNDS))
                for storage, poses, _, compression in [c for c in cases if c[2] == shape]:
                    elapsed, rss, line = best([
                        run_process(in_bag, out_bag, storage, poses, compression)
                        for _ in range(args.repeat)])
                    written = int(line.split(', ')[1].split()[0])
                    size = sum(os.path.getsize(os.path.join(out_bag, f))
                               for f in os.listdir(out_bag))
                    rows.append((n, storage, poses, shape, compression, elapsed, rss, written,
                                 size))
                shutil.rmtree(in_bag)
    finally:
        shutil.rmtree(work, ignore_errors=True)
    print(f'# dq_fk_bag process, RL15 (6 joints, 7 frames), MCAP in, end to end '
          f'(process start, read, FK, write), best of {args.repeat}')
    print('| messages | storage | pose topics | input | compression | seconds | messages/s '
          '| peak RSS MiB | joint vectors written | output MiB | output messages |')
    print('|---|---|---|---|---|---|---|---|---|---|---|')
    for n, storage, poses, shape, compression, elapsed, rss, written, size in rows:
        figure(f'{n:,} messages, {storage}, poses {poses}, {shape} input, {compression}',
               round(n / elapsed), 'JointStates/s', group='dq_fk_bag process', show=False)
        per_input = 1 + {'all': 7, 'end': 1, 'none': 0}[poses]
        print(f'| {n:,} | {storage} | {poses} | {shape} | {compression} | {elapsed:.2f} '
              f'| {n / elapsed:,.0f} | {rss:.0f} | {written:,} | {size / 2**20:,.0f} '
              f'| {per_input} per vector + 1 /tf_static |')
    # memory flat in the bag's length: the shortest and the longest bag, same case
    by_case = {}
    for n, storage, poses, shape, compression, _, rss, _, _ in rows:
        by_case.setdefault((storage, poses, shape, compression), []).append((n, rss))
    lengths = sorted(args.messages)
    for (storage, poses, shape, compression), sizes in sorted(by_case.items()):
        sizes = dict(sizes)
        if len(lengths) < 2 or (storage, poses, shape, compression) != \
                ('mcap', 'all', 'full', 'none'):
            continue
        grown = sizes[lengths[-1]] / sizes[lengths[0]] - 1
        figure(f'peak RSS, {lengths[-1]:,} messages against {lengths[0]:,} (every topic, '
               f'MCAP)', round(100 * grown, 1), '%', '<= 10 %', grown <= 0.10,
               group='dq_fk_bag process')
    return 0


if __name__ == '__main__':
    sys.exit(main())
