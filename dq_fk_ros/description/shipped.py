"""
The robots shipped with the package (``config/``) and the package's other shared folders.

:func:`share_folders` finds a folder the package installs under ``share/dq_fk_ros``
(colcon's ament index, or pip's data folder of the environment it installed into) or holds in
its source tree (an editable install): ``config`` for the robots, ``web`` for dq_fk_view's
page.
"""

import os
import sys
import sysconfig


def share_folders(name: str) -> list[str]:
    """
    Return the candidate folders ``name`` (``config``, ``web``) may be in, in order.

    The ament index (colcon, a ROS install), then pip's data folder (``pip install``:
    ``<prefix>/share/dq_fk_ros``, where ``AMENT_PREFIX_PATH`` is not set), then the source tree.
    """
    candidates = []
    try:
        from ament_index_python.packages import get_package_share_directory
        candidates.append(os.path.join(get_package_share_directory('dq_fk_ros'), name))
    except Exception:  # not installed through ament (or ament_index missing)
        pass
    for prefix in (sysconfig.get_path('data'), sys.prefix):
        folder = os.path.join(prefix, 'share', 'dq_fk_ros', name)
        if folder not in candidates:
            candidates.append(folder)
    source_tree = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    candidates.append(os.path.join(source_tree, name))
    return candidates


def shipped_robot_path(name: str) -> str:
    """
    Find a robot file shipped with the package by name, e.g. ``'rl15'``.

    Looks in the installed share directory (colcon) first, then in the source tree's
    ``config/`` (an editable install).
    """
    filename = name if name.endswith('.yaml') else name + '.yaml'
    candidates = share_folders('config')
    for folder in candidates:
        path = os.path.join(folder, filename)
        if os.path.isfile(path):
            return path
    raise FileNotFoundError(f'no shipped robot {filename!r} in {" or ".join(candidates)}')


def shipped_robots_dir() -> str:
    """Return the folder of the robots shipped with the package."""
    return os.path.dirname(shipped_robot_path('rl15'))


def shipped_robots() -> list[str]:
    """List the names of the robot files shipped in ``config/``."""
    folder = shipped_robots_dir()
    return sorted(f[:-5] for f in os.listdir(folder) if f.endswith('.yaml'))


__all__ = ['share_folders', 'shipped_robot_path', 'shipped_robots', 'shipped_robots_dir']
