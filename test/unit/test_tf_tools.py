"""dq_fk tf's printing (dq_fk_ros.ros.tf_tools): tf2_echo's lines, RPY, view_frames' DOT."""

import math
import shutil

from dq_fk_ros.ros import tf_tools
from dq_fk_ros.transforms.buffer_core import BufferCore
from hypothesis import given, strategies as st
import numpy as np
import pytest


def test_echo_prints_tf2_echos_lines_for_the_fig_4_pose():
    h = math.sqrt(0.5)
    text = tf_tools.format_echo(1_700_000_000_000_000_005, (1.025, 0.0, 1.445, h, 0.0, h, 0.0))
    assert text.splitlines()[:3] == [
        'At time 1700000000.5',   # tf2_echo prints the nanoseconds as an unpadded integer
        '- Translation: [1.025, 0.000, 1.445]',
        '- Rotation: in Quaternion (xyzw) [0.707, 0.000, 0.707, 0.000]']
    assert text.splitlines()[5] == '- Matrix:'
    rows = [[float(v) for v in line.split()] for line in text.splitlines()[6:10]]
    assert rows == [[0, 0, 1, 1.025], [0, -1, 0, 0], [1, 0, 0, 1.445], [0, 0, 0, 1]]


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


def test_without_dot_the_gv_is_written_and_it_says_how_to_get_dot(tmp_path, monkeypatch):
    monkeypatch.setattr(shutil, 'which', lambda name: None)
    with pytest.raises(RuntimeError, match=r'frames.gv written; .*apt-get install graphviz'):
        tf_tools.write_frames(BufferCore(), str(tmp_path / 'frames.pdf'))
    assert open(tmp_path / 'frames.gv').read() == 'digraph G {\n"no tf data recieved"\n}'
