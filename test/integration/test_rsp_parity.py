"""
dq_fk_node's TF against robot_state_publisher's rule, on every robot of example-robot-data.

robot_state_publisher (Jazzy: ``addChildren`` over kdl_parser's tree) publishes one
transform per URDF joint, parent link -> child link, and nothing else: revolute, continuous,
prismatic and mimic joints on /tf, fixed ones on /tf_static, planar ones as fixed at their
origin (kdl_parser converts them), a floating one not at all (its child is then the root of
a second tree). That rule is read here from the URDF with xml.etree, not from the package.
Each robot runs as shipped, then with a floating joint above its root and a planar one in
the middle of its tree, then the other way round. Poses: pinocchio's, to 1e-9, each link in
the root of its TF tree. Several nodes run at once, each under its own ``frame_prefix``.
"""

import glob
import os
import xml.etree.ElementTree as ElementTree

import homogeneous_tf as htf
import numpy as np
import pinocchio_oracle as oracle
import pytest
from ros_harness import Harness, TF_STATIC_QOS
from tf2_msgs.msg import TFMessage
from vendor_urdfs import robots_dir

pytestmark = pytest.mark.integration

MOVING = ('revolute', 'continuous', 'prismatic')
GROUP = 8  # nodes at once


def vendor_robots():
    """Every URDF of example-robot-data that is a robot (part files have no <link>)."""
    out = []
    for path in sorted(glob.glob(os.path.join(robots_dir(), '**', '*.urdf'), recursive=True)):
        with open(path, encoding='utf-8') as stream:
            text = stream.read()
        if ElementTree.fromstring(text).find('link') is not None:
            out.append((os.path.relpath(path, robots_dir()), text))
    return out


def rsp_edges(text):
    """Return ``(moving, static)``: the ``(parent, child)`` links RSP publishes, by its rule."""
    joints = ElementTree.fromstring(text).findall('joint')
    kinds = {j.get('name'): j.get('type') for j in joints}
    mimics = {j.get('name'): j.find('mimic').get('joint') for j in joints
              if j.find('mimic') is not None}

    def driven(name, seen=()):  # a mimic moves once its source joint is named
        if name not in mimics:
            return kinds.get(name) in MOVING
        return mimics[name] not in seen and driven(mimics[name], seen + (name,))
    moving, static = set(), set()
    for j in joints:
        edge = (j.find('parent').get('link').lstrip('/'), j.find('child').get('link').lstrip('/'))
        kind = j.get('type')
        if kind in MOVING and driven(j.get('name')):
            moving.add(edge)
        elif kind in ('fixed', 'planar'):
            static.add(edge)
    return moving, static


def mimic_values(text, values):
    """Return ``values`` with every mimic joint's value (multiplier * source + offset)."""
    out = dict(values)
    joints = {j.get('name'): j for j in ElementTree.fromstring(text).findall('joint')}
    for _ in range(len(joints)):
        for name, j in joints.items():
            m = j.find('mimic')
            if m is not None and m.get('joint') in out and name not in out:
                out[name] = float(m.get('multiplier', 1)) * out[m.get('joint')] + \
                    float(m.get('offset', 0))
    return out


def with_joint(text, kind, where):
    """
    Add a ``kind`` joint to a URDF: above its root (``root``) or mid-tree (``middle``).

    Mid-tree: below the link halfway down the deepest path, which has children; its child
    joints then hang from the new joint's child.
    """
    robot = ElementTree.fromstring(text)
    joints = robot.findall('joint')
    parent = {j.find('child').get('link'): j.find('parent').get('link') for j in joints}
    links = [link.get('name') for link in robot.findall('link')]
    origin = ElementTree.fromstring('<origin xyz="0.1 -0.2 0.3" rpy="0.3 -0.2 0.1"/>')
    if where == 'root':
        root = next(link for link in links if link not in parent)
        new, above, below = f'added_{kind}_root', f'added_{kind}_root', root
    else:
        def depth(link):
            return 0 if link not in parent else 1 + depth(parent[link])
        deepest = max(links, key=depth)
        path = [deepest]
        while path[-1] in parent:
            path.append(parent[path[-1]])
        middle = path[len(path) // 2]
        new, above, below = f'added_{kind}_mid', middle, f'added_{kind}_mid'
        for j in joints:
            if j.find('parent').get('link') == middle:
                j.find('parent').set('link', below)
    robot.insert(0, ElementTree.Element('link', name=new))
    joint = ElementTree.Element('joint', name=f'{new}_joint', type=kind)
    joint.append(ElementTree.Element('parent', link=above))
    joint.append(ElementTree.Element('child', link=below))
    joint.append(origin)
    robot.insert(1, joint)
    return ElementTree.tostring(robot, encoding='unicode')


def variants():
    """Each robot as shipped, and with floating and planar joints added: (id, urdf text)."""
    out = []
    for name, text in vendor_robots():
        out.append((name, text))
        out.append((f'{name}+floating root+planar middle',
                    with_joint(with_joint(text, 'planar', 'middle'), 'floating', 'root')))
        out.append((f'{name}+planar root+floating middle',
                    with_joint(with_joint(text, 'floating', 'middle'), 'planar', 'root')))
    return out


VARIANTS = variants()
GROUPS = [VARIANTS[k:k + GROUP] for k in range(0, len(VARIANTS), GROUP)]


def tree_root(transforms, frame):
    """Return the root of ``frame``'s tree in a list of TransformStamped."""
    parents = {t.child_frame_id: t.header.frame_id for t in transforms}
    while frame in parents:
        frame = parents[frame]
    return frame


@pytest.mark.parametrize('group', GROUPS, ids=[f'{g[0][0]}..' for g in GROUPS])
def test_tf_is_robot_state_publishers_and_poses_are_pinocchios(group, ros_domain_id):
    rng = np.random.default_rng(len(group[0][0]))
    harness = Harness()
    try:
        tf = harness.listen(TFMessage, '/tf', 1000)
        static = harness.listen(TFMessage, '/tf_static', TF_STATIC_QOS)
        expected = {}
        for k, (name, text) in enumerate(group):
            harness.start_node(robot_description=text, frame_prefix=f'r{k}/')
            expected[f'r{k}/'] = (name, text) + rsp_edges(text)
        values = {}
        for _, text in group:
            for j in ElementTree.fromstring(text).findall('joint'):
                if j.get('type') in MOVING and j.find('mimic') is None:
                    values.setdefault(j.get('name'), float(rng.uniform(-0.5, 0.5)))
        msg = harness.joint_state(list(values), list(values.values()))

        def split(messages):
            by_prefix = {}
            for m in messages:
                for t in m.transforms:
                    prefix = t.child_frame_id.split('/', 1)[0] + '/'
                    by_prefix.setdefault(prefix, []).append(t)
            return by_prefix

        def complete():
            now = split(m for m in tf if m.transforms and
                        m.transforms[0].header.stamp == msg.header.stamp)
            latched = split(static)
            return all((not moving or prefix in now) and (not fixed or prefix in latched)
                       for prefix, (_, _, moving, fixed) in expected.items())
        assert harness.spin_until(complete, publish=msg, timeout_s=60), \
            [name for name, _ in group]
        now = split(m for m in tf if m.transforms and
                    m.transforms[0].header.stamp == msg.header.stamp)
        latched = split(static)
        for prefix, (name, text, moving, fixed) in expected.items():
            got_moving = {(t.header.frame_id, t.child_frame_id) for t in now.get(prefix, [])}
            got_static = {(t.header.frame_id, t.child_frame_id) for t in latched.get(prefix, [])}

            def unprefixed(edges):
                return {(p[len(prefix):], c[len(prefix):]) for p, c in edges}
            assert unprefixed(got_moving) == moving, (name, unprefixed(got_moving) ^ moving)
            assert unprefixed(got_static) == fixed, (name, unprefixed(got_static) ^ fixed)
            transforms = now.get(prefix, []) + latched.get(prefix, [])
            try:
                pin_model = oracle.urdf_model(text, mimic=True)
                joint_values = values
            except ValueError:  # pinocchio refuses the mimic joints: give it their values
                pin_model = oracle.urdf_model(text)
                joint_values = mimic_values(text, values)
            links = sorted({c for _, c in moving | fixed})
            placements = oracle.link_placements(
                pin_model, oracle.configuration(pin_model, joint_values),
                links + sorted({tree_root(transforms, prefix + link)[len(prefix):]
                                for link in links}))
            for link in links:
                root = tree_root(transforms, prefix + link)
                ours = htf.compose(transforms, root, prefix + link)
                theirs = np.linalg.inv(placements[root[len(prefix):]]) @ placements[link]
                np.testing.assert_allclose(ours, theirs, atol=1e-9, err_msg=f'{name}: {link}')
    finally:
        harness.close()
