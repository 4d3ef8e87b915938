"""
Where a ROS package is, as ROS finds it: ``$(find pkg)`` and ``package://pkg/...``.

On a full ROS 2 install the ament index answers; on a pip-only one there is often no index
for a robot's description package, and a URDF or xacro from a vendor still names it. A
:class:`PackageResolver` looks, in order:

1. the packages given explicitly (``--package NAME=DIR`` on the tools, the node's
   ``package_paths``);
2. the ament index of every prefix on ``AMENT_PREFIX_PATH``
   (``share/ament_index/resource_index/packages/NAME``: the package is ``share/NAME``);
3. the folders on ``ROS_PACKAGE_PATH``, searched below for a ``package.xml`` whose
   ``<name>`` is the package (ROS 1's rule: a folder holding a ``package.xml`` is a package,
   and nothing below it is searched; a ``CATKIN_IGNORE`` or ``AMENT_IGNORE`` file hides a
   folder);
4. above the URDF or xacro file: a folder of that name holding a ``package.xml`` (the file's
   own package, or a sibling of one of its folders);
5. the ament index of the running Python environment's own prefixes
   (:func:`python_prefixes`: ``sys.prefix`` and every ``site-packages/*.prefix``, where
   example-robot-data's cmeel wheel puts ``share/example-robot-data`` with its index): what
   ``pip install`` put beside this package, found with nothing set.

A package that is not found is :class:`PackageNotFound`, one line naming it and the places
searched. Plain Python, no ROS.
"""

from collections.abc import Mapping, Sequence
from functools import lru_cache
import os
import re
import sys
import sysconfig
import xml.etree.ElementTree as ElementTree

MAX_SEARCH_DEPTH = 6          # folders below a ROS_PACKAGE_PATH entry
MAX_SEARCH_FOLDERS = 20_000   # folders looked at per ROS_PACKAGE_PATH entry
MAX_PACKAGE_XML_BYTES = 1 << 20
PACKAGE_NAME = re.compile(r'[A-Za-z0-9_][A-Za-z0-9_.-]*')  # REP 144, and names in the wild
IGNORE_MARKERS = ('CATKIN_IGNORE', 'AMENT_IGNORE', 'COLCON_IGNORE')


INDEX = os.path.join('share', 'ament_index', 'resource_index', 'packages')


@lru_cache(maxsize=1)
def python_prefixes() -> tuple[str, ...]:
    """
    Return the prefixes of the running Python environment that carry an ament index.

    ``sys.prefix`` (a venv's ``share/``: ament_cmake's wheels) and each ``*.prefix`` folder
    of its site-packages (cmeel's ``cmeel.prefix``: example-robot-data, pinocchio), those
    holding ``share/ament_index/resource_index/packages``, in that order.
    """
    candidates = [sys.prefix]
    folders = []
    for key in ('purelib', 'platlib'):
        folder = sysconfig.get_paths().get(key)
        if folder and folder not in folders:
            folders.append(folder)
    for folder in folders:
        try:
            names = sorted(os.listdir(folder))
        except OSError:
            continue
        candidates += [os.path.join(folder, n) for n in names if n.endswith('.prefix')]
    return tuple(p for p in candidates if os.path.isdir(os.path.join(p, INDEX)))


class PackageNotFound(LookupError):
    """A package no rule finds; the message is one line."""


def parse_package_option(text: str, what: str = '--package') -> tuple[str, str]:
    """Return ``(name, folder)`` of a ``NAME=DIR`` option (ValueError: one line)."""
    name, eq, folder = str(text).partition('=')
    if not eq or not PACKAGE_NAME.fullmatch(name) or not folder:
        raise ValueError(f'{what} {str(text)[:80]!r}: give NAME=DIR (a package name, then the '
                         f'folder holding its package.xml)')
    if not os.path.isdir(folder):
        raise ValueError(f'{what} {name}={folder[:80]}: no such folder')
    return name, os.path.abspath(folder)


def package_xml_name(folder: str) -> str | None:
    """Return the ``<name>`` of ``folder/package.xml``, or None if it has none readable."""
    path = os.path.join(folder, 'package.xml')
    try:
        with open(path, 'rb') as stream:
            data = stream.read(MAX_PACKAGE_XML_BYTES + 1)
    except OSError:
        return None
    if len(data) > MAX_PACKAGE_XML_BYTES or b'<!ENTITY' in data:
        return None
    try:
        element = ElementTree.fromstring(data).find('name')
    except ElementTree.ParseError:
        return None
    return element.text.strip() if element is not None and element.text else None


class PackageResolver:
    """
    Find packages as the module doc says.

    :param packages: ``{name: folder}`` given explicitly (they come first).
    :param near: a URDF or xacro file: packages above it are found too (rule 4).
    :param within: folders rule 4 may not leave (a file named at run time), or None.
    :param environ: where ``AMENT_PREFIX_PATH`` and ``ROS_PACKAGE_PATH`` are read (default:
        this process's environment).
    :param python: the Python environment's prefixes of rule 5 (default:
        :func:`python_prefixes`; ``()``: none).
    """

    def __init__(self, packages: Mapping[str, str] | None = None, near: str | None = None,
                 within: Sequence[str] | None = None,
                 environ: Mapping[str, str] | None = None,
                 python: Sequence[str] | None = None):
        """Note where to look; nothing is read until :meth:`find` is asked."""
        environ = os.environ if environ is None else environ
        self.packages = {name: os.path.abspath(folder)
                         for name, folder in (packages or {}).items()}
        self.near = None if near is None else os.path.abspath(os.fspath(near))
        self.within = None if within is None else [os.path.realpath(w) for w in within]
        self.prefixes = [p for p in environ.get('AMENT_PREFIX_PATH', '').split(os.pathsep) if p]
        self.ros_package_path = [p for p in environ.get('ROS_PACKAGE_PATH', '').split(os.pathsep)
                                 if p]
        self.python = python_prefixes() if python is None else tuple(python)
        self._found = {}
        self._scanned = None

    def find(self, name: str) -> str:
        """Return the folder of package ``name`` (raise :class:`PackageNotFound`)."""
        if name in self._found:
            return self._found[name]
        if not PACKAGE_NAME.fullmatch(str(name)):
            raise PackageNotFound(f'package {str(name)[:80]!r}: not a package name')
        folder = (self.packages.get(name) or _ament(self.prefixes, name)
                  or self._ros_package_path(name) or self._above(name)
                  or _ament(self.python, name))
        if folder is None:
            raise PackageNotFound(f'package {name!r} not found; searched: {self.searched()}')
        self._found[name] = folder
        return folder

    def searched(self) -> str:
        """Say in a few words where :meth:`find` looks."""
        places = []
        if self.packages:
            places.append('--package ' + ', '.join(sorted(self.packages)))
        places.append('the ament index of AMENT_PREFIX_PATH' + (
            f' ({os.pathsep.join(self.prefixes)})' if self.prefixes else ' (not set)'))
        places.append('ROS_PACKAGE_PATH' + (f' ({os.pathsep.join(self.ros_package_path)})'
                                            if self.ros_package_path else ' (not set)'))
        if self.near is not None:
            places.append(f'the folders above {self.near}')
        if self.python:
            places.append(f'the ament index of this Python ({os.pathsep.join(self.python)})')
        return '; '.join(places)

    def resolve(self, uri: str) -> str:
        """
        Return the file a ``package://`` or ``file://`` URI (or a plain path) names.

        Raises :class:`PackageNotFound` for an unknown package, ValueError for a URI that
        leaves its package (``..``) or has another scheme.
        """
        uri = str(uri)
        if uri.startswith('package://'):
            name, _, rest = uri[len('package://'):].partition('/')
            folder = self.find(name)
            path = os.path.normpath(os.path.join(folder, rest))
            if os.path.commonpath([path, folder]) != folder:
                raise ValueError(f'{uri[:120]}: leaves package {name!r}')
            return path
        if uri.startswith('file://'):
            return uri[len('file://'):]
        if '://' in uri:
            raise ValueError(f'{uri[:120]}: only package:// and file:// are resolved')
        return uri

    # -- the rules ---------------------------------------------------------------------------
    def _ros_package_path(self, name):
        if self._scanned is None:
            self._scanned = {}
            for root in self.ros_package_path:
                for folder in _package_folders(root):
                    found = package_xml_name(folder)
                    if found and found not in self._scanned:
                        self._scanned[found] = folder
        return self._scanned.get(name)

    def _above(self, name):
        if self.near is None:
            return None
        at = os.path.dirname(self.near)
        while True:
            for candidate in (at, os.path.join(at, name)):
                if os.path.basename(candidate) == name and self._inside(candidate) and \
                        os.path.isfile(os.path.join(candidate, 'package.xml')):
                    return candidate
            up = os.path.dirname(at)
            if up == at:
                return None
            at = up

    def _inside(self, folder):
        if self.within is None:
            return True
        real = os.path.realpath(folder)
        return any(os.path.commonpath([real, w]) == w for w in self.within)


def _ament(prefixes, name):
    """Return ``share/NAME`` of the first prefix whose ament index lists ``name``, or None."""
    for prefix in prefixes:
        share = os.path.join(prefix, 'share', name)
        if os.path.isfile(os.path.join(prefix, INDEX, name)) and os.path.isdir(share):
            return share
    return None


def _package_folders(root):
    """Yield the package folders below ``root`` (ROS 1's crawl, bounded)."""
    stack, seen = [(os.path.abspath(root), 0)], 0
    while stack and seen < MAX_SEARCH_FOLDERS:
        folder, depth = stack.pop()
        seen += 1
        try:
            names = os.listdir(folder)
        except OSError:
            continue
        if any(marker in names for marker in IGNORE_MARKERS):
            continue
        if 'package.xml' in names:
            yield folder
            continue
        if depth < MAX_SEARCH_DEPTH:
            for child in sorted(names, reverse=True):
                path = os.path.join(folder, child)
                if not child.startswith('.') and os.path.isdir(path) and \
                        not os.path.islink(path):
                    stack.append((path, depth + 1))


__all__ = ['PackageNotFound', 'PackageResolver', 'package_xml_name', 'parse_package_option',
           'python_prefixes']
