"""
The folders that make ``import tf2_ros`` find this package (``dq_fk tf compat-path``).

Put first on ``PYTHONPATH``, they make ``tf2_ros``, ``tf2_py``, ``tf2_geometry_msgs`` and
``tf2_sensor_msgs`` resolve to dq_fk_ros.

``compat/tf2`` holds re-exports named as tf2's packages and their submodules;
``compat/sensor_msgs_py`` holds ``sensor_msgs_py.point_cloud2``, given only where the
environment has no ``sensor_msgs_py`` of its own (common_interfaces' is not on PyPI). Nothing is
installed: the folders are on the path only where the user puts them, so on a full ROS
install the real tf2 stays what ``import tf2_ros`` finds (this prints a note there).
"""

import importlib.util
import os

HERE = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), 'compat')
PACKAGES = ('tf2_ros', 'tf2_py', 'tf2_geometry_msgs', 'tf2_sensor_msgs')


def _found_elsewhere(name: str):
    """Return where ``name`` is importable from, outside the compat folders (None: nowhere)."""
    try:
        spec = importlib.util.find_spec(name)
    except (ImportError, ValueError):
        return None
    if spec is None or spec.origin is None:
        return None
    return None if os.path.abspath(spec.origin).startswith(HERE + os.sep) else spec.origin


def compat_folders() -> list:
    """Return the folders to put first on ``PYTHONPATH`` (module doc)."""
    folders = [os.path.join(HERE, 'tf2')]
    if _found_elsewhere('sensor_msgs_py') is None:
        folders.append(os.path.join(HERE, 'sensor_msgs_py'))
    return folders


def real_tf2() -> list:
    """Return ``[(package, where)]`` of tf2 packages the environment has of its own."""
    return [(name, where) for name in PACKAGES if (where := _found_elsewhere(name))]


def main(out, err) -> int:
    """Print the folders joined by ``os.pathsep``; a note on ``err`` where tf2 is installed."""
    for name, where in real_tf2():
        print(f'note: this environment has its own {name} ({where}); with the printed '
              f'folder first on PYTHONPATH, import {name} finds dq_fk_ros instead', file=err)
    print(os.pathsep.join(compat_folders()), file=out)
    return 0


__all__ = ['compat_folders', 'main', 'PACKAGES', 'real_tf2']
