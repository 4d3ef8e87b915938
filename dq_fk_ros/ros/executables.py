"""This package's programs: where they are installed, and the main loop their nodes share."""

import os
import sys

# After a publisher counts its matched subscriptions, the subscribers' side of the match may
# still be in progress (messages sent then are lost): wait this long before the first one.
MATCH_SETTLE_S = 0.5

MODULES = {'dq_fk_node': 'dq_fk_ros.ros.node',
           'fake_joint_publisher': 'dq_fk_ros.ros.fake_joint_publisher',
           'dq_fk': 'dq_fk_ros.cli.dq_fk',
           'dq_fk_bag': 'dq_fk_ros.cli.dq_fk_bag'}


def executable(name):
    """
    Return the argv prefix that runs program ``name``.

    The installed executable in ``<prefix>/lib/dq_fk_ros/`` (what ``ros2 run`` runs) when
    there is one, else ``python -m`` of its module.
    """
    path = os.path.join(sys.prefix, 'lib', 'dq_fk_ros', name)
    if os.access(path, os.X_OK):
        return [path]
    return [sys.executable, '-m', MODULES[name]]


def spin_until_shutdown(program, make_node, user_errors, args=None):
    """
    Create a node with ``make_node()`` and spin it until SIGINT/SIGTERM; return the exit code.

    As Jazzy's rclpy examples do, with try/finally. An exception of ``user_errors`` while
    creating the node (a bad robot file, a bad parameter) is printed as one line
    ``program: message`` and gives exit code 1, without a traceback.
    """
    import rclpy
    from rclpy.executors import ExternalShutdownException
    rclpy.init(args=args)
    node = None
    try:
        node = make_node()
        rclpy.spin(node)
    except user_errors as exc:
        print(f'{program}: {exc}', file=sys.stderr)
        return 1
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
    return 0
