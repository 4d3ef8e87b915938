"""
``dq_fk_bag``: joint states from rosbag2 files, without rosbag2 (bags via ``rosbags``).

* ``dq_fk_bag process IN_BAG OUT_BAG --robot FILE``: every JointState of the bag, through the
  same input rules as the node, then the batched FK in chunks, written as /tf, /tf_static and
  the pose topics of the node to a new bag (:mod:`dq_fk_ros.bag.process`); ``--csv`` writes
  the end-effector pose per message.
* ``dq_fk_bag process IN [IN ...] --output-dir OUT --robot FILE``: every bag under the IN
  paths, on every core (``--jobs``) or a Dask cluster (``--scheduler``), resumable
  (:mod:`dq_fk_ros.bag.fleet`); exit 1 if any bag failed.
* ``dq_fk_bag tf BAG TARGET SOURCE --csv FILE (--rate HZ | --at-topic TOPIC)``: a frame's
  pose in another over the bag's TF (:mod:`dq_fk_ros.bag.tf_export`).
* ``dq_fk_bag play BAG``: publishes the bag's JointState messages with their recorded timing
  (``--rate``, ``--loop``, ``--start``, ``--duration``, ``--clock``) into a running node
  (:mod:`dq_fk_ros.ros.bag_play`).
"""

import argparse
import math
import os
import sys

from dq_fk_ros.bag.process import check_compression, process_bag, ProcessOptions
from dq_fk_ros.cli.dq_fk import add_package_option, add_urdf_chain_options
from dq_fk_ros.cli.interrupts import interrupted_code, take_signals
from dq_fk_ros.description.loading import load_robot
from dq_fk_ros.errors import BagDamaged, BagError, RobotDescriptionError
from dq_fk_ros.storage.formats import STORAGES
from dq_fk_ros.storage.text import printable


def output_bytes(path) -> int:
    """Return the bytes of an output bag: a file's size, or the files' of a bag folder."""
    if os.path.isfile(path):
        return os.path.getsize(path)
    total = 0
    for folder, _, files in os.walk(path):
        total += sum(os.path.getsize(os.path.join(folder, name)) for name in files
                     if os.path.isfile(os.path.join(folder, name)))
    return total


def _megabytes(size):
    return f'{size / 1e6:.1f} MB' if size >= 100_000 else f'{size / 1e3:.1f} kB'


def summary_line(path, s) -> str:
    """One line saying what ``process`` read, wrote and skipped (a :class:`ProcessSummary`)."""
    parts = [f'{path}: {s.read} JointState messages, {s.written} written'
             + (f' to {s.output} ({_megabytes(output_bytes(s.output))})' if s.output else '')]
    if s.incomplete:
        parts.append(f'{s.incomplete} incomplete (joints not all seen yet)')
    if s.rejected:
        parts.append('rejected (' + ', '.join(f'{k}: {v}' for k, v in
                                              sorted(s.rejected.items())) + ')')
    if s.unknown_joints:
        parts.append('unknown joints ignored: ' + ', '.join(printable(n, 40) for n in
                                                            s.unknown_joints))
    return ', '.join(parts)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog='dq_fk_bag', description='Joint-state bags: offline FK into a new bag, or replay.')
    sub = parser.add_subparsers(dest='command', required=True)
    p = sub.add_parser(
        'process', help='compute every frame for every JointState of a bag (or of many)',
        usage='dq_fk_bag process IN_BAG OUT_BAG --robot R [options]\n'
              '       dq_fk_bag process IN [IN ...] --output-dir OUT --robot R '
              '[--jobs N | --scheduler ADDRESS] [options]')
    p.add_argument('paths', nargs='+', metavar='IN',
                   help='IN_BAG OUT_BAG; with --output-dir: bags, bag files or folders of bags')
    p.add_argument('--robot', required=True,
                   help='DH robot file, URDF/xacro file or shipped robot name (e.g. rl15, '
                   'ur5e); required: a bag does not say which robot recorded it')
    add_urdf_chain_options(p)
    add_package_option(p)
    p.add_argument('--topic', help='JointState topic (default: the only one in the bag)')
    p.add_argument('--storage', choices=STORAGES, default='mcap')
    p.add_argument('--compression', choices=('none', 'zstd', 'lz4'), default='none',
                   help='MCAP chunks compressed (default none: the fastest; zstd: the '
                   'smallest)')
    p.add_argument('--reference-reader', action='store_true',
                   help="read an MCAP bag with rosbags' reader (the reference; slower) "
                   'instead of a chunk at a time')
    p.add_argument('--overwrite', action='store_true', help='replace OUT_BAG if it exists')
    p.add_argument('--csv', metavar='FILE', help='also write the end-effector pose per message')
    p.add_argument('--csv-only', action='store_true', help='write the CSV and no bag')
    p.add_argument('--copy-input', action='store_true', help='copy the input topics through')
    p.add_argument('--pose-namespace', default='/dq_fk_node',
                   help='pose topics are <ns>/pose/<frame> (default /dq_fk_node, as the node)')
    p.add_argument('--frame-prefix', default='', help='as the node parameter frame_prefix')
    p.add_argument('--poses', choices=('all', 'end', 'none'), default='end',
                   help='pose topics written besides /tf, /tf_static and /robot_description: '
                   "the end effector's (default), every frame on TF (a bag many times the "
                   'input), none')
    p.add_argument('--dh-frames', dest='dh_frames', action='store_true', default=None,
                   help="as the node's publish_dh_frames: /tf and poses carry the DH frames "
                   "too (a URDF robot's default is the URDF's links only, as "
                   'robot_state_publisher; a DH file has them anyway)')
    p.add_argument('--out-of-limits', choices=('warn', 'clamp', 'reject'), default='warn')
    p.add_argument('--quiet', action='store_true', help='no progress output')
    g = p.add_argument_group('a fleet of bags (docs/bags.md, "A fleet of bags")')
    g.add_argument('--output-dir', metavar='OUT',
                   help='process every bag under the IN paths into OUT (same layout)')
    g.add_argument('--jobs', type=int, metavar='N',
                   help='worker processes (default: the CPUs this process may use)')
    g.add_argument('--scheduler', metavar='ADDRESS',
                   help="a Dask scheduler (tcp://HOST:8786) or 'local' (a LocalCluster of "
                   "--jobs processes); needs pip install 'dq_fk_ros[cluster]'")
    g.add_argument('--force', action='store_true', help='redo bags whose output is complete')
    g.add_argument('--report', metavar='FILE', help='also write the closing table as JSON')
    g.add_argument('--window-messages', type=int, metavar='N',
                   help='JointStates per window of a large MCAP bag (default: automatic)')
    p = sub.add_parser('example', help='write a bag of joint states (a sine sweep) to try '
                       'the other commands on')
    p.add_argument('out_bag', metavar='OUT_BAG')
    p.add_argument('--robot', default='rl15',
                   help='DH robot file, URDF/xacro file or shipped robot name (default rl15)')
    add_urdf_chain_options(p)
    add_package_option(p)
    p.add_argument('--seconds', type=finite, default=10.0, help='length (default 10 s)')
    p.add_argument('--rate', type=finite, default=100.0, help='messages per second (100)')
    p = sub.add_parser('play', help='publish the JointState messages with recorded timing')
    p.add_argument('bag', metavar='BAG')
    p.add_argument('--topic', help='JointState topic (default: the only one in the bag)')
    p.add_argument('--output-topic', metavar='TOPIC',
                   help="publish on this topic instead of the bag's (e.g. a robot's namespace)")
    p.add_argument('--rate', type=finite, default=1.0, help='speed factor (default 1)')
    p.add_argument('--loop', action='store_true', help='start over at the end')
    p.add_argument('--start', type=finite, default=0.0, help='skip this many seconds')
    p.add_argument('--duration', type=finite, help='play this many seconds')
    p.add_argument('--clock', action='store_true', help='publish /clock (use_sim_time)')
    p.add_argument('--wait-for-subscribers', type=int, default=0, metavar='N',
                   help='start once N subscriptions are matched (default 0: at once)')
    p.add_argument('--quiet', action='store_true', help='no progress output')
    p = sub.add_parser('tf', help="one frame's pose in another over the bag's TF, as CSV "
                       '(at a rate, or at the stamps of a topic)')
    p.add_argument('bag', metavar='BAG')
    p.add_argument('target', metavar='TARGET', help='the frame the pose is in (e.g. base_link)')
    p.add_argument('source', metavar='SOURCE', help='the frame whose pose is written')
    p.add_argument('--csv', required=True, metavar='FILE',
                   help='output: stamp_ns,x,y,z,qx,qy,qz,qw (m; quaternion x y z w)')
    when = p.add_mutually_exclusive_group(required=True)
    when.add_argument('--rate', type=finite, metavar='HZ',
                      help='a row every 1/HZ s over the span of /tf')
    when.add_argument('--at-topic', metavar='TOPIC',
                      help="a row at each message's header stamp (e.g. a camera's images)")
    p.add_argument('--start', type=finite, default=0.0,
                   help='seconds after the bag starts to read /tf from (default 0)')
    p.add_argument('--end', type=finite, help='seconds after the bag starts to stop at')
    return parser


def check_one_bag_arguments(args) -> None:
    """Refuse fleet options without --output-dir, and anything but IN_BAG OUT_BAG."""
    if len(args.paths) != 2:
        raise BagError(f'process takes IN_BAG OUT_BAG ({len(args.paths)} paths given); '
                       f'for many bags: process IN [IN ...] --output-dir OUT')
    fleet = [name for name, value in (('--jobs', args.jobs), ('--scheduler', args.scheduler),
                                      ('--force', args.force), ('--report', args.report),
                                      ('--window-messages', args.window_messages))
             if value not in (None, False)]
    if fleet:
        raise BagError(f'{fleet[0]} is for a fleet of bags: give --output-dir OUT')


def process_many(args) -> int:
    """Run ``process IN [IN ...] --output-dir OUT``: the fleet; print the closing table."""
    import json
    from dq_fk_ros.bag.fleet import process_fleet, report_table
    for name, value in (('--csv', args.csv), ('--csv-only', args.csv_only),
                        ('--overwrite', args.overwrite)):
        if value:
            raise BagError(f'{name} is for one bag; with --output-dir, outputs not recorded '
                           f'complete are replaced and --force redoes the others')
    for name, value in (('--jobs', args.jobs), ('--window-messages', args.window_messages)):
        if value is not None and value < 1:
            raise BagError(f'{name} must be at least 1, got {value}')
    if args.report and os.path.isdir(args.report):
        raise BagError(f'--report {args.report} is a folder; give a file name')
    options = ProcessOptions(
        topic=args.topic, storage=args.storage, copy_input=args.copy_input,
        pose_namespace=args.pose_namespace, frame_prefix=args.frame_prefix,
        out_of_limits=args.out_of_limits, progress=False, poses=args.poses,
        dh_frames=args.dh_frames, compression=args.compression,
        reference_reader=args.reference_reader)
    check_compression(options)
    summary = process_fleet(args.paths, args.output_dir, args.robot, options, jobs=args.jobs,
                            scheduler=args.scheduler, force=args.force,
                            progress=not args.quiet, window_messages=args.window_messages,
                            base=args.urdf_base, tip=args.urdf_tip,
                            packages=dict(args.package))
    print(report_table(summary))
    if args.report:
        with open(args.report, 'w', encoding='utf-8') as stream:
            json.dump(summary.as_dict(), stream, indent=1)
            stream.write('\n')
    return 1 if summary.failed else 0


def write_example(args) -> int:
    """Write ``dq_fk_bag example``'s bag: the robot's joints sweeping as fake_joint_publisher."""
    from dq_fk_ros.bag.example import write_example_bag
    from dq_fk_ros.ros.fake_joint_publisher import JointMotion
    if not (0 < args.seconds <= 3600 and 0 < args.rate <= 10000):
        raise BagError('--seconds must be from 0 to 3600 and --rate from 0 to 10000')
    if os.path.lexists(args.out_bag):
        raise BagError(f'{args.out_bag}: exists; choose another path')
    model = load_robot(args.robot, args.urdf_base, args.urdf_tip,
                       packages=dict(args.package)).model
    motion = JointMotion('sine', model.limits)
    count = write_example_bag(args.out_bag, model.joint_names, motion.sample, args.seconds,
                              args.rate)
    print(f'{args.out_bag}: {count} JointState messages of {model.name} on /joint_states')
    return 0


def export_tf_csv(args) -> int:
    """Run ``dq_fk_bag tf``; print what was written and what TF could not answer."""
    from dq_fk_ros.storage.reading import open_reader
    from dq_fk_ros.bag.tf_export import export_tf
    if args.start < 0 or (args.end is not None and args.end <= args.start):
        raise BagError('--start must be 0 or more and --end after it')
    reader = open_reader(args.bag)
    origin, length = reader.start_time, max(0, reader.end_time - reader.start_time)
    reader.close()
    if args.start * 1e9 >= length and (args.start or length):
        raise BagError(f'--start {args.start:g} s is at or past the end of {args.bag} (its '
                       f'messages span {length / 1e9:.3f} s)')
    start = origin + round(args.start * 1e9) if args.start else None
    end = origin + round(args.end * 1e9) if args.end is not None and \
        args.end * 1e9 < length else None   # (past the end: to the end)
    done = export_tf(args.bag, args.target, args.source, args.csv, rate_hz=args.rate,
                     at_topic=args.at_topic, start=start, end=end)
    print(f'{args.csv}: {done.rows} poses of {printable(args.source)} in '
          f'{printable(args.target)}' + (f'; {done.unanswered} stamps TF could not answer, '
                                         'left out' if done.unanswered else ''))
    if done.dropped:
        print(f'dq_fk_bag: {args.bag}: {done.dropped}', file=sys.stderr)
    return 0


def finite(text) -> float:
    """Parse a finite float for argparse (``nan`` and ``inf`` are refused)."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f'{text!r} is not a number') from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f'{text!r} is not a finite number')
    return value


def main(argv=None) -> int:
    """
    Run ``dq_fk_bag``; return the exit code.

    0: done. 1: the bag was read, but part of it was damaged (skipped) or no message could
    be used. 2: the command cannot run as given (arguments, paths, robot file, topics,
    a refused output); nothing is written then. 130 (143): interrupted by Ctrl-C
    (SIGTERM), with :func:`~dq_fk_ros.cli.interrupts.take_signals` in force.
    """
    args = build_parser().parse_args(argv)
    try:
        if args.command == 'process' and args.output_dir is not None:
            return process_many(args)
        if args.command == 'process':
            check_one_bag_arguments(args)
            robot = load_robot(args.robot, args.urdf_base, args.urdf_tip,
                               packages=dict(args.package)).model
            options = ProcessOptions(
                topic=args.topic, storage=args.storage, overwrite=args.overwrite,
                csv_path=args.csv, csv_only=args.csv_only, copy_input=args.copy_input,
                pose_namespace=args.pose_namespace, frame_prefix=args.frame_prefix,
                out_of_limits=args.out_of_limits, progress=not args.quiet, poses=args.poses,
                dh_frames=args.dh_frames, compression=args.compression,
                reference_reader=args.reference_reader)
            s = process_bag(args.paths[0], args.paths[1], robot, options)
            print(summary_line(args.paths[0], s))
        elif args.command == 'example':
            return write_example(args)
        elif args.command == 'tf':
            return export_tf_csv(args)
        else:
            from dq_fk_ros.ros.bag_play import play_bag, PlayOptions  # rclpy only here
            s = play_bag(args.bag, PlayOptions(
                topic=args.topic, rate=args.rate, loop=args.loop, start_s=args.start,
                duration_s=args.duration, clock=args.clock, progress=not args.quiet,
                wait_for=args.wait_for_subscribers, output_topic=args.output_topic))
            print(f'{args.bag}: published {s.sent} JointState messages')
        for line in (s.note, s.error):
            if line:
                print(f'dq_fk_bag: {line}', file=sys.stderr)
        if s.error:
            return 1
    except BagDamaged as exc:
        print(f'dq_fk_bag: {exc}', file=sys.stderr)
        return 1
    except (BagError, RobotDescriptionError, FileNotFoundError) as exc:
        print(f'dq_fk_bag: {exc}', file=sys.stderr)
        return 2
    except OSError as exc:  # the file system refused (permissions, disk full)
        print(f'dq_fk_bag: {exc.strerror or exc}'
              + (f': {exc.filename}' if exc.filename else ''), file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print('dq_fk_bag: interrupted; what was finished is kept (a fleet run again resumes '
              'the rest)', file=sys.stderr)
        fleet = sys.modules.get('dq_fk_ros.bag.fleet')
        if fleet is not None and fleet.ABANDONED:  # a Dask client would wait 10 s to close
            sys.stdout.flush()
            sys.stderr.flush()
            os._exit(interrupted_code())
        return interrupted_code()
    return 0


if __name__ == '__main__':
    take_signals()
    sys.exit(main())
