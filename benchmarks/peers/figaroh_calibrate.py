"""
figaroh calibrates bench_calibration.py's data (run in the benchmark venv: figaroh, pin).

figaroh's own way (its UR10 and TIAGo examples, ``BaseCalibration``): a unified config
(``calibration_level: full_params``, one marker measuring x, y, z), the measurements as its
CSV (``x1, y1, z1`` and a column per joint), ``initialize()`` (its QR selection of the
identifiable parameters) and ``solve()`` (Levenberg-Marquardt with its outlier rounds), the
cost of its docstring (``calc_updated_fkm``, log-map residuals, its weighting), on the URDF
``dq_fk urdf`` writes of the nominal table (``robot.urdf`` beside the data), the
measurement frame and the marker unknown (``known_baseframe``/``known_tipframe`` False, as
its examples set them; figaroh starts them from its own closed-form estimate). Prints one
JSON line.
"""

import json
import logging
import os
import sys
import time
import warnings

from figaroh.calibration.base_calibration import BaseCalibration
from figaroh.calibration.calibration_tools import calc_updated_fkm
from figaroh.tools.load_robot import load_robot
import numpy as np
import yaml

warnings.filterwarnings('ignore')
logging.disable(logging.WARNING)


class BenchCalibration(BaseCalibration):
    """The cost of BaseCalibration's docstring: positions, figaroh's weighting."""

    def cost_function(self, var):
        estimated = calc_updated_fkm(self.model, self.data, var, self.q_measured,
                                     self.calib_config)
        return self.apply_measurement_weighting(
            self._compute_logmap_residuals(self.PEE_measured, estimated))


def write_inputs(data, robot, q, p, path, name):
    """Write figaroh's CSV of positions and joint values."""
    joints = [robot.model.names[i] for i in range(1, robot.model.njoints)]
    columns = ['x1', 'y1', 'z1'] + joints
    rows = np.concatenate([p, q[:, :len(joints)]], axis=1)
    with open(os.path.join(path, name), 'w', encoding='utf-8') as stream:
        stream.write(','.join(columns) + '\n')
        for row in rows:
            stream.write(','.join(f'{v:.12g}' for v in row) + '\n')


def main():
    data = np.load(sys.argv[1])
    repeat = int(sys.argv[2])
    folder = os.path.dirname(os.path.abspath(sys.argv[1]))
    robot = load_robot(os.path.join(folder, 'robot.urdf'), load_by_urdf=True)
    tool = robot.model.frames[-1].name
    write_inputs(data, robot, data['q_train'], data['p_train'], folder, 'train.csv')
    config = {
        'schema_version': '2.0',
        'robot': {'name': robot.model.name},
        'tasks': {'calibration': {
            'type': 'kinematic_calibration',
            'kinematics': {'base_frame': 'universe', 'tool_frame': tool},
            'measurements': {'markers': [{'measurable_dof': [True, True, True, False, False,
                                                             False]}]},
            'parameters': {'calibration_level': 'full_params'},
            'data': {'source_file': os.path.join(folder, 'train.csv'),
                     'number_of_samples': int(len(data['q_train']))}}}}
    path = os.path.join(folder, 'figaroh.yaml')
    with open(path, 'w', encoding='utf-8') as stream:
        yaml.safe_dump(config, stream)
    best, calibration = float('inf'), None
    for _ in range(repeat):
        calibration = BenchCalibration(robot, path)
        # as its UR10 and TIAGo examples: the measurement frame and the marker unknown
        calibration.calib_config['known_baseframe'] = False
        calibration.calib_config['known_tipframe'] = False
        start = time.perf_counter()
        calibration.initialize()
        calibration.solve(enable_logging=False)
        best = min(best, time.perf_counter() - start)
    q_test = np.tile(robot.q0, (len(data['q_test']), 1))
    q_test[:, calibration.calib_config['config_idx']] = data['q_test']
    calibration.calib_config['NbSample'] = len(q_test)   # (the held-out set's size)
    predicted = calc_updated_fkm(calibration.model, calibration.data, calibration.var_, q_test,
                                 calibration.calib_config)
    predicted = np.asarray(predicted).reshape(3, -1).T
    error = predicted - data['p_test']
    print(json.dumps({'rms_m': float(np.sqrt(np.mean(np.sum(error ** 2, axis=1)))),
                      'seconds': best,
                      'setup': 'BaseCalibration full_params, initialize() + solve()'}))
    return 0


if __name__ == '__main__':
    sys.exit(main())
