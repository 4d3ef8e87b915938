"""dq_fk tf's printing (dq_fk_ros.ros.tf_tools): tf2_echo's lines, RPY, view_frames' DOT."""

import math
import shutil

from dq_fk_ros.ros import tf_tools
from dq_fk_ros.transforms.buffer_core import BufferCore
from hypothesis import given, strategies as st
import numpy as np
import pytest


def test_echo_prints_what_tf2_echo_printed_for_the_same_transform():
    """
    Hold the lines to a real tf2_echo run (Jazzy) quoted in a public calibration guide.

    The guide also gives the pose to six decimals: p = (0.048601, -0.054869, 0.019026),
    q (xyzw) = (-0.287173, -0.120993, 0.346576, 0.884747); the time line as another run
    printed it, "At time 1101.270000000" (nanoseconds to nine digits).
    """
    pose = (0.048601, -0.054869, 0.019026, -0.287173, -0.120993, 0.346576, 0.884747)
    text = tf_tools.format_echo(1101_270_000_000, pose)
    assert text == ('At time 1101.270000000\n'
                    '- Translation: [0.049, -0.055, 0.019]\n'
                    '- Rotation: in Quaternion (xyzw) [-0.287, -0.121, 0.347, 0.885]\n'
                    '- Rotation: in RPY (radian) [-0.634, -0.015, 0.752]\n'
                    '- Rotation: in RPY (degree) [-36.305, -0.862, 43.065]\n'
                    '- Matrix:\n'
                    '  0.730 -0.544 -0.413  0.049\n'
                    '  0.683  0.595  0.424 -0.055\n'
                    '  0.015 -0.592  0.806  0.019\n'
                    '  0.000  0.000  0.000  1.000\n')


def rotation(roll, pitch, yaw):
    cr, sr, cp, sp, cy, sy = (math.cos(roll), math.sin(roll), math.cos(pitch),
                              math.sin(pitch), math.cos(yaw), math.sin(yaw))
    rz = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]])
    ry = np.array([[cp, 0, sp], [0, 1, 0], [-sp, 0, cp]])
    rx = np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]])
    return rz @ ry @ rx   # fixed axes x, then y, then z: ROS's RPY


@given(st.lists(st.floats(-1, 1), min_size=4, max_size=4).filter(
    lambda q: np.linalg.norm(q) > 0.1))
def test_rpy_gives_back_the_rotation(q):
    q = np.array(q) / np.linalg.norm(q)
    expected = np.array(tf_tools.matrix_rows((0, 0, 0, *q)))[:3, :3]
    np.testing.assert_allclose(rotation(*tf_tools.rpy(*q)), expected, atol=1e-6)


def test_frames_names_from_peers_stay_names_in_the_dot_text(tmp_path):
    core = BufferCore()
    core.set_transform('world', 'base', 0, (0, 0, 0, 0, 0, 0, 1), 'rsp', static=True)
    evil = 'x"]; "injected" -> "y\\'
    core.set_transform('base', evil, 10**9, (0, 0, 0, 0, 0, 0, 1), 'node"\n')
    gv, pdf = tf_tools.write_frames(core, str(tmp_path / 'frames.pdf'), 2 * 10**9)
    assert open(pdf, 'rb').read(5) == b'%PDF-'
    # as Graphviz reads the text: the hostile name is one node, no node "injected"
    import json
    import subprocess
    graph = json.loads(subprocess.run(['dot', '-Tjson', gv], capture_output=True,
                                      check=True).stdout)
    names = {o['name'] for o in graph['objects'] if 'nodes' not in o}
    # (a backslash is shown doubled: DOT has no other way to end a name in one)
    assert evil.replace('\\', '\\\\') in names
    assert 'injected' not in names and 'y' not in names
    assert len(graph['edges']) == 3   # two transforms and the legend's


def test_frames_whose_names_share_a_long_start_or_differ_unprintably_are_two_nodes(tmp_path):
    # names alike in their first 200 characters had been drawn as one node
    core = BufferCore()
    stem = 'f' * 300
    names = [stem + 'a', stem + 'b', 'ctl\x01', 'ctl\x02', 'ctl?', 'ctl\\x01']
    for name in names:
        assert core.set_transform('world', name, 10**9, (0, 0, 0, 0, 0, 0, 1), 'peer')
    gv, _ = tf_tools.write_frames(core, str(tmp_path / 'frames.pdf'), 2 * 10**9)
    import json
    import subprocess
    graph = json.loads(subprocess.run(['dot', '-Tjson', gv], capture_output=True,
                                      check=True).stdout)
    nodes = [o['name'] for o in graph['objects'] if 'nodes' not in o]
    assert len(nodes) == len(set(nodes)) == len(names) + 2   # and world, and the legend
    assert stem + 'a' in nodes and 'ctl\\x01' in nodes and 'ctl\\\\x01' in nodes


def test_without_dot_the_gv_is_written_and_it_says_how_to_get_dot(tmp_path, monkeypatch):
    monkeypatch.setattr(shutil, 'which', lambda name: None)
    with pytest.raises(RuntimeError, match=r'frames.gv written; .*apt-get install graphviz'):
        tf_tools.write_frames(BufferCore(), str(tmp_path / 'frames.pdf'))
    assert open(tmp_path / 'frames.gv').read() == 'digraph G {\n"no tf data recieved"\n}'
