"""
A new per-frame output made from docs/architecture.md's recipe alone: a row, values, a type.

The row made here, each frame's origin as a ``geometry_msgs/PointStamped`` on
``~/point/<frame>``, is added to the output table (``FRAME_OUTPUTS``) and its type to the
bag tool's ``OUTPUT_TYPES``, and nothing else: the node publishes it for every frame with a
pose topic, ``dq_fk_bag process`` writes it for every message, and its points are the
positions of the pose topics' poses. Before the one output pipeline a row could not carry
its layout and values (this test failed at its import) and a new output took five files.
"""

from dq_fk_ros.bag.output_types import from_typestore, OUTPUT_TYPES
from dq_fk_ros.bag.process import process_bag
from dq_fk_ros.description.schema import load_robot_description
from dq_fk_ros.description.shipped import shipped_robot_path
from dq_fk_ros.messages import outputs
from dq_fk_ros.messages.cdr_templates import CdrTemplate
from geometry_msgs.msg import PointStamped, PoseStamped
import numpy as np
import pytest
from ros_harness import Harness
from rosbags.rosbag2 import Reader
from test_bag import js_bytes, NAMES, T0, trajectory, TS, write_bag

pytestmark = pytest.mark.integration


def point_stamped_template(frame_id):
    """Return the layout of a ``geometry_msgs/PointStamped`` (a header, three float64)."""
    t = CdrTemplate()
    t.stamp()
    t.string(frame_id)
    t.f64s(3)
    return t


def point_values(plan, q, qdot, absolute, frames):
    """Return each frame's origin: the first three of its pose's values."""
    array, columns, rows = outputs.pose_values(plan, q, qdot, absolute, frames)
    return array[..., :3], columns, rows


POINT = outputs.Output('~/point/{frame}', 'geometry_msgs/msg/PointStamped', 10, False,
                       'the origin of each frame with a pose topic', 'pose_frames',
                       'publish_poses', point_stamped_template, point_values)


@pytest.fixture
def with_points(monkeypatch):
    """Add the point row to the output table and its type to the bag tool's types."""
    monkeypatch.setattr(outputs, 'FRAME_OUTPUTS', outputs.FRAME_OUTPUTS + (POINT,))
    monkeypatch.setitem(OUTPUT_TYPES, POINT.msgtype, from_typestore(POINT.msgtype))


def test_the_bag_tool_writes_a_new_row_of_the_table(with_points, tmp_path):
    q = trajectory(50)
    write_bag(tmp_path / 'in', [(T0 + k * 10**7, js_bytes(NAMES, q[k], T0 + k * 10**7))
                                for k in range(50)])
    process_bag(tmp_path / 'in', tmp_path / 'out', load_robot_description(
        shipped_robot_path('rl15')), poses='all', progress=False)
    by_topic = {}
    with Reader(tmp_path / 'out') as reader:
        for conn, _, raw in reader.messages():
            by_topic.setdefault(conn.topic, []).append(TS.deserialize_cdr(raw, conn.msgtype))
    points = sorted(t for t in by_topic if t.startswith('/dq_fk_node/point/'))
    assert [t.replace('/point/', '/pose/') for t in points] == \
        sorted(t for t in by_topic if t.startswith('/dq_fk_node/pose/'))
    assert len(points) == 7
    for topic in points:
        poses = by_topic[topic.replace('/point/', '/pose/')]
        assert len(by_topic[topic]) == len(poses) == 50
        for point, pose in zip(by_topic[topic], poses):
            assert point.header == pose.header
            p = pose.pose.position
            assert (point.point.x, point.point.y, point.point.z) == (p.x, p.y, p.z)


def test_the_node_publishes_a_new_row_of_the_table(with_points, ros_domain_id):
    harness = Harness()
    try:
        harness.start_node()
        points = harness.listen(PointStamped, harness.topic('point/eeCarry_seg6'))
        poses = harness.listen(PoseStamped, harness.topic('pose/eeCarry_seg6'))
        state = harness.joint_state(NAMES, [0.1, -0.2, 0.3, 0.4, -0.5, 0.6])
        assert harness.spin_until(lambda: points and poses, publish=state)
        point, pose = points[-1], poses[-1]
        assert point.header.frame_id == pose.header.frame_id == 'world'
        p = pose.pose.position
        np.testing.assert_array_equal([point.point.x, point.point.y, point.point.z],
                                      [p.x, p.y, p.z])
    finally:
        harness.close()
