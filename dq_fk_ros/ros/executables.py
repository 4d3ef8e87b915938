"""This package's programs: where they are installed, and the main loop their nodes share."""

import gc
import importlib
import os
import signal
import sys

# After a publisher counts its matched subscriptions, the subscribers' side of the match may
# still be in progress (messages sent then are lost): wait this long before the first one.
MATCH_SETTLE_S = 0.5

MODULES = {'dq_fk_node': 'dq_fk_ros.ros.node',
           'fake_joint_publisher': 'dq_fk_ros.ros.fake_joint_publisher',
           'dq_fk_view': 'dq_fk_ros.viewers.view',
           'dq_fk': 'dq_fk_ros.cli.dq_fk',
           'dq_fk_bag': 'dq_fk_ros.cli.dq_fk_bag'}


def executable(name) -> list:
    """
    Return the argv prefix that runs program ``name``.

    The installed executable in ``<prefix>/lib/dq_fk_ros/`` (what ``ros2 run`` runs) when
    there is one, else ``python -m`` of its module.
    """
    path = os.path.join(sys.prefix, 'lib', 'dq_fk_ros', name)
    if os.access(path, os.X_OK):
        return [path]
    return [sys.executable, '-m', MODULES[name]]


def take_sigint() -> None:
    """
    Let SIGINT (Ctrl-C) raise ``KeyboardInterrupt`` and let SIGINT and SIGTERM through.

    What Python does in a terminal's foreground, also where it would not: a script's
    ``prog &`` starts with SIGINT ignored (bash does so for background jobs), and a parent may
    hand its children SIGINT blocked; either way a ``kill -INT`` before rclpy takes the signal
    would be lost and the program would run on.
    """
    signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT, signal.SIGTERM})
    signal.signal(signal.SIGINT, _interrupt)


_interrupted = []   # a Ctrl-C taken by _interrupt (before rclpy takes the signal)
_importing = []     # set while run_program imports the program's module


def _interrupt(signum, frame):
    _interrupted.append(signum)
    if _importing:
        # nothing to clean up yet, and a KeyboardInterrupt raised inside importlib's own
        # callbacks is printed as "Exception ignored ... Traceback" (a fresh-clone CI run)
        os._exit(0)
    raise KeyboardInterrupt


def run_main(main) -> int:
    """
    Return ``main()``'s exit code, 0 after a Ctrl-C that comes before it takes the signal.

    After such a Ctrl-C, any error on the way out is its own: Python 3.11 wraps a
    KeyboardInterrupt raised in a class's ``__set_name__`` (while rclpy's modules are
    imported) in a RuntimeError (test_program_signals.py's ``while-starting``).
    """
    take_sigint()
    try:
        code = main()
    except KeyboardInterrupt:  # while starting: rclpy not yet up, nothing to clean up
        return 0
    except Exception:
        if not _interrupted:
            raise
        return 0
    return 0 if code is None else code


def run_program(module: str) -> int:
    """Import ``module`` (a Ctrl-C meanwhile stops it quietly) and return its ``main()``'s code."""
    def main():
        _importing.append(module)
        try:
            program = importlib.import_module(module)
        finally:
            _importing.clear()
        return program.main()
    return run_main(main)


def run_dq_fk_node() -> int:
    """Run the ``dq_fk_node`` console script."""
    return run_program('dq_fk_ros.ros.node')


def run_fake_joint_publisher() -> int:
    """Run the ``fake_joint_publisher`` console script."""
    return run_program('dq_fk_ros.ros.fake_joint_publisher')


def run_dq_fk_view() -> int:
    """Run the ``dq_fk_view`` console script."""
    return run_program('dq_fk_ros.viewers.view')


def run_dq_fk_foxglove() -> int:
    """Run the ``dq_fk_foxglove`` console script."""
    return run_program('dq_fk_ros.viewers.foxglove_live')


def spin_until_shutdown(program, make_node, user_errors, args=None, usage=None) -> int:
    """
    Create a node with ``make_node()`` and spin it until SIGINT/SIGTERM; return the exit code.

    As Jazzy's rclpy examples do, with try/finally. A user error while starting (an
    exception of ``user_errors`` such as a bad robot file, a parameter of the wrong type, a
    missing ``--params-file``) is printed as one line ``program: message`` and gives exit
    code 1, without a traceback. ``-h``/``--help`` (before ``--ros-args``) prints ``usage``
    and exits 0 without starting ROS.
    """
    from dq_fk_ros.ros.parameters import wants_help
    if usage is not None and wants_help(sys.argv if args is None else args):
        print(usage, end='')
        return 0
    import rclpy
    from rclpy._rclpy_pybind11 import RCLError
    from rclpy.exceptions import (
        InvalidParameterTypeException, InvalidParameterValueException,
        NameValidationException, ParameterException)
    from rclpy.executors import ExternalShutdownException
    if not isinstance(user_errors, tuple):
        user_errors = (user_errors,)
    node = None
    missing = _missing_params_files(sys.argv if args is None else args)
    if missing:  # rcl would log an error of its own and raise; say it once, plainly
        print(f'{program}: --params-file {missing}: no such file', file=sys.stderr)
        return 1
    try:
        rclpy.init(args=args)
        node = make_node()
        # everything built so far (rclpy, numpy, the robot) lives as long as the program:
        # out of the collector's sight, a full collection takes microseconds, not ~15 ms
        gc.freeze()
        rclpy.spin(node)
    except (*user_errors, RCLError, ParameterException, InvalidParameterValueException,
            NameValidationException) as exc:
        if node is None and not rclpy.ok():
            return 0  # SIGINT while starting: rclpy failed on the context it shut down
        print(f'{program}: {_one_line(exc)}', file=sys.stderr)
        return 1
    except InvalidParameterTypeException as exc:
        print(f'{program}: {_one_line(exc)} (a double needs a decimal point, e.g. 10.0; '
              f'a bool is true or false)', file=sys.stderr)
        return 1
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except Exception:
        if node is None and not rclpy.ok():
            return 0  # SIGINT while starting, in the middle of rclpy's own set-up
        raise
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
    return 0


def _missing_params_files(argv):
    """Return the first ``--params-file`` argument that is not a file, or None."""
    argv = list(argv)
    for k, arg in enumerate(argv[:-1]):
        if arg == '--params-file' and '--ros-args' in argv[:k] and \
                not os.path.isfile(argv[k + 1]):
            return argv[k + 1]
    return None


def _one_line(exc):
    """Return the first line of an exception's message, without rcl's source locations."""
    from dq_fk_ros.errors import first_line
    return first_line(exc).split(', at /')[0]


VIEWER_PORT = 8765   # dq_fk_view's and dq_fk_foxglove's default port (Foxglove's own)


def add_mesh_options(parser) -> None:
    """Add ``--package NAME=DIR`` and ``--mesh-dir DIR``: where a URDF's meshes may come from."""
    parser.add_argument('--package', action='append', default=[], metavar='NAME=DIR',
                        help="where package NAME is, for the URDF's package:// meshes "
                        '(repeatable; before the ament index and ROS_PACKAGE_PATH)')
    parser.add_argument('--mesh-dir', action='append', default=[], metavar='DIR',
                        help='a folder file:// meshes may be served from (repeatable; '
                        'none by default)')


def check_mesh_options(parser, args) -> None:
    """Check the options of :func:`add_mesh_options`; set ``args.packages`` ({name: dir})."""
    from dq_fk_ros.description.packages import parse_package_option
    try:
        args.packages = dict(parse_package_option(option) for option in args.package)
    except ValueError as exc:
        parser.error(str(exc))
    for folder in args.mesh_dir:
        if not os.path.isdir(folder):
            parser.error(f'--mesh-dir {folder}: no such folder')
