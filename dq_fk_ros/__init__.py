"""
Dual-quaternion forward kinematics from a DH table, published to ROS 2.

Layers, bottom up (a layer imports only those below it; docs/architecture.md):

* :mod:`dq_fk_ros.kinematics`: dual quaternions, DH chains and trees (a table and an
  engine each), twists; numpy and the C kernel only.
* :mod:`dq_fk_ros.description`: the YAML robot description, URDF in and out.
* :mod:`dq_fk_ros.messages`: joint-state input rules, the merge and its input, the CDR
  wire format, the output table and plan; no rclpy.
* :mod:`dq_fk_ros.transforms`: tf2's BufferCore over arrays (TF read back), no rclpy.
* :mod:`dq_fk_ros.storage`: the bag formats (MCAP, rosbag2, ROS 1) read and written.
* :mod:`dq_fk_ros.bag`: processing bags (one, a window, a fleet), TF out of bags.
* :mod:`dq_fk_ros.ros`: the rclpy nodes, their outputs and message conversion, TF tools.
* :mod:`dq_fk_ros.viewers`: ``dq_fk_view`` (a browser) and ``dq_fk_foxglove``.
* :mod:`dq_fk_ros.cli`: the ``dq_fk`` and ``dq_fk_bag`` command lines.

Beside them, :mod:`dq_fk_ros.tf`: tf2_ros's ``Buffer``, ``TransformListener`` and
broadcasters without tf2 (``from dq_fk_ros import tf as tf2_ros``).

The surface a user imports (``from dq_fk_ros import load_robot``); each name is loaded on
first use, so ``import dq_fk_ros`` stays light (no ROS, no rosbags until asked):

* :func:`load_robot` (a DH file, a URDF or xacro, a shipped name) -> ``LoadedRobot`` whose
  ``model`` is a :class:`RobotModel` (``forward_all(q)``, ``frame_poses(q)``, ...);
* :class:`KinematicChain`, :class:`DHJoint`, :class:`DualQuaternion`: the numerical core;
  :func:`kernel_info`: whether it runs on the compiled kernel or on numpy;
* :func:`process_bag` (with :class:`ProcessOptions`, returning a :class:`ProcessSummary`):
  joint states in a bag -> every frame's pose and TF in another; :func:`process_fleet`
  (a :class:`FleetSummary`): every bag under some folders, on every core or a Dask cluster;
* the errors: :class:`DqFkError` and under it :class:`RobotDescriptionError`,
  :class:`ParameterError`, :class:`BagError`, :class:`CdrError`.
"""

__version__ = '0.1.0'   # setup.py and package.xml read the same (test_package_xml.py)

_SURFACE = {
    'load_robot': 'dq_fk_ros.description.loading',
    'RobotModel': 'dq_fk_ros.description.robot_model',
    'KinematicChain': 'dq_fk_ros.kinematics.dh',
    'DHJoint': 'dq_fk_ros.kinematics.dh',
    'DualQuaternion': 'dq_fk_ros.kinematics.dual_quaternion',
    'process_bag': 'dq_fk_ros.bag.process',
    'ProcessOptions': 'dq_fk_ros.bag.process',
    'ProcessSummary': 'dq_fk_ros.bag.process',
    'process_fleet': 'dq_fk_ros.bag.fleet',
    'FleetSummary': 'dq_fk_ros.bag.fleet',
    'kernel_info': 'dq_fk_ros.kinematics.kernel',
    'DqFkError': 'dq_fk_ros.errors',
    'RobotDescriptionError': 'dq_fk_ros.errors',
    'ParameterError': 'dq_fk_ros.errors',
    'BagError': 'dq_fk_ros.errors',
    'CdrError': 'dq_fk_ros.errors',
}
__all__ = sorted(_SURFACE)


def __getattr__(name):
    """Import a name of the surface on first use (PEP 562)."""
    if name not in _SURFACE:
        raise AttributeError(f'module {__name__!r} has no attribute {name!r}')
    import importlib
    value = getattr(importlib.import_module(_SURFACE[name]), name)
    globals()[name] = value
    return value


def __dir__():
    """List the surface with the module's own names."""
    return sorted(set(globals()) | set(_SURFACE))
