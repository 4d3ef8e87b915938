"""
dq_fk calibrate from a bag: a tracker's PoseStamped paired with the robot's JointStates.

The bag is a measuring session as a robot runs it: the arm moves between configurations
and rests at each while the tracker measures; the test's own truth (test_calibration.py's
4x4 products of a perturbed UR5e) gives the poses. A pose taken while the arm moved, and
one with no joint state near it, are left out and counted; the calibrated table predicts
held-out poses within the tracker's noise.
"""

import json
import math
import os
import sys

from dq_fk_ros.cli.dq_fk import main
import numpy as np
import pytest
from rosbags.rosbag2 import Writer
from test_bag import Header, js_bytes, T0, Time, TS

sys.path.insert(0, os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))),
                                'unit'))
from test_calibration import (  # noqa: E402, I100 (the truth of the CSV tests)
    configurations, END, perturbed, quaternion_xyzw, Robot, SIGMA_P, SIGMA_R, small_rotation,
    WORLD)

pytest.importorskip('scipy')
pytestmark = pytest.mark.integration
PoseStamped = TS.types['geometry_msgs/msg/PoseStamped']
Pose = TS.types['geometry_msgs/msg/Pose']
Point = TS.types['geometry_msgs/msg/Point']
Quaternion = TS.types['geometry_msgs/msg/Quaternion']
RATE_NS = 10_000_000   # JointStates at 100 Hz


def pose_bytes(stamp_ns, m, rng):
    """Return a serialized PoseStamped of the 4x4 ``m`` with the tracker's noise."""
    x, y, z = m[:3, 3] + rng.normal(0, SIGMA_P, 3)
    qx, qy, qz, qw = quaternion_xyzw(m[:3, :3] @ small_rotation(rng, SIGMA_R))
    msg = PoseStamped(header=Header(stamp=Time(sec=stamp_ns // 10**9, nanosec=stamp_ns % 10**9),
                                    frame_id='tracker'),
                      pose=Pose(position=Point(x=x, y=y, z=z),
                                orientation=Quaternion(x=qx, y=qy, z=qz, w=qw)))
    return bytes(TS.serialize_cdr(msg, 'geometry_msgs/msg/PoseStamped'))


def test_a_bag_session_calibrates_as_its_csv_would(tmp_path):
    robot = Robot('ur5e')
    rng = np.random.default_rng(11)
    truth = perturbed(robot, rng)
    stops = configurations(robot, rng, 70)
    joint_states, poses = [], []
    t = T0
    previous = stops[0]
    for k, q in enumerate(stops):
        for step in range(1, 51):           # 0.5 s of motion to the next stop
            t += RATE_NS
            joint_states.append((t, previous + (q - previous) * step / 50))
            if k == 3 and step == 25:       # a pose taken while the arm moves
                poses.append((t + RATE_NS // 2, robot.poses(truth, [q], WORLD, END)[0]))
        for step in range(30):              # 0.3 s at rest: the tracker measures mid-way
            t += RATE_NS
            joint_states.append((t, q))
            if step == 15:
                poses.append((t + 3_000_000, robot.poses(truth, [q], WORLD, END)[0]))
        previous = q
    poses.append((t + 10**9, poses[-1][1]))  # a second after the last joint state
    with Writer(tmp_path / 'session', version=9) as writer:
        js = writer.add_connection('/joint_states', 'sensor_msgs/msg/JointState', typestore=TS)
        tracker = writer.add_connection('/tracker/pose', 'geometry_msgs/msg/PoseStamped',
                                        typestore=TS)
        messages = [(s, js, js_bytes(robot.joints, q, s)) for s, q in joint_states]
        messages += [(s, tracker, pose_bytes(s, m, rng)) for s, m in poses]
        for stamp, conn, raw in sorted(messages, key=lambda m: m[0]):
            writer.write(conn, stamp, raw)
    assert main(['calibrate', 'ur5e', '--bag', str(tmp_path / 'session'), '--pose-topic',
                 '/tracker/pose', '-o', str(tmp_path / 'calibrated.yaml'), '--report',
                 str(tmp_path / 'report.json')]) == 0
    report = json.loads((tmp_path / 'report.json').read_text())
    pairing = report['pairing']
    assert (pairing['poses'], pairing['paired'], pairing['moving'],
            pairing['no_joint_state']) == (72, 70, 1, 1)
    assert report['orientation_measured'] and report['measurements'] == 70
    after = report['residuals']['after']['holdout']
    assert after['position_rms_m'] < 2 * SIGMA_P * math.sqrt(3)
    assert after['orientation_rms_rad'] < 2 * SIGMA_R * math.sqrt(3)
    before = report['residuals']['before']['holdout']['position_rms_m']
    assert before > 0.3e-3


def test_a_pose_topic_of_another_type_is_refused_in_one_line(tmp_path, capsys):
    robot = Robot('ur5e')
    with Writer(tmp_path / 'bag', version=9) as writer:
        js = writer.add_connection('/joint_states', 'sensor_msgs/msg/JointState', typestore=TS)
        writer.write(js, T0, js_bytes(robot.joints, np.zeros(6), T0))
    assert main(['calibrate', 'ur5e', '--bag', str(tmp_path / 'bag'), '--pose-topic',
                 '/joint_states', '-o', str(tmp_path / 'out.yaml')]) == 1
    err = capsys.readouterr().err
    assert 'not geometry_msgs/msg/PoseStamped' in err and err.count('\n') == 1
    assert not (tmp_path / 'out.yaml').exists()
