"""Vendor URDFs from the example-robot-data wheel (a dev requirement), for the tests."""

import glob
import os
import sysconfig

from dq_fk_ros.description.loading import load_robot

# the arms the tests drive through the node and the message layer: (path, tip)
UR5 = ('ur_description/urdf/ur5_robot.urdf', 'tool0')
PANDA = ('panda_description/urdf/panda.urdf', 'panda_leftfinger')
Z1 = ('z1_description/urdf/z1.urdf', 'link06')  # its gripper: a side branch


def robots_dir():
    """Return the URDF folder of the example-robot-data wheel; one clear line if missing."""
    pattern = os.path.join(sysconfig.get_paths()['purelib'], 'cmeel.prefix', 'share',
                           'example-robot-data', 'robots')
    found = glob.glob(pattern)
    assert found, ('example-robot-data is not installed in this environment: '
                   'pip install -r requirements/dev.txt (make setup does)')
    return found[0]


def vendor_path(arm):
    """Return the file of one of the arms above."""
    return os.path.join(robots_dir(), arm[0])


def vendor_robot(arm):
    """Load one of the arms above, converted (a LoadedRobot)."""
    return load_robot(vendor_path(arm), tip=arm[1])
