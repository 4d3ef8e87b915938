"""
dq_fk calibrate against figaroh and pybotics on the same synthetic measurements.

A robot file's DH table (default: the Panda, a modified table as pybotics models robots)
is perturbed as a real arm is off its nominal one (~0.5 mm, ~0.05 deg a parameter),
placed 2 m from a laser tracker, given a reflector on its flange and measured at random
configurations with 20 um of noise a component (test/dh_truth.py, the tests' plain 4x4
products). Each tool calibrates from the same training measurements, starting from
the same rigid fit of the nominal points (the Kabsch start); each is judged by the RMS of
its predicted positions against the noise-free truth at held-out configurations, and timed
over its calibration call (best of ``--repeat``).

The peers run in venvs of their own (pybotics pins numpy < 2): their Python is
``$DQ_FK_PYBOTICS_PYTHON`` and ``$DQ_FK_FIGAROH_PYTHON`` (``make bench`` makes both); a
peer whose Python is not given is reported as not run. Set-ups (each the library's own
documented way, benchmarks/peers/*.py): pybotics' ``OptimizationHandler`` with every
kinematic-chain parameter, the world frame and the tool position free, fitted by
``scipy.optimize.least_squares`` on ``optimize_accuracy`` (its calibration example);
figaroh's geometric calibration (``BaseCalibration``, ``calib_level: full_params``, the
identifiable parameters by its QR, Levenberg-Marquardt) on the URDF ``dq_fk urdf`` writes
of the nominal table.

Targets (issue "Calibrate the DH table"): held-out RMS <= each peer's; wall time <= 0.5x
the faster peer's.
"""

import argparse
import json
import math
import os
import subprocess
import sys
import tempfile
import time

from bench_results import figure
from dq_fk_ros.calibration.dh_model import DhPoseModel
from dq_fk_ros.calibration.identify import calibrate, Measurements
from dq_fk_ros.description.loading import load_robot
from dq_fk_ros.description.to_urdf import robot_to_urdf
from dq_fk_ros.kinematics.dh import homogeneous_from_dq
import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(os.path.dirname(HERE), 'test'))
from dh_truth import frame_matrix as frame, kabsch, positions, trans  # noqa: E402, I100
PEERS = {'pybotics': 'DQ_FK_PYBOTICS_PYTHON', 'figaroh': 'DQ_FK_FIGAROH_PYTHON'}
WORLD = frame([2.1, -0.8, 0.4], [0.05, -0.1, 2.6])   # the robot in the tracker's frame
END = trans(0.03, -0.02, 0.07)                        # the reflector on the flange
SIGMA = 20e-6


def make_data(robot, n_train, n_test, seed):
    """Return the benchmark's data (a dict of arrays) and the robot's model."""
    model = load_robot(robot).model
    table = model.chain.table
    nominal = np.stack([table.theta0, table.d0, table.a, table.alpha], axis=1)
    rng = np.random.default_rng(seed)
    noise = np.stack([rng.normal(0, math.radians(0.05), len(nominal)),
                      rng.normal(0, 0.5e-3, len(nominal)), rng.normal(0, 0.5e-3, len(nominal)),
                      rng.normal(0, math.radians(0.05), len(nominal))], axis=1)
    truth = nominal + noise
    base = homogeneous_from_dq(np.array(table.base))
    tool = np.eye(4) if table.tool is None else homogeneous_from_dq(np.array(table.tool))
    limits = np.array(table.limits, dtype=float)
    lower, upper = np.maximum(limits[:, 0], -math.pi), np.minimum(limits[:, 1], math.pi)
    q_train = rng.uniform(lower, upper, (n_train, len(lower)))
    q_test = rng.uniform(lower, upper, (n_test, len(lower)))
    convention = table.convention
    p_train = positions(truth, convention, base, tool, WORLD, END, q_train) + \
        rng.normal(0, SIGMA, (n_train, 3))
    p_test = positions(truth, convention, base, tool, WORLD, END, q_test)
    world0 = kabsch(positions(nominal, convention, base, tool, np.eye(4), np.eye(4), q_train),
                    p_train)
    return model, {'nominal': nominal, 'base': base, 'tool': tool, 'world0': world0,
                   'q_train': q_train, 'p_train': p_train, 'q_test': q_test, 'p_test': p_test,
                   'sigma': SIGMA, 'modified': convention == 'modified', 'limits': limits}


def ours(model, data, repeat):
    """Return ``(held-out RMS m, best seconds)`` of dq_fk calibrate's fit (Python API)."""
    table = model.chain.table
    dh = DhPoseModel.from_table(table, model.frame_names[1:1 + len(table.a)])
    measured = Measurements(data['q_train'], data['p_train'])
    best = math.inf
    for _ in range(repeat):
        start = time.perf_counter()
        result = calibrate(dh, measured)
        best = min(best, time.perf_counter() - start)
    predicted, _ = dh.predict(result.params, data['q_test'])
    return rms(predicted - data['p_test']), best


def rms(errors):
    return float(np.sqrt(np.mean(np.sum(np.asarray(errors) ** 2, axis=1))))


def peer(name, path, model, repeat):
    """Return the peer's JSON answer, or ``{'error': why}``."""
    python = os.environ.get(PEERS[name])
    if not python:
        return {'error': f'${PEERS[name]} not set (make bench sets it)'}
    folder = os.path.dirname(path)
    if name == 'figaroh':
        with open(os.path.join(folder, 'robot.urdf'), 'w', encoding='utf-8') as stream:
            stream.write(robot_to_urdf(model))
    run = subprocess.run([python, os.path.join(HERE, 'peers', f'{name}_calibrate.py'), path,
                          str(repeat)], capture_output=True, text=True, timeout=3600,
                         cwd=folder, env={**os.environ, 'PYTHONPATH': HERE})
    lines = [line for line in run.stdout.splitlines() if line.startswith('{')]
    if run.returncode or not lines:
        tail = (run.stderr.strip().splitlines() or ['no output'])[-1]
        return {'error': f'exit {run.returncode}: {tail[:200]}'}
    return json.loads(lines[-1])


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.strip().splitlines()[0])
    parser.add_argument('--robot', default='panda', help='a DH file or shipped robot')
    parser.add_argument('--train', type=int, default=100, help='measurements fitted')
    parser.add_argument('--test', type=int, default=200, help='held-out configurations')
    parser.add_argument('--repeat', type=int, default=3, help='timed runs, best kept')
    parser.add_argument('--seed', type=int, default=1)
    args = parser.parse_args(argv)
    model, data = make_data(args.robot, args.train, args.test, args.seed)
    rows = {}
    with tempfile.TemporaryDirectory(prefix='bench_calibration_') as folder:
        path = os.path.join(folder, 'data.npz')
        np.savez(path, **data)
        rows['dq_fk calibrate'] = dict(zip(('rms_m', 'seconds'), ours(model, data, args.repeat)))
        for name in PEERS:
            rows[name] = peer(name, path, model, args.repeat)
    print(f'# calibration of {model.name} ({len(data["nominal"])} DH rows), {args.train} '
          f'measured positions (20 um noise), judged on {args.test} held-out configurations')
    print('| tool | held-out RMS (um) | wall time (ms) | set-up |')
    print('|---|---|---|---|')
    for name, row in rows.items():
        if 'error' in row:
            print(f'| {name} | not run | | {row["error"]} |')
        else:
            print(f'| {name} | {row["rms_m"] * 1e6:.2f} | {row["seconds"] * 1e3:.1f} | '
                  f'{row.get("setup", "this package: frames, rank, LM with the DQ Jacobian")} |')
    mine = rows['dq_fk calibrate']
    ran = {n: r for n, r in rows.items() if n in PEERS and 'error' not in r}
    for name, row in ran.items():
        figure(f'held-out RMS against {name}', mine['rms_m'] * 1e6, 'um',
               f'<= {name} {row["rms_m"] * 1e6:.2f} um', mine['rms_m'] <= row['rms_m'],
               group='calibration')
    if ran:
        fastest = min(ran, key=lambda n: ran[n]['seconds'])
        ratio = mine['seconds'] / ran[fastest]['seconds']
        figure(f'wall time against the faster peer ({fastest})', ratio, 'x', '<= 0.5x',
               ratio <= 0.5, group='calibration')
    for name in PEERS:
        if name not in ran:
            print(f'- {name}: NOT measured ({rows[name]["error"]})')
    return 0


if __name__ == '__main__':
    sys.exit(main())
