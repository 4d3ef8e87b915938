"""
``dq_fk calibrate``: a robot's DH table identified from measured poses, or a plan to measure.

``dq_fk calibrate ROBOT DATA.csv -o CALIBRATED.yaml [--report REPORT.json]``, or ``--bag
BAG --pose-topic TOPIC`` instead of the CSV; ``dq_fk calibrate ROBOT --plan N -o
PLAN.csv`` proposes N configurations to measure. ROBOT is a DH file, a shipped robot or a
URDF/xacro (through its DH table, as ``dq_fk from-urdf`` writes it). The method:
:mod:`dq_fk_ros.calibration.identify`; docs/calibration.md.
"""

import csv
import datetime
import json
import math
import os
import sys

from dq_fk_ros.calibration.calibrated_yaml import calibrated_yaml
from dq_fk_ros.calibration.dh_model import DhPoseModel
from dq_fk_ros.calibration.identify import (
    calibrate, Measurements, plan_configurations, require_scipy, residuals_of)
from dq_fk_ros.calibration.measurements import read_bag, read_csv
from dq_fk_ros.calibration.report import plot_residuals, report
from dq_fk_ros.description.loading import is_urdf, resolve_robot
from dq_fk_ros.description.schema import (
    load_robot_description, MAX_FILE_BYTES, parse_robot_description)
from dq_fk_ros.errors import DqFkError, RobotDescriptionError
import numpy as np

MAX_PLAN = 1000   # configurations (20 candidates each are scored)


class CalibrateUsage(DqFkError):
    """A mistake in ``dq_fk calibrate``'s arguments (one line)."""


def robot_text(args) -> tuple:
    """Return ``(DH YAML text, what it came from, its RobotModel)`` of ROBOT (a URDF converted)."""
    path = resolve_robot(args.robot)
    if is_urdf(path):
        from dq_fk_ros.description.from_urdf import load_urdf_description
        conversion, _ = load_urdf_description(path, args.urdf_base, args.urdf_tip, 'standard',
                                              dict(args.package))
        source = f'{path} (its DH table, as dq_fk from-urdf writes it)'
        return conversion.text, source, parse_robot_description(conversion.text, source)
    model = load_robot_description(path)  # its one-line errors first
    with open(path, encoding='utf-8') as stream:
        return stream.read(MAX_FILE_BYTES + 1), path, model


def check_arguments(args) -> None:
    """Refuse argument combinations and values that cannot work (one line)."""
    if args.plan is not None:
        if not 1 <= args.plan <= MAX_PLAN:
            raise CalibrateUsage(f'--plan {args.plan}: give 1 to {MAX_PLAN} configurations')
        if args.data or args.bag:
            raise CalibrateUsage('--plan proposes configurations to measure: give no data')
        return
    if bool(args.data) == bool(args.bag):
        raise CalibrateUsage('give the measurements: DATA.csv, or --bag BAG --pose-topic TOPIC')
    if args.bag and not args.pose_topic:
        raise CalibrateUsage('--bag needs --pose-topic (the measured geometry_msgs/PoseStamped)')
    if not 0.0 <= args.holdout <= 0.9:
        raise CalibrateUsage(f'--holdout {args.holdout}: a share from 0 to 0.9')
    for name in ('position_noise', 'orientation_noise', 'max_gap', 'max_motion'):
        value = getattr(args, name)
        if value is not None and not (math.isfinite(value) and value > 0):
            raise CalibrateUsage(f'--{name.replace("_", "-")} {value}: a positive number')


def check_outputs(args) -> None:
    """
    Refuse an output that is an input, another output, or a symbolic link (one line).

    Outputs (``-o``, ``--report``, ``--plot``) are never an input (ROBOT, DATA.csv, a file
    of ``--bag``'s folder), as for bags: compared after links, and by inode (a hard link).
    """
    inputs = [('ROBOT', resolve_robot(args.robot))]
    inputs += [(what, path) for what, path in (('DATA', args.data), ('--bag', args.bag)) if path]
    outputs = [(what, path) for what, path in (('-o', args.output), ('--report', args.report),
                                               ('--plot', args.plot)) if path]
    seen = []
    for what, path in outputs:
        real = os.path.realpath(path)
        for other, given in inputs + seen:
            there = os.path.realpath(given)
            if real == there or real.startswith(there.rstrip(os.sep) + os.sep) or \
                    _same_inode(path, given):
                raise CalibrateUsage(f'{what} {path} would overwrite {other} {given}; outputs '
                                     'are never an input or another output: choose another path')
        if os.path.islink(path):
            raise CalibrateUsage(f'{what} {path} is a symbolic link; not following it (give the '
                                 'real path)')
        seen.append((what, path))


def _same_inode(a, b) -> bool:
    try:
        return os.path.samefile(a, b)
    except OSError:   # (one of them does not exist yet)
        return False


def cmd_calibrate(args) -> int:
    """Run ``dq_fk calibrate`` (module doc); return the exit code."""
    check_arguments(args)
    check_outputs(args)
    require_scipy()
    text, source, model = robot_text(args)
    table = model.chain.table
    n_rows = len(table.a)
    dh = DhPoseModel.from_table(table, model.frame_names[1:1 + n_rows])
    names = list(table.names)
    if args.plan is not None:
        q, index = plan_configurations(dh, table.limits, table.angular, args.plan,
                                       not args.position_only, args.seed)
        _write_plan(args.output, names, q)
        print(f'wrote {args.output}: {len(q)} configurations of {model.name} within its limits '
              f'(observability index O1 {index * 1e3:.3g} mm, '
              f'{"positions" if args.position_only else "poses"} measured)')
        return 0
    if args.bag:
        data, counts = read_bag(args.bag, names, args.pose_topic, args.joint_topic,
                                args.max_gap, args.max_motion, not args.position_only)
    else:
        data, counts = read_csv(args.data, names), None
        if args.position_only and data.quaternions is not None:
            data = Measurements(data.q, data.positions)
    result = calibrate(dh, data, args.position_noise, args.orientation_noise, args.holdout,
                       args.seed)
    n = 4 * n_rows
    rows = result.params[:n].reshape(n_rows, 4)
    what = args.bag or args.data
    note = (f'Calibrated by dq_fk calibrate on {datetime.date.today().isoformat()} from '
            f'{os.path.basename(what)} ({len(data)} measurements, '
            f'{"poses" if data.quaternions is not None else "positions"}); the DH rows are '
            f'identified, everything else as in {os.path.basename(source.split(" (")[0])}.')
    out = calibrated_yaml(text, source, dh.nominal_rows, rows, note)
    check = parse_robot_description(out, args.output)   # what every tool will load
    if not np.allclose(np.stack([check.chain.table.theta0, check.chain.table.d0,
                                 check.chain.table.a, check.chain.table.alpha], 1), rows,
                       rtol=0, atol=1e-8):
        raise RobotDescriptionError(f'{args.output}: the rows written do not load back')
    with open(args.output, 'w', encoding='utf-8') as stream:
        stream.write(out)
    sources = {'robot': model.name, 'robot_file': source, 'data': what,
               'measurements': len(data),
               'orientation_measured': data.quaternions is not None}
    if counts is not None:
        sources['pairing'] = counts
    content = report(result, sources)
    if args.report:
        with open(args.report, 'w', encoding='utf-8') as stream:
            json.dump(content, stream, indent=2)
            stream.write('\n')
    if args.plot:
        before = np.linalg.norm(residuals_of(dh, result.nominal, data).position, axis=1)
        after = np.linalg.norm(residuals_of(dh, result.params, data).position, axis=1)
        plot_residuals(args.plot, before, after, f'{model.name}: {len(data)} measurements')
    _summary(args, result, content)
    return 0


def _write_plan(path, names, q):
    with open(path, 'w', encoding='utf-8', newline='') as stream:
        writer = csv.writer(stream)
        writer.writerow(names)
        for row in q:
            writer.writerow([f'{v:.6f}' for v in row])


def _summary(args, result, content) -> None:
    residuals = content['residuals']

    def line(part):
        b, a = residuals['before'].get(part), residuals['after'].get(part)
        if b is None:
            return None
        text = (f'{part}: position RMS {b["position_rms_m"] * 1e3:.3f} -> '
                f'{a["position_rms_m"] * 1e3:.3f} mm (max {b["position_max_m"] * 1e3:.3f} -> '
                f'{a["position_max_m"] * 1e3:.3f})')
        if 'orientation_rms_rad' in b:
            text += (f', orientation RMS {math.degrees(b["orientation_rms_rad"]):.4f} -> '
                     f'{math.degrees(a["orientation_rms_rad"]):.4f} deg')
        return text + f' on {b["measurements"]} measurements'
    print(f'observability index O1 {result.observability * 1e3:.3g} mm; held at their nominal '
          f'values (the data cannot separate them): '
          f'{", ".join(content["unidentifiable"]) or "none"}')
    for part in ('fit', 'holdout'):
        text = line(part)
        if text:
            print(text)
    wrote = [args.output] + [p for p in (args.report, args.plot) if p]
    print(f'wrote {", ".join(wrote)}', file=sys.stderr)


__all__ = ['cmd_calibrate']
