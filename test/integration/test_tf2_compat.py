"""
Code written for tf2_ros runs unchanged through the compat path (``dq_fk tf compat-path``).

The scripts below are the ROS 2 tf2 tutorials' shapes (a static broadcaster, a dynamic
broadcaster, a listener on the user's node spun by ``rclpy.spin``, ``do_transform_pose``, a
loop of ``spin_once``), with tf2's own imports and nothing of dq_fk_ros in them; each runs
as a process with the compat folders first on ``PYTHONPATH``, beside a real dq_fk_node (the
RL15 at zero joints: [Zivkovic2023] Fig. 4). Every one ends as Jazzy's rclpy examples end
(Ctrl-C, then ``destroy_node`` and ``try_shutdown``), with exit 0 and no abort. geometry2's
own tests are run by scripts/geometry2_tests.py (they stay geometry2's).
"""

import os
import signal
import sys

from dq_fk_ros.cli.compat_path import compat_folders
from process_lines import process_lines
import pytest

pytestmark = pytest.mark.integration

# the end of Jazzy's rclpy examples: Ctrl-C in rclpy.spin is rclpy's ExternalShutdownException
# (its signal handler shut the context down); the tutorials' `except KeyboardInterrupt` then
# ends in that traceback with exit 1, with the real tf2_ros as here
SPIN_UNTIL_CTRL_C = """
from rclpy.executors import ExternalShutdownException


def main():
    rclpy.init()
    node = {node}
    try:
        rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        node.destroy_node()
        rclpy.try_shutdown()


if __name__ == '__main__':
    main()
"""

STATIC_BROADCASTER = """
import rclpy
from geometry_msgs.msg import TransformStamped
from rclpy.node import Node
from tf2_ros.static_transform_broadcaster import StaticTransformBroadcaster


class StaticFramePublisher(Node):
    def __init__(self):
        super().__init__('static_turtle_tf2_broadcaster')
        self.tf_static_broadcaster = StaticTransformBroadcaster(self)
        t = TransformStamped()
        t.header.stamp = self.get_clock().now().to_msg()
        t.header.frame_id = 'world'
        t.child_frame_id = 'mystaticturtle'
        t.transform.translation.z = 1.0
        t.transform.rotation.w = 1.0
        self.tf_static_broadcaster.sendTransform(t)
        print('sent', flush=True)
""" + SPIN_UNTIL_CTRL_C.format(node='StaticFramePublisher()')

DYNAMIC_BROADCASTER = """
import math
import rclpy
from geometry_msgs.msg import TransformStamped
from rclpy.node import Node
from tf2_ros import TransformBroadcaster


class DynamicFrameBroadcaster(Node):
    def __init__(self):
        super().__init__('dynamic_frame_tf2_broadcaster')
        self.tf_broadcaster = TransformBroadcaster(self)
        self.timer = self.create_timer(0.1, self.broadcast_timer_callback)

    def broadcast_timer_callback(self):
        t = TransformStamped()
        t.header.stamp = self.get_clock().now().to_msg()
        t.header.frame_id = 'eeCarry_seg6'
        t.child_frame_id = 'carrot1'
        t.transform.translation.x = 0.5
        t.transform.rotation.w = 1.0
        self.tf_broadcaster.sendTransform(t)
""" + SPIN_UNTIL_CTRL_C.format(node='DynamicFrameBroadcaster()')

LISTENER = """
import rclpy
from rclpy.node import Node
from tf2_ros import TransformException
from tf2_ros.buffer import Buffer
from tf2_ros.transform_listener import TransformListener


class FrameListener(Node):
    def __init__(self):
        super().__init__('turtle_tf2_frame_listener')
        self.tf_buffer = Buffer()
        self.tf_listener = TransformListener(self.tf_buffer, self)
        self.timer = self.create_timer(0.1, self.on_timer)

    def on_timer(self):
        for target, source in (('world', 'eeCarry_seg6'), ('world', 'mystaticturtle'),
                               ('world', 'carrot1')):
            try:
                t = self.tf_buffer.lookup_transform(target, source, rclpy.time.Time())
            except TransformException as ex:
                self.get_logger().info(f'Could not transform {target} to {source}: {ex}')
                continue
            p = t.transform.translation
            print(f'{source} {p.x:.6f} {p.y:.6f} {p.z:.6f}', flush=True)
""" + SPIN_UNTIL_CTRL_C.format(node='FrameListener()')

DO_TRANSFORM_POSE = """
import rclpy
from geometry_msgs.msg import Pose, PoseStamped
from rclpy.duration import Duration
from rclpy.node import Node
import tf2_geometry_msgs
from tf2_geometry_msgs import do_transform_pose
from tf2_ros.buffer import Buffer
from tf2_ros.transform_listener import TransformListener

rclpy.init()
node = Node('pose_in_world')
buffer = Buffer()
listener = TransformListener(buffer, node, spin_thread=True)
t = buffer.lookup_transform('world', 'eeCarry_seg6', rclpy.time.Time(),
                            timeout=Duration(seconds=20))
pose = Pose()
pose.position.z = 0.1          # 10 cm along the end effector's z
pose.orientation.w = 1.0
p = do_transform_pose(pose, t).position
print(f'pose {p.x:.6f} {p.y:.6f} {p.z:.6f}', flush=True)
stamped = PoseStamped(pose=pose)
stamped.header.frame_id = 'eeCarry_seg6'
stamped.header.stamp = t.header.stamp
q = buffer.transform(stamped, 'world').pose.position
print(f'stamped {q.x:.6f} {q.y:.6f} {q.z:.6f}', flush=True)
node.destroy_node()
rclpy.shutdown()
"""

SPIN_ONCE = """
import rclpy
import tf2_ros

rclpy.init()
node = rclpy.create_node('spin_once_user')
buffer = tf2_ros.Buffer()
listener = tf2_ros.TransformListener(buffer, node)
for _ in range(600):
    rclpy.spin_once(node, timeout_sec=0.1)
    if buffer.can_transform('world', 'eeCarry_seg6', rclpy.time.Time()):
        print('got it', flush=True)
        break
rclpy.shutdown()
"""


@pytest.fixture
def run_script(processes, tmp_path):
    """Start a script (its text) with the compat path first on PYTHONPATH."""
    def start(name, text):
        path = tmp_path / f'{name}.py'
        path.write_text(text)
        env = dict(os.environ, PYTHONPATH=os.pathsep.join(
            compat_folders() + [os.environ.get('PYTHONPATH', '')]))
        proc = processes.start([sys.executable, str(path)], env=env, cwd=str(tmp_path))
        return proc, process_lines(proc)
    return start


def ends_cleanly(proc, ctrl_c=True):
    if ctrl_c:
        proc.send_signal(signal.SIGINT)
    out, _ = proc.communicate(timeout=60)
    assert 'terminate called' not in (out or '') and 'Traceback' not in (out or ''), out
    assert proc.returncode == 0, (proc.returncode, out)


def test_the_tutorials_broadcasters_and_listener_run_unchanged(dq_fk_robot, run_script):
    dq_fk_robot('rl15')
    static, static_lines = run_script('static_broadcaster', STATIC_BROADCASTER)
    assert static_lines.until(lambda line: line.strip() == 'sent', 60), static_lines.lines
    dynamic, _ = run_script('dynamic_broadcaster', DYNAMIC_BROADCASTER)
    listener, lines = run_script('listener', LISTENER)
    seen = {}
    while len(seen) < 3:
        line = lines.until(lambda line: line.split()[:1] in (
            ['eeCarry_seg6'], ['mystaticturtle'], ['carrot1']), 60)
        assert line is not None, lines.lines[-20:]
        name, *xyz = line.split()
        seen[name] = [float(v) for v in xyz]
    # [Zivkovic2023] Fig. 4: the end effector at (1.025, 0, 1.445), its quaternion x y z w
    # (0.707107, 0, 0.707107, 0): its x is the world's z, its z the world's x; carrot1,
    # 0.5 m along its x, is 0.5 m above it
    assert seen['eeCarry_seg6'] == pytest.approx([1.025, 0.0, 1.445], abs=1e-6)
    assert seen['mystaticturtle'] == pytest.approx([0.0, 0.0, 1.0], abs=1e-6)
    assert seen['carrot1'] == pytest.approx([1.025, 0.0, 1.945], abs=1e-6)
    for proc in (listener, dynamic, static):
        ends_cleanly(proc)


def test_do_transform_pose_and_a_spin_once_loop_run_unchanged(dq_fk_robot, run_script):
    dq_fk_robot('rl15')
    poser, lines = run_script('do_transform_pose', DO_TRANSFORM_POSE)
    spinner, spun = run_script('spin_once', SPIN_ONCE)
    for label in ('pose', 'stamped'):
        line = lines.until(lambda line: line.startswith(label + ' '), 60)
        assert line is not None, lines.lines[-20:]
        # 0.1 m along eeCarry_seg6's z, which is the world's x at Fig. 4
        assert [float(v) for v in line.split()[1:]] == pytest.approx([1.125, 0.0, 1.445],
                                                                     abs=1e-6)
    ends_cleanly(poser, ctrl_c=False)
    assert spun.until(lambda line: line.strip() == 'got it', 60), spun.lines[-20:]
    ends_cleanly(spinner, ctrl_c=False)
