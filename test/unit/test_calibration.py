"""
dq_fk calibrate against a truth this test makes with its own 4x4 DH products.

A robot's published table (read from its YAML here, units converted here) is perturbed as
a real arm is off its nominal one (lengths ~0.5 mm, angles ~0.05 deg), placed in a laser
tracker's frame, given a reflector (or a 6D probe) on its flange, and measured at random
configurations with a tracker's noise (20 um, 1e-4 rad a component). The calibrated table
and frames must then predict held-out configurations within noise of the truth, and the
parameters held as unidentifiable must be the ones the geometry says.
"""

import csv
import json
import math
import os
import sys

from dq_fk_ros.calibration.dh_model import DhPoseModel
from dq_fk_ros.calibration.identify import identifiable, preference
from dq_fk_ros.calibration.measurements import DataError, read_csv
from dq_fk_ros.cli.dq_fk import main
from dq_fk_ros.description.schema import load_robot_description
from dq_fk_ros.description.shipped import shipped_robot_path
import numpy as np
import pytest
import yaml

TEST = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path[:0] = [TEST, os.path.join(TEST, 'integration')]
from dh_truth import frame_matrix, row_matrix  # noqa: E402, I100 (the tests' helpers)
from homogeneous_tf import pose_matrix_of_tuple  # noqa: E402
from vendor_urdfs import UR5, vendor_path  # noqa: E402

pytest.importorskip('scipy')
LENGTH = {'m': 1.0, 'mm': 1e-3}
SIGMA_P, SIGMA_R = 20e-6, 1e-4


class Robot:
    """A DH robot file read by this test: its rows (m, rad), base, tool, joints."""

    def __init__(self, name):
        self.path = name if os.path.exists(name) else shipped_robot_path(name)
        with open(self.path, encoding='utf-8') as stream:
            doc = yaml.safe_load(stream)
        units = doc.get('units', {})
        length = LENGTH[units.get('length', 'm')]
        angle = math.pi / 180 if units.get('angle', 'rad') == 'deg' else 1.0
        self.convention = doc['convention']
        self.rows = np.array([[r.get('theta', 0) * angle, r.get('d', 0) * length,
                               r.get('a', 0) * length, r.get('alpha', 0) * angle]
                              for r in doc['chain']], dtype=float)
        self.frames = [r['frame'] for r in doc['chain']]
        self.joints = [r['joint'] for r in doc['chain']]
        self.limits = np.array([np.array(r.get('limits', [-180, 180])) * angle
                                for r in doc['chain']])
        base, tool = doc.get('base') or {}, doc.get('tool')
        self.base = self.placement(base, length, angle)
        self.tool = np.eye(4) if tool is None else self.placement(tool, length, angle)

    @staticmethod
    def placement(entry, length, angle):
        """Return the 4x4 of a base or tool entry: xyz and rpy, or xyz and a quaternion."""
        xyz = np.array(entry.get('xyz', [0, 0, 0])) * length
        if 'quaternion' in entry:
            return pose_matrix_of_tuple((*xyz, *entry['quaternion']))
        return frame_matrix(xyz, np.array(entry.get('rpy', [0, 0, 0])) * angle)

    def poses(self, rows, q, world, end):
        """Return the measured frame's 4x4 pose at each configuration of ``q``."""
        out = []
        for values in q:
            m = world @ self.base
            for (theta, d, a, alpha), v in zip(rows, values):
                m = m @ row_matrix(theta + v, d, a, alpha, self.convention)
            out.append(m @ self.tool @ end)
        return np.array(out)


def quaternion_xyzw(m):
    """Return the (x, y, z, w) quaternion of a rotation matrix (w >= 0)."""
    w = 0.5 * math.sqrt(max(0.0, 1 + m[0, 0] + m[1, 1] + m[2, 2]))
    if w > 0.1:
        q = [(m[2, 1] - m[1, 2]) / (4 * w), (m[0, 2] - m[2, 0]) / (4 * w),
             (m[1, 0] - m[0, 1]) / (4 * w), w]
    else:
        x = 0.5 * math.sqrt(max(0.0, 1 + m[0, 0] - m[1, 1] - m[2, 2]))
        q = [x, (m[0, 1] + m[1, 0]) / (4 * x), (m[0, 2] + m[2, 0]) / (4 * x),
             (m[2, 1] - m[1, 2]) / (4 * x)]
    q = np.array(q)
    return q * np.sign(q[3] or 1.0)


def small_rotation(rng, sigma):
    """Return a rotation matrix of a random rotation vector of ``sigma`` rad a component."""
    v = rng.normal(0, sigma, 3)
    angle = np.linalg.norm(v)
    k = skew = np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])
    if angle > 0:
        k = skew / angle
    return np.eye(3) + math.sin(angle) * k + (1 - math.cos(angle)) * k @ k


def configurations(robot, rng, n):
    lower = np.maximum(robot.limits[:, 0], -math.pi)
    upper = np.minimum(robot.limits[:, 1], math.pi)
    return rng.uniform(lower, upper, size=(n, len(robot.joints)))


WORLD = frame_matrix([2.1, -0.8, 0.4], [0.05, -0.1, 2.6])     # the robot in the tracker
END = frame_matrix([0.03, -0.02, 0.07], [0.4, -0.3, 0.2])    # the reflector on the flange


def measure(robot, truth, q, rng, orientation):
    """Return the CSV rows of the truth's poses at ``q`` with the tracker's noise."""
    rows = []
    for m, values in zip(robot.poses(truth, q, WORLD, END), q):
        position = m[:3, 3] + rng.normal(0, SIGMA_P, 3)
        row = list(values) + list(position)
        if orientation:
            row += list(quaternion_xyzw(m[:3, :3] @ small_rotation(rng, SIGMA_R)))
        rows.append(row)
    return rows


def write_csv(path, robot, rows, orientation):
    with open(path, 'w', newline='', encoding='utf-8') as stream:
        writer = csv.writer(stream)
        writer.writerow(robot.joints + ['x', 'y', 'z'] +
                        (['qx', 'qy', 'qz', 'qw'] if orientation else []))
        writer.writerows(rows)


def perturbed(robot, rng):
    """Return the robot's rows as a real arm has them: off by ~0.5 mm and ~0.05 deg."""
    noise = np.stack([rng.normal(0, math.radians(0.05), len(robot.rows)),
                      rng.normal(0, 0.5e-3, len(robot.rows)),
                      rng.normal(0, 0.5e-3, len(robot.rows)),
                      rng.normal(0, math.radians(0.05), len(robot.rows))], axis=1)
    return robot.rows + noise


def unidentifiable_by_geometry(robot, orientation):
    """Return the parameters the geometry says no data can separate (docs/calibration.md)."""
    first, last = robot.frames[0], robot.frames[-1]
    if robot.convention == 'standard':
        held = {f'{first}.theta', f'{first}.d'}       # the fixed frame's rotation about z0
        #                                                 and shift along it absorb them
        held |= {f'{last}.{f}' for f in ('theta', 'd', 'a', 'alpha')}  # after the last
        #                                                 joint: the measured frame absorbs
    else:   # modified: a row's alpha and a come before its joint, theta and d after
        held = {f'{first}.{f}' for f in ('theta', 'd', 'a', 'alpha')}
        held |= {f'{last}.theta', f'{last}.d'}
    # a run of parallel axes (alpha 0 between them): one d, their sum
    for i in range(1, len(robot.rows)):
        if robot.convention == 'standard' and abs(robot.rows[i - 1, 3]) < 1e-9 and \
                robot.frames[i] != last:
            held.add(f'{robot.frames[i]}.d')
    if not orientation:
        held |= {'end_rx', 'end_ry', 'end_rz'}
    return held


CASES = [('ur5e', False), ('ur5e', True), ('rl15', True), ('puma560', True),
         ('panda', True)]


@pytest.mark.parametrize('name,orientation', CASES)
def test_the_calibrated_table_predicts_held_out_poses_within_the_trackers_noise(
        name, orientation, tmp_path):
    robot = Robot(name)
    rng = np.random.default_rng(len(name) + orientation)
    truth = perturbed(robot, rng)
    q = configurations(robot, rng, 80)
    write_csv(tmp_path / 'data.csv', robot, measure(robot, truth, q, rng, orientation),
              orientation)
    assert main(['calibrate', name, str(tmp_path / 'data.csv'), '-o',
                 str(tmp_path / 'calibrated.yaml'), '--report',
                 str(tmp_path / 'report.json')]) == 0
    report = json.loads((tmp_path / 'report.json').read_text())
    assert set(report['unidentifiable']) == unidentifiable_by_geometry(robot, orientation)
    # the calibrated file, read by this test as it read the published one
    calibrated = Robot(name)
    calibrated.path = tmp_path / 'calibrated.yaml'
    with open(calibrated.path, encoding='utf-8') as stream:
        doc = yaml.safe_load(stream)
    units = doc.get('units', {})
    length = LENGTH[units.get('length', 'm')]
    angle = math.pi / 180 if units.get('angle', 'rad') == 'deg' else 1.0
    rows = np.array([[r['theta'] * angle, r['d'] * length, r['a'] * length,
                      r['alpha'] * angle] for r in doc['chain']])
    load_robot_description(calibrated.path)   # every tool loads it
    world = report['fixed_frame_in_measurement']
    end = report['measured_in_end']
    world = pose_matrix_of_tuple((*world['xyz'], *world['quaternion_xyzw']))
    end = pose_matrix_of_tuple((*end['xyz'], *end['quaternion_xyzw']))
    held_out = configurations(robot, rng, 50)
    true_poses = robot.poses(truth, held_out, WORLD, END)
    predicted = robot.poses(rows, held_out, world, end)
    error = np.linalg.norm(predicted[:, :3, 3] - true_poses[:, :3, 3], axis=1)
    assert np.sqrt(np.mean(error ** 2)) < 1.5 * SIGMA_P * math.sqrt(3), error.max()
    if orientation:
        relative = np.einsum('nji,njk->nik', predicted[:, :3, :3], true_poses[:, :3, :3])
        angles = np.arccos(np.clip((np.trace(relative, axis1=1, axis2=2) - 1) / 2, -1, 1))
        assert np.sqrt(np.mean(angles ** 2)) < 1.5 * SIGMA_R * math.sqrt(3)
    # the published table, its frames fitted, is far off: the test has something to find
    before = report['residuals']['before']['holdout']['position_rms_m']
    after = report['residuals']['after']['holdout']['position_rms_m']
    assert before > 0.3e-3 and after < 2 * SIGMA_P * math.sqrt(3)


def test_a_urdf_robot_is_calibrated_through_its_dh_table(tmp_path, capsys):
    """The URDF's DH table as dq_fk from-urdf writes it is the nominal: the file written."""
    assert main(['from-urdf', vendor_path(UR5), '--tip', UR5[1], '-o',
                 str(tmp_path / 'ur5.yaml')]) == 0
    robot = Robot(str(tmp_path / 'ur5.yaml'))
    rng = np.random.default_rng(5)
    truth = perturbed(robot, rng)
    q = configurations(robot, rng, 60)
    write_csv(tmp_path / 'data.csv', robot, measure(robot, truth, q, rng, True), True)
    assert main(['calibrate', vendor_path(UR5), str(tmp_path / 'data.csv'), '--tip', UR5[1],
                 '-o', str(tmp_path / 'calibrated.yaml'), '--report',
                 str(tmp_path / 'report.json'), '--plot', str(tmp_path / 'residuals.png')]) == 0
    report = json.loads((tmp_path / 'report.json').read_text())
    calibrated = Robot(str(tmp_path / 'calibrated.yaml'))
    world, end = (pose_matrix_of_tuple((*report[k]['xyz'], *report[k]['quaternion_xyzw']))
                  for k in ('fixed_frame_in_measurement', 'measured_in_end'))
    held_out = configurations(robot, rng, 40)
    error = np.linalg.norm(robot.poses(truth, held_out, WORLD, END)[:, :3, 3] -
                           calibrated.poses(calibrated.rows, held_out, world, end)[:, :3, 3],
                           axis=1)
    assert np.sqrt(np.mean(error ** 2)) < 1.5 * SIGMA_P * math.sqrt(3)
    with open(tmp_path / 'residuals.png', 'rb') as stream:
        assert stream.read(8) == b'\x89PNG\r\n\x1a\n'
    # the links of the URDF kept: a calibrated URDF from it
    capsys.readouterr()
    assert main(['urdf', str(tmp_path / 'calibrated.yaml')]) == 0
    urdf = capsys.readouterr().out
    assert '<robot' in urdf and 'wrist_3_link' in urdf


def test_the_jacobian_is_the_central_difference_of_the_prediction():
    for name in ('ur5e', 'panda'):
        model = load_robot_description(shipped_robot_path(name))
        table = model.chain.table
        dh = DhPoseModel.from_table(table, model.frame_names[1:1 + len(table.a)])
        rng = np.random.default_rng(3)
        params = dh.nominal(np.r_[rng.normal(size=3), rng.normal(size=3)],
                            np.r_[rng.normal(0, 0.1, 3), rng.normal(size=3)])
        q = rng.uniform(-2, 2, (5, model.chain.dof))
        _, quat, jac = dh.predict(params, q, jacobian=True)
        h = 1e-6
        for k in range(len(params)):
            step = np.zeros(len(params))
            step[k] = h
            p1, q1 = dh.predict(params + step, q)
            p0, q0 = dh.predict(params - step, q)
            np.testing.assert_allclose((p1 - p0) / (2 * h), jac[:, :3, k], atol=1e-6)
            # the rotation rate: 2 vec(dq q*) in the measurement frame
            dq = (q1 - q0) / (2 * h)
            conj = quat * np.array([1, -1, -1, -1])
            w0, v0 = quat_product(dq, conj)
            np.testing.assert_allclose(2 * v0, jac[:, 3:, k], atol=1e-6)


def quat_product(p, q):
    pw, pv, qw, qv = p[:, :1], p[:, 1:], q[:, :1], q[:, 1:]
    return pw * qw - np.sum(pv * qv, 1, keepdims=True), pw * qv + qw * pv + np.cross(pv, qv)


def test_rank_keeps_the_first_of_dependent_columns():
    j = np.array([[1.0, 2.0, 0.0, 1.0], [0.0, 0.0, 1.0, 1.0], [0.0, 0.0, 0.0, 0.0]])
    assert identifiable(j, [0, 1, 2, 3]) == ([0, 2], [1, 3])
    assert identifiable(j, [3, 2, 1, 0]) == ([3, 2], [1, 0])


def test_a_plan_beats_random_configurations_and_is_within_the_limits(tmp_path):
    assert main(['calibrate', 'ur5e', '--plan', '30', '-o', str(tmp_path / 'plan.csv')]) == 0
    with open(tmp_path / 'plan.csv', encoding='utf-8') as stream:
        rows = list(csv.reader(stream))
    robot = Robot('ur5e')
    assert rows[0] == robot.joints and len(rows) == 31
    q = np.array(rows[1:], dtype=float)
    assert (q >= np.maximum(robot.limits[:, 0], -math.pi) - 1e-9).all()
    assert (q <= np.minimum(robot.limits[:, 1], math.pi) + 1e-9).all()
    model = load_robot_description(robot.path)
    dh = DhPoseModel.from_table(model.chain.table, robot.frames)
    from dq_fk_ros.calibration.identify import observability_index, scaled_jacobian
    params = dh.nominal()
    every = scaled_jacobian(dh, params, q, True, np.arange(len(params)))
    kept = sorted(identifiable(every, preference(dh))[0])
    planned = observability_index(scaled_jacobian(dh, params, q, True, kept), len(q))
    rng = np.random.default_rng(0)
    for _ in range(5):
        r = configurations(robot, rng, 30)
        assert planned > observability_index(scaled_jacobian(dh, params, r, True, kept), 30)


@pytest.mark.parametrize('header,row,message', [
    (['a', 'x', 'y', 'z'], ['0'] * 4, 'no column'),
    (None, ['0'] * 8 + ['nan'], 'line 2: column z: not a finite number'),
    (None, ['0'] * 8 + ['secret'], 'line 2: column z: not a finite number'),
    ('quaternion', ['0'] * 9 + ['0.5', '0', '0', '0.5'], 'not a unit quaternion'),
    ('partial', ['0'] * 10, 'without the others'),
])
def test_a_csv_that_does_not_fit_the_robot_is_refused_in_one_line(
        tmp_path, header, row, message):
    joints = Robot('ur5e').joints
    if header is None:
        header = joints + ['x', 'y', 'z']
    elif header == 'quaternion':
        header = joints + ['x', 'y', 'z', 'qx', 'qy', 'qz', 'qw']
    elif header == 'partial':
        header = joints + ['x', 'y', 'z', 'qx']
    path = tmp_path / 'data.csv'
    with open(path, 'w', newline='', encoding='utf-8') as stream:
        csv.writer(stream).writerows([header, row[:len(header)] + row[len(header):]])
    with pytest.raises(DataError) as caught:
        read_csv(path, joints)
    text = str(caught.value)
    assert message in text and '\n' not in text and 'secret' not in text


def test_too_few_measurements_for_the_parameters_are_refused_in_one_line(tmp_path, capsys):
    robot = Robot('ur5e')
    rng = np.random.default_rng(2)
    q = configurations(robot, rng, 10)
    write_csv(tmp_path / 'data.csv', robot, measure(robot, robot.rows, q, rng, False), False)
    assert main(['calibrate', 'ur5e', str(tmp_path / 'data.csv'), '-o',
                 str(tmp_path / 'out.yaml')]) == 1
    err = capsys.readouterr().err
    assert ('8 measurements fitted (10 given, 2 held out): at least 11 are needed for the 33 '
            'parameters') in err
    assert err.count('\n') == 1 and not (tmp_path / 'out.yaml').exists()


def test_values_no_robot_has_are_refused_in_one_line(tmp_path, capsys):
    """1e308 overflowed the fit into numpy warnings and 'SVD did not converge'."""
    robot = Robot('ur5e')
    rows = [[1e308, 0, 0, 0, 0, 0, 1e308, 0, 0]] * 20
    write_csv(tmp_path / 'data.csv', robot, rows, False)
    assert main(['calibrate', 'ur5e', str(tmp_path / 'data.csv'), '-o',
                 str(tmp_path / 'out.yaml')]) == 1
    err = capsys.readouterr().err
    assert err == 'dq_fk: a joint value of magnitude 1e+308: at most 10000 (rad, m) is taken\n'


def test_a_fifo_is_not_read_as_a_csv(tmp_path):
    os.mkfifo(tmp_path / 'data.csv')
    with pytest.raises(DataError, match='not a regular file'):
        read_csv(tmp_path / 'data.csv', Robot('ur5e').joints)


def test_a_plan_too_large_is_refused_in_one_line(tmp_path, capsys):
    assert main(['calibrate', 'ur5e', '--plan', '1000000', '-o', str(tmp_path / 'p.csv')]) == 1
    err = capsys.readouterr().err
    assert '--plan 1000000: give 1 to 1000 configurations' in err and err.count('\n') == 1


def _ur5e_data(tmp_path, name='data.csv'):
    robot = Robot('ur5e')
    rng = np.random.default_rng(5)
    q = configurations(robot, rng, 40)
    write_csv(tmp_path / name, robot, measure(robot, perturbed(robot, rng), q, rng, False),
              False)
    return tmp_path / name


@pytest.mark.parametrize('option', ['-o', '--report', '--plot'])
@pytest.mark.parametrize('victim', ['data', 'robot', 'hard link', 'symbolic link'])
def test_an_output_naming_an_input_is_refused_and_the_input_kept(
        tmp_path, capsys, option, victim):
    # `-o DATA.csv` had overwritten the measurements and exited 0
    data = _ur5e_data(tmp_path)
    robot = tmp_path / 'ur5e.yaml'
    robot.write_text(open(shipped_robot_path('ur5e'), encoding='utf-8').read())
    before = {p: p.read_bytes() for p in (data, robot)}
    target = {'data': data, 'robot': robot}.get(victim)
    if victim == 'hard link':
        target = tmp_path / 'alias.csv'
        os.link(data, target)
    elif victim == 'symbolic link':
        target = tmp_path / 'link.csv'
        os.symlink(data, target)
    outputs = {'-o': tmp_path / 'out.yaml', '--report': tmp_path / 'r.json',
               '--plot': tmp_path / 'p.png'}
    outputs[option] = target
    argv = ['calibrate', str(robot), str(data)]
    for name, path in outputs.items():
        argv += [name, str(path)]
    assert main(argv) == 1
    err = capsys.readouterr().err
    assert err.count('\n') == 1 and option in err and ('would overwrite' in err
                                                       or 'symbolic link' in err), err
    assert {p: p.read_bytes() for p in (data, robot)} == before
    assert not any(outputs[o].exists() for o in outputs if o != option)


def test_two_outputs_on_one_path_are_refused(tmp_path, capsys):
    data = _ur5e_data(tmp_path)
    assert main(['calibrate', 'ur5e', str(data), '-o', str(tmp_path / 'x'), '--report',
                 str(tmp_path / 'x')]) == 1
    err = capsys.readouterr().err
    assert '--report' in err and 'would overwrite -o' in err and err.count('\n') == 1


def test_a_csv_saved_as_csv_utf8_with_a_byte_order_mark_is_read(tmp_path):
    # a spreadsheet's "CSV UTF-8" puts U+FEFF before the header: "no column joint_1" before
    data = _ur5e_data(tmp_path)
    marked = tmp_path / 'marked.csv'
    marked.write_bytes(b'\xef\xbb\xbf' + data.read_bytes())
    joints = Robot('ur5e').joints
    plain, with_mark = read_csv(data, joints), read_csv(marked, joints)
    np.testing.assert_array_equal(plain.q, with_mark.q)
    np.testing.assert_array_equal(plain.positions, with_mark.positions)
