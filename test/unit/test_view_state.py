"""dq_fk_view's state: what the page gets, without any ROS or web process."""

import json
from types import SimpleNamespace

from dq_fk_ros.viewers import view_state
from dq_fk_ros.viewers.view import parse_args
from dq_fk_ros.viewers.view_panel import JointPanel
from dq_fk_ros.viewers.view_state import ViewState
from dq_fk_ros.viewers.view_web import _client_message, host_allowed
from hypothesis import given, strategies as st
import pytest

IDENTITY = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0)


def frames(state):
    message = json.loads(state.frames_message())
    return message, {f[0]: f for f in message['frames']}


class Clock:
    """A ``time`` module whose ``monotonic()`` moves only when a test moves it."""

    def __init__(self):
        self.now = 1000.0

    def monotonic(self):
        return self.now


def test_the_root_with_most_frames_is_the_fixed_frame_and_the_deepest_is_selected(monkeypatch):
    clock = Clock()
    monkeypatch.setattr(view_state, 'time', clock)
    state = ViewState(stale_after_s=0.2)
    assert state.frames_message() is None
    state.take_transforms([('world', 'base', (0, 0, 1.0, 0, 0, 0, 1.0))], static=True)
    state.take_transforms([('base', 'link1', (0.5, 0, 0, 0, 0, 0, 1.0)),
                           ('link1', 'tool', (0.25, 0, 0, 0, 0, 0, 1.0)),
                           ('link1', 'link1_dh_z', (0.1, 0, 0, 0, 0, 0, 1.0)),
                           ('link1', 'camera', IDENTITY),
                           ('odom', 'robot2', IDENTITY), ('x', 'x', IDENTITY)], static=False)
    message, by_name = frames(state)
    assert message['type'] == 'frames' and message['fixed_frame'] == 'world'
    assert sorted(by_name) == ['base', 'camera', 'link1', 'link1_dh_z',
                               'tool']
    assert by_name['tool'][1:9] == ['link1', 0.75, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]
    # the deepest frames: camera and tool (alphabetical first), never a URDF helper
    assert message['select'] == 'camera'
    assert not any(f[9] for f in message['frames'])
    clock.now += 0.19   # not yet stale
    assert not any(f[9] for f in frames(state)[0]['frames'])
    clock.now += 0.02   # the /tf frames go stale, the /tf_static ones never
    _, by_name = frames(state)
    assert by_name['tool'][9] and not by_name['base'][9]


def test_a_chosen_fixed_frame_and_selection_are_kept():
    state = ViewState(fixed_frame='base', select='tool')
    state.take_transforms([('world', 'base', IDENTITY), ('base', 'tool', IDENTITY)], True)
    message, by_name = frames(state)
    assert message['fixed_frame'] == 'base' and message['select'] == 'tool'
    assert list(by_name) == ['tool']


def test_a_new_description_is_a_new_version_only_when_it_changes():
    state = ViewState()
    state.take_description('<robot name="a"/>')
    state.take_description('<robot name="a"/>')
    assert state.urdf_version == 1
    state.take_description('<robot name="b"/>')
    assert state.urdf_version == 2 and state.urdf == '<robot name="b"/>'


@pytest.mark.parametrize('argv, words', [
    (['--port', '70000'], '--port 70000: give 0..65535'),
    (['--rate', '0'], '--rate 0: give more than 0'),
    (['--stale-after', '-1'], '--stale-after: give a positive number'),
])
def test_bad_options_are_one_line(argv, words, capsys):
    with pytest.raises(SystemExit) as caught:
        parse_args(argv)
    assert caught.value.code == 2 and words in capsys.readouterr().err


def test_defaults_listen_on_loopback():
    args = parse_args([])
    assert (args.host, args.port, args.rate) == ('127.0.0.1', 8765, 30.0)


def tf_bytes(edges, stamp_ns=0):
    """Serialize a TFMessage with rclpy: ``[(parent, child, (x, y, z, qx, qy, qz, qw))]``."""
    from geometry_msgs.msg import TransformStamped
    from rclpy.serialization import serialize_message
    from tf2_msgs.msg import TFMessage
    msg = TFMessage()
    for parent, child, pose in edges:
        t = TransformStamped()
        t.header.frame_id, t.child_frame_id = parent, child
        t.header.stamp.sec, t.header.stamp.nanosec = divmod(stamp_ns, 1_000_000_000)
        tr, r = t.transform.translation, t.transform.rotation
        tr.x, tr.y, tr.z, r.x, r.y, r.z, r.w = pose
        msg.transforms.append(t)
    return serialize_message(msg)


def test_only_each_publishers_newest_tf_is_read_and_bad_bytes_are_counted():
    state = ViewState()
    arm = [('world', 'a', (1.0, 0, 0, 0, 0, 0, 1.0)), ('a', 'b', (0, 1.0, 0, 0, 0, 0, 1.0))]
    other = [('world', 'c', (5.0, 0, 0, 0, 0, 0, 1.0))]
    state.take_raw_tf(tf_bytes(arm, 10))
    state.take_raw_tf(tf_bytes(other, 11))       # another publisher: kept too
    state.take_raw_tf(b'\x00\x01\x00\x00\xff\xff')  # not a TFMessage: counted
    arm[0] = ('world', 'a', (2.0, 0, 0, 0, 0, 0, 1.0))
    state.take_raw_tf(tf_bytes(arm, 12))
    message, by_name = frames(state)
    assert by_name['a'][2] == 2.0 and by_name['b'][2:5] == [2.0, 1.0, 0.0]
    assert by_name['c'][2] == 5.0 and message['stamp_ns'] == 12
    assert state.counts['bad_tf'] == 1
    assert state.counts['tf_messages'] == 2  # the newest of each of the two layouts


@given(st.one_of(st.text(max_size=200), st.binary(max_size=200),
                 st.recursive(st.one_of(st.none(), st.booleans(), st.floats(),
                                        st.text(max_size=5)),
                              lambda inner: st.one_of(
                                  st.lists(inner, max_size=3),
                                  st.dictionaries(st.text(max_size=5), inner, max_size=3)),
                              max_leaves=20).map(json.dumps),
                 st.integers(1, 40_000).map(lambda n: '[' * n + ']' * n),
                 st.integers(1, 40_000).map(lambda n: '{"a":' * n + '1' + '}' * n)))
def test_any_page_message_is_judged_without_an_exception(data):
    """A 64 KB nested JSON message raised RecursionError in the view."""
    kinds = SimpleNamespace(TEXT='text', BINARY='binary')
    kind = kinds.BINARY if isinstance(data, bytes) else kinds.TEXT
    judged = _client_message(SimpleNamespace(type=kind, data=data), kinds)
    hello = kind == kinds.TEXT and data.replace(' ', '') == '{"type":"hello"}'
    assert (judged == 'hello') is hello
    if isinstance(judged, dict):   # a joints message: the panel judges it, never raising
        assert judged['type'] == 'joints'
        panel = JointPanel()
        panel.take_description('<robot name="r"><link name="a"/><link name="b"/>'
                               '<joint name="j" type="continuous"><parent link="a"/>'
                               '<child link="b"/></joint></robot>')
        panel.take_page(judged)
        assert -3.2 < panel.joint_state()[1][0] < 3.2
    else:
        assert judged in ('hello', None)


@pytest.mark.parametrize('host, allowed', [
    ('127.0.0.1', True), ('127.3.4.5', True), ('localhost', True), ('::1', True),
    ('[::1]', True), ('LOCALHOST.', True), ('evil.example', False), ('10.0.0.1', False),
    ('', False), ('0.0.0.0', False), ('localhost.evil.example', False)])
def test_only_loopback_hosts_are_allowed_by_default(host, allowed):
    assert host_allowed(host) is allowed
    assert host_allowed('robot.local', ('robot.local',))
