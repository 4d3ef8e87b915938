"""
Forward-kinematics speed of the dq_fk_ros core against the peers a user would pick instead.

Prints one table per robot (RL15 of [Zivkovic2023] and the Puma 560): microseconds per single
call (end effector, all frames) and configurations per second for a batch of N, each with
the ratio ``peer time / dq_fk_ros time`` (above 1: dq_fk_ros is faster). Peers that are
not installed are listed as such (``make bench`` installs them from
requirements/bench.txt into .venv-bench).

Before timing, every peer's end-effector pose is checked against the core at random
configurations, so that all rows compute the same thing.

Run: ``python benchmarks/bench_core.py [--n 100000] [--repeat 7]``.
"""

import argparse
import functools
import math
import os
import platform
import statistics
import sys
import time

from bench_results import figure
from dq_fk_ros.kinematics.chain_batches import forward_all_batch_reference, forward_batch_reference
from dq_fk_ros.kinematics.chain_engines import ReferenceEngine
from dq_fk_ros.kinematics.dh import DHJoint, homogeneous_from_dq, KinematicChain
from dq_fk_ros.kinematics.kernel import kernel_info
import numpy as np

DEG = math.pi / 180.0

# (a [m], alpha [rad], d [m], theta offset [rad]) per revolute row, standard DH
ROBOTS = {
    # [Zivkovic2023] Table 3; theta_2 = q2 + 90 deg
    'RL15': [(0.200, 90 * DEG, 0.0, 0.0), (0.600, 0.0, 0.0, 90 * DEG),
             (0.115, 90 * DEG, 0.0, 0.0), (0.0, -90 * DEG, 0.825, 0.0),
             (0.0, 90 * DEG, 0.0, 0.0), (0.0, 0.0, 0.0, 0.0)],
    # Puma 560, lengths as published by Corke (roboticstoolbox's Puma560)
    'Puma560': [(0.0, 90 * DEG, 0.0, 0.0), (0.4318, 0.0, 0.0, 0.0),
                (0.0203, -90 * DEG, 0.15005, 0.0), (0.0, 90 * DEG, 0.4318, 0.0),
                (0.0, -90 * DEG, 0.0, 0.0), (0.0, 0.0, 0.0, 0.0)],
}


def per_call_seconds(fn, repeat, min_time=0.2):
    """Median seconds per call of ``fn()`` over ``repeat`` timed runs of >= ``min_time``."""
    number = 1
    while True:
        start = time.perf_counter()
        for _ in range(number):
            fn()
        elapsed = time.perf_counter() - start
        if elapsed >= min_time / 4 or number > 1 << 20:
            break
        number *= 4
    number = max(1, int(number * (min_time / 4) / max(elapsed, 1e-9)))
    samples = []
    for _ in range(repeat):
        start = time.perf_counter()
        for _ in range(number):
            fn()
        samples.append((time.perf_counter() - start) / number)
    return statistics.median(samples)


# -- the contenders -------------------------------------------------------------------
def make_dq_fk_ros(rows):
    chain = KinematicChain([DHJoint(a=a, alpha=al, d=d, theta=off) for a, al, d, off in rows])
    return {
        'name': f"dq_fk_ros ({kernel_info()['active']} path)",
        'end': chain.forward,
        'all': chain.forward_all,
        'batch_end': chain.forward_batch,
        'batch_all': chain.forward_all_batch,
        'end_matrix': lambda q: chain.forward(q).to_matrix(),
    }


def make_dq_fk_ros_buffers(rows):
    """Return the same chain filling arrays the caller made once (``out=``): no allocation."""
    chain = KinematicChain([DHJoint(a=a, alpha=al, d=d, theta=off) for a, al, d, off in rows])
    frames = np.empty((chain.n_frames, 8))
    made = {}

    def into(method, shape):
        def call(qs):
            key = (method, len(qs))
            if key not in made:  # made on the first call, reused by the timed ones
                made[key] = np.empty((len(qs),) + shape)
            return method(qs, out=made[key])
        return call
    return {
        'name': f"dq_fk_ros ({kernel_info()['active']}, caller's buffers)",
        'end': None,
        'all': functools.partial(chain.forward_all, out=frames),  # (no extra Python frame)
        'batch_end': into(chain.forward_batch, (8,)),
        'batch_all': into(chain.forward_all_batch, (chain.n_frames, 8)),
        'end_matrix': lambda q: chain.forward(q).to_matrix(),
    }


def make_dq_fk_ros_reference(rows):
    """Return the numpy reference path of the same chain (what runs without the kernel)."""
    if kernel_info()['active'] != 'c':
        raise ImportError('the kernel is not active: the row above is the numpy path')
    chain = KinematicChain([DHJoint(a=a, alpha=al, d=d, theta=off) for a, al, d, off in rows])
    reference = ReferenceEngine(chain.table)
    return {
        'name': 'dq_fk_ros (numpy reference path)',
        'end': reference.end,
        'all': reference.frames,
        'batch_end': functools.partial(forward_batch_reference, chain.table),
        'batch_all': functools.partial(forward_all_batch_reference, chain.table),
        'end_matrix': lambda q: homogeneous_from_dq(reference.end(q)),
    }


def make_numpy_4x4(rows):
    a = np.array([r[0] for r in rows])
    alpha = np.array([r[1] for r in rows])
    d = np.array([r[2] for r in rows])
    off = np.array([r[3] for r in rows])
    ca, sa = np.cos(alpha), np.sin(alpha)

    def matrices(q):
        """Return the standard DH 4x4s of every row, shape q.shape + (4, 4)."""
        t = np.asarray(q) + off
        ct, st = np.cos(t), np.sin(t)
        m = np.zeros(t.shape + (4, 4))
        m[..., 0, 0], m[..., 0, 1], m[..., 0, 2], m[..., 0, 3] = ct, -st * ca, st * sa, a * ct
        m[..., 1, 0], m[..., 1, 1], m[..., 1, 2], m[..., 1, 3] = st, ct * ca, -ct * sa, a * st
        m[..., 2, 1], m[..., 2, 2], m[..., 2, 3] = sa, ca, d
        m[..., 3, 3] = 1.0
        return m

    def all_frames(q):
        m = matrices(q)
        out = [m[..., 0, :, :]]
        for i in range(1, len(rows)):
            out.append(out[-1] @ m[..., i, :, :])
        return out

    return {
        'name': 'numpy 4x4 chain',
        'end': lambda q: all_frames(q)[-1],
        'all': all_frames,
        'batch_end': lambda q: all_frames(q)[-1],
        'batch_all': all_frames,
        'end_matrix': lambda q: all_frames(q)[-1],
    }


def make_rtb(rows):
    import roboticstoolbox as rtb
    robot = rtb.DHRobot([rtb.RevoluteDH(a=a, alpha=al, d=d, offset=off)
                         for a, al, d, off in rows])
    ets = robot.ets()
    return [{
        'name': 'roboticstoolbox DHRobot',
        'end': robot.fkine,
        'all': robot.fkine_all,
        'batch_end': None,
        'batch_all': None,
        'end_matrix': lambda q: robot.fkine(q).A,
    }, {
        'name': 'roboticstoolbox ETS (compiled)',
        'end': ets.fkine,
        'all': None,
        'batch_end': ets.fkine,
        'batch_all': None,
        'end_matrix': lambda q: np.asarray(ets.fkine(q).A),
    }]


def make_dqrobotics(rows):
    from dqrobotics.robot_modeling import DQ_SerialManipulatorDH
    n = len(rows)
    dh = np.array([[r[3] for r in rows], [r[2] for r in rows], [r[0] for r in rows],
                   [r[1] for r in rows], [0.0] * n])
    robot = DQ_SerialManipulatorDH(dh)

    def end_matrix(q):
        x = robot.fkm(q)
        vec = np.asarray(x.vec8())
        return homogeneous_from_dq(vec)

    return {
        'name': 'dqrobotics DQ_SerialManipulatorDH',
        'end': robot.fkm,
        'all': lambda q: [robot.fkm(q, i) for i in range(n)],
        'batch_end': lambda qs: [robot.fkm(q) for q in qs],
        'batch_all': None,
        'end_matrix': end_matrix,
    }


def make_pinocchio(rows):
    import pinocchio as pin
    model = pin.Model()
    parent, placement = 0, pin.SE3.Identity()
    offsets = np.array([r[3] for r in rows])

    def after_joint(a, alpha, d):
        """Tz(d) Tx(a) Rx(alpha), the constant part of a standard DH row."""
        rot = pin.utils.rotate('x', alpha)
        return pin.SE3(np.eye(3), np.array([0.0, 0.0, d])) * pin.SE3(rot, np.array([a, 0, 0]))

    for i, (a, alpha, d, _) in enumerate(rows):
        parent = model.addJoint(parent, pin.JointModelRZ(), placement, f'joint_{i + 1}')
        model.appendBodyToJoint(parent, pin.Inertia.Random(), pin.SE3.Identity())
        placement = after_joint(a, alpha, d)
    tool = model.addFrame(pin.Frame('tool', parent, placement, pin.FrameType.OP_FRAME))
    data = model.createData()

    def end(q):
        pin.forwardKinematics(model, data, q + offsets)
        return data.oMi[parent] * placement

    def all_frames(q):
        pin.framesForwardKinematics(model, data, q + offsets)
        return data.oMf

    def end_matrix(q):
        pin.framesForwardKinematics(model, data, q + offsets)
        return data.oMf[tool].homogeneous

    return {
        'name': 'pinocchio (C++)',
        'end': end,
        'all': all_frames,
        'batch_end': lambda qs: [end(q) for q in qs],
        'batch_all': None,
        'end_matrix': end_matrix,
    }


PEERS = [('dq_fk_ros numpy path', make_dq_fk_ros_reference),
         ('numpy', make_numpy_4x4), ('roboticstoolbox', make_rtb),
         ('dqrobotics', make_dqrobotics), ('pinocchio', make_pinocchio)]


def contenders(rows):
    out = [make_dq_fk_ros(rows), make_dq_fk_ros_buffers(rows)]
    missing = []
    for module, factory in PEERS:
        try:
            made = factory(rows)
        except ImportError:
            missing.append(module)
            continue
        out.extend(made if isinstance(made, list) else [made])
    return out, missing


def check_agreement(entries, rows, rng):
    """Largest end-effector difference of each peer to dq_fk_ros over 20 random q."""
    ours = entries[0]['end_matrix']
    worst = {}
    for q in rng.uniform(-math.pi, math.pi, size=(20, len(rows))):
        ref = ours(q)
        for e in entries[1:]:
            err = float(np.max(np.abs(np.asarray(e['end_matrix'](q)) - ref)))
            worst[e['name']] = max(worst.get(e['name'], 0.0), err)
    return worst


def fmt_ratio(peer, ours):
    return f'{peer / ours:6.2f}x' if peer and ours else '     -'


def run_robot(label, rows, n_batch, repeat, rng):
    entries, missing = contenders(rows)
    worst = check_agreement(entries, rows, rng)
    for name, err in worst.items():
        if err > 1e-9:
            raise SystemExit(f'{name} disagrees with dq_fk_ros on {label} by {err:.3g}')
    q = rng.uniform(-math.pi, math.pi, size=len(rows))
    qs = rng.uniform(-math.pi, math.pi, size=(n_batch, len(rows)))
    results = []
    for e in entries:
        r = {'name': e['name']}
        for key in ('end', 'all'):
            r[key] = per_call_seconds(lambda f=e[key]: f(q), repeat) if e[key] else None
        for key in ('batch_end', 'batch_all'):
            if e[key] is None:
                r[key] = None
                continue
            reps = max(3, repeat // 2)
            samples = []
            for _ in range(reps):
                start = time.perf_counter()
                e[key](qs)
                samples.append(time.perf_counter() - start)
            r[key] = statistics.median(samples)
        results.append(r)

    ours = results[0]
    print(f'\n## {label} ({len(rows)} revolute joints), batch N = {n_batch}')
    print('ratio = peer time / dq_fk_ros time (above 1: dq_fk_ros is faster)\n')
    print(f"| {'implementation':34s} | end us | ratio  | all us | ratio  "
          f'| batch end cfg/s | ratio  | batch all cfg/s | ratio  |')
    print('|' + '---|' * 9)
    for r in results:
        def us(key):
            return f'{r[key] * 1e6:6.2f}' if r[key] else '     -'

        def rate(key):
            return f'{n_batch / r[key]:15,.0f}' if r[key] else ' ' * 14 + '-'
        print(f"| {r['name']:34s} | {us('end')} | {fmt_ratio(r['end'], ours['end'])} "
              f"| {us('all')} | {fmt_ratio(r['all'], ours['all'])} "
              f"| {rate('batch_end')} | {fmt_ratio(r['batch_end'], ours['batch_end'])} "
              f"| {rate('batch_all')} | {fmt_ratio(r['batch_all'], ours['batch_all'])} |")
    if missing:
        print(f"\nnot installed (make bench installs them): {', '.join(missing)}")
    print('end-effector agreement with dq_fk_ros (max abs 4x4 difference): '
          + ', '.join(f'{k}: {v:.1e}' for k, v in worst.items()))
    print_targets(label, results, n_batch)


def print_targets(label, results, n_batch):
    """Print the compiled kernel's targets (issue "A compiled kernel") with met / NOT met."""
    ours = results[0]
    print(f'\ntargets ({label}):')
    for peer in ('pinocchio (C++)', 'dqrobotics DQ_SerialManipulatorDH'):
        theirs = next((r for r in results if r['name'] == peer), None)
        for key, what in (('end', 'end effector'), ('all', 'all frames')):
            if theirs is None or not theirs[key]:
                print(f'- single call, {what}, faster than {peer}: not measured (not installed)')
                continue
            ratio = theirs[key] / ours[key]
            figure(f'{label}: single call, {what}, faster than {peer}', round(ratio, 2), 'x',
                   '> 1x', ratio > 1, group='the compiled kernel')
    for row, how in ((ours, 'a new array'), (results[1], "the caller's buffer")):
        all_us = row['all'] * 1e6
        figure(f'{label}: single call, all frames, {how}', round(all_us, 2), 'us',
               '<= 0.5 us (aim)', all_us <= 0.5, group='the compiled kernel')
    goals = (('batch_end', 'end effector', 20e6), ('batch_all', 'all frames', 5e6))
    for row, how in ((ours, 'new arrays'), (results[1], "caller's buffers")):
        for key, what, goal in goals:
            rate = n_batch / row[key]
            figure(f'{label}: batch, {what}, {how}', round(rate / 1e6, 1), 'M cfg/s',
                   f'>= {goal / 1e6:.0f} M', rate >= goal, group='the compiled kernel')


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.strip().splitlines()[0])
    parser.add_argument('--n', type=int, default=100_000, help='batch size (default 100000)')
    parser.add_argument('--repeat', type=int, default=7, help='timed runs per figure')
    parser.add_argument('--robot', choices=sorted(ROBOTS), action='append',
                        help='robot(s) to run (default: all)')
    args = parser.parse_args(argv)
    rng = np.random.default_rng(0)
    print(f'# dq_fk_ros core benchmark: Python {platform.python_version()}, '
          f'numpy {np.__version__}, {os.cpu_count()} CPUs, {platform.machine()}')
    print('single calls: median over runs; dq_fk_ros "all" returns frames 0..n as (n+1, 8)')
    for label in args.robot or sorted(ROBOTS, reverse=True):
        run_robot(label, ROBOTS[label], args.n, args.repeat, rng)
    return 0


if __name__ == '__main__':
    sys.exit(main())
