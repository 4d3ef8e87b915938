"""
Headless demo: dq_fk_node and fake_joint_publisher as separate processes, poses over DDS.

Starts the node with the shipped RL15 and the fake publisher in ``zeros`` mode, waits for the
first poses, prints one line per frame as received (frame, parent from TF, position,
quaternion x y z w) and stops. With ``--live`` the publisher sweeps the joints (``sine``) and
the end-effector pose is printed twice a second until Ctrl-C; with ``--view`` dq_fk_view
shows the robot in a browser too (it prints the address to open); with ``--foxglove``
dq_fk_foxglove serves it to the Foxglove app (the demo prints what to click there).

The caller sets ``ROS_DOMAIN_ID`` and ``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST``
(``make demo`` does).
"""

import argparse
import os
import signal
import subprocess
import sys
import time

from dq_fk_ros.description.schema import load_robot_description
from dq_fk_ros.description.shipped import shipped_robot_path
from dq_fk_ros.ros.executables import executable
from dq_fk_ros.ros.executables import VIEWER_PORT as DEFAULT_PORT
from geometry_msgs.msg import PoseStamped
import rclpy
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from tf2_msgs.msg import TFMessage


FOXGLOVE_STEPS = """demo: in the Foxglove app (desktop, or app.foxglove.dev on this machine):
  1. Open connection > Foxglove WebSocket > ws://127.0.0.1:{port} > Open
  2. Add panel > 3D; in its settings: Frame > Display frame: world
  3. Custom layers > + > URDF: Source "Topic", Topic "/robot_description"
  4. (a pose plot) Add panel > Plot; + series /dq_fk_node/pose/eeCarry_seg6.pose.position.z
  or import docs/foxglove_layout.json (Layouts > Import) for both panels at once"""


class PoseWatcher:
    """Subscribe to every frame's pose and to TF; remember the latest of each."""

    def __init__(self, node, model, node_name='dq_fk_node'):
        """Create the subscriptions on ``node``."""
        self.poses = {}
        self.parents = {}
        for frame in model.frame_names:
            node.create_subscription(PoseStamped, f'/{node_name}/pose/{frame}',
                                     lambda msg, f=frame: self.poses.__setitem__(f, msg), 10)
        # tf2_ros's StaticListenerQoS: depth 100 keeps every broadcaster's latched message
        static_qos = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE,
                                durability=DurabilityPolicy.TRANSIENT_LOCAL)
        node.create_subscription(TFMessage, '/tf_static', self._on_tf, static_qos)
        node.create_subscription(TFMessage, '/tf', self._on_tf, 100)

    def _on_tf(self, msg):
        for t in msg.transforms:
            self.parents[t.child_frame_id] = t.header.frame_id


def format_pose(frame, parent, msg) -> str:
    """Format one line: frame, TF parent, x y z, qx qy qz qw (the pose as published)."""
    p, o = msg.pose.position, msg.pose.orientation
    values = [p.x, p.y, p.z, o.x, o.y, o.z, o.w]
    return (f'{frame:14s} {parent:14s} '
            + ' '.join(f'{round(v, 9) + 0.0:9.6f}' for v in values))


def main(argv=None) -> int:
    """Run the demo; exit code 0 once the poses were shown, 1 if they never came."""
    parser = argparse.ArgumentParser(description=__doc__.strip().splitlines()[0])
    parser.add_argument('--live', action='store_true',
                        help='keep running in sine mode, printing the end-effector pose')
    parser.add_argument('--view', action='store_true',
                        help='also start dq_fk_view (the robot in a browser; prints its URL)')
    parser.add_argument('--foxglove', action='store_true',
                        help='also start dq_fk_foxglove (the robot in the Foxglove app)')
    parser.add_argument('--port', type=int, default=DEFAULT_PORT,
                        help=f'dq_fk_view or dq_fk_foxglove port ({DEFAULT_PORT})')
    parser.add_argument('--timeout', type=float, default=30.0,
                        help='seconds to wait for the first poses (default 30)')
    args = parser.parse_args(argv)
    model = load_robot_description(shipped_robot_path('rl15'))
    print(f"demo: ROS_DOMAIN_ID={os.environ.get('ROS_DOMAIN_ID', '0')}, "
          f"discovery {os.environ.get('ROS_AUTOMATIC_DISCOVERY_RANGE', 'SUBNET')}; "
          f'starting dq_fk_node ({model.name}) and fake_joint_publisher '
          f"({'sine' if args.live else 'zeros'})", flush=True)
    log_args = ['--ros-args', '--log-level', 'warn']
    # own sessions: a Ctrl-C reaches the demo only, which then stops each child once
    procs = [
        subprocess.Popen(executable('dq_fk_node') + log_args, start_new_session=True),
        subprocess.Popen(executable('fake_joint_publisher') + log_args + [
            '-p', f"mode:={'sine' if args.live else 'zeros'}", '-p', 'rate_hz:=50.0'],
            start_new_session=True),
    ]
    if args.view:
        procs.append(subprocess.Popen(executable('dq_fk_view') + [
            '--port', str(args.port), '--select', 'eeCarry_seg6'] + log_args,
            start_new_session=True))
    if args.foxglove:
        procs.append(subprocess.Popen(executable('dq_fk_foxglove') + [
            '--port', str(args.port)] + log_args, start_new_session=True))
        print(FOXGLOVE_STEPS.format(port=args.port), flush=True)
    rclpy.init(args=log_args)
    node = rclpy.create_node('dq_fk_demo')
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    watcher = PoseWatcher(node, model)
    ee = model.end_effector or model.frame_names[-1]
    rc = 0
    try:
        deadline = time.monotonic() + args.timeout
        while not (len(watcher.poses) == len(model.frame_names)
                   and all(f in watcher.parents for f in model.frame_names)):
            if time.monotonic() > deadline:
                print(f'demo: no poses within {args.timeout:g} s (have '
                      f'{sorted(watcher.poses)}); is DDS blocked on loopback?', file=sys.stderr)
                return 1
            executor.spin_once(timeout_sec=0.05)
        print(f'{"frame":14s} {"tf_parent":14s} {"x":>9s} {"y":>9s} {"z":>9s} '
              f'{"qx":>9s} {"qy":>9s} {"qz":>9s} {"qw":>9s}   (pose in {model.fixed_frame}, '
              f'not relative to tf_parent; m, quaternion x y z w)')
        for frame in model.frame_names:
            print(format_pose(frame, watcher.parents[frame], watcher.poses[frame]))
        if args.live:
            print('demo: live end-effector pose (Ctrl-C to stop)', flush=True)
            next_print = 0.0
            while True:
                executor.spin_once(timeout_sec=0.05)
                if time.monotonic() >= next_print:
                    print(format_pose(ee, watcher.parents[ee], watcher.poses[ee]), flush=True)
                    next_print = time.monotonic() + 0.5
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
        for proc in procs:
            proc.send_signal(signal.SIGINT)
        for proc in procs:
            try:
                proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                proc.kill()
                rc = 1
    return rc


if __name__ == '__main__':
    sys.exit(main())
