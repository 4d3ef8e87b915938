"""
The node as a drop-in for robot_state_publisher: a vendor URDF in, the URDF's TF tree out.

The node runs in-process and talks to the test over DDS. The test composes the TF graph it
receives and compares every URDF link with pinocchio's kinematics of the vendor's URDF;
the TF parents must be the URDF's parent links, as robot_state_publisher publishes them.
"""

import math
import os
import xml.etree.ElementTree as ElementTree

from builtin_interfaces.msg import Time
from dq_fk_ros.description.loading import load_robot
from geometry_msgs.msg import PoseStamped
import homogeneous_tf as htf
import numpy as np
import pinocchio_oracle as oracle
import pytest
from rclpy.parameter import Parameter
from ros_harness import Harness, TF_STATIC_QOS
from std_msgs.msg import String
from tf2_msgs.msg import TFMessage
from vendor_urdfs import PANDA, robots_dir, UR5, vendor_path, vendor_robot, Z1

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
        assert_tf_is_pinocchios(transforms, model.fixed_frame, pin_model,
                                dict(zip(model.joint_names, q)), links, parents)
    return links


def assert_tf_is_pinocchios(transforms, fixed_frame, pin_model, values, links, parents):
    """Each link composed from ``transforms`` is pinocchio's, under its URDF parent (1e-9)."""
    pin_q = oracle.configuration(pin_model, values)
    expected = oracle.link_placements(pin_model, pin_q, links + [fixed_frame])
    root = np.linalg.inv(expected[fixed_frame])
    for link in links:
        np.testing.assert_allclose(htf.compose(transforms, fixed_frame, link),
                                   root @ expected[link], atol=1e-9, err_msg=link)
        assert htf.parent_of(transforms, link) == parents[link], link


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
        # a shipped name; run-time files from the test's folder and the vendor's
        node = harness.start_node(robot_description_file='ur5e', robot_description_dirs=(
            f'{tmp_path}:{os.path.dirname(vendor_path(UR5))}'))
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


def test_publish_frequency_throttles_tf_by_stamps_unless_ignore_timestamp(ros_domain_id):
    """robot_state_publisher's default, 20 Hz of stamps, on /tf; the poses at every update."""
    names = [f'joint_{i}' for i in range(1, 7)]
    every = list(range(0, 101, 10))
    for params, expected_ms in (({'publish_frequency': None}, [0, 50, 100]),
                                ({'publish_frequency': 20.0, 'ignore_timestamp': True}, every),
                                ({'publish_frequency': 0.0}, every)):
        harness = Harness()
        try:
            harness.start_node(**params)
            tf = harness.listen(TFMessage, '/tf', 100)
            poses = harness.listen(PoseStamped, harness.topic('pose/eeCarry_seg6'), 100)
            harness.spin_until(lambda: False, timeout_s=0.5)  # discovery
            for ms in range(0, 101, 10):
                stamp = Time(sec=100, nanosec=ms * 1_000_000)
                harness.joint_pub.publish(harness.joint_state(names, [0.1] * 6, stamp=stamp))
                harness.spin_until(lambda: False, timeout_s=0.02)
            harness.spin_until(lambda: len(tf) >= len(expected_ms), timeout_s=3.0)
            harness.spin_until(lambda: False, timeout_s=0.3)
            got = [t.transforms[0].header.stamp.nanosec // 1_000_000 for t in tf]
            assert got == expected_ms, params
            assert [p.header.stamp.nanosec // 1_000_000 for p in poses] == every, params
        finally:
            harness.close()


def test_a_side_branch_joint_is_published_once_joint_states_name_it(ros_domain_id):
    robot = vendor_robot(Z1)
    model = robot.model
    assert model.joint_names[-1] == 'jointGripper' and len(model.branches) == 1
    chain = list(model.joint_names[:6])
    harness = Harness()
    try:
        harness.start_node(robot_description_file=vendor_path(Z1), urdf_tip_link=Z1[1])
        tf = harness.listen(TFMessage, '/tf', 100)
        static = harness.listen(TFMessage, '/tf_static', TF_STATIC_QOS)
        arm = harness.joint_state(chain, [0.1, 0.5, -0.4, 0.2, 0.3, -0.6])
        assert harness.spin_until(lambda: static and tf and tf[-1].transforms[0].header.stamp
                                  == arm.header.stamp, publish=arm)
        published = {t.child_frame_id for t in static[-1].transforms + tf[-1].transforms}
        assert 'link06' in published and 'gripperStator' in published  # fixed: static
        assert 'gripperMover' not in published  # its joint was never named
        gripper = harness.joint_state(['jointGripper'], [-0.8])
        assert harness.spin_until(lambda: any(
            t.child_frame_id == 'gripperMover' for t in tf[-1].transforms), publish=gripper)
        # the same tree as the vendor's URDF, gripper and all, by pinocchio
        check_tf_tree(harness, model, robot.urdf, np.random.default_rng(2), rounds=2)
    finally:
        harness.close()


TIAGO = 'tiago_description/robots/tiago.urdf'


def test_each_branch_of_a_mobile_manipulator_appears_when_its_joints_do(ros_domain_id):
    """
    Arm, then head, then hand controllers, each its own JointState, as robot_state_publisher.

    TIAGo (example-robot-data): the torso and arm, the head and the hand are chains of the
    tree; the wheels are never named, and never published.
    """
    robot = load_robot(os.path.join(robots_dir(), TIAGO))
    model = robot.model
    arm = ['torso_lift_joint'] + [f'arm_{k}_joint' for k in range(1, 8)]
    head = ['head_1_joint', 'head_2_joint']
    hand = ['hand_thumb_joint', 'hand_index_joint', 'hand_mrl_joint']
    assert set(arm + head + hand) <= set(model.joint_names)
    harness = Harness()
    try:
        harness.start_node(robot_description_file=os.path.join(robots_dir(), TIAGO))
        tf = harness.listen(TFMessage, '/tf', 100)
        static = harness.listen(TFMessage, '/tf_static', TF_STATIC_QOS)

        def children():
            return {t.child_frame_id for t in tf[-1].transforms} if tf else set()
        values = dict(zip(arm, np.random.default_rng(5).uniform(0.0, 0.3, len(arm))))
        state = harness.joint_state(arm, [values[n] for n in arm])
        assert harness.spin_until(lambda: 'arm_7_link' in children(), publish=state)
        seen = children()
        assert {'torso_lift_link', 'arm_1_link', 'arm_7_link'} <= seen
        assert not {'head_1_link', 'head_2_link', 'hand_thumb_link', 'wheel_left_link'} & seen
        values.update(head_1_joint=0.4, head_2_joint=-0.3)
        state = harness.joint_state(head, [0.4, -0.3])
        assert harness.spin_until(lambda: 'head_2_link' in children(), publish=state)
        assert 'arm_7_link' in children() and 'hand_thumb_link' not in children()
        values.update(hand_thumb_joint=0.5, hand_index_joint=0.6, hand_mrl_joint=0.7)
        state = harness.joint_state(hand, [0.5, 0.6, 0.7])
        assert harness.spin_until(lambda: 'hand_thumb_link' in children(), publish=state)
        assert 'wheel_left_link' not in children()  # never named: never on /tf
        # each link published (under its URDF parent) is where pinocchio puts it
        assert harness.spin_until(lambda: static)  # transient local: may come after /tf
        transforms = static[-1].transforms + tf[-1].transforms
        parents = urdf_parents(robot.urdf)
        assert_tf_is_pinocchios(transforms, model.fixed_frame, oracle.urdf_model(robot.urdf),
                                values, sorted(children() & set(parents)), parents)
    finally:
        harness.close()


def test_a_bag_writes_a_side_branch_from_the_message_that_names_it(tmp_path):
    from rosbags.rosbag2 import Reader, Writer
    from rosbags.typesys import get_typestore, Stores
    from dq_fk_ros.bag.process import process_bag
    store = get_typestore(Stores.ROS2_JAZZY)
    types = store.types
    model = vendor_robot(Z1).model
    t0 = 1_700_000_000_000_000_000

    def joint_state(names, positions, stamp):
        header = types['std_msgs/msg/Header'](stamp=types['builtin_interfaces/msg/Time'](
            sec=stamp // 10**9, nanosec=stamp % 10**9), frame_id='')
        msg = types['sensor_msgs/msg/JointState'](
            header=header, name=list(names), position=np.asarray(positions, dtype=float),
            velocity=np.zeros(0), effort=np.zeros(0))
        return bytes(store.serialize_cdr(msg, 'sensor_msgs/msg/JointState'))

    with Writer(tmp_path / 'in', version=9) as writer:
        conn = writer.add_connection('/joint_states', 'sensor_msgs/msg/JointState',
                                     typestore=store)
        for k in range(20):  # the gripper's joint appears from message 12 on
            stamp = t0 + k * 10_000_000
            names = list(model.joint_names) if k >= 12 else list(model.joint_names[:6])
            writer.write(conn, stamp, joint_state(names, [0.01 * k] * len(names), stamp))
    summary = process_bag(tmp_path / 'in', tmp_path / 'out', model, progress=False,
                          poses='all')
    assert summary.written == 20
    with Reader(tmp_path / 'out') as reader:
        tf = [(t, store.deserialize_cdr(raw, c.msgtype)) for c, t, raw in reader.messages(
            connections=[c for c in reader.connections if c.topic == '/tf'])]
        mover = [c for c in reader.connections
                 if c.topic == '/dq_fk_node/pose/gripperMover']
        poses = [t for _, t, _ in reader.messages(connections=mover)]
    stamps = sorted(t for t, msg in tf
                    if any(x.child_frame_id == 'gripperMover' for x in msg.transforms))
    assert stamps == [t0 + k * 10_000_000 for k in range(12, 20)]
    assert sorted(poses) == stamps


def test_a_xacro_with_find_on_a_pip_only_install(ros_domain_id, tmp_path, processes):
    """$(find arm_description) failed everywhere: AMENT_PREFIX_PATH is not set here."""
    import sys
    from dq_fk_ros.ros.executables import executable
    from geometry_msgs.msg import PoseStamped
    sys.path.insert(0, os.path.join(os.path.dirname(os.path.dirname(__file__)), 'unit'))
    from test_packages import ARM, make_package
    package = make_package(tmp_path / 'vendor' / 'some_folder')
    robot = tmp_path / 'arm.urdf.xacro'
    robot.write_text(ARM)
    option = f'arm_description={package}'
    # the node and the fake publisher, with the package_paths parameter
    harness = Harness()
    try:
        harness.start_node(robot_description_file=str(robot), package_paths=[option])
        poses = harness.listen(PoseStamped, harness.topic('pose/l2'))
        fake = processes.start(executable('fake_joint_publisher') + [
            '--ros-args', '-p', f'robot_description_file:={robot}', '-p',
            f"package_paths:=['{option}']", '-p', 'mode:=fixed', '-p',
            'positions:=[0.0, 0.0]'])
        assert harness.spin_until(lambda: poses, timeout_s=20), fake.poll()
        p = poses[-1].pose.position
        np.testing.assert_allclose([p.x, p.y, p.z], [0, 0, 0.6], atol=1e-12)
    finally:
        harness.close()
    # dq_fk_bag process with --package, and without it a one-line error naming the package
    from test_bag import js_bytes, write_bag
    write_bag(tmp_path / 'in', [(10**9 + k, js_bytes(['j1', 'j2'], [0.1 * k, 0], 10**9 + k))
                                for k in range(5)])
    base = executable('dq_fk_bag') + ['process', str(tmp_path / 'in'), str(tmp_path / 'out'),
                                      '--robot', str(robot), '--quiet']
    proc = processes.start(base)
    output, _ = proc.communicate(timeout=60)
    assert proc.returncode == 2 and "package 'arm_description' not found" in output, output
    proc = processes.start(base + ['--package', option])
    output, _ = proc.communicate(timeout=60)
    assert proc.returncode == 0 and '5 written' in output, output
    bad = processes.start(executable('dq_fk_node') + ['--ros-args', '-p',
                                                      "package_paths:=['nameonly']"])
    output, _ = bad.communicate(timeout=30)
    assert bad.returncode == 1 and 'package_paths: ' in output and 'NAME=DIR' in output


def test_tf_names_as_the_urdf_writes_them_and_valid_topic_names(ros_domain_id):
    """link_11.0 and /base_link were refused; on TF they are link_11.0 and base_link."""
    from geometry_msgs.msg import PoseStamped
    text = ('<robot name="r"><link name="/base_link"/><link name="link_11.0"/>'
            '<link name="tip-1"/><joint name="j1" type="revolute"><parent link="/base_link"/>'
            '<child link="link_11.0"/><axis xyz="0 0 1"/><limit lower="-1" upper="1" '
            'effort="1" velocity="1"/></joint><joint name="j2" type="revolute">'
            '<parent link="link_11.0"/><child link="tip-1"/><origin xyz="0.2 0 0"/>'
            '<axis xyz="0 1 0"/><limit lower="-1" upper="1" effort="1" velocity="1"/>'
            '</joint></robot>')
    harness = Harness()
    try:
        node = harness.start_node(robot_description=text)
        # the node's messages name its parameters, not the command line's options
        result = node.set_parameters([Parameter('urdf_tip_link', value='nolink')])[0]
        assert not result.successful and "urdf_tip_link 'nolink' is not a link" in \
            result.reason, result.reason
        tf = harness.listen(TFMessage, '/tf')
        tip = harness.listen(PoseStamped, harness.topic('pose/tip_1'))
        link = harness.listen(PoseStamped, harness.topic('pose/link_11_0'))
        state = harness.joint_state(['j1', 'j2'], [0.5, 0.0])
        assert harness.spin_until(lambda: tf and tip and link, publish=state)
        edges = {(t.header.frame_id, t.child_frame_id) for m in tf for t in m.transforms}
        static = harness.listen(TFMessage, '/tf_static', TF_STATIC_QOS)
        assert harness.spin_until(lambda: static)
        edges |= {(t.header.frame_id, t.child_frame_id) for t in static[-1].transforms}
        # the URDF's own tree on TF, names as tf2 reads them
        assert {('base_link', 'link_11.0'), ('link_11.0', 'tip-1')} <= edges, edges
        assert not any(name.startswith('/') for edge in edges for name in edge)
        p = tip[-1].pose.position
        np.testing.assert_allclose([p.x, p.y, p.z], [0.2 * math.cos(0.5), 0.2 * math.sin(0.5),
                                                     0.0], atol=1e-12)
        assert tip[-1].header.frame_id == 'base_link'
    finally:
        harness.close()


def test_publish_dh_frames_puts_the_dh_frames_on_tf_and_back_off(ros_domain_id):
    """A URDF's default is robot_state_publisher's tree; the DH frames for debugging."""
    harness = Harness()
    try:
        node = harness.start_node(robot_description_file=vendor_path(UR5),
                                  urdf_tip_link='tool0')
        tf = harness.listen(TFMessage, '/tf', 100)
        static = harness.listen(TFMessage, '/tf_static', TF_STATIC_QOS)
        names = list(node._model.joint_names)
        msg = harness.joint_state(names, [0.1] * 6)

        def frames():
            return {t.child_frame_id for m in static[-1:] + tf[-1:] for t in m.transforms}
        assert harness.spin_until(lambda: static and tf, publish=msg)
        links = set(urdf_parents(open(vendor_path(UR5)).read()))
        assert frames() == links
        assert harness.probe.count_publishers(harness.topic('pose/dh3')) == 0
        assert harness.probe.count_publishers(harness.topic('pose/tool0')) == 1
        assert node.get_parameter_or('publish_dh_frames', None).value is None  # unset
        result = node.set_parameters([Parameter('publish_dh_frames', value=True)])
        assert result[0].successful
        tf.clear()
        debug = links | {f'dh{k}' for k in range(7)}
        # (the new /tf_static and the next /tf come in either order)
        assert harness.spin_until(lambda: tf and frames() >= debug, publish=msg), frames()
        assert harness.probe.count_publishers(harness.topic('pose/dh3')) == 1
        assert node.set_parameters([Parameter('publish_dh_frames', value=False)])[0].successful
        tf.clear()
        assert harness.spin_until(lambda: tf and frames() == links, publish=msg), frames()
        refused = node.set_parameters([Parameter('publish_dh_frames', value='yes')])
        assert not refused[0].successful
    finally:
        harness.close()
