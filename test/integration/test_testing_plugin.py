"""
The pytest plugin users get (dq_fk_ros.testing): dq_fk_robot, set_joints, assert_pose_close.

The RL15's poses are the paper's (Fig. 4, zero pose) and the test's own 4x4 DH products of
[Zivkovic2023] Table 3 (test/dh_truth.py), never the package's kinematics.
"""

import math
import os
import subprocess
import sys
import textwrap

from dq_fk_ros.testing import assert_pose_close, next_message, wait_until
from dq_fk_ros.testing.robot import RobotError
import numpy as np
import pytest

sys.path.insert(0, os.path.join(os.path.dirname(__file__), '..'))
from dh_truth import row_matrix, trans  # noqa: E402, I100 (the tests' own helper)

pytestmark = pytest.mark.integration
DEG = math.pi / 180
RL15_ROWS = [(0, 0, 0.2, 90 * DEG), (90 * DEG, 0, 0.6, 0), (0, 0, 0.115, 90 * DEG),
             (0, 0.825, 0, -90 * DEG), (0, 0, 0, 90 * DEG), (0, 0, 0, 0)]   # Table 3, m rad


def rl15_truth(q):
    """Return eeCarry_seg6 in world as ((x, y, z), (qx, qy, qz, qw)), by 4x4 products."""
    m = trans(0, 0, 0.73)
    for (theta, d, a, alpha), v in zip(RL15_ROWS, q):
        m = m @ row_matrix(theta + v, d, a, alpha, 'standard')
    r = m[:3, :3]
    w = math.sqrt(max(0.0, 1 + np.trace(r))) / 2
    if w > 1e-6:
        quat = ((r[2, 1] - r[1, 2]) / (4 * w), (r[0, 2] - r[2, 0]) / (4 * w),
                (r[1, 0] - r[0, 1]) / (4 * w), w)
    else:   # (a half turn: the axis from the diagonal)
        x = math.sqrt(max(0.0, (1 + r[0, 0] - r[1, 1] - r[2, 2]) / 4))
        y = math.copysign(math.sqrt(max(0.0, (1 - r[0, 0] + r[1, 1] - r[2, 2]) / 4)), r[0, 1])
        z = math.copysign(math.sqrt(max(0.0, (1 - r[0, 0] - r[1, 1] + r[2, 2]) / 4)), r[0, 2])
        quat = (x, y, z, 0.0)
    return tuple(m[:3, 3]), quat


def test_a_robot_at_fixed_joints_then_set_at_run_time(dq_fk_robot):
    robot = dq_fk_robot('rl15')
    pose = robot.wait_for('world', 'eeCarry_seg6')
    # [Zivkovic2023] Fig. 4: the zero pose, as printed
    assert_pose_close(pose, ((1.025, 0.0, 1.445), (0.707107, 0.0, 0.707107, 0.0)),
                      atol_m=1e-9, atol_rad=1e-6)
    assert_pose_close(pose, rl15_truth([0] * 6), atol_m=1e-9, atol_rad=1e-9)
    stamp = robot.set_joints({'joint_2': 0.5, 'joint_5': -0.3})
    pose = robot.pose('world', 'eeCarry_seg6')
    assert pose.header.stamp.sec * 10**9 + pose.header.stamp.nanosec >= stamp
    assert_pose_close(pose, rl15_truth([0, 0.5, 0, 0, -0.3, 0]), atol_m=1e-9, atol_rad=1e-9)
    with pytest.raises(AssertionError, match=r'^pose of eeCarry_seg6 in world: position off'):
        assert_pose_close(pose, rl15_truth([0] * 6), atol_m=1e-3)
    with pytest.raises(RobotError, match="no joint 'joint_9'; its joints: joint_1, joint_2"):
        robot.set_joints({'joint_9': 1.0})


def test_two_robots_in_one_test_and_node_parameters_as_keywords(dq_fk_robot):
    left = dq_fk_robot('rl15', joints={'joint_1': 0.25}, frame_prefix='left/')
    right = dq_fk_robot('rl15', frame_prefix='right/', publish_frequency=50.0)
    # a DH file's fixed frame is shared: both arms stand in one world
    assert left.frames[0] == right.fixed_frame == 'world'
    assert left.frames[-1] == 'left/eeCarry_seg6'
    expected = rl15_truth([0.25, 0, 0, 0, 0, 0])
    assert_pose_close(left.wait_for('world', 'left/eeCarry_seg6'), expected,
                      atol_m=1e-9, atol_rad=1e-9)
    assert_pose_close(right.wait_for('world', 'right/eeCarry_seg6'),
                      rl15_truth([0] * 6), atol_m=1e-9, atol_rad=1e-9)
    right.set_joints({'joint_1': 0.25})
    assert_pose_close(right.pose('world', 'right/eeCarry_seg6'), expected,
                      atol_m=1e-9, atol_rad=1e-9)


def test_joints_replayed_from_a_csv(dq_fk_robot, tmp_path):
    rows = tmp_path / 'joints.csv'
    rows.write_text('joint_1,joint_3\n0.1,0.0\n0.2,0.1\n0.3,0.2\n', encoding='utf-8')
    robot = dq_fk_robot('rl15', joints_csv=rows, rate_hz=20.0)
    stamp = robot.wait_replayed()
    pose = robot.pose('world', 'eeCarry_seg6')
    assert pose.header.stamp.sec * 10**9 + pose.header.stamp.nanosec >= stamp
    assert_pose_close(pose, rl15_truth([0.3, 0, 0.2, 0, 0, 0]), atol_m=1e-9, atol_rad=1e-9)


def test_joints_replayed_from_a_bag(dq_fk_robot, tmp_path):
    from dq_fk_ros.cli import dq_fk_bag
    from rclpy.duration import Duration
    from rclpy.time import Time
    from rosbags.rosbag2 import Reader
    from rosbags.typesys import get_typestore, Stores
    bag = tmp_path / 'joints'
    assert dq_fk_bag.main(['example', str(bag), '--robot', 'rl15', '--seconds', '1',
                           '--rate', '20']) == 0
    # the bag's last JointState, read by rosbags
    store = get_typestore(Stores.ROS2_JAZZY)
    with Reader(bag) as reader:
        last = None
        for conn, _, raw in reader.messages():
            last = store.deserialize_cdr(raw, conn.msgtype)
    q = [last.position[list(last.name).index(f'joint_{k}')] for k in range(1, 7)]
    stamp = last.header.stamp.sec * 10**9 + last.header.stamp.nanosec
    robot = dq_fk_robot('rl15', joints_bag=bag, publish_frequency=0.0,
                        joint_states_reliability='reliable')
    assert robot.joints.wait(timeout=60) == 0   # the player ends with the bag
    assert robot.buffer.can_transform('world', 'eeCarry_seg6', Time(nanoseconds=stamp),
                                      timeout=Duration(seconds=20))
    pose = robot.buffer.lookup_transform('world', 'eeCarry_seg6', Time(nanoseconds=stamp))
    assert_pose_close(pose, rl15_truth(q), atol_m=1e-9, atol_rad=1e-9)


def test_a_program_of_the_package_under_a_name_and_namespace(dq_fk_processes):
    """``start_program``: the package's programs with ROS parameters, for tests of them."""
    import rclpy
    from sensor_msgs.msg import JointState
    proc = dq_fk_processes.start_program('fake_joint_publisher', 'mode:=fixed',
                                         'positions:=[0.1, 0.2, 0.3, 0.4, 0.5, 0.6]',
                                         node_name='arm_source', namespace='/left/')
    assert (proc.node_name, proc.namespace) == ('arm_source', '/left')
    msg = next_message(JointState, '/left/joint_states', timeout_s=20)
    assert list(msg.position) == pytest.approx([0.1, 0.2, 0.3, 0.4, 0.5, 0.6])
    context = rclpy.Context()
    rclpy.init(context=context)
    probe = rclpy.create_node('plugin_graph_probe', context=context)
    try:
        assert wait_until(lambda: ('arm_source', '/left') in
                          probe.get_node_names_and_namespaces(), 10)
    finally:
        probe.destroy_node()
        context.try_shutdown()


def test_a_failing_test_of_a_user_leaves_no_process_and_the_plugin_loads_by_itself(
        tmp_path):
    # a user's project: only pytest and the installed package, no conftest of ours
    (tmp_path / 'test_user.py').write_text(textwrap.dedent("""
        import os

        def test_fails_with_a_robot_running(dq_fk_robot):
            robot = dq_fk_robot('rl15')
            robot.wait_for('world', 'eeCarry_seg6')
            with open(os.environ['PIDS'], 'w') as stream:
                stream.write(f'{robot.node.pid} {robot.joints.pid}')
            assert False, 'the user test fails'
        """), encoding='utf-8')
    env = dict(os.environ, PIDS=str(tmp_path / 'pids'))
    env.pop('ROS_DOMAIN_ID', None)
    done = subprocess.run([sys.executable, '-m', 'pytest', '-q', '-p', 'no:cacheprovider',
                           '-p', 'no:randomly', str(tmp_path / 'test_user.py')],
                          cwd=tmp_path, env=env, capture_output=True, text=True, timeout=120)
    assert done.returncode == 1 and '1 failed' in done.stdout, done.stdout[-2000:]
    assert 'the user test fails' in done.stdout
    for pid in (tmp_path / 'pids').read_text().split():
        assert not os.path.exists(f'/proc/{pid}') or \
            open(f'/proc/{pid}/stat').read().split()[2] == 'Z', pid


@pytest.mark.parametrize('signal_name', ['SIGINT', 'SIGKILL'])
def test_an_interrupted_or_killed_pytest_leaves_no_process(tmp_path, signal_name):
    # Ctrl-C: the fixtures' teardown stops them; SIGKILL: they die with pytest (PDEATHSIG)
    import signal
    import time
    (tmp_path / 'test_user.py').write_text(textwrap.dedent("""
        import os, time

        def test_waits_for_ever(dq_fk_robot):
            robot = dq_fk_robot('rl15')
            robot.wait_for('world', 'eeCarry_seg6')
            with open(os.environ['PIDS'] + '.part', 'w') as stream:
                stream.write(f'{robot.node.pid} {robot.joints.pid}')
            os.rename(os.environ['PIDS'] + '.part', os.environ['PIDS'])
            while True:   # (not Event().wait(): a SIGINT the kernel hands to one of DDS's
                time.sleep(0.1)   # threads would never wake a main thread blocked in it)
        """), encoding='utf-8')
    pids = tmp_path / 'pids'
    env = dict(os.environ, PIDS=str(pids))
    proc = subprocess.Popen([sys.executable, '-X', 'faulthandler', '-m', 'pytest', '-q',
                             '-p', 'no:cacheprovider', '-p', 'no:randomly', '-p', 'no:timeout',
                             str(tmp_path / 'test_user.py')],
                            cwd=tmp_path, env=env, stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True, start_new_session=True,
                            # Ctrl-C as a terminal sends it: SIGINT not ignored (this run may
                            # have been started with it ignored, and exec hands that on)
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    try:
        deadline = time.monotonic() + 60
        while not pids.exists() and proc.poll() is None and time.monotonic() < deadline:
            time.sleep(0.05)   # (polling a file the child writes, with a deadline)
        assert pids.exists(), proc.communicate(timeout=10)[0][-2000:]
        children = [int(p) for p in pids.read_text().split()]
        proc.send_signal(getattr(signal, signal_name))
        try:
            proc.communicate(timeout=60)
        except subprocess.TimeoutExpired:   # a hang: every thread's stack (faulthandler)
            proc.send_signal(signal.SIGABRT)
            out = proc.communicate(timeout=30)[0]
            raise AssertionError(f'pytest still running 60 s after {signal_name}: '
                                 f'{out[-6000:]}') from None
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()

    def gone(pid):
        try:
            with open(f'/proc/{pid}/stat', encoding='ascii') as stream:
                return stream.read().split()[2] == 'Z'
        except FileNotFoundError:
            return True
    deadline = time.monotonic() + 15
    while not all(gone(pid) for pid in children) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert all(gone(pid) for pid in children), children
