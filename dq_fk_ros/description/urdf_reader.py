"""
A URDF read: ``.urdf`` or ``.xacro`` text in (xacro run confined), a :class:`UrdfTree` out.

Plain Python (xml.etree; ``xacro`` from PyPI for ``.xacro`` files), no ROS. Linear in the
size of the URDF (at most :data:`MAX_URDF_ELEMENTS` links and joints); every problem is one
:class:`~dq_fk_ros.errors.RobotDescriptionError` line.
"""

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from functools import cached_property
import math
import os
import xml.etree.ElementTree as ElementTree
from xml.parsers import expat

from dq_fk_ros.description.robot_model import MAX_FILE_BYTES, MAX_LENGTH_M, rpy_matrix
from dq_fk_ros.description.xacro_sandbox import (
    default_read_roots, expand_xacro, TIME_LIMIT_S, XacroRefused)
from dq_fk_ros.errors import RobotDescriptionError
import numpy as np

MOVING = ('revolute', 'continuous', 'prismatic')
MAX_URDF_BYTES = 8 * MAX_FILE_BYTES  # a URDF (or a xacro's expansion) is at most 8 MiB
MAX_URDF_ELEMENTS = 4096    # links, and joints, in one URDF (talos: 100; the checks are linear)


@dataclass(frozen=True)
class UrdfJointSpec:
    """One ``<joint>`` of a URDF: origin as a 4x4 matrix, axis a unit 3-vector."""

    name: str
    kind: str
    parent: str
    child: str
    origin: np.ndarray
    axis: np.ndarray
    lower: float = None
    upper: float = None
    velocity: float = None
    mimic: tuple = None          # (joint, multiplier, offset)


@dataclass(frozen=True)
class UrdfTree:
    """The links and joints of a URDF: ``joints`` by child link, ``children`` by parent."""

    name: str
    source: str
    links: tuple
    joints: dict
    children: dict
    slashed: tuple = ()   # link names the URDF wrote with a leading slash (tf2 strips it)

    @property
    def roots(self) -> list[str]:
        """Links that are no joint's child."""
        return [link for link in self.links if link not in self.joints]

    @cached_property
    def by_name(self) -> dict[str, 'UrdfJointSpec']:
        """Return the joints by name."""
        return {joint.name: joint for joint in self.joints.values()}


def _too_large(source):
    return RobotDescriptionError(f'{source}: larger than {MAX_URDF_BYTES // 1024} KiB; a URDF '
                                 f'is at most that big')


def read_urdf_text(path: str | os.PathLike, read_roots: Sequence[str] | None = None,
                   time_limit_s: float = TIME_LIMIT_S, should_stop: Callable | None = None,
                   packages: Mapping[str, str] | None = None,
                   within: Sequence[str] | None = None) -> str:
    """
    Return the URDF XML of a ``.urdf`` file, or of a ``.xacro`` file expanded by xacro.

    xacro runs confined (:mod:`dq_fk_ros.description.xacro_sandbox`): it may read under
    ``read_roots`` only (default: the file's package or folder and the ROS package paths)
    and in the packages ``$(find)`` finds (``packages``: ``{name: folder}`` first; ``within``:
    folders the search above the file may not leave), and is stopped after ``time_limit_s``.
    """
    path = os.fspath(path)
    if not os.path.isfile(path):
        raise RobotDescriptionError(f'{path}: no such file' if not os.path.exists(path) else
                                    f'{path}: not a file')
    if os.path.getsize(path) > MAX_URDF_BYTES:
        raise _too_large(path)
    if path.endswith('.xacro'):
        try:
            import xacro  # noqa: F401  (the child process imports it; say here if missing)
        except ImportError:
            raise RobotDescriptionError(f'{path}: a .xacro file needs the xacro package '
                                        f'(pip install xacro)') from None
        roots = default_read_roots(path) if read_roots is None else read_roots
        try:
            return expand_xacro(path, roots, time_limit_s, should_stop=should_stop,
                                packages=packages, within=within)
        except XacroRefused as exc:
            raise RobotDescriptionError(f'{path}: xacro failed: {exc}',
                                        f'{path}: xacro failed') from None
    try:
        with open(path, 'rb') as stream:
            data = stream.read(MAX_URDF_BYTES + 1)   # (it may have grown since)
        if len(data) > MAX_URDF_BYTES:
            raise _too_large(path)
        return data.decode('utf-8')
    except UnicodeDecodeError:
        raise RobotDescriptionError(f'{path}: not UTF-8 text') from None
    except OSError as exc:
        raise RobotDescriptionError(f'{path}: cannot be read ({exc.strerror})') from None


def parse_xml(text: str) -> ElementTree.Element:
    """
    Return the root element of ``text`` read as urdfdom reads it: without XML namespaces.

    urdfdom's TinyXML2 takes a prefix as part of a name, declared or not
    (``<limit drake:acceleration="2.5"/>``, as airo-models' UR5e ships); ElementTree's
    namespace-aware reader refuses an undeclared one ("unbound prefix"). Here expat reads
    names as written, so ``drake:acceleration`` is one more attribute no one looks up. Same
    expat, same bounds (no external entities; callers refuse entity declarations).

    :raises ElementTree.ParseError: when ``text`` is not well-formed XML
    """
    builder = ElementTree.TreeBuilder()
    parser = expat.ParserCreate()
    parser.StartElementHandler = builder.start
    parser.EndElementHandler = builder.end
    parser.CharacterDataHandler = builder.data
    try:
        parser.Parse(text, True)
    except expat.ExpatError as exc:
        error = ElementTree.ParseError(str(exc))
        error.code, error.position = exc.code, (exc.lineno, exc.offset)
        raise error from None
    return builder.close()


def parse_urdf(text: str, source: str = '<string>') -> UrdfTree:
    """Parse URDF XML into a :class:`UrdfTree`; any problem is one RobotDescriptionError."""
    if len(text) > MAX_URDF_BYTES:
        raise _too_large(source)
    if '<!ENTITY' in text:
        raise RobotDescriptionError(f'{source}: XML entity declarations are not accepted in a '
                                    f'URDF')
    try:
        root = parse_xml(text)
    except ElementTree.ParseError as exc:
        raise RobotDescriptionError(f'{source}: not valid XML: {exc}') from None
    if root.tag != 'robot':
        raise RobotDescriptionError(f'{source}: the root element is <{root.tag[:40]}>, not '
                                    f'<robot>; is this a URDF?',
                                    f'{source}: the root element is not <robot>; not a URDF')
    name = root.get('name', '') or 'robot'
    link_elements, joint_elements = root.findall('link'), root.findall('joint')
    for what, elements in (('<link>', link_elements), ('<joint>', joint_elements)):
        if len(elements) > MAX_URDF_ELEMENTS:
            raise RobotDescriptionError(f'{source}: {len(elements)} {what} elements; a URDF '
                                        f'has at most {MAX_URDF_ELEMENTS}')
    links, known, slashed = [], set(), []
    for element in link_elements:
        link = element.get('name')
        if link and link.startswith('/'):
            slashed.append(link)
            link = tf_name(link)
        if not link:
            raise RobotDescriptionError(f'{source}: a <link> without a name')
        if link in known:
            raise RobotDescriptionError(f'{source}: link {link[:70]!r} is defined twice')
        known.add(link)
        links.append(link)
    if not links:
        raise RobotDescriptionError(f'{source}: no <link> elements')
    joints, children, names = {}, {}, set()
    for element in joint_elements:
        joint = _joint(element, source, known)
        if joint.name in names:
            raise RobotDescriptionError(f'{source}: joint {joint.name[:70]!r} is defined twice')
        names.add(joint.name)
        if joint.child in joints:
            raise RobotDescriptionError(
                f'{source}: link {joint.child[:70]!r} is the child of two joints '
                f'({joints[joint.child].name[:70]!r} and {joint.name[:70]!r}); a URDF is a tree')
        joints[joint.child] = joint
        children.setdefault(joint.parent, []).append(joint)
    tree = UrdfTree(name, source, tuple(links), joints, children, tuple(slashed))
    if not tree.roots:
        raise RobotDescriptionError(f'{source}: every link has a parent joint: the joints '
                                    f'form a cycle')
    # a cycle below a root: walking up never ends at a root. Each link is walked once: a
    # walk stops at a link already known to reach a root
    reaches_root = set(tree.roots)
    for link in links:
        path, on_path, at = [], set(), link
        while at not in reaches_root:
            if at in on_path:
                raise RobotDescriptionError(f'{source}: the joints form a cycle through link '
                                            f'{at[:70]!r}')
            path.append(at)
            on_path.add(at)
            at = joints[at].parent
        reaches_root.update(path)
    return tree


def tf_name(link: str) -> str:
    """Return a link name as tf2 takes it: without one leading slash (``/base`` -> ``base``)."""
    return link[1:] if link.startswith('/') else link


def _joint(element, source, links):
    name = element.get('name') or ''
    kind = element.get('type') or ''
    where = f'{source}: joint {name!r}'
    if not name:
        raise RobotDescriptionError(f'{source}: a <joint> without a name')
    if kind not in MOVING + ('fixed', 'floating', 'planar'):
        raise RobotDescriptionError(f'{where}: type {kind!r}; allowed: revolute, continuous, '
                                    f'prismatic, fixed, floating, planar')
    ends = {}
    for tag in ('parent', 'child'):
        node = element.find(tag)
        link = node.get('link') if node is not None else None
        link = tf_name(link) if link else link
        if not link:
            raise RobotDescriptionError(f'{where}: no <{tag} link="...">')
        if link not in links:
            raise RobotDescriptionError(f'{where}: {tag} link {link!r} is not defined (no '
                                        f'<link name="{link[:60]}">)')
        ends[tag] = link
    origin = np.eye(4)
    node = element.find('origin')
    if node is not None:
        xyz = _numbers(node.get('xyz', '0 0 0'), 3, f'{where}: origin xyz')
        if max(abs(v) for v in xyz) > MAX_LENGTH_M:
            raise RobotDescriptionError(f'{where}: origin xyz is beyond {MAX_LENGTH_M:g} m')
        rpy = _numbers(node.get('rpy', '0 0 0'), 3, f'{where}: origin rpy')
        origin[:3, :3] = rpy_matrix(*rpy)
        origin[:3, 3] = xyz
    axis = np.array([1.0, 0.0, 0.0])  # URDF's default axis
    node = element.find('axis')
    if node is not None:
        axis = np.array(_numbers(node.get('xyz', '1 0 0'), 3, f'{where}: axis xyz'))
    if kind in MOVING:
        largest = float(np.max(np.abs(axis)))
        if not largest > 0.0 or not largest * np.linalg.norm(axis / largest) > 1e-12:
            raise RobotDescriptionError(f'{where}: axis xyz is all zeros')
        axis = axis / largest  # no overflow for huge components
        axis = axis / np.linalg.norm(axis)
    lower = upper = velocity = None
    node = element.find('limit')
    if node is not None and kind in ('revolute', 'prismatic'):
        lower = _numbers(node.get('lower', '0'), 1, f'{where}: limit lower')[0]
        upper = _numbers(node.get('upper', '0'), 1, f'{where}: limit upper')[0]
        if lower > upper:
            raise RobotDescriptionError(f'{where}: limit lower {lower:g} is above upper '
                                        f'{upper:g}')
    if node is not None and node.get('velocity') is not None and kind in MOVING:
        velocity = _numbers(node.get('velocity'), 1, f'{where}: limit velocity')[0]
    mimic = None
    node = element.find('mimic')
    if node is not None and kind in MOVING:
        followed = node.get('joint')
        if not followed:
            raise RobotDescriptionError(f'{where}: <mimic> without a joint')
        mimic = (followed,
                 _numbers(node.get('multiplier', '1'), 1, f'{where}: mimic multiplier')[0],
                 _numbers(node.get('offset', '0'), 1, f'{where}: mimic offset')[0])
    return UrdfJointSpec(name, kind, ends['parent'], ends['child'], origin, axis, lower, upper,
                         velocity, mimic)


def _numbers(text, size, where):
    try:
        values = [float(v) for v in text.split()]
    except ValueError:
        raise RobotDescriptionError(f'{where}: {text[:60]!r} is not {size} numbers') from None
    if len(values) != size or not all(math.isfinite(v) for v in values):
        raise RobotDescriptionError(f'{where}: {text[:60]!r} is not {size} finite numbers')
    return values


__all__ = ['MAX_URDF_ELEMENTS', 'MOVING', 'parse_urdf', 'read_urdf_text', 'tf_name',
           'UrdfJointSpec', 'UrdfTree']
