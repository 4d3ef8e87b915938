"""
A DH robot description from a URDF: ``dq_fk from-urdf`` and the node's URDF input.

Plain Python (xml.etree, numpy; ``xacro`` from PyPI for ``.xacro`` files), no ROS.

The whole tree below ``base`` becomes DH chains: the first from ``base`` to ``tip`` (default:
the end of the longest chain), then, walking the URDF parents first, every moving joint not
yet on a chain starts one that follows the longest path of moving joints below it, hanging
from the DH frame its first joint's parent moves with. Each chain is read at zero joint
values: every moving joint is a line in space (its axis through its origin). The DH frames
are built on those lines by their common normals ([Radavelli2014] Sec. 2, Spong's or
Craig's rules):

* skew axes: the unique common normal; ``x`` points from one axis to the next;
* intersecting axes: ``x = z_prev x z_next`` through the intersection (``a = 0``);
* parallel axes: the normal through the previous frame's origin (``d = 0``);
* coincident axes: ``x`` kept from the previous frame (``a = alpha = 0``);
* intersecting axes take the sign of ``x`` nearer the previous frame's ``x``;
* frame 0 sits on the first axis where it passes closest to the base link's origin, its
  ``x`` along the base link's x (or y) as far as the axis allows; the last frame keeps the
  previous one's axes (``a_n = alpha_n = 0``); in modified DH frame 0 is frame 1 at zero.

``z`` always points along the URDF axis, so every row has ``scale: 1``; a row's zero value
(``theta`` or ``d``) is its offset at the URDF's zero.
The base transform places frame 0 in its parent; every URDF link becomes a ``links``
entry (its pose in the DH frame it moves with, published under its URDF parent), so TF
carries the URDF's own tree. A mimic joint is a mimic row (chains of mimics followed to
their source). A chain is split where two axes are so nearly parallel that their common
normal lies :data:`FAR_NORMAL_M` away. Floating and planar joints (and what is below them),
and mimics of joints that are not published, are skipped and named.
"""

from dataclasses import dataclass
from functools import cached_property
import json
import math
import os
import xml.etree.ElementTree as ElementTree

from dq_fk_ros.description.errors import listing, printable_line, RobotDescriptionError
from dq_fk_ros.description.robot_model import (
    JOINT_NAME, MAX_FILE_BYTES, MAX_LENGTH_M, MAX_NAME_CHARS, MAX_ROWS, rpy_matrix, TF_FRAME_ID)
from dq_fk_ros.description.schema import parse_robot_description, yaml_number
from dq_fk_ros.description.xacro_sandbox import (
    default_read_roots, expand_xacro, TIME_LIMIT_S, XacroRefused)
from dq_fk_ros.kinematics.dual_quaternion import quat_from_matrix
import numpy as np

MOVING = ('revolute', 'continuous', 'prismatic')
PARALLEL_TOL = 1e-9         # |sin| of the angle between two axes below which they are parallel
LENGTH_TOL_M = 1e-9         # distances below which two points (or lines) meet
NOISE = 1e-15               # numbers written as 0 (m or rad; far below the tests' 1e-12)
FAR_NORMAL_M = 10.0         # a common normal this far from the joints splits the chain
MAX_URDF_ELEMENTS = 4096    # links, and joints, in one URDF (talos: 100; the checks are linear)
# how the tools call the base and tip links (messages name the option of the tool that said it)
OPTIONS = ('--base', '--tip')
NODE_OPTIONS = ('urdf_base_link', 'urdf_tip_link')


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
    def roots(self):
        """Links that are no joint's child."""
        return [link for link in self.links if link not in self.joints]

    @cached_property
    def by_name(self):
        """Return the joints by name."""
        return {joint.name: joint for joint in self.joints.values()}


def read_urdf_text(path, read_roots=None, time_limit_s=TIME_LIMIT_S, should_stop=None,
                   packages=None, within=None):
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
    if os.path.getsize(path) > 8 * MAX_FILE_BYTES:
        raise RobotDescriptionError(f'{path}: larger than {8 * MAX_FILE_BYTES // 1024} KiB; a '
                                    f'URDF is at most that big')
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
            data = stream.read(8 * MAX_FILE_BYTES + 1)
        return data.decode('utf-8')
    except UnicodeDecodeError:
        raise RobotDescriptionError(f'{path}: not UTF-8 text') from None
    except OSError as exc:
        raise RobotDescriptionError(f'{path}: cannot be read ({exc.strerror})') from None


def parse_urdf(text, source='<string>'):
    """Parse URDF XML into a :class:`UrdfTree`; any problem is one RobotDescriptionError."""
    if len(text) > 8 * MAX_FILE_BYTES:
        raise RobotDescriptionError(f'{source}: larger than {8 * MAX_FILE_BYTES // 1024} KiB; '
                                    f'a URDF is at most that big')
    if '<!ENTITY' in text:
        raise RobotDescriptionError(f'{source}: XML entity declarations are not accepted in a '
                                    f'URDF')
    try:
        root = ElementTree.fromstring(text)
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


def tf_name(link):
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


# -- the chain ---------------------------------------------------------------------------
def chain_joints(tree, base=None, tip=None, options=OPTIONS):
    """
    Return ``(base, tip, joints)``: the joints from ``base`` down to ``tip``.

    Defaults: ``base`` is the root link; ``tip`` the child link of the last moving joint on
    the longest chains below ``base`` (mimic joints not counted; links fixed below it are
    published anyway). Chains that end in different joints: an error that lists them.
    ``options``: the names of the base and tip options in messages (:data:`OPTIONS`,
    :data:`NODE_OPTIONS`).
    """
    source = tree.source
    base_option, tip_option = options
    base = tf_name(base) if base else base
    tip = tf_name(tip) if tip else tip
    for name, value in ((base_option, base), (tip_option, tip)):
        if value is not None and value not in tree.links:
            raise RobotDescriptionError(f'{source}: {name} {value!r} is not a link of the URDF; '
                                        f'links: {listing(tree.links)}')
    if base is None:
        roots = tree.roots
        if len(roots) > 1:
            raise RobotDescriptionError(f'{source}: several root links ({listing(roots)}); '
                                        f'choose one with {base_option}')
        base = roots[0]
    if tip is None:
        tip = _default_tip(tree, base, tip_option)
    joints, at = [], tip
    while at != base:
        if at not in tree.joints:
            raise RobotDescriptionError(f'{source}: {tip_option} {tip!r} is not below '
                                        f'{base_option} {base!r}')
        joints.append(tree.joints[at])
        at = tree.joints[at].parent
    joints.reverse()
    for joint in joints:
        if joint.kind in ('floating', 'planar'):
            raise RobotDescriptionError(f'{source}: joint {joint.name!r} on the chain is '
                                        f'{joint.kind}; a DH chain takes revolute, continuous, '
                                        f'prismatic and fixed joints')
    return base, tip, joints


def longest_chain_tips(tree, base):
    """
    Return the links that end the longest chains of moving joints below ``base``.

    Each is the child link of a chain's last moving joint (mimic joints not counted), in the
    URDF's link order; ``[None]`` when no moving joint is below ``base``.
    """
    best, tips = -1, set()
    stack = [(base, 0, None)]
    while stack:
        link, count, last = stack.pop()
        below = [j for j in tree.children.get(link, []) if j.kind not in ('floating', 'planar')]
        if not below:
            if count > best:
                best, tips = count, {last}
            elif count == best:
                tips.add(last)
            continue
        for joint in below:
            counts = joint.kind in MOVING and joint.mimic is None
            stack.append((joint.child, count + counts, joint.child if counts else last))
    order = {link: k for k, link in enumerate(tree.links)}
    return sorted(tips, key=lambda t: order.get(t, -1))


def _default_tip(tree, base, tip_option=OPTIONS[1]):
    """
    Return the end of the longest chain below ``base``: the first in the URDF's order.

    Among equally long chains (two legs, two arms, fingers) the first wins and the others
    become side branches; ``base`` itself when no moving joint is below it (a sensor rig).
    """
    tip = longest_chain_tips(tree, base)[0]
    return base if tip is None else tip


# -- DH frames on the joint axes -----------------------------------------------------------
def _unit(v):
    return v / np.linalg.norm(v)


def _common_normal(p1, u1, p2, u2, through, x_before):
    """
    Return ``(foot on line 1, foot on line 2, x, kind)`` of the common normal of two lines.

    Parallel lines: the normal through ``through`` (a point on line 1); coincident ones:
    ``x_before``; intersecting ones: ``+-(u1 x u2)``, the sign nearer ``x_before``.
    """
    cross = np.cross(u1, u2)
    sin = np.linalg.norm(cross)
    w = p1 - p2
    if sin < PARALLEL_TOL:
        foot2 = p2 + np.dot(through - p2, u2) * u2
        gap = foot2 - through
        if np.linalg.norm(gap) < LENGTH_TOL_M:
            return through, through, x_before, 'coincident'
        return through, foot2, _unit(gap), 'parallel'
    # the feet p1 + s u1, p2 + t u2, with 1 - (u1.u2)^2 = |u1 x u2|^2 and the numerators
    # as cross products: no cancellation for nearly parallel axes (Romeo's thumbs, 1e-7 rad)
    denominator = np.dot(cross, cross)
    s = -np.dot(np.cross(u2, cross), w) / denominator
    t = -np.dot(np.cross(u1, cross), w) / denominator
    foot1, foot2 = p1 + s * u1, p2 + t * u2
    gap = foot2 - foot1
    if np.linalg.norm(gap) < LENGTH_TOL_M:
        middle = 0.5 * (foot1 + foot2)
        x = cross / sin
        return middle, middle, (-x if np.dot(x, x_before) < 0.0 else x), 'intersecting'
    # the normal is along u1 x u2: exact, where the direction of a short gap is not
    x = cross / sin
    return foot1, foot2, (-x if np.dot(x, gap) < 0.0 else x), 'skew'


def _frames_on_axes(lines, convention):
    """
    Return the DH frames 0..n as 4x4 matrices (base link coordinates) and each axis' case.

    ``lines``: ``(point, unit direction)`` of the n joint axes at zero.
    """
    n = len(lines)
    p1, u1 = lines[0]
    reference = p1 + np.dot(-p1, u1) * u1   # on axis 1, closest to the base link's origin
    # frame 0's x: the base link's x (else y) where the first axis allows, so that the base
    # transform is as plain as the URDF
    x = None
    for axis in (np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0])):
        projected = axis - np.dot(axis, u1) * u1
        if np.linalg.norm(projected) > 1e-6:
            x = _unit(projected)
            break
    x0 = x
    normals, kinds = [], ['first']
    through = reference
    for i in range(n - 1):
        (pa, ua), (pb, ub) = lines[i], lines[i + 1]
        foot1, foot2, x, kind = _common_normal(pa, ua, pb, ub, through, x)
        normals.append((foot1, foot2, x))
        kinds.append(kind)
        through = foot2
    x_last = normals[-1][2] if normals else x0

    def frame(origin, x_axis, z_axis):
        m = np.eye(4)
        x_axis = _unit(x_axis - np.dot(x_axis, z_axis) * z_axis)
        m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = x_axis, np.cross(z_axis, x_axis), z_axis, origin
        return m

    if convention == 'standard':  # frame i (0..n-1): z on axis i+1, x on the normal i/i+1
        frames = [frame(reference, x0, u1)]
        for i in range(1, n):
            frames.append(frame(normals[i - 1][1], normals[i - 1][2], lines[i][1]))
        frames.append(frames[-1].copy())
    else:  # modified: frame i (1..n): z on axis i, x on the normal i/i+1; frame 0 = frame 1
        frames = []
        for i in range(n - 1):
            frames.append(frame(normals[i][0], normals[i][2], lines[i][1]))
        last_origin = normals[-1][1] if normals else reference
        frames.append(frame(last_origin, x_last, lines[-1][1]))
        frames.insert(0, frames[0].copy())
    return frames, kinds


def _angle(a, b, about):
    return math.atan2(float(np.dot(np.cross(a, b), about)), float(np.dot(a, b)))


def _dh_row(before, after, convention):
    """Return ``(theta, d, a, alpha)`` taking DH frame ``before`` to ``after`` (4x4 each)."""
    x0, z0, o0 = before[:3, 0], before[:3, 2], before[:3, 3]
    x1, z1, o1 = after[:3, 0], after[:3, 2], after[:3, 3]
    step = o1 - o0
    if convention == 'standard':  # Rz(theta) Tz(d) Tx(a) Rx(alpha)
        return (_angle(x0, x1, z0), float(np.dot(step, z0)), float(np.dot(step, x1)),
                _angle(z0, z1, x1))
    # modified: Rx(alpha) Tx(a) Rz(theta) Tz(d)
    return (_angle(x0, x1, z1), float(np.dot(step, z1)), float(np.dot(step, x0)),
            _angle(z0, z1, x0))


# -- the robot description ---------------------------------------------------------------
@dataclass(frozen=True)
class Conversion:
    """What :func:`urdf_to_description` made: the YAML text and what it left out."""

    text: str
    base: str
    tip: str
    skipped: tuple          # side-branch joints not published (one line each)
    warnings: tuple = ()    # what a user should know (one line each): names changed


def urdf_to_description(text, source='<string>', base=None, tip=None, convention='standard',
                        options=OPTIONS):
    """
    Convert URDF XML into the YAML text of a DH robot description (see the module doc).

    :param base: the link the chain starts at (default: the root); it is the fixed frame.
    :param tip: the link the chain ends at (default: the leaf of the longest moving chain).
    :param convention: ``standard`` (Spong, distal) or ``modified`` (Craig, proximal).
    :param options: the names of the base and tip options, for messages (:data:`OPTIONS`).
    :returns: a :class:`Conversion`; raises :class:`RobotDescriptionError` (one line).
    """
    if convention not in ('standard', 'modified'):
        raise RobotDescriptionError(f'convention {convention!r}; allowed: standard, modified')
    tree = parse_urdf(text, source)
    base, tip, path = chain_joints(tree, base, tip, options)
    for link in [base] + [j.child for j in path]:
        _check_frame(link, source)
    moving = [j for j in path if j.kind in MOVING]
    if len(moving) > MAX_ROWS:
        raise RobotDescriptionError(f'{source}: {len(moving)} moving joints; a robot '
                                    f'description has at most {MAX_ROWS} rows')
    for j in moving:
        _check_joint(j.name, source)
    chain_names = {j.name for j in moving}
    published = _publishable(tree, base)
    for j in moving:
        if j.mimic is not None and _mimic_source(tree, j, published)[0] not in chain_names:
            raise RobotDescriptionError(
                f'{source}: joint {j.name!r} on the chain mimics {j.mimic[0]!r}, which is not '
                f'a moving joint of the chain {base!r} -> {tip!r}')

    # poses at zero, in the base link, of every link published
    pose = {base: np.eye(4)}
    for link in _below(tree, base, published):
        joint = tree.joints[link]
        pose[link] = pose[joint.parent] @ joint.origin
    plans = [part for plan in [_ChainPlan(base, base, tuple(path), tip)]
             + _branch_plans(tree, base, path, published) for part in _split(plan, pose)]
    if sum(len(plan.moving) for plan in plans) > MAX_ROWS:
        raise RobotDescriptionError(f'{source}: {sum(len(p.moving) for p in plans)} moving '
                                    f'joints; a robot description has at most {MAX_ROWS} rows')
    taken = set(tree.links)
    body = {base: base}          # link -> the DH frame (or the base link) it moves with
    frame_pose = {base: np.eye(4)}
    chains = []
    order = list(_below(tree, base, published))
    for c, plan in enumerate(plans + [None]):
        for link in order:  # links fixed to a link of known body move with it
            joint = tree.joints[link]
            if link not in body and joint.kind not in MOVING and joint.parent in body:
                body[link] = body[joint.parent]
        if plan is not None:
            chains.append(_chain_entry(plan, c, pose, body, frame_pose, taken, convention,
                                       published, tree))
    links = []
    for link in _below(tree, base, published):
        links.append(_link_entry(tree.joints[link], pose, body, frame_pose))
    skipped = [j for j in tree.joints.values() if j.parent in pose and j.child not in pose]
    end_effector = tip
    if not moving:  # the fixed frame cannot be the end effector: the deepest link
        end_effector = links[-1][0]['frame'] if links else chains[0]['names'][1]
    text = _yaml(tree, source, base, tip, convention, chains, links, skipped, end_effector)
    parse_robot_description(text, f'{source} (converted)')  # the output must load: fail here
    warnings = ()
    loose = [j for j in skipped if j.kind in ('floating', 'planar')]
    if loose:
        warnings += (f'{source}: {len(loose)} floating or planar joint(s) get no transform, as '
                     f'in robot_state_publisher (their links are not on TF): '
                     f'{listing([_comment(j.name)[:80] for j in loose], 5)}',)
    if tree.slashed:
        shown = ', '.join(_comment(n)[:80] for n in tree.slashed[:5])
        more = f' and {len(tree.slashed) - 5} more' if len(tree.slashed) > 5 else ''
        warnings += (f'{source}: link names with a leading slash are published without it, '
                     f'as tf2 strips it: {shown}{more}',)
    return Conversion(text, base, tip, tuple(skipped), warnings)


@dataclass(frozen=True)
class _ChainPlan:
    """One DH chain of the tree: its joints (fixed ones too) from ``anchor`` to ``tip``."""

    anchor: str      # the link its first joint hangs from (frame 0 is placed in its axes)
    parent: str      # the same link; its DH frame is the chain's parent
    path: tuple      # the joints from anchor down to tip
    tip: str

    @property
    def moving(self):
        """Return the moving joints of the path (one DH row each)."""
        return [j for j in self.path if j.kind in MOVING]


def _split(plan, pose):
    """
    Split a chain where two axes are so nearly parallel that DH would lose precision.

    Such axes (Romeo's thumbs: 1e-7 rad apart, 18 mm) have their common normal
    :data:`FAR_NORMAL_M` or more away: rows with offsets of kilometres, whose rounding
    shows at 1e-9 m. The rest of the chain becomes a chain of its own, hanging from the
    DH frame before (its base transform is exact).
    """
    moving = [k for k, j in enumerate(plan.path) if j.kind in MOVING]
    for a, b in zip(moving, moving[1:]):
        first, second = plan.path[a], plan.path[b]
        m1 = pose[first.parent] @ first.origin
        m2 = pose[second.parent] @ second.origin
        p1, u1 = m1[:3, 3], m1[:3, :3] @ first.axis
        p2, u2 = m2[:3, 3], m2[:3, :3] @ second.axis
        cross = np.cross(u1, u2)
        if np.linalg.norm(cross) < PARALLEL_TOL:
            continue
        w = p1 - p2
        s = -np.dot(np.cross(u2, cross), w) / np.dot(cross, cross)
        t = -np.dot(np.cross(u1, cross), w) / np.dot(cross, cross)
        if max(abs(s), abs(t)) > FAR_NORMAL_M:
            head = _ChainPlan(plan.anchor, plan.parent, plan.path[:b], plan.path[b - 1].child)
            tail = _ChainPlan(second.parent, second.parent, plan.path[b:], plan.tip)
            return [head] + _split(tail, pose)
    return [plan]


def _publishable(tree, base):
    """
    Return the names of the joints below ``base`` that get a transform.

    Floating and planar joints get none (robot_state_publisher's rule), nor anything below
    them; nor joints with names this package cannot publish, nor mimics of joints that are
    not published (followed to their source through chains of mimics).
    """
    ok, stack = set(), [base]
    while stack:
        link = stack.pop()
        for j in tree.children.get(link, []):
            if j.kind in ('floating', 'planar'):
                continue
            if len(j.child) > MAX_NAME_CHARS or not TF_FRAME_ID.fullmatch(j.child):
                continue
            if j.kind in MOVING and j.mimic is None and not JOINT_NAME.fullmatch(j.name):
                continue
            ok.add(j.name)
            stack.append(j.child)
    while True:  # mimics whose source is not published are not either (nor what is below)
        bad = {name for name in ok if tree.by_name[name].mimic is not None
               and _mimic_source(tree, tree.by_name[name], ok)[0] is None}
        if not bad:
            return _reachable(tree, base, ok)
        ok -= bad
        ok = _reachable(tree, base, ok)


def _reachable(tree, base, ok):
    """Return the joints of ``ok`` reached from ``base`` through joints of ``ok``."""
    out, stack = set(), [base]
    while stack:
        for j in tree.children.get(stack.pop(), []):
            if j.name in ok:
                out.add(j.name)
                stack.append(j.child)
    return out


def _mimic_source(tree, joint, published):
    """
    Return ``(source, multiplier, offset)``: a mimic joint followed to a joint of its own.

    Chains of mimics compose (``m2 (m1 q + o1) + o2``); ``(None, ...)`` when the source is
    not a published joint, the chain loops, or a joint is not moving.
    """
    multiplier, offset, seen = 1.0, 0.0, set()
    while joint.mimic is not None:
        if joint.name in seen:
            return None, 0.0, 0.0
        seen.add(joint.name)
        name, m, o = joint.mimic
        # this joint is m * q(name) + o, and the first one multiplier * q(this) + offset
        multiplier, offset = multiplier * m, offset + multiplier * o
        source = tree.by_name.get(name)
        if source is None or source.kind not in MOVING or name not in published:
            return None, 0.0, 0.0
        joint = source
    return joint.name, multiplier, offset


def _below(tree, base, published):
    """Yield the links below ``base`` reached through published joints, parents first."""
    order = [base]
    for link in order:
        for j in tree.children.get(link, []):
            if j.name in published:
                order.append(j.child)
                yield j.child


def _longest_path(tree, link, published):
    """Return the joints of the path below ``link`` with most moving joints (first on ties)."""
    best = []
    best_count = 0
    stack = [(link, [])]
    while stack:
        at, path = stack.pop()
        count = sum(j.kind in MOVING for j in path)
        if count > best_count:
            best, best_count = path, count
        for j in reversed(tree.children.get(at, [])):
            if j.name in published:
                stack.append((j.child, path + [j]))
    while best and best[-1].kind not in MOVING:
        best = best[:-1]
    return best


def _branch_plans(tree, base, main_path, published):
    """
    Return the other chains of the tree: every moving joint not on the first chain is on one.

    Walking the URDF from ``base`` (parents first, the URDF's order), a moving joint not yet
    on a chain starts one: it and the longest path of moving joints below it.
    """
    covered = {j.name for j in main_path}
    plans = []
    for link in [base] + list(_below(tree, base, published)):
        for j in tree.children.get(link, []):
            if j.name not in published or j.name in covered or j.kind not in MOVING:
                continue
            path = [j] + _longest_path(tree, j.child, published)
            covered.update(joint.name for joint in path)
            plans.append(_ChainPlan(link, link, tuple(path), path[-1].child))
    return plans


def _chain_entry(plan, c, pose, body, frame_pose, taken, convention, published, tree):
    """
    Convert one chain of the tree: its DH frames on the joint axes, its rows and base.

    Records in ``body`` the DH frame each link of its path moves with, and in ``frame_pose``
    every DH frame's pose at zero (base link coordinates).
    """
    anchor = pose[plan.anchor]
    to_anchor = np.linalg.inv(anchor)
    lines, at = [], {}
    for j in plan.path:
        if j.kind in MOVING:
            local = to_anchor @ pose[j.parent] @ j.origin
            lines.append((local[:3, 3], local[:3, :3] @ j.axis))
        at[j.child] = len(lines)
    if lines:
        frames, kinds = _frames_on_axes(lines, convention)
    else:  # no moving joint: one fixed row, every link fixed to the base (only /tf_static)
        frames, kinds = [np.eye(4), np.eye(4)], ['first']
    frames = [anchor @ f for f in frames]   # in base link coordinates
    names = _dh_frame_names(len(frames), taken, '' if c == 0 else plan.tip, c)
    taken.update(names)
    parent = body[plan.parent]
    for name, f in zip(names, frames):
        frame_pose[name] = f
    for j in plan.path:
        body[j.child] = names[at[j.child]] if at[j.child] else body[j.parent]
    rows = []
    for i, j in enumerate(plan.moving):
        theta, d, a, alpha = _dh_row(frames[i], frames[i + 1], convention)
        row = {'frame': names[i + 1]}
        if j.kind == 'prismatic':
            row['type'] = 'prismatic'
        if j.mimic is not None:
            source, multiplier, offset = _mimic_source(tree, j, published)
            row['mimic'] = {'joint': source, 'multiplier': multiplier, 'offset': offset}
        else:
            row['joint'] = j.name
        row.update(theta=theta, d=d, a=a, alpha=alpha)
        if j.mimic is None and j.kind != 'continuous' and j.lower is not None:
            row['limits'] = [j.lower, j.upper]
        if j.mimic is None and j.velocity is not None and j.velocity > 0:
            row['max_velocity'] = j.velocity
        note = (f'URDF joint {j.name} ({j.kind}{", mimic" if j.mimic else ""}): '
                f'{j.parent} -> {j.child}; axis {kinds[i]}{" to the previous" if i else ""}')
        rows.append((row, note))
    if not plan.moving:
        rows.append(({'frame': names[1], 'type': 'fixed', 'theta': 0.0, 'd': 0.0, 'a': 0.0,
                      'alpha': 0.0}, 'no moving joint: a fixed row (every link is static)'))
    base_offset = np.linalg.solve(frame_pose[parent], frames[0]) if parent in frame_pose \
        else frames[0]
    return {'parent': parent, 'base': base_offset, 'names': names, 'rows': rows,
            'plan': plan}


def tree_joint(tree, name):
    """Return the joint called ``name`` (a :class:`UrdfJointSpec`)."""
    joint = tree.by_name.get(name)
    if joint is None:
        raise RobotDescriptionError(f'{tree.source}: no joint {name[:70]!r}')
    return joint


def _link_entry(joint, pose, body, frame_pose):
    """One ``links`` entry: the child link of ``joint``, fixed to the DH frame it moves with."""
    child = joint.child
    entry = {'frame': child, 'parent': body[child]}
    if entry['parent'] != joint.parent:
        entry['tf_parent'] = joint.parent
    offset = np.linalg.solve(frame_pose[body[child]], pose[child])
    entry['xyz'] = offset[:3, 3].tolist()
    w, x, y, z = quat_from_matrix(offset[:3, :3])
    entry['quaternion'] = [x, y, z, w]
    note = (f'URDF link {child}: child of {joint.name} ({joint.kind}'
            f'{", mimic" if joint.mimic else ""}) on {joint.parent}')
    return entry, note


def _why_skipped(joint):
    """Say in a few words why a side-branch joint is not published."""
    if joint.kind in ('floating', 'planar'):
        return f'a {joint.kind} joint (a DH description takes one-axis joints)'
    if joint.mimic is not None:
        return f'mimics {joint.mimic[0]}, which is not published'
    return 'a name this package cannot publish'


def _dh_frame_names(count, taken, tip='', chain=0):
    """
    Name the DH frames of a chain: ``dh0``, ``dh1``... for the first, ``<tip>_dh0``... else.

    Names the URDF (or an earlier chain) already uses, or too long, get another pattern
    (the last: ``dq_fk_chain<chain>_dh0``...).
    """
    patterns = ('dh{}', 'dh_{}', 'dq_fk_dh{}') if not tip else \
        (tip + '_dh{}', tip + '_dh_{}', tip + '_dq_fk_dh{}', f'dq_fk_chain{chain}_dh{{}}')
    for pattern in patterns:
        names = [pattern.format(k) for k in range(count)]
        if not taken.intersection(names) and all(len(n) <= MAX_NAME_CHARS for n in names):
            return names
    raise RobotDescriptionError(f'the URDF uses every DH frame name dq_fk would give '
                                f'({patterns[0].format(0)[:80]}...)')


def _check_frame(link, source):
    if len(link) > MAX_NAME_CHARS or not TF_FRAME_ID.fullmatch(link):
        raise RobotDescriptionError(
            f'{source}: link name {link[:70]!r} is not a frame id tf2 takes (printable ASCII '
            f'without spaces; at most {MAX_NAME_CHARS})')


def _check_joint(name, source):
    if len(name) > MAX_NAME_CHARS or not JOINT_NAME.fullmatch(name):
        raise RobotDescriptionError(f'{source}: joint name {name[:70]!r} is not usable (a '
                                    f'letter or underscore, then letters, digits, _ . / -)')


def _flow(mapping):
    """Write a YAML flow mapping of numbers, names and small lists (JSON is valid YAML)."""
    parts = []
    for key, value in mapping.items():
        parts.append(f'{key}: {_value(value)}')
    return '{' + ', '.join(parts) + '}'


def _value(value):
    if isinstance(value, dict):
        return _flow(value)
    if isinstance(value, (list, tuple)):
        return '[' + ', '.join(_value(v) for v in value) + ']'
    if isinstance(value, str):
        return json.dumps(value)
    value = float(value)
    value = 0.0 if abs(value) < NOISE else value  # rounding noise (and -0.0) written as 0
    return yaml_number(value)


def _comment(text):
    """Make user text a one-line YAML comment (no line breaks, printable only)."""
    return printable_line(text, 300)


def _transform(frame, m):
    w, x, y, z = quat_from_matrix(m[:3, :3])
    return _flow({'frame': frame, 'xyz': m[:3, 3].tolist(), 'quaternion': [x, y, z, w]})


def _yaml(tree, source, base, tip, convention, chains, links, skipped, end_effector):
    first = chains[0]['names']
    more = f' and {len(chains) - 1} more chains' if len(chains) > 1 else ''
    lines = [
        f'# Converted by `dq_fk from-urdf` from {_comment(source)}: the chain {_comment(base)} '
        f'-> {_comment(tip)}{more}.',
        f'# {convention} DH frames on the joint axes by their common normals (docs/'
        f'robot_description.md, "From a URDF"); the DH frames are published as '
        f'{first[0]}..{first[-1]}' + (' (<tip>_dh0... for the other chains)' if more else '')
        + ', the URDF links under their URDF parents.',
    ]
    for joint in skipped:
        lines.append(f'# skipped: side branch {_comment(joint.name)} ({joint.kind}) -> '
                     f'{_comment(joint.child)}: {_why_skipped(joint)}')
    lines += [
        f'robot: {json.dumps(_comment(tree.name)[:128])}',
        f'convention: {convention}',
        f'fixed_frame: {base}']

    def rows(chain, indent):
        out = []
        for row, note in chain['rows']:
            out += [f'{indent}# {_comment(note)}', f'{indent}- {_flow(row)}']
        return out

    if len(chains) == 1:
        lines += ['# frame 0 of the DH chain, in the base link',
                  'base: ' + _transform(first[0], chains[0]['base']), 'chain:']
        lines += rows(chains[0], '  ')
    else:
        lines.append('chains:')
        for chain in chains:
            plan = chain['plan']
            lines += [f'  # from {_comment(plan.anchor)} to {_comment(plan.tip)}; frame 0 in '
                      f'{_comment(chain["parent"])}',
                      f'  - parent: {json.dumps(chain["parent"])}',
                      '    base: ' + _transform(chain['names'][0], chain['base']),
                      '    chain:']
            lines += rows(chain, '      ')
    if links:
        lines.append('links:')
        for entry, note in links:
            lines += [f'  # {_comment(note)}', f'  - {_flow(entry)}']
    lines.append(f'end_effector: {end_effector}')
    return '\n'.join(lines) + '\n'


def load_urdf_description(path, base=None, tip=None, convention='standard', packages=None,
                          options=OPTIONS):
    """
    Read a ``.urdf``/``.xacro`` file and convert it: ``(Conversion, urdf text)``.

    :param packages: ``{name: folder}`` for xacro's ``$(find)`` (before the ROS paths).
    :param options: the names of the base and tip options, for messages.
    """
    text = read_urdf_text(path, packages=packages)
    return urdf_to_description(text, os.fspath(path), base, tip, convention, options), text


__all__ = ['chain_joints', 'Conversion', 'load_urdf_description', 'parse_urdf',
           'read_urdf_text', 'urdf_to_description', 'UrdfJointSpec', 'UrdfTree']
