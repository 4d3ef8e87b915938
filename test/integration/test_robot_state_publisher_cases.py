"""
robot_state_publisher's own launch tests, run against dq_fk_node.

Its test suite starts robot_state_publisher with a two-link URDF as its
``robot_description`` parameter and asks tf2 for link1 -> link2 (5 m along x, within 0.01 m)
and that base_link -> wim_link does not exist: with a moving joint at pi
(two_links_moving_joint), a fixed joint (two_links_fixed_joint, refused by dq_fk_node
before: "a DH chain needs at least one moving joint") and a fixed joint under
``frame_prefix: my_prefix/`` (two_links_fixed_joint_prefix). Here the node is a process
given the URDF the same way (a parameters file), and a tf2 lookup is the composition of the
transforms received on /tf and /tf_static (no tf2_ros on a pip-only install).
"""

import math
import time

import homogeneous_tf as htf
import numpy as np
import pytest
from ros_harness import TF_STATIC_QOS
from tf2_msgs.msg import TFMessage
import yaml

EPS = 0.01  # robot_state_publisher's tests' tolerance


def two_links(joint_type):
    """Two links, joint1 between them 5 m along x (the URDFs of the three tests)."""
    axis = '' if joint_type == 'fixed' else '<axis xyz="0 0 1"/>'
    return ('<?xml version="1.0"?><robot name="test_robot"><link name="link1"/>'
            f'<link name="link2"/><joint name="joint1" type="{joint_type}">'
            '<parent link="link1"/><child link="link2"/><origin xyz="5 0 0" rpy="0 0 0"/>'
            f'{axis}</joint></robot>')


def lookup(transforms, target, source):
    """Return tf2's lookupTransform(target, source) as a 4x4, or None if not connected."""
    parents = {t.child_frame_id: t.header.frame_id for t in transforms}

    def to_root(frame):
        path = [frame]
        while path[-1] in parents and len(path) < 1000:
            path.append(parents[path[-1]])
        return path
    up_target, up_source = to_root(target), to_root(source)
    if up_target[-1] != up_source[-1] or not ({target, source} & (set(parents) |
                                                                  set(parents.values()))):
        return None
    root = up_target[-1]
    return np.linalg.inv(htf.compose(transforms, root, target)) @ \
        htf.compose(transforms, root, source)


@pytest.mark.parametrize('case, joint_type, prefix, positions', [
    ('two_links_moving_joint', 'continuous', '', [math.pi]),
    ('two_links_fixed_joint', 'fixed', '', None),
    ('two_links_fixed_joint_prefix', 'fixed', 'my_prefix/', None),
])
def test_robot_state_publishers_launch_test(case, joint_type, prefix, positions, tmp_path,
                                            processes, listener):
    from dq_fk_ros.ros.executables import executable
    params = tmp_path / 'params.yaml'
    params.write_text(yaml.safe_dump({'dq_fk_node': {'ros__parameters': {
        'robot_description': two_links(joint_type), 'frame_prefix': prefix}}}))
    node = processes.start(executable('dq_fk_node') + ['--ros-args', '--params-file',
                                                       str(params)])
    tf = listener.listen(TFMessage, '/tf', 100)
    static = listener.listen(TFMessage, '/tf_static', TF_STATIC_QOS)
    link1, link2 = prefix + 'link1', prefix + 'link2'

    def received():
        return [t for m in static[-1:] + tf[-1:] for t in m.transforms]

    def seen():
        return lookup(received(), link1, link2) is not None
    # a freshly stamped state every 50 ms, as a joint_state_publisher sends: the node throttles
    # /tf by the stamps (robot_state_publisher's rule), so one stamp repeated is published
    # once, and lost if that was before this listener's /tf subscription was matched
    deadline = time.monotonic() + 10
    while not seen() and time.monotonic() < deadline:
        state = None if positions is None else listener.joint_state(['joint1'], positions)
        listener.spin_until(seen, publish=state, timeout_s=0.05)
    assert seen(), (case, node.poll())
    t = lookup(received(), link1, link2)
    np.testing.assert_allclose(t[:3, 3], [5.0, 0.0, 0.0], atol=EPS)
    assert lookup(received(), 'base_link', 'wim_link') is None
    if positions is None:  # nothing moves: robot_state_publisher sends no /tf either
        listener.spin_until(lambda: False, timeout_s=0.5,
                            publish=listener.joint_state(['other_robots_joint'], [0.0]))
        assert not tf, tf[:1]
    assert node.poll() is None
