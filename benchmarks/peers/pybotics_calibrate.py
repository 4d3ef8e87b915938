"""
pybotics calibrates bench_calibration.py's data (run in pybotics' own venv: numpy < 2).

pybotics' own way (its calibration example): an ``OptimizationHandler`` over the nominal
robot with every kinematic-chain parameter, the world frame and the tool's position free,
``scipy.optimize.least_squares`` on ``optimize_accuracy`` (one absolute position error a
measurement), started at the rigid fit of the nominal points. Prints one JSON line.
"""

import json
import sys
import time

import numpy as np
from pybotics.kinematic_chain import MDHKinematicChain
from pybotics.optimization import OptimizationHandler, optimize_accuracy
from pybotics.robot import Robot
from pybotics.tool import Tool
import scipy.optimize


def main():
    data = np.load(sys.argv[1])
    repeat = int(sys.argv[2])
    if not bool(data['modified']):
        print(json.dumps({'error': 'pybotics models modified DH only'}))
        return 0
    rows = data['nominal']   # theta, d, a, alpha; pybotics' MDH links: alpha, a, theta, d
    links = np.stack([rows[:, 3], rows[:, 2], rows[:, 0], rows[:, 1]], axis=1)
    best, handler = float('inf'), None
    for _ in range(repeat):
        robot = Robot(kinematic_chain=MDHKinematicChain.from_parameters(links.copy()),
                      tool=Tool(matrix=data['tool'].copy()),
                      world_frame=data['world0'] @ data['base'])
        handler = OptimizationHandler(
            robot=robot, kinematic_chain_mask=[True] * robot.kinematic_chain.num_parameters,
            tool_mask=[True, True, True, False, False, False], world_mask=[True] * 6)
        start = time.perf_counter()
        result = scipy.optimize.least_squares(
            fun=optimize_accuracy, x0=handler.generate_optimization_vector(),
            args=(handler, data['q_train'], data['p_train']))
        best = min(best, time.perf_counter() - start)
        handler.apply_optimization_vector(result.x)
    predicted = np.array([handler.robot.fk(q)[:3, 3] for q in data['q_test']])
    error = predicted - data['p_test']
    print(json.dumps({'rms_m': float(np.sqrt(np.mean(np.sum(error ** 2, axis=1)))),
                      'seconds': best,
                      'setup': 'OptimizationHandler (chain, world, tool position), '
                               'least_squares on optimize_accuracy'}))
    return 0


if __name__ == '__main__':
    sys.exit(main())
