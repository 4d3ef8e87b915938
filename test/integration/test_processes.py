"""
dq_fk_node and fake_joint_publisher as separate processes (the console scripts), over DDS.

The test listens from its own rclpy context; every process is started and reaped by the
``processes`` fixture on this run's private domain.
"""

import math
import os
import re
import signal
import sys

from diagnostic_msgs.msg import DiagnosticArray
from dq_fk_ros.description.schema import load_robot_description
from dq_fk_ros.description.shipped import shipped_robot_path
from dq_fk_ros.testing import wait_until
from geometry_msgs.msg import PoseStamped
import homogeneous_tf as htf
import numpy as np
import pytest
from ros_harness import node_topic, start, TF_STATIC_QOS
from sensor_msgs.msg import JointState
from tf2_msgs.msg import TFMessage

pytestmark = pytest.mark.integration


def stamp_key(stamp):
    return (stamp.sec, stamp.nanosec)


@pytest.mark.parametrize('robot', ['rl15', 'panda'])
def test_poses_and_tf_equal_core_fk_of_the_published_joints(processes, listener, robot):
    path = shipped_robot_path(robot)
    model = load_robot_description(path)
    node = start(processes, 'dq_fk_node', f'robot_description_file:={path}')
    start(processes, 'fake_joint_publisher', f'robot_description_file:={path}', 'mode:=sine',
          'rate_hz:=50.0')
    joints = listener.listen(JointState, '/joint_states')
    ee = model.frame_names[-1]
    poses = listener.listen(PoseStamped, node_topic(node, f'pose/{ee}'))
    tf = listener.listen(TFMessage, '/tf')

    def pairs():  # the poses whose JointState this listener has, with it
        by_stamp = {stamp_key(m.header.stamp): m for m in joints}
        return by_stamp, [(p, by_stamp[stamp_key(p.header.stamp)]) for p in poses
                          if stamp_key(p.header.stamp) in by_stamp]

    def enough():
        by_stamp, matched = pairs()
        return len(matched) >= 90 and len(tf) >= 100 and all(
            stamp_key(m.transforms[0].header.stamp) in by_stamp for m in tf[-20:])
    # wait for poses with their JointState, not for counts: a loaded run once had 100 poses
    # and none whose JointState the listener had yet (its subscriptions match in any order)
    assert listener.spin_until(enough, timeout_s=30)
    by_stamp, matched = pairs()
    for pose, js in matched:
        q = np.array([js.position[list(js.name).index(n)] for n in model.joint_names])
        expected = model.chain.forward(q).to_matrix()
        np.testing.assert_allclose(htf.pose_matrix(pose.pose), expected, atol=1e-9)
    _, relative = None, None
    for msg in tf[-20:]:
        js = by_stamp[stamp_key(msg.transforms[0].header.stamp)]
        q = np.array([js.position[list(js.name).index(n)] for n in model.joint_names])
        absolute, relative = model.chain.frame_poses(q)
        for t in msg.transforms:
            k = model.frame_names.index(t.child_frame_id)
            np.testing.assert_allclose(htf.transform_matrix(t.transform),
                                       htf.pose_matrix_of_tuple(relative[k - 1]), atol=1e-9)


@pytest.mark.parametrize('kind', ['floating', 'planar'])
def test_fake_joint_publisher_drives_a_urdf_with_a_floating_or_planar_root(
        processes, listener, tmp_path, kind):
    """solo12 under a floating or planar root: JointStates named no joint, 16 of 16 missing."""
    from test_rsp_parity import rsp_edges, with_joint
    from vendor_urdfs import robots_dir
    path = tmp_path / f'solo12_{kind}.urdf'
    path.write_text(with_joint(open(os.path.join(
        robots_dir(), 'solo_description/robots/solo12.urdf')).read(), kind, 'root'))
    moving, fixed = rsp_edges(path.read_text())
    start(processes, 'dq_fk_node', f'robot_description_file:={path}')
    start(processes, 'fake_joint_publisher', f'robot_description_file:={path}', 'mode:=sine',
          'rate_hz:=50.0')
    joints = listener.listen(JointState, '/joint_states')
    tf = listener.listen(TFMessage, '/tf')
    static = listener.listen(TFMessage, '/tf_static', TF_STATIC_QOS)
    assert listener.spin_until(lambda: joints and tf and static, timeout_s=20)
    assert len(joints[-1].name) == 12
    assert {(t.header.frame_id, t.child_frame_id) for t in tf[-1].transforms} == moving
    assert {(t.header.frame_id, t.child_frame_id) for t in static[-1].transforms} == fixed


def test_fake_joint_publisher_takes_the_robot_as_joint_state_publisher_does(
        processes, listener, tmp_path):
    """From the robot_description parameter (URDF XML) and from the topic, as well as a file."""
    import json
    from dq_fk_ros.ros.executables import executable
    from ros_harness import unique_node_name
    panda = load_robot_description(shipped_robot_path('panda'))
    urdf = ('<robot name="two"><link name="a"/><link name="b"/><link name="c"/>'
            '<joint name="alpha" type="continuous"><parent link="a"/><child link="b"/></joint>'
            '<joint name="beta" type="prismatic"><parent link="b"/><child link="c"/>'
            '<limit lower="0" upper="1" effort="1" velocity="1"/></joint></robot>')
    params = tmp_path / 'fake.yaml'
    name = unique_node_name('fake_from_parameter')
    params.write_text(json.dumps({name: {'ros__parameters': {
        'robot_description': urdf, 'mode': 'zeros', 'rate_hz': 20.0}}}))
    processes.start(executable('fake_joint_publisher') + [
        '--ros-args', '-r', f'__node:={name}', '-r', 'joint_states:=from_parameter',
        '--params-file', str(params)])
    # the node publishes robot_description (latched); the publisher waits for it
    start(processes, 'dq_fk_node', 'robot_description_file:=panda')
    start(processes, 'fake_joint_publisher', 'from_topic:=true', 'mode:=zeros',
          'rate_hz:=20.0')
    by_parameter = listener.listen(JointState, '/from_parameter')
    by_topic = listener.listen(JointState, '/joint_states')
    assert listener.spin_until(lambda: by_parameter and by_topic, timeout_s=20)
    assert list(by_parameter[-1].name) == ['alpha', 'beta']
    assert list(by_topic[-1].name) == list(panda.joint_names)


def test_tf_static_reaches_a_subscriber_that_starts_late(processes, listener):
    start(processes, 'dq_fk_node')
    # its /joint_states subscription is made after /tf_static is sent: subscribe after that
    assert wait_until(lambda: listener.probe.count_subscribers('/joint_states'), 20)
    static = listener.listen(TFMessage, '/tf_static', TF_STATIC_QOS)
    assert listener.spin_until(lambda: static, timeout_s=10)
    pairs = [(t.header.frame_id, t.child_frame_id) for t in static[-1].transforms]
    assert pairs == [('world', 'base_seg0')] + [
        (f, f + '_dh_z') for f in ('shoulder_seg1', 'upperarm_seg2', 'elbow_seg3',
                                   'forearm_seg4', 'wrist_seg5')]  # the URDF's helper links
    np.testing.assert_allclose(static[-1].transforms[0].transform.translation.z, 0.73)


def is_malformed(msg, joint_names):
    return (len(msg.name) != len(msg.position)
            or any(not math.isfinite(v) for v in msg.position)
            or not set(msg.name) & set(joint_names))


def test_fault_injection_every_valid_update_published_and_rejections_counted(processes,
                                                                             listener):
    model = load_robot_description(shipped_robot_path('rl15'))
    # reliable input, so that "every valid update is published" is checkable exactly
    node = start(processes, 'dq_fk_node', 'joint_states_reliability:=reliable')
    # a queue for every message of the run: a loaded machine (CI beside other work) may
    # leave this process behind the 100 Hz stream for a while (10 deep lost the last ones)
    poses = listener.listen(PoseStamped, node_topic(node, 'pose/eeCarry_seg6'), 1000)
    diagnostics = listener.listen(DiagnosticArray, '/diagnostics')
    joints = listener.listen(JointState, '/joint_states', 1000)
    assert listener.spin_until(lambda: diagnostics, timeout_s=10)  # the node is up
    total = 300
    start(processes, 'fake_joint_publisher', 'mode:=random_walk', 'rate_hz:=100.0',
          'fault_fraction:=0.2', f'max_messages:={total}', 'seed:=7',
          'wait_for_subscribers:=2')

    def counters():
        if not diagnostics:
            return {}
        return {v.key: v.value for v in diagnostics[-1].status[0].values}
    assert listener.spin_until(
        lambda: len(joints) == total and counters().get('updates_received') == str(total),
        timeout_s=30), (len(joints), counters())
    malformed = [m for m in joints if is_malformed(m, model.joint_names)]
    valid = [m for m in joints if not is_malformed(m, model.joint_names)]
    assert 30 <= len(malformed) <= 90  # about 20 %
    listener.spin_until(lambda: len(poses) >= len(valid), timeout_s=5)
    c = counters()
    assert int(c['updates_rejected']) == len(malformed)
    assert int(c['updates_published']) == len(valid)
    assert {stamp_key(m.header.stamp) for m in valid} == \
        {stamp_key(p.header.stamp) for p in poses}


def test_the_node_resumes_when_the_publisher_restarts(processes, listener):
    node = start(processes, 'dq_fk_node')
    poses = listener.listen(PoseStamped, node_topic(node, 'pose/eeCarry_seg6'))
    publisher = start(processes, 'fake_joint_publisher', 'mode:=zeros')
    assert listener.spin_until(lambda: poses, timeout_s=20)
    os.killpg(publisher.pid, signal.SIGKILL)
    publisher.wait()
    poses.clear()
    start(processes, 'fake_joint_publisher', 'mode:=fixed',
          'positions:=[0.5, 0.0, 0.0, 0.0, 0.0, 0.0]')
    assert listener.spin_until(lambda: poses and poses[-1].pose.position.y > 0.4,
                               timeout_s=20)
    np.testing.assert_allclose([poses[-1].pose.position.x, poses[-1].pose.position.y],
                               [1.025 * math.cos(0.5), 1.025 * math.sin(0.5)], atol=1e-9)


def test_two_robots_with_different_prefixes_do_not_mix(processes, listener):
    panda = shipped_robot_path('panda')
    left_node = start(processes, 'dq_fk_node', 'frame_prefix:=left/', namespace='/left')
    start(processes, 'fake_joint_publisher', 'mode:=zeros', namespace='/left')
    right_node = start(processes, 'dq_fk_node', 'frame_prefix:=right/',
                       f'robot_description_file:={panda}', namespace='/right')
    start(processes, 'fake_joint_publisher', f'robot_description_file:={panda}', 'mode:=fixed',
          'positions:=[0.3, -0.2, 0.1, -1.5, 0.2, 1.6, 0.4]', namespace='/right')
    tf = listener.listen(TFMessage, '/tf')
    static = listener.listen(TFMessage, '/tf_static', TF_STATIC_QOS)
    left = listener.listen(PoseStamped, node_topic(left_node, 'pose/eeCarry_seg6'))
    right = listener.listen(PoseStamped, node_topic(right_node, 'pose/panda_link8'))

    def children():
        return {t.child_frame_id for msg in tf + static for t in msg.transforms}
    assert listener.spin_until(
        lambda: left and right and {'left/eeCarry_seg6', 'right/panda_link7', 'left/base_seg0',
                                    'right/panda_link8'} <= children(), timeout_s=20), \
        (len(left), len(right), sorted(children()))
    latest = {}
    for msg in tf + static:
        for t in msg.transforms:
            prefixes = {t.child_frame_id.split('/')[0], t.header.frame_id.split('/')[0]}
            assert prefixes in ({'left'}, {'right'}, {'world', 'left'}, {'world', 'right'}), \
                (t.header.frame_id, t.child_frame_id)
            latest[t.child_frame_id] = t
    transforms = list(latest.values())
    np.testing.assert_allclose(htf.compose(transforms, 'world', 'left/eeCarry_seg6')[:3, 3],
                               [1.025, 0, 1.445], atol=1e-9)
    panda_model = load_robot_description(panda)
    q = np.array([0.3, -0.2, 0.1, -1.5, 0.2, 1.6, 0.4])
    expected = panda_model.chain.forward(q).to_matrix()
    np.testing.assert_allclose(htf.compose(transforms, 'world', 'right/panda_link8'), expected,
                               atol=1e-9)
    np.testing.assert_allclose(htf.pose_matrix(right[-1].pose), expected, atol=1e-9)


PROGRAMS = ['dq_fk_node', 'fake_joint_publisher', 'dq_fk_view', 'dq_fk', 'dq_fk_bag',
            'dq_fk_foxglove']


@pytest.mark.parametrize('program', PROGRAMS)
def test_every_installed_program_imports_its_function_without_a_metadata_lookup(program):
    """
    setup.py's direct_script: as pip writes a wheel's scripts, not setuptools' develop ones.

    Those find their function through importlib.metadata, ~30 ms of every start here.
    """
    path = os.path.join(sys.prefix, 'lib', 'dq_fk_ros', program)   # where setup.cfg puts it
    with open(path, encoding='utf-8') as script:
        text = script.read()
    assert text.startswith('#!') and os.access(path, os.X_OK)
    assert 'importlib' not in text and 'pkg_resources' not in text, text
    assert re.search(r'^from dq_fk_ros(\.\w+)+ import run_\w+|^from dq_fk_ros(\.\w+)+ import '
                     r'main$', text, re.M), text


@pytest.mark.parametrize('program', PROGRAMS)
@pytest.mark.parametrize('flag', ['--help', '-h'])
def test_every_program_answers_help_with_its_options_and_starts_nothing(program, flag,
                                                                        processes):
    from dq_fk_ros.ros.executables import executable
    proc = processes.start(executable(program) + [flag])
    out, _ = proc.communicate(timeout=30)
    assert proc.returncode == 0, out
    assert out.startswith('usage: ') and program in out.splitlines()[0], out[:200]
    if program == 'dq_fk_node':  # its ROS parameters, from the table it declares
        from dq_fk_ros.ros.node_parameters import NODE_PARAMETERS
        assert all(f'  {p.name} (' in out for p in NODE_PARAMETERS)
        assert '  package_paths ([], read only)' in out
    if program == 'fake_joint_publisher':
        assert '  positions ([0.0])' in out and "  mode ('sine')" in out
