"""
dq_fk_foxglove against a Foxglove WebSocket client written from the protocol's spec.

The node, the fake joint publisher and dq_fk_foxglove run as processes on the test's DDS
domain; a test-side ROS listener records what the node published, and the client
(:mod:`foxglove_client`) what Foxglove would see: the same transforms, the URDF, its meshes
byte for byte, and nothing else from the disk.
"""

import os
import xml.etree.ElementTree as ElementTree

from dq_fk_ros.description.meshes import visual_mesh_uris
from dq_fk_ros.ros.executables import executable
from foxglove_client import FoxgloveClient, wait
from geometry_msgs.msg import PoseStamped
from proc_table import listening
from process_lines import process_lines
import pytest
from ros_harness import node_topic, start, TF_STATIC_QOS
from tf2_msgs.msg import TFMessage
from vendor_urdfs import robots_dir, UR5, vendor_path

pytestmark = pytest.mark.integration


def start_foxglove(processes, *args):
    """Start dq_fk_foxglove on a free port; return ``(process, ws:// URL)`` once it listens."""
    proc = start(processes, 'dq_fk_foxglove', options=['--port', '0', *args])
    reader = process_lines(proc)
    line = reader.until(lambda text: 'Foxglove WebSocket > ' in text, timeout_s=30)
    if line is None:
        raise AssertionError(f'dq_fk_foxglove did not start: {"".join(reader.lines)}')
    return proc, line.rsplit('> ', 1)[1].strip()


def transforms_of_proto(message):
    """Return ``{(parent, child): (stamp ns, x, y, z, qx, qy, qz, qw)}`` of FrameTransforms."""
    out = {}
    for t in message.transforms:
        out[(t.parent_frame_id, t.child_frame_id)] = (
            t.timestamp.seconds * 1_000_000_000 + t.timestamp.nanos,
            t.translation.x, t.translation.y, t.translation.z,
            t.rotation.x, t.rotation.y, t.rotation.z, t.rotation.w)
    return out


def transforms_of_ros(msg):
    """Return the same for a tf2_msgs/TFMessage."""
    return {(t.header.frame_id, t.child_frame_id): (
        t.header.stamp.sec * 1_000_000_000 + t.header.stamp.nanosec,
        t.transform.translation.x, t.transform.translation.y, t.transform.translation.z,
        t.transform.rotation.x, t.transform.rotation.y, t.transform.rotation.z,
        t.transform.rotation.w) for t in msg.transforms}


def assert_same_as_the_node(listener, client, tf, static):
    """Every /tf FrameTransforms equals the node's /tf of its stamp; /tf_static the same."""
    assert wait(lambda: len(client.messages.get('/tf', [])) >= 5 and
                client.messages.get('/tf_static'), 30), sorted(client.messages)

    def matched():
        """Compare the client's /tf with the node's of the same stamp; count the pairs."""
        by_stamp = {}
        for msg in list(tf):
            got = transforms_of_ros(msg)
            by_stamp[next(iter(got.values()))[0]] = got
        count = 0
        for _, message in list(client.messages['/tf']):
            got = transforms_of_proto(message)  # decoded by the schema the channel advertised
            expected = by_stamp.get(next(iter(got.values()))[0])
            if expected is not None:
                assert got.keys() == expected.keys()
                for edge, values in got.items():
                    assert values == pytest.approx(expected[edge], abs=1e-9), edge
                count += 1
        return count
    # the test's listener takes one message a spin: under load it lags behind the client
    assert listener.spin_until(lambda: matched() >= 3, timeout_s=30), matched()
    latched = {}
    for msg in static:
        latched.update(transforms_of_ros(msg))
    sent = transforms_of_proto(client.messages['/tf_static'][-1][1])
    assert sent.keys() == latched.keys()
    for edge, values in sent.items():
        assert values[1:] == pytest.approx(latched[edge][1:], abs=1e-9), edge


def test_rl15_frames_reach_foxglove_as_the_node_computed_them(processes, listener):
    node = start(processes, 'dq_fk_node', 'publish_frequency:=0.0')
    start(processes, 'fake_joint_publisher', 'mode:=sine', 'rate_hz:=200.0')
    tf = listener.listen(TFMessage, '/tf', 1000)
    static = listener.listen(TFMessage, '/tf_static', TF_STATIC_QOS)
    _, url = start_foxglove(processes)
    client = FoxgloveClient(url)
    try:
        assert client.subprotocol in ('foxglove.sdk.v1', 'foxglove.websocket.v1')
        assert client.server_info['op'] == 'serverInfo'
        for topic in ('/tf', '/tf_static'):
            channel = client.channel(topic)
            assert (channel['schemaName'], channel['encoding'], channel['schemaEncoding']) == (
                'foxglove.FrameTransforms', 'protobuf', 'protobuf'), topic
        # the 3D panel's URDF layer lists topics of std_msgs String schemas
        assert client.channel('/robot_description')['schemaName'] == 'std_msgs/msg/String'
        joint_channel = client.channel('/joint_states')
        assert (joint_channel['schemaName'], joint_channel['encoding']) == (
            'sensor_msgs/msg/JointState', 'json')
        pose_topic = node_topic(node, 'pose/eeCarry_seg6')
        poses = listener.listen(PoseStamped, pose_topic, 1000)
        assert wait(lambda: any(c['topic'] == pose_topic
                                for c in list(client.channels.values())), 30)
        assert client.channel(pose_topic)['schemaName'] == 'foxglove.PoseInFrame'
        client.subscribe('/tf', '/tf_static', '/joint_states', pose_topic)
        listener.spin_until(lambda: len(tf) >= 50 and static, timeout_s=30)
        sent_before = len(client.messages.get('/tf', []))
        listener.spin_until(lambda: len(client.messages.get('/tf', [])) >= sent_before + 8,
                            timeout_s=30)
        assert_same_as_the_node(listener, client, tf, static)
        edges = transforms_of_proto(client.messages['/tf'][-1][1])
        assert ('wrist_seg5', 'eeCarry_seg6') in edges
        joints = client.messages['/joint_states'][-1][1]
        assert joints['name'][:6] == [f'joint_{k}' for k in range(1, 7)]
        assert len(joints['position']) == 6
        # the end effector's pose as the node published it (same stamp, same values)
        # until one stamp reached both (the client may get one before the listener: a
        # loaded fresh-clone run compared before any had, seed 3914703975)

        def one_in_both():
            stamps = {(p.header.stamp.sec, p.header.stamp.nanosec) for p in list(poses)}
            return any((got.timestamp.seconds, got.timestamp.nanos) in stamps
                       for _, got in list(client.messages.get(pose_topic, [])))
        listener.spin_until(one_in_both, timeout_s=30)
        published = {(p.header.stamp.sec, p.header.stamp.nanosec): p for p in list(poses)}
        matched = 0
        for _, got in client.messages[pose_topic]:
            assert got.frame_id == 'world'
            mine = published.get((got.timestamp.seconds, got.timestamp.nanos))
            if mine is not None:
                assert (got.pose.position.x, got.pose.position.y, got.pose.position.z,
                        got.pose.orientation.x, got.pose.orientation.y,
                        got.pose.orientation.z, got.pose.orientation.w) == (
                    mine.pose.position.x, mine.pose.position.y, mine.pose.position.z,
                    mine.pose.orientation.x, mine.pose.orientation.y,
                    mine.pose.orientation.z, mine.pose.orientation.w)
                matched += 1
        assert matched >= 1
        # 200 Hz in, at most --rate (30) a second out, the newest: the rate by the server's
        # log times of what it sent (the client's arrival times bunch under load: 34.5 a
        # second counted by arrival in a fresh-clone run). Only the bound is asserted (load
        # can only lower a rate); that the forwarding goes on is the 40 within the deadline
        count = len(client.messages['/tf'])
        listener.spin_until(lambda: len(client.messages['/tf']) >= count + 40, timeout_s=30)
        sent = [log_time for log_time, _ in client.messages['/tf'][count:]]
        per_second = (len(sent) - 1) / ((sent[-1] - sent[0]) / 1e9)
        assert per_second <= 33, per_second
    finally:
        client.close()


def test_ur5_meshes_come_back_byte_for_byte_and_nothing_else(processes, listener, tmp_path):
    urdf_path = vendor_path(UR5)
    package = os.path.dirname(robots_dir())  # the share folder of package example-robot-data
    prefix = 'package://example-robot-data/'
    start(processes, 'dq_fk_node', f'robot_description_file:={urdf_path}',
          f'urdf_tip_link:={UR5[1]}', 'publish_frequency:=0.0')
    start(processes, 'fake_joint_publisher', f'robot_description_file:={urdf_path}',
          f'urdf_tip_link:={UR5[1]}', 'mode:=sine', 'rate_hz:=100.0')
    tf = listener.listen(TFMessage, '/tf', 1000)
    static = listener.listen(TFMessage, '/tf_static', TF_STATIC_QOS)
    secret = tmp_path / 'secret.stl'
    secret.write_bytes(b'solid not-yours\nendsolid\n')
    # no --package: example-robot-data is found in the venv (its cmeel prefix's ament index)
    _, url = start_foxglove(processes)
    client = FoxgloveClient(url)
    try:
        client.subscribe('/tf', '/tf_static', '/robot_description')
        listener.spin_until(lambda: client.messages.get('/robot_description'), timeout_s=30)
        urdf = client.messages['/robot_description'][-1][1]['data']
        assert urdf == open(urdf_path).read()
        uris = visual_mesh_uris(urdf)
        assert len(uris) >= 7 and all(u.startswith(prefix) for u in uris)
        for uri in uris:
            status, error, data = client.fetch_asset(uri)
            path = os.path.join(package, uri[len(prefix):])
            assert (status, error) == (0, '') and data == open(path, 'rb').read(), uri
        first = uris[0][len(prefix):]
        for uri in (f'{prefix}../../../../../etc/passwd',
                    f'{prefix}{first}/../../../../../../../etc/passwd',
                    f'{prefix}robots/../../../../../../etc/passwd',
                    f'file://{secret}', '/etc/passwd', f'file://{package}/{first}',
                    f'{prefix}robots/ur_description/urdf/ur5_robot.urdf',
                    'http://example.com/a.stl', 'package://other/meshes/a.stl', ''):
            status, error, data = client.fetch_asset(uri)
            assert status == 1 and data == b'' and 'root:' not in error, uri
        listener.spin_until(lambda: len(tf) >= 50 and static, timeout_s=30)
        sent_before = len(client.messages.get('/tf', []))
        listener.spin_until(lambda: len(client.messages.get('/tf', [])) >= sent_before + 8,
                            timeout_s=30)
        assert_same_as_the_node(listener, client, tf, static)
        links = {c for _, c in transforms_of_proto(client.messages['/tf'][-1][1])} | \
            {c for _, c in transforms_of_proto(client.messages['/tf_static'][-1][1])}
        joints = ElementTree.fromstring(urdf).findall('joint')
        assert links == {j.find('child').get('link') for j in joints}  # the URDF's tree
    finally:
        client.close()


def test_a_static_robot_reaches_a_client_that_connects_late(processes, listener, tmp_path):
    path = tmp_path / 'rig.urdf'
    path.write_text('<robot name="rig"><link name="link1"/><link name="link2"/>'
                    '<joint name="j" type="fixed"><parent link="link1"/><child link="link2"/>'
                    '<origin xyz="5 0 0"/></joint></robot>')
    start(processes, 'dq_fk_node', f'robot_description_file:={path}')
    _, url = start_foxglove(processes)
    listener.spin_until(lambda: False, timeout_s=3.0)  # long after the only /tf_static
    client = FoxgloveClient(url)
    try:
        client.subscribe('/tf_static')
        assert wait(lambda: client.messages.get('/tf_static'), 20)
        sent = transforms_of_proto(client.messages['/tf_static'][-1][1])
        assert list(sent) == [('link1', 'link2')] and sent[('link1', 'link2')][1] == 5.0
        second = FoxgloveClient(url)  # and another one later still
        try:
            second.subscribe('/tf_static')
            assert wait(lambda: second.messages.get('/tf_static'), 20)
        finally:
            second.close()
    finally:
        client.close()


def test_bytes_that_do_not_parse_are_never_passed_through(processes, listener):
    """A JointState or PoseStamped of garbage is dropped; the next good one goes through."""
    from rclpy.serialization import serialize_message
    _, url = start_foxglove(processes)
    pose_pub = listener.probe.create_publisher(PoseStamped, '/hostile/pose/tool', 10)
    client = FoxgloveClient(url)
    try:
        assert wait(lambda: any(c['topic'] == '/hostile/pose/tool'
                                for c in list(client.channels.values())), 30)
        client.subscribe('/joint_states', '/hostile/pose/tool')
        good_joints = serialize_message(listener.joint_state(['a', 'b'], [0.5, -0.5]))
        good_pose = serialize_message(PoseStamped())
        for bad_joints, bad_pose in ((good_joints[:-20], good_pose[:-8]),  # cut short
                                     (b'\x00\x01\x00\x00' + b'\xff' * 60, good_pose + b'\x00' * 8),
                                     (good_joints[:1] + b'\x00' + good_joints[2:],
                                      good_pose[:1] + b'\x00' + good_pose[2:])):
            for _ in range(5):
                listener.joint_pub.publish(bad_joints)
                pose_pub.publish(bad_pose)
                listener.spin_until(lambda: False, timeout_s=0.1)
        assert client.messages.get('/joint_states') is None
        assert client.messages.get('/hostile/pose/tool') is None

        def good_ones_arrived():
            pose_pub.publish(good_pose)
            return client.messages.get('/joint_states') and \
                client.messages.get('/hostile/pose/tool')
        listener.spin_until(good_ones_arrived, timeout_s=20,
                            publish=listener.joint_state(['a', 'b'], [0.5, -0.5]))
        assert client.messages['/joint_states'][-1][1]['position'] == [0.5, -0.5]
        assert client.messages['/hostile/pose/tool'][-1][1].frame_id == ''
    finally:
        client.close()


def test_bad_clients_cannot_stop_the_server_or_grow_it(processes, listener):
    start(processes, 'dq_fk_node', 'publish_frequency:=0.0')
    start(processes, 'fake_joint_publisher', 'mode:=sine', 'rate_hz:=200.0')
    proc, url = start_foxglove(processes)

    def rss_kb():
        with open(f'/proc/{proc.pid}/status') as status:
            return next(int(line.split()[1]) for line in status if line.startswith('VmRSS'))
    good = FoxgloveClient(url)
    good.subscribe('/tf')
    assert wait(lambda: good.messages.get('/tf'), 30)
    before = rss_kb()
    bad = [FoxgloveClient(url) for _ in range(5)]
    slow = []
    try:
        channel = bad[0].channel('/tf')['id']
        bad[0].send(b'\xff' * 10_000)                       # a binary frame of no opcode
        bad[1].send('{"op": "nonsense", "x": [[[[[[[]]]]]]]}')  # an unknown op
        bad[2].send('not json at all {{{')
        bad[3].send({'op': 'subscribe', 'subscriptions': [
            {'id': k, 'channelId': channel} for k in range(5000)]})
        for k in range(2000):  # thousands of subscribes (one took over 10 s in a loaded run)
            try:
                bad[4].send({'op': 'subscribe', 'subscriptions': [{'id': 10_000 + k,
                                                                   'channelId': channel}]}, 60)
            except (ConnectionResetError, TimeoutError):
                # the SDK drops a client whose control queue (a status reply per refused
                # subscribe) fills faster than it reads, or stops reading from it (its
                # send then waits on TCP: 60 s in a loaded CI run): ways to survive it, not
                # failures; what must hold (the good client served, the server up, its
                # memory bounded) is asserted below
                break
        slow += [FoxgloveClient(url) for _ in range(3)]     # readers that never read
        for s in slow:
            s.subscribe('/tf', '/joint_states')
            s._loop.call_soon_threadsafe(s._ws._response.connection.transport.pause_reading)
        count = len(good.messages['/tf'])   # the good client is still served:
        assert listener.spin_until(lambda: len(good.messages['/tf']) > count + 50,
                                   timeout_s=30)
        assert proc.poll() is None
        assert rss_kb() - before < 64 * 1024, (before, rss_kb())  # KB
    finally:
        for client in bad + slow:
            client.close()
        good.close()


def test_without_the_sdk_it_says_how_to_get_it(processes, tmp_path):
    hide = tmp_path / 'hide'
    hide.mkdir()
    (hide / 'foxglove.py').write_text('raise ImportError("hidden by the test")\n')
    proc = processes.start(executable('dq_fk_foxglove'),
                           env={'PYTHONPATH': str(hide)})
    output, _ = proc.communicate(timeout=30)
    assert proc.returncode == 1
    assert output.strip().splitlines() == [
        'dq_fk_foxglove needs the Foxglove SDK: pip install "dq_fk_ros[foxglove]" '
        '(or pip install foxglove-sdk; make setup installs it)']


def test_it_listens_on_loopback_only_by_default(processes):
    proc, url = start_foxglove(processes)
    port = int(url.rsplit(':', 1)[1])
    sockets = listening([proc.pid])
    # the gate on 127.0.0.1, the SDK's server behind it on a random 127.x.y.z, nothing else
    assert ('0100007F', port) in sockets and len(sockets) == 2, sockets
    assert all(int(address, 16) & 0xFF == 127 for address, _ in sockets), sockets


def test_ctrl_c_while_the_server_starts_is_a_quiet_stop(monkeypatch, capsys):
    """
    SIGINT inside foxglove-sdk's start_server: pyo3 returns a SystemError caused by it.

    That is a Ctrl-C, not a port that cannot be listened on (exit 1 and "cannot listen"
    once in a loaded test run: test_program_signals.py's while-starting case).
    """
    import foxglove
    from dq_fk_ros.viewers import foxglove_live
    # in this process, not the SDK's one-way global log routing (a later test's SDK server
    # would log through it; see the closing note of issue 50)
    monkeypatch.setattr(foxglove_live, 'route_sdk_log', lambda _: None)

    def interrupted(**_):
        try:
            raise KeyboardInterrupt
        except KeyboardInterrupt as exc:
            raise SystemError('<built-in function start_server> returned a result with an '
                              'exception set') from exc
    monkeypatch.setattr(foxglove, 'start_server', interrupted)
    assert foxglove_live.main(['dq_fk_foxglove']) == 0
    assert 'cannot listen' not in capsys.readouterr().err


def test_a_thousand_half_open_connections_and_foreign_pages_leave_it_serving(processes):
    import resource
    import socket
    import time
    proc, url = start_foxglove(processes)
    port = int(url.rsplit(':', 1)[1])
    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    resource.setrlimit(resource.RLIMIT_NOFILE, (min(hard, 8192), hard))
    idle = []
    try:
        # past the common 1024 descriptors: the SDK alone stopped listening for good here
        for _ in range(1100):
            idle.append(socket.create_connection(('127.0.0.1', port), timeout=20))
        # the gate dropped them after its 10 s handshake bound: a client gets in again
        upgrade = (f'GET / HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\nUpgrade: websocket\r\n'
                   'Connection: Upgrade\r\nSec-WebSocket-Key: AAAAAAAAAAAAAAAAAAAAAA==\r\n'
                   'Sec-WebSocket-Version: 13\r\nSec-WebSocket-Protocol: foxglove.sdk.v1\r\n')
        deadline = time.monotonic() + 40
        answer = b''
        while not answer.startswith(b'HTTP/1.1 101') and time.monotonic() < deadline:
            try:
                with socket.create_connection(('127.0.0.1', port), timeout=20) as probe:
                    probe.sendall((upgrade + '\r\n').encode())
                    answer = probe.recv(100)
            except OSError:
                answer = b''
            if not answer.startswith(b'HTTP/1.1 101'):
                time.sleep(1.0)
        assert answer.startswith(b'HTTP/1.1 101'), answer
        client = FoxgloveClient(url)
        assert client.server_info
        client.close()
        evil = socket.create_connection(('127.0.0.1', port), timeout=20)
        evil.sendall((upgrade + 'Origin: https://evil.example\r\n\r\n').encode())
        assert evil.recv(100).startswith(b'HTTP/1.1 403')
        assert proc.poll() is None
    finally:
        for sock in idle:
            sock.close()
        resource.setrlimit(resource.RLIMIT_NOFILE, (soft, hard))


def test_invalid_client_messages_do_not_write_a_line_each(processes):
    proc, url = start_foxglove(processes)
    reader = process_lines(proc)
    bad = FoxgloveClient(url)
    try:
        for k in range(500):  # the SDK logs each one ('Invalid message from ...')
            try:
                bad.send('not json at all {{{' if k % 2 else b'\xff' * 16)
            except (ConnectionResetError, TimeoutError):
                # the server may drop, or stop reading, a client that sends nothing valid
                # (both seen under a CPU hog on both cores): what must hold, few log
                # lines, is asserted below
                break
        assert reader.until(lambda text: 'sdk:' in text, timeout_s=30), 'no SDK line'
        reader.until(lambda text: False, timeout_s=3)   # a window for more: 5 at most in all
        sdk_lines = [line for line in reader.lines if 'sdk:' in line]
        assert 1 <= len(sdk_lines) <= 5, sdk_lines[:8]
        assert 'Invalid message' in sdk_lines[0]
    finally:
        bad.close()
