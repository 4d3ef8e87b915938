"""
``dq_fk``: the robot description on the command line.

``dq_fk validate FILE...``, ``dq_fk fk FILE --joints ...``, ``dq_fk urdf FILE``,
``dq_fk plot FILE``, ``dq_fk from-urdf ROBOT.urdf -o robot.yaml``, ``dq_fk list`` run no ROS
process; ``dq_fk show ROBOT`` starts the node and the view (:mod:`dq_fk_ros.ros.show`);
``dq_fk tf echo|frames|monitor`` read TF (:mod:`dq_fk_ros.ros.tf_tools`); ``dq_fk
calibrate`` identifies a DH table from measured poses (:mod:`dq_fk_ros.cli.calibrate`).
FILE is a DH YAML file, a URDF or xacro file (converted on the way, as ``from-urdf`` does),
or the name of a shipped robot (``rl15``, ``puma560``...).
"""

import argparse
import json
import math
import os
import sys

from dq_fk_ros.description.loading import load_robot, resolve_robot
from dq_fk_ros.description.packages import parse_package_option
from dq_fk_ros.description.schema import load_robot_description
from dq_fk_ros.description.shipped import shipped_robot_path, shipped_robots
from dq_fk_ros.description.to_urdf import matrix_to_rpy, robot_to_urdf
from dq_fk_ros.errors import DqFkError, RobotDescriptionError
from dq_fk_ros.kinematics.dual_quaternion import DualQuaternion
from dq_fk_ros.messages.output_plan import OutputPlan
import numpy as np


class UsageError(Exception):
    """A command-line mistake; the message is one line for the user."""


def parse_joint_values(model, tokens, degrees) -> np.ndarray:
    """
    Joint values from ``q1 q2 ...`` (all, in chain order) or ``name=value ...`` (others 0).

    With ``degrees``, values of revolute joints are degrees; prismatic ones are metres.
    """
    names = model.joint_names
    revolute = model.angular
    if not tokens:
        tokens = ['0'] * len(names)
    named = ['=' in t for t in tokens]
    if any(named) and not all(named):
        raise UsageError('--joints takes either plain values in chain order or name=value '
                         'pairs, not a mix')
    values = {}
    if all(named):
        for token in tokens:
            name, _, text = token.partition('=')
            if name not in names:
                raise UsageError(f'--joints: unknown joint {name!r}; joints of '
                                 f'{model.name}: {", ".join(names)}')
            if name in values:
                raise UsageError(f'--joints: {name} is given twice '
                                 f'({values[name]:g} and {text}); give each joint once')
            values[name] = _number(text, name)
        values = {n: values.get(n, 0.0) for n in names}  # unnamed joints stay at zero
    else:
        if len(tokens) != len(names):
            raise UsageError(f'--joints: {model.name} has {len(names)} joints '
                             f'({", ".join(names)}), got {len(tokens)} values')
        values = {n: _number(t, n) for n, t in zip(names, tokens)}
    q = np.array([values[n] for n in names])
    if degrees:
        q[revolute] = np.radians(q[revolute])
    return q


def _number(text, name):
    try:
        value = float(text)
    except ValueError:
        raise UsageError(f'--joints: value of {name} is {text!r}, not a number') from None
    if not math.isfinite(value):
        raise UsageError(f'--joints: value of {name} must be finite, got {text!r}')
    return value


def frames_table(model, q, dh_frames=None) -> list:
    """
    One dict per frame: name, TF parent, on TF, pose in the fixed frame (m; quaternion x y z w).

    The pose is absolute (in the fixed frame), not relative to ``tf_parent``. ``on_tf``: the
    node publishes the frame's transform (``dh_frames``: its ``publish_dh_frames``; None:
    the robot's default), ``root`` for a floating joint's child (a TF root, no transform).
    """
    poses = model.forward_all(q)
    on_tf = set(OutputPlan(model, dh_frames=dh_frames).tf_frames)
    roots = set(model.tree_roots)
    rows = []
    for k, (name, parent, h) in enumerate(zip(model.frame_names, model.parent_frames, poses)):
        dq = DualQuaternion(h)
        pose = dq.to_pose_xyzw()
        matrix = dq.to_matrix()
        rows.append({'frame': name, 'tf_parent': parent,
                     'on_tf': 'yes' if k in on_tf else 'root' if k in roots else 'no',
                     'position': pose[:3].tolist(),
                     'quaternion_xyzw': pose[3:].tolist(),
                     'rpy': list(matrix_to_rpy(matrix[:3, :3])), 'matrix': matrix.tolist()})
    return rows


def _robot(args):
    """Load FILE of a command (a URDF with its --urdf-base/--urdf-tip)."""
    return load_robot(args.file, getattr(args, 'urdf_base', None),
                      getattr(args, 'urdf_tip', None), packages=dict(args.package)).model


def package_option(text) -> tuple:
    """Check one ``--package NAME=DIR``; return ``(name, folder)`` (argparse's type)."""
    try:
        return parse_package_option(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def add_package_option(parser) -> None:
    """Add ``--package NAME=DIR`` (repeatable): where a xacro's ``$(find NAME)`` is."""
    parser.add_argument('--package', metavar='NAME=DIR', action='append', default=[],
                        type=package_option,
                        help='for a xacro: $(find NAME) is DIR (repeat for more; before the '
                        'ament index, ROS_PACKAGE_PATH and the folders above the file)')


def add_urdf_chain_options(parser) -> None:
    """Add ``--base``/``--tip`` (once ``--urdf-base``/``--urdf-tip``): a URDF's chain's ends."""
    parser.add_argument('--base', '--urdf-base', dest='urdf_base', metavar='LINK',
                        help='for a URDF: the link the DH chain starts at (default: the root)')
    parser.add_argument('--tip', '--urdf-tip', dest='urdf_tip', metavar='LINK',
                        help='for a URDF: the link the DH chain ends at (default: the child of '
                        'the last moving joint of the longest chain)')


def cmd_validate(args) -> int:
    failed = 0
    for name in args.files:
        path = resolve_robot(name)
        try:
            robot = load_robot(path, packages=dict(args.package))
        except RobotDescriptionError as exc:
            print(exc, file=sys.stderr)
            failed += 1
            continue
        model = robot.model
        rows = sum(len(chain.joints) for _, chain, _ in model.chains)
        chains = f'{len(model.chains)} chains, ' if model.branches else ''
        print(f'{path}: ok ({model.name}, {model.chain.convention} DH, {chains}'
              f'{rows} rows, {model.dof} joints, {len(model.frame_names)} frames)')
        if robot.conversion is not None:
            print(f'  {robot.summary()}')
        for line in robot.warnings:
            print(f'dq_fk: warning: {line}', file=sys.stderr)
    return 1 if failed else 0


def cmd_fk(args) -> int:
    model = _robot(args)
    if args.code:  # the straight-line FK code the node runs for this robot
        print(model.frame_poses_code(), end='')
        return 0
    q = parse_joint_values(model, args.joints, args.deg)
    lower, upper = model.limits[:, 0], model.limits[:, 1]
    for n, v, lo, hi in zip(model.joint_names, q, lower, upper):
        if v < lo or v > hi:
            print(f'warning: {n} = {v:.6g} is outside its limits [{lo:.6g}, {hi:.6g}]',
                  file=sys.stderr)
    rows = frames_table(model, q, args.dh_frames)
    if args.json:
        for r in rows:
            if not args.rpy:
                r.pop('rpy')
            if not args.matrix:
                r.pop('matrix')
        json.dump({'robot': model.name, 'fixed_frame': model.fixed_frame,
                   'joints': dict(zip(model.joint_names, q.tolist())), 'frames': rows},
                  sys.stdout, indent=2)
        print()
        return 0
    width = max(len(r['frame']) for r in rows)
    pwidth = max(len(r['tf_parent']) for r in rows)
    header = f'{"frame":{width}s}  {"tf_parent":{pwidth}s}  {"on_tf":5s}  ' \
             f'{"x":>10s} {"y":>10s} {"z":>10s}  ' \
             f'{"qx":>9s} {"qy":>9s} {"qz":>9s} {"qw":>9s}'
    if args.rpy:
        header += f'  {"roll":>9s} {"pitch":>9s} {"yaw":>9s}'
    print(f'# {model.name}: every pose is in {model.fixed_frame}, not relative to its tf_parent '
          f'(m; quaternion x y z w{"; rpy rad" if args.rpy else ""}); on_tf: the node publishes '
          f'its transform (root: a TF root, below a floating joint)')
    print(header)
    for r in rows:
        line = (f'{r["frame"]:{width}s}  {r["tf_parent"]:{pwidth}s}  {r["on_tf"]:5s}  '
                + ' '.join(f'{_tidy(v):10.6f}' for v in r['position']) + '  '
                + ' '.join(f'{_tidy(v):9.6f}' for v in r['quaternion_xyzw']))
        if args.rpy:
            line += '  ' + ' '.join(f'{_tidy(v):9.6f}' for v in r['rpy'])
        print(line)
        if args.matrix:
            for row in r['matrix']:
                print('    ' + ' '.join(f'{_tidy(v):10.6f}' for v in row))
    return 0


def _tidy(value):
    """Round away rounding noise so that the table never shows -0.000000."""
    return round(value, 9) + 0.0


def cmd_urdf(args) -> int:
    model = _robot(args)
    text = robot_to_urdf(model)
    if args.output in (None, '-'):
        sys.stdout.write(text)
    else:
        with open(args.output, 'w', encoding='utf-8') as stream:
            stream.write(text)
        print(f'wrote {args.output} ({model.name}, links named after its frames)',
              file=sys.stderr)
    return 0


def cmd_plot(args) -> int:
    from dq_fk_ros.description.plot import DEFAULT_VIEW, save_robot_plot
    extension = os.path.splitext(args.output)[1].lower()
    if extension not in ('.png', '.svg'):
        raise UsageError(f'-o {args.output}: give a .png or .svg file name')
    view = tuple(args.view) if args.view else DEFAULT_VIEW
    if not all(math.isfinite(v) for v in view):
        raise UsageError(f'--view: azimuth and elevation must be finite degrees, got {view}')
    folder = os.path.dirname(os.path.abspath(args.output))
    if not os.path.isdir(folder):
        raise UsageError(f'-o {args.output}: folder {folder} does not exist')
    model = _robot(args)
    q = parse_joint_values(model, args.joints, args.deg)
    try:
        save_robot_plot(model, q, args.output, view, args.helpers)
    except ImportError:
        raise UsageError('dq_fk plot needs matplotlib (pip install matplotlib; on a ROS '
                         'install: apt install python3-matplotlib)') from None
    print(f'wrote {args.output} ({model.name})', file=sys.stderr)
    return 0


def cmd_from_urdf(args) -> int:
    from dq_fk_ros.description.from_urdf import load_urdf_description  # URDF modules: lazily
    conversion, _ = load_urdf_description(args.file, args.base, args.tip, args.convention,
                                          dict(args.package))
    if args.output in (None, '-'):
        sys.stdout.write(conversion.text)
    else:
        if os.path.isdir(args.output):
            raise UsageError(f'-o {args.output} is a folder; give a file name')
        with open(args.output, 'w', encoding='utf-8') as stream:
            stream.write(conversion.text)
    for joint in conversion.skipped:
        print(f'skipped side branch {joint.name} ({joint.kind}) -> {joint.child}',
              file=sys.stderr)
    for line in conversion.warnings:
        print(f'dq_fk: warning: {line}', file=sys.stderr)
    where = 'standard output' if args.output in (None, '-') else args.output
    print(f'wrote {where}: {args.convention} DH chain {conversion.base} -> {conversion.tip} '
          f'of {args.file}', file=sys.stderr)
    return 0


def cmd_show(args) -> int:
    from dq_fk_ros.ros.show import show  # rclpy's programs: imported only for this command
    if not 0 <= args.port <= 65535:
        raise UsageError(f'--port {args.port}: give a port 1 to 65535')
    return show(args.robot, args.port, args.host, dict(args.package),
                args.urdf_base or '', args.urdf_tip or '')


def cmd_tf(args) -> int:
    if args.tf_command == 'compat-path':
        from dq_fk_ros.cli import compat_path
        return compat_path.main(sys.stdout, sys.stderr)
    import signal
    from dq_fk_ros.ros import tf_tools  # rclpy's: imported only for this command
    # Ctrl-C ends echo and monitor (exit 0), also as a script's background job, which
    # starts with SIGINT ignored
    signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT, signal.SIGTERM})
    signal.signal(signal.SIGINT, signal.default_int_handler)
    signal.signal(signal.SIGTERM, signal.default_int_handler)
    try:
        return _tf_command(tf_tools, args)
    except KeyboardInterrupt:
        return 0


def _tf_command(tf_tools, args):
    if args.tf_command == 'echo':
        if not 0 < args.rate <= 1000:
            raise UsageError(f'--rate {args.rate:g}: give 0 to 1000 Hz')
        return tf_tools.echo(args.target, args.source, args.rate, args.count)
    if args.tf_command == 'frames':
        if args.bag is None and not 0 < args.seconds <= 3600:
            raise UsageError(f'--seconds {args.seconds:g}: give 0 to 3600')
        try:
            return tf_tools.frames(args.output, args.bag, args.seconds)
        except RuntimeError as exc:
            raise UsageError(str(exc)) from None
    if (args.target is None) != (args.source is None):
        raise UsageError('monitor takes no frames, or TARGET and SOURCE')
    return tf_tools.monitor(args.target, args.source, args.seconds)


def cmd_calibrate(args) -> int:
    from dq_fk_ros.cli.calibrate import cmd_calibrate as run  # scipy: lazily
    return run(args)


def cmd_list(args) -> int:
    for name in shipped_robots():
        model = load_robot_description(shipped_robot_path(name))
        print(f'{name:20s} {model.dof} joints  {shipped_robot_path(name)}')
    if args.verbose:
        from dq_fk_ros.kinematics.kernel import kernel_info
        from dq_fk_ros.messages.cdr import COMPILED_WHY
        print(f"FK kernel: {kernel_info()['why']}")
        print(f'CDR writer and JointState reader of the node: {COMPILED_WHY}')
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog='dq_fk', description='Forward kinematics from a YAML DH robot description '
        '(dual quaternions). FILE is a path or a shipped robot name (see "dq_fk list").')
    sub = parser.add_subparsers(dest='command', required=True)
    p = sub.add_parser('validate', help='check robot description files')
    p.add_argument('files', nargs='+', metavar='FILE')
    add_package_option(p)
    p.set_defaults(func=cmd_validate)
    p = sub.add_parser('fk', help='print the pose of every frame')
    p.add_argument('file', metavar='FILE')
    p.add_argument('--joints', nargs='*', default=[], metavar='Q',
                   help='all joint values in chain order, or name=value pairs (joints not '
                        'named are 0); rad and m, or degrees with --deg')
    p.add_argument('--deg', action='store_true', help='revolute joint values in degrees')
    p.add_argument('--rpy', action='store_true', help='also print roll, pitch, yaw (rad)')
    p.add_argument('--matrix', action='store_true', help='also print the 4x4 matrix')
    p.add_argument('--json', action='store_true', help='print JSON instead of a table')
    p.add_argument('--dh-frames', dest='dh_frames', action='store_true', default=None,
                   help="mark the DH frames on TF too, as the node's publish_dh_frames "
                   "(default: the robot's: a URDF's links only, a DH file's every frame)")
    p.add_argument('--code', action='store_true',
                   help="print the robot's generated straight-line FK code (frame_poses) and "
                   'stop')
    add_urdf_chain_options(p)
    add_package_option(p)
    p.set_defaults(func=cmd_fk)
    p = sub.add_parser('urdf', help='write a URDF whose links are the published frames')
    p.add_argument('file', metavar='FILE')
    p.add_argument('-o', '--output', help='output file (default: standard output)')
    add_urdf_chain_options(p)
    add_package_option(p)
    p.set_defaults(func=cmd_urdf)
    p = sub.add_parser('plot', help='draw the robot at given joint values (PNG or SVG)')
    p.add_argument('file', metavar='FILE')
    p.add_argument('--joints', nargs='*', default=[], metavar='Q',
                   help='as for fk (default: all zeros)')
    p.add_argument('--deg', action='store_true', help='revolute joint values in degrees')
    p.add_argument('-o', '--output', required=True, metavar='OUT.png|OUT.svg',
                   help='the picture to write (.png or .svg)')
    p.add_argument('--view', nargs=2, type=float, metavar=('AZIMUTH', 'ELEVATION'),
                   default=None, help='camera direction in degrees (default -60 25)')
    p.add_argument('--helpers', action='store_true',
                   help="also draw the DH method's helper frames (dh0..., <tip>_dh0...)")
    add_urdf_chain_options(p)
    add_package_option(p)
    p.set_defaults(func=cmd_plot)
    p = sub.add_parser('from-urdf', help='write the DH robot description of a URDF chain')
    p.add_argument('file', metavar='ROBOT.urdf|ROBOT.urdf.xacro')
    p.add_argument('--base', metavar='LINK', help='first link of the chain (default: the root)')
    p.add_argument('--tip', metavar='LINK',
                   help='last link of the chain (default: the child of the last moving joint '
                        'of the longest chain; links fixed below it are kept anyway)')
    p.add_argument('--convention', choices=('standard', 'modified'), default='standard',
                   help='DH convention of the table (default: standard, Spong)')
    p.add_argument('-o', '--output', metavar='robot.yaml',
                   help='output file (default: standard output)')
    add_package_option(p)
    p.set_defaults(func=cmd_from_urdf)
    p = sub.add_parser('show', help='your robot in a browser with a slider per joint (node, '
                       'view and joint panel, as urdf_tutorial display.launch.py)')
    p.add_argument('robot', metavar='ROBOT', help='a URDF or xacro file, a DH YAML file or a '
                   'shipped robot name')
    p.add_argument('--port', type=int, default=8765, help="the page's port (default 8765)")
    p.add_argument('--host', default='127.0.0.1',
                   help='address the page listens on (default 127.0.0.1: this machine only)')
    add_urdf_chain_options(p)
    add_package_option(p)
    p.set_defaults(func=cmd_show)
    p = sub.add_parser('tf', help='TF without tf2: echo a transform, draw the frames, monitor '
                       '(tf2_echo, view_frames, tf2_monitor)')
    tf_sub = p.add_subparsers(dest='tf_command', required=True)
    q = tf_sub.add_parser('echo', help="print SOURCE's pose in TARGET, as tf2_echo")
    q.add_argument('target', metavar='TARGET')
    q.add_argument('source', metavar='SOURCE')
    q.add_argument('--rate', type=float, default=1.0, help='prints a second (default 1)')
    q.add_argument('--count', type=int, help='stop after this many (default: Ctrl-C)')
    q = tf_sub.add_parser('frames', help='write frames.gv and frames.pdf, as view_frames')
    q.add_argument('--bag', help="a bag's TF instead of listening")
    q.add_argument('-o', '--output', default='frames.pdf', help='the PDF (default frames.pdf; '
                   'the .gv beside it)')
    q.add_argument('--seconds', type=float, default=5.0, help='listen this long (default 5)')
    q = tf_sub.add_parser('monitor', help='rate and delay per frame, as tf2_monitor')
    q.add_argument('target', metavar='TARGET', nargs='?')
    q.add_argument('source', metavar='SOURCE', nargs='?')
    q.add_argument('--seconds', type=float, help='stop after this long (default: Ctrl-C)')
    tf_sub.add_parser('compat-path', help='print the folder that, first on PYTHONPATH, makes '
                      'import tf2_ros (tf2_py, tf2_geometry_msgs, tf2_sensor_msgs) find this '
                      'package (docs/tf.md)')
    p.set_defaults(func=cmd_tf)
    p = sub.add_parser('calibrate', help='identify the DH table from measured poses (CSV or '
                       'bag), or plan the configurations to measure (docs/calibration.md)')
    p.add_argument('robot', metavar='ROBOT', help='a DH file, a shipped robot name or a URDF')
    p.add_argument('data', metavar='DATA.csv', nargs='?', help='a column per joint (rad, m), '
                   'x, y, z (m) and, if measured, qx, qy, qz, qw')
    p.add_argument('-o', '--output', required=True, metavar='CALIBRATED.yaml',
                   help='the robot file with the identified rows (with --plan: PLAN.csv)')
    p.add_argument('--report', metavar='REPORT.json', help='what was identified, how well')
    p.add_argument('--plot', metavar='RESIDUALS.png', help='position errors before and after')
    p.add_argument('--bag', help='measurements from a bag instead: --pose-topic paired with '
                   'its joint states')
    p.add_argument('--pose-topic', metavar='TOPIC', help='the measured PoseStamped topic')
    p.add_argument('--joint-topic', metavar='TOPIC', help='the JointState topic (default: '
                   "the bag's only one)")
    p.add_argument('--max-gap', type=float, default=0.05, metavar='S', help='a pose needs a '
                   'joint state within this many seconds before and after (default 0.05)')
    p.add_argument('--max-motion', type=float, default=1e-3, metavar='Q', help='leave out a '
                   'pose taken while a joint moved more than this (rad or m; default 0.001)')
    p.add_argument('--position-only', action='store_true',
                   help='use the measured positions only (no orientation)')
    p.add_argument('--position-noise', type=float, metavar='M',
                   help='position noise (m, one sigma; default: estimated)')
    p.add_argument('--orientation-noise', type=float, metavar='RAD',
                   help='orientation noise (rad, one sigma; default: estimated)')
    p.add_argument('--holdout', type=float, default=0.2, metavar='SHARE',
                   help='share of the measurements kept out of the fit to judge it (0.2)')
    p.add_argument('--seed', type=int, default=0, help='for the held-out draw and --plan')
    p.add_argument('--plan', type=int, metavar='N',
                   help='write N configurations within the limits that maximise the '
                   'observability index, as a CSV to drive the robot to')
    add_urdf_chain_options(p)
    add_package_option(p)
    p.set_defaults(func=cmd_calibrate)
    p = sub.add_parser('list', help='list the shipped robots')
    p.add_argument('--verbose', '-v', action='store_true',
                   help='also say which FK path is active (the C kernel or numpy)')
    p.set_defaults(func=cmd_list)
    return parser


def main(argv=None) -> int:
    """
    Run the ``dq_fk`` command; return the exit code.

    0: done. 1: an invalid robot file or argument (one line on stderr each). 2: a usage
    mistake that argparse reports (unknown option, missing argument).
    """
    args = build_parser().parse_args(argv)
    try:
        return args.func(args)
    except BrokenPipeError:  # the reader went away (| head): stop quietly
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        return 1
    except (DqFkError, UsageError, ValueError, OSError) as exc:
        print(f'dq_fk: {exc}', file=sys.stderr)
        return 1


if __name__ == '__main__':
    sys.exit(main())
