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
The base transform places frame 0 in its parent; every URDF link becomes a ``links`` entry
(its pose in the DH frame it moves with, published under its URDF parent), so TF carries
the URDF's own tree. A mimic joint is a mimic row (chains of mimics followed to their
source). A chain is split where two axes are so nearly parallel that their common normal
lies :data:`~.urdf_chains.FAR_NORMAL_M` away (:mod:`.urdf_chains` chooses the chains).
Floating and planar joints are as robot_state_publisher has them: a planar joint is a fixed
one at its origin (kdl_parser converts it); a floating joint's child is a ``type:
floating`` link, computed at the joint's origin and on TF the root of a tree of its own,
everything below it published (no DH chain crosses a floating joint: a moving joint below
one starts a chain). Mimics of joints that are not published are skipped and named. The DH
frames are the computation's: the YAML says ``publish_dh_frames: false``, so TF carries the
URDF's links alone.
"""

from collections.abc import Mapping
from dataclasses import dataclass, replace
import os

from dq_fk_ros.description.dh_fit import dh_row, frames_on_axes
from dq_fk_ros.description.robot_model import (
    JOINT_NAME, MAX_NAME_CHARS, MAX_ROWS, RobotModel, TF_FRAME_ID)
from dq_fk_ros.description.schema import parse_robot_description
from dq_fk_ros.description.to_yaml import ChainText, comment, description_yaml
from dq_fk_ros.description.urdf_chains import (
    branch_plans, ChainPlan, links_below, mimic_source, publishable_joints, split_chain)
from dq_fk_ros.description.urdf_reader import (
    MOVING, parse_urdf, read_urdf_text, tf_name, UrdfTree)
from dq_fk_ros.errors import listing, RobotDescriptionError
from dq_fk_ros.kinematics.dual_quaternion import quat_from_matrix
import numpy as np

# how the tools call the base and tip links (messages name the option of the tool that said it)
OPTIONS = ('--base', '--tip')
NODE_OPTIONS = ('urdf_base_link', 'urdf_tip_link')


# -- the chain ---------------------------------------------------------------------------
def chain_joints(tree: UrdfTree, base: str | None = None, tip: str | None = None,
                 options: tuple[str, str] = OPTIONS) -> tuple[str, str, list]:
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
    if tip is None:  # among equally long chains (two legs, arms, fingers) the first in the
        # URDF's order; the others become side branches. base itself if nothing moves below
        tip = longest_chain_tips(tree, base)[0] or base
    joints, at = [], tip
    while at != base:
        if at not in tree.joints:
            raise RobotDescriptionError(f'{source}: {tip_option} {tip!r} is not below '
                                        f'{base_option} {base!r}')
        joints.append(tree.joints[at])
        at = tree.joints[at].parent
    joints.reverse()
    for joint in joints:
        if joint.kind == 'floating':
            raise RobotDescriptionError(f'{source}: joint {joint.name!r} on the chain is '
                                        f'floating; a DH chain takes revolute, continuous, '
                                        f'prismatic, fixed and planar (as fixed) joints: choose '
                                        f'a {base_option} below it or a {tip_option} above it')
    return base, tip, joints


def longest_chain_tips(tree: UrdfTree, base: str) -> list[str]:
    """
    Return the links that end the longest chains of moving joints below ``base``.

    Each is the child link of a chain's last moving joint (mimic joints not counted), in the
    URDF's link order; ``[None]`` when no moving joint is below ``base``.
    """
    best, tips = -1, set()
    stack = [(base, 0, None)]
    while stack:
        link, count, last = stack.pop()
        below = [j for j in tree.children.get(link, []) if j.kind != 'floating']
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


# -- the robot description ---------------------------------------------------------------
@dataclass(frozen=True)
class Conversion:
    """What :func:`urdf_to_description` made: the YAML text, its model, what it left out."""

    text: str
    base: str
    tip: str
    skipped: tuple          # side-branch joints not published (one line each)
    warnings: tuple = ()    # what a user should know (one line each): names changed
    model: RobotModel | None = None  # ``text`` parsed (once: the loaders take this one)


def urdf_to_description(text: str, source: str = '<string>', base: str | None = None,
                        tip: str | None = None, convention: str = 'standard',
                        options: tuple[str, str] = OPTIONS) -> 'Conversion':
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
    tree, orphans = _detach_orphan_mimics(parse_urdf(text, source))
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
    published = publishable_joints(tree, base)
    for j in moving:
        if j.mimic is not None and mimic_source(tree, j, published)[0] not in chain_names:
            raise RobotDescriptionError(
                f'{source}: joint {j.name!r} on the chain mimics {j.mimic[0]!r}, which is not '
                f'a moving joint of the chain {base!r} -> {tip!r}')

    # poses at zero, in the base link, of every link published
    pose = {base: np.eye(4)}
    for link in links_below(tree, base, published):
        joint = tree.joints[link]
        pose[link] = pose[joint.parent] @ joint.origin
    plans = [part for plan in [ChainPlan(base, base, tuple(path), tip)]
             + branch_plans(tree, base, path, published) for part in split_chain(plan, pose)]
    if sum(len(plan.moving) for plan in plans) > MAX_ROWS:
        raise RobotDescriptionError(f'{source}: {sum(len(p.moving) for p in plans)} moving '
                                    f'joints; a robot description has at most {MAX_ROWS} rows')
    taken = set(tree.links)
    body = {base: base}          # link -> the DH frame (or the base link) it moves with
    frame_pose = {base: np.eye(4)}
    chains = []
    order = list(links_below(tree, base, published))
    for c, plan in enumerate(plans + [None]):
        for link in order:  # links fixed to a link of known body move with it
            joint = tree.joints[link]
            if link not in body and joint.kind not in MOVING and joint.parent in body:
                body[link] = body[joint.parent]
        if plan is not None:
            chains.append(_chain_entry(plan, c, pose, body, frame_pose, taken, convention,
                                       published, tree))
    links = []
    for link in links_below(tree, base, published):
        links.append(_link_entry(tree.joints[link], pose, body, frame_pose))
    skipped = [j for j in tree.joints.values() if j.parent in pose and j.child not in pose]
    end_effector = tip
    if not moving:  # the fixed frame cannot be the end effector: the deepest link
        end_effector = links[-1][0]['frame'] if links else chains[0]['names'][1]
    text = _description_text(tree, source, base, tip, convention, chains, links, skipped,
                             end_effector)
    model = parse_robot_description(text, f'{source} (converted)')  # it must load: fail here
    warnings = _joint_kind_warnings(tree, source, base, published, orphans)
    if tree.slashed:
        shown = ', '.join(comment(n)[:80] for n in tree.slashed[:5])
        more = f' and {len(tree.slashed) - 5} more' if len(tree.slashed) > 5 else ''
        warnings += (f'{source}: link names with a leading slash are published without it, '
                     f'as tf2 strips it: {shown}{more}',)
    return Conversion(text, base, tip, tuple(skipped), warnings, model)


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
        frames, kinds = frames_on_axes(lines, convention)
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
        theta, d, a, alpha = dh_row(frames[i], frames[i + 1], convention)
        row = {'frame': names[i + 1]}
        if j.kind == 'prismatic':
            row['type'] = 'prismatic'
        if j.mimic is not None:
            source, multiplier, offset = mimic_source(tree, j, published)
            row['mimic'] = {'joint': source, 'multiplier': multiplier, 'offset': offset}
        else:
            row['joint'] = j.name
        row.update(theta=theta, d=d, a=a, alpha=alpha)
        if j.mimic is None and j.lower is not None:   # (a continuous joint has none)
            row['limits'] = [j.lower, j.upper]
        if j.mimic is None and j.velocity is not None and j.velocity > 0:
            row['max_velocity'] = j.velocity
        note = (f'URDF joint {j.name} ({j.kind}{", mimic" if j.mimic else ""}): '
                f'{j.parent} -> {j.child}; axis {kinds[i]}{" to the previous" if i else ""}')
        rows.append((row, note))
    if not plan.moving:
        rows.append(({'frame': names[1], 'type': 'fixed', 'theta': 0.0, 'd': 0.0, 'a': 0.0,
                      'alpha': 0.0}, 'no moving joint: a fixed row (every link is static)'))
    base_offset = np.linalg.solve(frame_pose[parent], frames[0])   # (the base link's: identity)
    return {'parent': parent, 'base': base_offset, 'names': names, 'rows': rows,
            'plan': plan}


def _link_entry(joint, pose, body, frame_pose):
    """One ``links`` entry: the child link of ``joint``, fixed to the DH frame it moves with."""
    child = joint.child
    entry = {'frame': child, 'parent': body[child]}
    if entry['parent'] != joint.parent:
        entry['tf_parent'] = joint.parent
    if joint.kind == 'floating':  # at its origin; no transform (the YAML's type: floating)
        entry['type'] = 'floating'
    offset = np.linalg.solve(frame_pose[body[child]], pose[child])
    entry['xyz'] = offset[:3, 3].tolist()
    w, x, y, z = quat_from_matrix(offset[:3, :3])
    entry['quaternion'] = [x, y, z, w]
    note = (f'URDF link {child}: child of {joint.name} ({joint.kind}'
            f'{", mimic" if joint.mimic else ""}) on {joint.parent}'
            + ('; fixed at its origin, as robot_state_publisher' if joint.kind == 'planar'
               else '')
            + ('; at its origin, not on TF: it roots a TF tree' if joint.kind == 'floating'
               else ''))
    return entry, note


def _description_text(tree, source, base, tip, convention, chains, links, skipped,
                      end_effector):
    """Write the converted robot's YAML: where it came from, then its chains and links."""
    first = chains[0]['names']
    more = f' and {len(chains) - 1} more chains' if len(chains) > 1 else ''
    comments = [
        f'Converted by `dq_fk from-urdf` from {comment(source)}: the chain {comment(base)} -> '
        f'{comment(tip)}{more}.',
        f'{convention} DH frames on the joint axes by their common normals (docs/urdf.md); '
        f'the DH frames are {first[0]}..{first[-1]}'
        + (' (<tip>_dh0... for the other chains)' if more else '')
        + '; TF carries the URDF links under their URDF parents, as robot_state_publisher '
        '(publish_dh_frames: true adds the DH frames).']
    comments += [f'skipped: side branch {comment(j.name)} ({j.kind}) -> {comment(j.child)}: '
                 f'{_why_skipped(j)}' for j in skipped]
    texts = [ChainText(c['parent'], c['base'], tuple(c['names']), tuple(c['rows']),
                       f"from {comment(c['plan'].anchor)} to {comment(c['plan'].tip)}; frame 0 "
                       f"in {comment(c['parent'])}") for c in chains]
    return description_yaml(comments, tree.name, convention, base, texts, links, end_effector,
                            publish_dh_frames=False)


def _detach_orphan_mimics(tree):
    """
    Return ``(tree, names)``: the mimic joints whose source is no moving joint made plain.

    robot_state_publisher computes a mimic joint only when a JointState names its source;
    otherwise the joint moves by its own value in the JointState (its mimic loop never
    overwrites a value the message gave). A source the URDF does not have (example-robot-data's
    alex_psyonic_hands: ``mimic joint="index_q1"`` for ``Left_index_q1``) is never named, so
    such a joint is a joint of its own.
    """
    everything = set(tree.by_name)
    orphans = {j.child: replace(j, mimic=None) for j in tree.joints.values()
               if j.mimic is not None and j.kind in MOVING
               and mimic_source(tree, j, everything)[0] is None}
    if not orphans:
        return tree, ()
    joints = {child: orphans.get(child, j) for child, j in tree.joints.items()}
    children = {parent: [orphans.get(j.child, j) for j in below]
                for parent, below in tree.children.items()}
    tree = replace(tree, joints=joints, children=children)
    return tree, tuple(j.name for j in orphans.values())


def _joint_kind_warnings(tree, source, base, published, orphans=()):
    """
    Say once each how the URDF's planar and floating joints are published (one line each).

    As robot_state_publisher: a planar joint is fixed at its origin (kdl_parser converts it
    and warns), a floating joint has no transform and its child roots a TF tree.
    """
    below = list(links_below(tree, base, published))
    joints = [tree.joints[link] for link in below]
    out = ()
    planar = [comment(j.name)[:80] for j in joints if j.kind == 'planar']
    if planar:
        out += (f'{source}: {len(planar)} planar joint(s) published as fixed at their origin, '
                f'on /tf_static (robot_state_publisher: kdl_parser converts them): '
                f'{listing(planar, 5)}',)
    shown = [comment(j.name)[:80] for j in joints if j.name in orphans]
    if shown:
        out += (f'{source}: {len(shown)} mimic joint(s) of joints the URDF does not have (or '
                f'that do not move) move by their own joint state, as robot_state_publisher '
                f'moves them: {listing(shown, 5)}',)
    floating = [j for j in joints if j.kind == 'floating']
    if floating:
        parts = []
        for j in floating[:5]:
            count = sum(1 for _ in links_below(tree, j.child, published))
            parts.append(f'{comment(j.name)[:80]} ({comment(j.parent)[:80]} -> '
                         f'{comment(j.child)[:80]}, {count} link(s) below)')
        more = f' and {len(floating) - 5} more' if len(floating) > 5 else ''
        out += (f'{source}: {len(floating)} floating joint(s) not published, as '
                f'robot_state_publisher (joint states cannot say where the child is; '
                f'odometry or localisation publishes it); each child roots a TF tree of its '
                f'own, the links below it published relative to it: {", ".join(parts)}{more}',)
    return out


def _why_skipped(joint):
    """Say in a few words why a side-branch joint is not published."""
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


def load_urdf_description(path: str | os.PathLike, base: str | None = None,
                          tip: str | None = None, convention: str = 'standard',
                          packages: Mapping[str, str] | None = None,
                          options: tuple[str, str] = OPTIONS) -> tuple['Conversion', str]:
    """
    Read a ``.urdf``/``.xacro`` file and convert it: ``(Conversion, urdf text)``.

    :param packages: ``{name: folder}`` for xacro's ``$(find)`` (before the ROS paths).
    :param options: the names of the base and tip options, for messages.
    """
    text = read_urdf_text(path, packages=packages)
    return urdf_to_description(text, os.fspath(path), base, tip, convention, options), text


__all__ = ['chain_joints', 'Conversion', 'load_urdf_description', 'NODE_OPTIONS', 'OPTIONS',
           'urdf_to_description']
