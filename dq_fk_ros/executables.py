"""Where this package's programs are, for starting them as processes (demo, tests, benchmarks)."""

import os
import sys

MODULES = {'dq_fk_node': 'dq_fk_ros.node',
           'fake_joint_publisher': 'dq_fk_ros.fake_joint_publisher',
           'dq_fk': 'dq_fk_ros.cli'}


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
