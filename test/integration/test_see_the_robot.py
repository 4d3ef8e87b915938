"""
RViz's RobotModel from the node alone: every URDF link resolves in the published TF.

The node runs in-process (its own rclpy context) and talks to the test over DDS. The test
composes the TF graph it receives itself (homogeneous_tf) and compares every link of the
URDF that ``dq_fk urdf`` writes with pinocchio's kinematics of that same URDF.
"""

import math
import xml.etree.ElementTree as ET

from dq_fk_ros.description.schema import load_robot_description
from dq_fk_ros.description.shipped import shipped_robot_path, shipped_robots
from dq_fk_ros.description.to_urdf import robot_to_urdf
import homogeneous_tf as htf
import numpy as np
import pinocchio_oracle as oracle
import pytest
from rclpy.parameter import Parameter
from ros_harness import Harness, TF_STATIC_QOS
from std_msgs.msg import String
from tf2_msgs.msg import TFMessage

pytestmark = pytest.mark.integration
DESCRIPTION_QOS = TF_STATIC_QOS  # reliable, transient local (depth 1 on the node's side)


def random_joints(model, rng):
    """Joint values within limits (+-pi, or +-0.5 m, where there are none)."""
    values = []
    for (lower, upper), name in zip(model.limits, model.joint_names):
        bound = 0.5 if name.startswith('d_') else math.pi
        lower, upper = max(lower, -bound), min(upper, bound)
        values.append(rng.uniform(lower, upper))
    return np.array(values)


def urdf_links(text):
    return [link.get('name') for link in ET.fromstring(text).iter('link')]


@pytest.mark.parametrize('robot', shipped_robots())
def test_every_urdf_link_resolves_in_tf_with_the_urdfs_own_kinematics(ros_domain_id, robot):
    path = shipped_robot_path(robot)
    model = load_robot_description(path)
    urdf = robot_to_urdf(model)
    links = [name for name in urdf_links(urdf) if name != model.fixed_frame]
    pin_model = oracle.urdf_model(urdf)
    rng = np.random.default_rng(12)
    harness = Harness()
    try:
        harness.start_node(robot_description_file=path)
        tf = harness.listen(TFMessage, '/tf', 100)
        static = harness.listen(TFMessage, '/tf_static', TF_STATIC_QOS)
        for _ in range(5):
            q = random_joints(model, rng)
            msg = harness.joint_state(model.joint_names, q)
            tf.clear()
            assert harness.spin_until(lambda: static and tf and tf[-1].transforms[0].header
                                      .stamp == msg.header.stamp, publish=msg), robot
            transforms = static[-1].transforms + tf[-1].transforms
            values = dict(zip(model.joint_names, q))
            for joint in ET.fromstring(urdf).iter('joint'):  # mimic joints, as the URDF says
                mimic = joint.find('mimic')
                if mimic is not None:
                    values[joint.get('name')] = float(mimic.get('multiplier')) * \
                        values[mimic.get('joint')] + float(mimic.get('offset'))
            pin_q = oracle.configuration(pin_model, values)
            expected = oracle.link_placements(pin_model, pin_q, links)
            for link in links:
                composed = htf.compose(transforms, model.fixed_frame, link)
                np.testing.assert_allclose(composed, expected[link], atol=1e-9,
                                           err_msg=f'{robot}: {link}')
        assert htf.parent_of(transforms, model.frame_names[-1]) == model.parent_frames[-1]
    finally:
        harness.close()


def test_robot_description_reaches_a_late_subscriber_and_names_the_published_frames(
        ros_domain_id):
    harness = Harness()
    try:
        node = harness.start_node(frame_prefix='left/')
        tf = harness.listen(TFMessage, '/tf', 100)
        static = harness.listen(TFMessage, '/tf_static', TF_STATIC_QOS)
        zero = harness.joint_state([f'joint_{i}' for i in range(1, 7)], [0.0] * 6)
        assert harness.spin_until(lambda: tf and static, publish=zero)
        late = harness.listen(String, '/robot_description', DESCRIPTION_QOS)  # joins late
        assert harness.spin_until(lambda: late)
        root = ET.fromstring(late[-1].data)  # a real XML parser
        assert root.tag == 'robot' and root.get('name') == 'rl15'
        transforms = static[-1].transforms + tf[-1].transforms
        published = {t.child_frame_id for t in transforms}
        # robot_state_publisher's convention: no frame_prefix in the URDF itself
        assert {'left/' + name for name in urdf_links(late[-1].data)} - {'left/world'} == \
            published
        # reloaded robot: the description is sent again
        late.clear()
        result = node.set_parameters([Parameter('robot_description_file',
                                                value=shipped_robot_path('panda'))])
        assert result[0].successful
        assert harness.spin_until(lambda: late and 'panda_link7' in late[-1].data)
    finally:
        harness.close()


def test_robot_description_can_be_switched_off(ros_domain_id):
    harness = Harness()
    try:
        harness.start_node(publish_robot_description=False)
        late = harness.listen(String, '/robot_description', DESCRIPTION_QOS)
        static = harness.listen(TFMessage, '/tf_static', TF_STATIC_QOS)
        assert harness.spin_until(lambda: static)
        harness.spin_until(lambda: late, timeout_s=1.0)
        assert late == []
    finally:
        harness.close()
