"""
The node as a drop-in for robot_state_publisher: a vendor URDF in, the URDF's TF tree out.

The node runs in-process and talks to the test over DDS. The test composes the TF graph it
receives and compares every URDF link with pinocchio's kinematics of the vendor's URDF;
the TF parents must be the URDF's parent links, as robot_state_publisher publishes them.
"""

import math
import xml.etree.ElementTree as ElementTree

from builtin_interfaces.msg import Time
import homogeneous_tf as htf
import numpy as np
import pinocchio_oracle as oracle
import pytest
from rclpy.parameter import Parameter
from ros_harness import Harness, TF_STATIC_QOS
from std_msgs.msg import String
from tf2_msgs.msg import TFMessage
from vendor_urdfs import PANDA, UR5, vendor_path, vendor_robot

pytestmark = pytest.mark.integration


def urdf_parents(text):
    """Return ``{child link: parent link}`` of a URDF."""
    return {j.find('child').get('link'): j.find('parent').get('link')
            for j in ElementTree.fromstring(text).findall('joint')}


def random_joints(model, rng):
    limits = model.limits.copy()
    limits[~np.isfinite(limits)] = math.pi * np.sign(limits[~np.isfinite(limits)])
    return rng.uniform(limits[:, 0], limits[:, 1])


def check_tf_tree(harness, model, urdf, rng, mimic=False, rounds=4):
    """Drive the node; every URDF link it publishes must match pinocchio, parents the URDF's."""
    pin_model = oracle.urdf_model(urdf, mimic=mimic)
    parents = urdf_parents(urdf)
    links = [name for name in model.frame_names if name in parents]
    tf = harness.listen(TFMessage, '/tf', 100)
    static = harness.listen(TFMessage, '/tf_static', TF_STATIC_QOS)
    for _ in range(rounds):
        q = random_joints(model, rng)
        msg = harness.joint_state(model.joint_names, q)
        tf.clear()
        assert harness.spin_until(lambda: static and tf and tf[-1].transforms[0].header
                                  .stamp == msg.header.stamp, publish=msg)
        transforms = static[-1].transforms + tf[-1].transforms
        pin_q = oracle.configuration(pin_model, dict(zip(model.joint_names, q)))
        expected = oracle.link_placements(pin_model, pin_q, links + [model.fixed_frame])
        root = np.linalg.inv(expected[model.fixed_frame])
        for link in links:
            np.testing.assert_allclose(htf.compose(transforms, model.fixed_frame, link),
                                       root @ expected[link], atol=1e-9, err_msg=link)
            assert htf.parent_of(transforms, link) == parents[link], link
    return links


def test_a_ur5_urdf_file_gives_its_own_link_names_and_tree(ros_domain_id):
    robot = vendor_robot(UR5)
    model = robot.model
    harness = Harness()
    try:
        harness.start_node(robot_description_file=vendor_path(UR5), urdf_tip_link='tool0')
        description = harness.listen(String, '/robot_description', TF_STATIC_QOS)
        links = check_tf_tree(harness, model, robot.urdf, np.random.default_rng(4))
        chain = ['base_link', 'shoulder_link', 'upper_arm_link', 'forearm_link',
                 'wrist_1_link', 'wrist_2_link', 'wrist_3_link']
        assert [link for link in links if link in chain] == chain
        assert set(links) == set(chain) | {'tool0', 'ee_link', 'base'}  # all but 'world'
        assert model.fixed_frame == 'world' and model.end_effector == 'tool0'
        # the vendor's URDF itself (its meshes, names, limits), as robot_state_publisher sends it
        assert harness.spin_until(lambda: description)
        assert description[-1].data == robot.urdf
    finally:
        harness.close()


def test_a_urdf_string_parameter_with_a_mimic_finger(ros_domain_id):
    robot = vendor_robot(PANDA)
    with open(vendor_path(PANDA), encoding='utf-8') as stream:
        text = stream.read()
    harness = Harness()
    try:
        harness.start_node(robot_description=text, urdf_tip_link=PANDA[1])
        links = check_tf_tree(harness, robot.model, text, np.random.default_rng(8), mimic=True)
        assert 'panda_rightfinger' in links  # the mimic finger, moved with its joint
    finally:
        harness.close()


def test_reload_between_urdf_and_dh_and_a_bad_urdf_is_refused(ros_domain_id, tmp_path):
    bad = tmp_path / 'bad.urdf'
    bad.write_text('<robot name="x"><link name="a"/><joint name="j" type="revolute">'
                   '<parent link="a"/><child link="ghost"/></joint></robot>')
    harness = Harness()
    try:
        node = harness.start_node(robot_description_file='ur5e')  # a shipped name
        static = harness.listen(TFMessage, '/tf_static', TF_STATIC_QOS)
        assert harness.spin_until(lambda: static)
        result = node.set_parameters([Parameter('robot_description_file', value=str(bad))])
        assert not result[0].successful
        assert result[0].reason == (f"{bad}: joint 'j': child link 'ghost' is not defined (no "
                                    f'<link name="ghost">)')
        static.clear()
        result = node.set_parameters([Parameter('robot_description_file',
                                                value=vendor_path(UR5))])
        assert result[0].successful
        assert harness.spin_until(lambda: static and 'tool0' in {
            t.child_frame_id for t in static[-1].transforms})
    finally:
        harness.close()


def test_publish_frequency_throttles_by_stamps_unless_ignore_timestamp(ros_domain_id):
    names = [f'joint_{i}' for i in range(1, 7)]
    for params, expected_ms in (({'publish_frequency': 20.0}, [0, 50, 100]),
                                ({'publish_frequency': 20.0, 'ignore_timestamp': True},
                                 list(range(0, 101, 10)))):
        harness = Harness()
        try:
            harness.start_node(**params)
            tf = harness.listen(TFMessage, '/tf', 100)
            harness.spin_until(lambda: False, timeout_s=0.5)  # discovery
            for ms in range(0, 101, 10):
                stamp = Time(sec=100, nanosec=ms * 1_000_000)
                harness.joint_pub.publish(harness.joint_state(names, [0.1] * 6, stamp=stamp))
                harness.spin_until(lambda: False, timeout_s=0.02)
            harness.spin_until(lambda: len(tf) >= len(expected_ms), timeout_s=3.0)
            harness.spin_until(lambda: False, timeout_s=0.3)
            got = [t.transforms[0].header.stamp.nanosec // 1_000_000 for t in tf]
            assert got == expected_ms, params
        finally:
            harness.close()
