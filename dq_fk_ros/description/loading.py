"""
One way in for every tool: a robot from a YAML DH file, a URDF/xacro file or a shipped name.

``load_robot('rl15')``, ``load_robot('config/mine.yaml')``, ``load_robot('ur5.urdf')``
and ``robot_from_urdf_text(xml)`` all give a :class:`LoadedRobot`; a URDF is converted by
:mod:`dq_fk_ros.description.from_urdf` on the way (its own link names kept).
"""

from collections.abc import Mapping
from dataclasses import dataclass, replace
import os

from dq_fk_ros.description.schema import load_robot_description
from dq_fk_ros.description.shipped import shipped_robot_path, shipped_robots
from dq_fk_ros.description.xacro_sandbox import ros_package_roots, TIME_LIMIT_S
from dq_fk_ros.errors import printable_line, RobotDescriptionError

URDF_SUFFIXES = ('.urdf', '.xacro')
# how the tools name the URDF chain's ends in messages (from_urdf.OPTIONS: the URDF modules,
# ~11 ms of imports, are imported only when a URDF is loaded; test_loading.py holds the two)
OPTIONS = ('--base', '--tip')


@dataclass(frozen=True)
class LoadedRobot:
    """
    A robot ready to use, and where it came from.

    ``urdf`` is the URDF XML it was converted from (xacro expanded: ``model.urdf``), or
    None for a DH file; ``conversion`` the
    :class:`~dq_fk_ros.description.from_urdf.Conversion` (None alike).
    """

    model: object
    conversion: object = None

    @property
    def warnings(self) -> tuple[str, ...]:
        """Return what the conversion changed that a user should know (lines; none: ())."""
        return self.conversion.warnings if self.conversion is not None else ()

    @property
    def urdf(self) -> str | None:
        """Return the URDF XML the robot was converted from (``model.urdf``), or None."""
        return self.model.urdf

    def summary(self) -> str:
        """Describe in one line how a URDF became this robot (empty for a DH file)."""
        if self.conversion is None:
            return ''
        c = self.conversion
        skipped = ', '.join(f'{printable_line(j.name, 80)} -> {printable_line(j.child, 80)}'
                            for j in c.skipped)
        skipped = f'; skipped side branches: {skipped}' if skipped else ''
        model = self.model   # (a conversion's side-branch joints are its other chains')
        if not self.model.dof:
            return (f'converted URDF {self.model.source}: no moving joint below {c.base}: '
                    f'{len(self.model.links)} URDF links, all static (/tf_static only)')
        if model.branches:
            rows = sum(len(chain.joints) for _, chain, _ in model.chains)
            return (f'converted URDF {model.source}: {len(model.chains)} DH chains from {c.base} '
                    f'(the first to {c.tip}), {rows} DH rows ({model.chain.convention}), '
                    f'{len(model.links)} URDF links; each transform published once joint '
                    f'states name its joints{skipped}')
        return (f'converted URDF {model.source}: chain {c.base} -> {c.tip}, '
                f'{len(model.chain.joints)} DH rows ({model.chain.convention}), '
                f'{len(model.links)} URDF links{skipped}')


def resolve_robot(spec: str | os.PathLike) -> str:
    """
    Return ``spec`` if it is a path, else the file of the shipped robot of that name.

    A name that is neither: :class:`RobotDescriptionError` listing the shipped robots.
    """
    spec = os.fspath(spec)
    if os.path.exists(spec) or os.sep in spec or spec.endswith(('.yaml',) + URDF_SUFFIXES):
        return spec
    try:
        return shipped_robot_path(spec)
    except FileNotFoundError:
        raise RobotDescriptionError(f'{spec}: no such file, and no shipped robot of that name '
                                    f'(shipped: {", ".join(shipped_robots())})') from None


def is_urdf(path: str | os.PathLike) -> bool:
    """Say whether ``path`` names a URDF (``.urdf``, ``.xacro``, ``.urdf.xacro``)."""
    return os.fspath(path).lower().endswith(URDF_SUFFIXES)


@dataclass(frozen=True)
class FileAccess:
    """
    What a robot file named by someone else (a run-time parameter) may be.

    ``dirs``: the folders it must lie in (after symlinks are resolved); ``xacro``: whether a
    ``.xacro`` file (a program) may be expanded; ``time_limit_s``: the limit for that.
    Errors under a :class:`FileAccess` quote no text of a file that is not a robot
    description (:attr:`RobotDescriptionError.public`).
    """

    dirs: tuple
    xacro: bool = False
    time_limit_s: float = TIME_LIMIT_S
    should_stop: object = None

    def check(self, path: str | os.PathLike) -> str:
        """Return the real path of ``path`` if it lies in one of :attr:`dirs`; else raise."""
        real, shown = os.path.realpath(path), printable_line(path, 200)
        for folder in self.dirs:
            folder = os.path.realpath(folder)
            if os.path.commonpath([real, folder]) == folder:
                break
        else:
            raise RobotDescriptionError(f'{shown}: not in the folders robot files may be read '
                                        f'from (robot_description_dirs: '
                                        f'{", ".join(self.dirs)})')
        # the name given and the file read alike (``robot.urdf.xacro/.``, a link to a xacro)
        named = os.fspath(path).lower().rstrip('/.' + os.sep)
        if (named.endswith('.xacro') or real.lower().endswith('.xacro')) and not self.xacro:
            raise RobotDescriptionError(
                f'{shown}: a .xacro file is a program and is not run when set at run time '
                f"(the node's read-only parameter allow_runtime_xacro is off)")
        return real


def load_robot(spec: str | os.PathLike, base: str | None = None, tip: str | None = None,
               convention: str = 'standard', access: 'FileAccess | None' = None,
               packages: Mapping[str, str] | None = None,
               options: tuple[str, str] = OPTIONS) -> LoadedRobot:
    """
    Load a robot from a DH YAML file, a URDF/xacro file or a shipped robot's name.

    :param base: for a URDF: the link the chain starts at (default: the root).
    :param tip: for a URDF: the link it ends at (default: see ``dq_fk from-urdf``).
    :param convention: for a URDF: the DH convention of the table made from it.
    :param access: a :class:`FileAccess` for a file someone else named: it must lie in
        ``access.dirs``, and a xacro may read only there and in the ROS package paths
        (default: the caller chose the file: any path, a xacro may read its package).
    :param packages: ``{name: folder}`` that a xacro's ``$(find name)`` gives first (see
        :mod:`dq_fk_ros.description.packages` for where else it looks).
    :param options: how the caller names ``base`` and ``tip`` in messages (``--base``,
        ``--tip``; the nodes: :data:`~dq_fk_ros.description.from_urdf.NODE_OPTIONS`).
    Raises :class:`RobotDescriptionError` (one line) for anything unusable.
    """
    path = resolve_robot(spec)
    roots = None
    if access is not None:  # a xacro reads only where the file may be, and ROS packages
        path = access.check(path)
        roots = list(access.dirs) + ros_package_roots()
    if not is_urdf(path):
        return LoadedRobot(load_robot_description(path))
    from dq_fk_ros.description.from_urdf import load_urdf_description, urdf_to_description
    from dq_fk_ros.description.urdf_reader import read_urdf_text
    if access is None:
        conversion, text = load_urdf_description(path, base, tip, convention, packages,
                                                 options)
    else:
        text = read_urdf_text(path, roots, access.time_limit_s, access.should_stop, packages,
                              within=access.dirs)
        conversion = urdf_to_description(text, path, base, tip, convention, options)
    return LoadedRobot(replace(conversion.model, source=path, urdf=text), conversion)


def robot_from_urdf_text(text: str, source: str = 'robot_description', base: str | None = None,
                         tip: str | None = None, convention: str = 'standard',
                         options: tuple[str, str] = OPTIONS) -> LoadedRobot:
    """Convert URDF XML given as text (robot_state_publisher's ``robot_description``)."""
    if not isinstance(text, str) or not text.strip():
        raise RobotDescriptionError(f'{source}: empty; give URDF XML')
    from dq_fk_ros.description.from_urdf import urdf_to_description
    conversion = urdf_to_description(text, source, base, tip, convention, options)
    return LoadedRobot(replace(conversion.model, source=source, urdf=text), conversion)


__all__ = ['FileAccess', 'is_urdf', 'load_robot', 'LoadedRobot', 'resolve_robot',
           'robot_from_urdf_text']
