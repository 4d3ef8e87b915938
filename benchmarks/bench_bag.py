"""
Offline bag processing speed and memory: ``dq_fk_bag process`` end to end (read, FK, write).

Writes a 6-DoF RL15 JointState bag of N messages (MCAP) into a temporary folder, then runs
``dq_fk_bag process`` on it in a child process for each case and prints messages per second
and the child's peak resident memory. A case is ``STORAGE:POSES:INPUT``: the output storage
(mcap, sqlite3), the pose topics written (all frames, the end effector only, none: /tf only)
and the input (``full``: every message names all six joints; ``split``: two publishers
alternate, three joints each, so every message merges with the one before). Two bag lengths
show whether memory grows with the bag.

Each child runs on one CPU (its affinity set to the first this process may use).

Run: ``python benchmarks/bench_bag.py [--messages 100000 1000000] [--cases mcap:all:full]``.
"""

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
import time

from bench_results import figure
from dq_fk_ros.ros.executables import executable
import numpy as np
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import get_typestore, Stores

CASES = ['mcap:all:full', 'mcap:end:full', 'mcap:none:full', 'sqlite3:all:full',
         'mcap:all:split']


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


def run_process(in_bag, out_bag, storage, poses):
    """Run ``dq_fk_bag process`` as a child; return (seconds, peak RSS MiB, summary line)."""
    argv = executable('dq_fk_bag') + ['process', in_bag, out_bag, '--robot', 'rl15',
                                      '--poses', poses,
                                      '--storage', storage, '--quiet', '--overwrite']
    start = time.perf_counter()
    # on one core, as the target says (the command is single-threaded anyway)
    proc = subprocess.Popen(argv, stdout=subprocess.PIPE, text=True,
                            preexec_fn=_one_cpu)
    _, status, usage = os.wait4(proc.pid, 0)
    elapsed = time.perf_counter() - start
    out = proc.stdout.read().strip()
    proc.stdout.close()
    if os.waitstatus_to_exitcode(status) != 0:
        raise SystemExit(f'dq_fk_bag process failed: {out}')
    return elapsed, usage.ru_maxrss / 1024.0, out


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.strip().splitlines()[0])
    parser.add_argument('--messages', type=int, nargs='+', default=[100_000, 1_000_000])
    parser.add_argument('--cases', nargs='+', default=CASES, metavar='STORAGE:POSES:INPUT')
    args = parser.parse_args(argv)
    cases = [tuple(c.split(':')) for c in args.cases]
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
                for storage, poses, _ in [c for c in cases if c[2] == shape]:
                    out_bag = os.path.join(work, 'out')
                    elapsed, rss, line = run_process(in_bag, out_bag, storage, poses)
                    written = int(line.split(', ')[1].split()[0])
                    rows.append((n, storage, poses, shape, elapsed, rss, written))
                shutil.rmtree(in_bag)
    finally:
        shutil.rmtree(work, ignore_errors=True)
    print('# dq_fk_bag process, RL15 (6 joints, 7 frames), MCAP in, end to end '
          '(process start, read, FK, write)')
    print('| messages | storage | pose topics | input | seconds | messages/s | peak RSS MiB '
          '| joint vectors written | output messages |')
    print('|---|---|---|---|---|---|---|---|---|')
    for n, storage, poses, shape, elapsed, rss, written in rows:
        figure(f'{n:,} messages, {storage}, poses {poses}, {shape} input', round(n / elapsed),
               'JointStates/s', group='dq_fk_bag process', show=False)
        per_input = 1 + {'all': 7, 'end': 1, 'none': 0}[poses]
        print(f'| {n:,} | {storage} | {poses} | {shape} | {elapsed:.1f} | {n / elapsed:,.0f} '
              f'| {rss:.0f} | {written:,} | {per_input} per vector + 1 /tf_static |')
    # issue "A compiled kernel": >= 400 000 JointStates a second on one core, every topic to
    # MCAP (the process's start included, as above)
    for n, storage, poses, shape, elapsed, _, _ in rows:
        if (storage, poses, shape) == ('mcap', 'all', 'full'):
            rate = n / elapsed
            figure(f'{n:,} messages, every topic to MCAP, one core', round(rate),
                   'JointStates/s', '>= 400,000', rate >= 400_000, group='dq_fk_bag process')
    return 0


if __name__ == '__main__':
    sys.exit(main())
