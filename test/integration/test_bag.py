"""dq_fk_bag on bags the tests write themselves with rosbags (MCAP and sqlite3)."""

import io
import math
import os

from diagnostic_msgs.msg import DiagnosticArray
from dq_fk_ros.bag.process import process_bag
from dq_fk_ros.cli.dq_fk_bag import main as bag_main
from dq_fk_ros.description.schema import load_robot_description
from dq_fk_ros.description.shipped import shipped_robot_path
from dq_fk_ros.description.to_urdf import robot_to_urdf
from dq_fk_ros.messages.cdr import parse_joint_state
from dq_fk_ros.messages.joint_states import JointStateMerger, PUBLISH
from dq_fk_ros.ros.executables import executable
from geometry_msgs.msg import PoseStamped, TwistStamped
import homogeneous_tf as htf
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
import numpy as np
import pytest
from ros_harness import Harness
from rosbags.interfaces import QosDurability
from rosbags.rosbag2 import Reader, StoragePlugin, Writer
from rosbags.typesys import get_types_from_msg, get_typestore, Stores
import yaml

TS = get_typestore(Stores.ROS2_JAZZY)
JointState = TS.types['sensor_msgs/msg/JointState']
Header = TS.types['std_msgs/msg/Header']
Time = TS.types['builtin_interfaces/msg/Time']
String = TS.types['std_msgs/msg/String']
RL15 = shipped_robot_path('rl15')
MODEL = load_robot_description(RL15)
NAMES = list(MODEL.joint_names)
T0 = 1_700_000_000_000_000_000
STORAGES = {'mcap': StoragePlugin.MCAP, 'sqlite3': StoragePlugin.SQLITE3}


def js_bytes(names, positions, stamp_ns, velocities=()):
    msg = JointState(header=Header(stamp=Time(sec=stamp_ns // 10**9, nanosec=stamp_ns % 10**9),
                                   frame_id=''),
                     name=list(names), position=np.asarray(positions, dtype=float),
                     velocity=np.asarray(velocities, dtype=float), effort=np.zeros(0))
    return bytes(TS.serialize_cdr(msg, 'sensor_msgs/msg/JointState'))


def trajectory(n):
    t = np.arange(n) * 0.01
    return np.stack([0.5 * np.sin(t * (k + 1)) for k in range(6)], axis=1)


def write_bag(path, messages, storage='mcap', extra_topic=False):
    """``messages``: (stamp_ns, raw bytes); also a std_msgs/String topic if ``extra_topic``."""
    with Writer(path, version=9, storage_plugin=STORAGES[storage]) as writer:
        conn = writer.add_connection('/joint_states', 'sensor_msgs/msg/JointState',
                                     typestore=TS)
        chat = writer.add_connection('/chatter', 'std_msgs/msg/String', typestore=TS) \
            if extra_topic else None
        for stamp, raw in messages:
            writer.write(conn, stamp, raw)
            if chat is not None:
                writer.write(chat, stamp, bytes(TS.serialize_cdr(
                    String(data='hello'), 'std_msgs/msg/String')))


def trajectory_rates(n):
    """Return the joint velocities of :func:`trajectory` (rad/s), its derivative."""
    t = np.arange(n) * 0.01
    return np.stack([0.5 * (k + 1) * np.cos(t * (k + 1)) for k in range(6)], axis=1)


def valid_bag(path, n=300, storage='mcap', velocities=False, **kw):
    q = trajectory(n)
    rates = trajectory_rates(n) if velocities else np.zeros((n, 0))
    stamps = [T0 + k * 10_000_000 for k in range(n)]
    write_bag(path, [(s, js_bytes(NAMES, row, s, rate)) for s, row, rate in zip(stamps, q, rates)],
              storage, **kw)
    return q, stamps


def read_topic(path, topic):
    with Reader(path) as reader:
        conns = [c for c in reader.connections if c.topic == topic]
        return [(t, TS.deserialize_cdr(raw, c.msgtype)) for c, t, raw in
                reader.messages(connections=conns)]


def stamp_ns(msg_header):
    return msg_header.stamp.sec * 10**9 + msg_header.stamp.nanosec


@pytest.mark.parametrize('storage', ['mcap', 'sqlite3'])
def test_offline_output_equals_core_fk(tmp_path, storage):
    q, stamps = valid_bag(tmp_path / 'in', storage=storage)
    summary = process_bag(tmp_path / 'in', tmp_path / 'out', RL15, storage=storage,
                          csv_path=tmp_path / 'ee.csv', progress=False, chunk=64, poses='all')
    assert summary.read == summary.written == len(q) and not summary.rejected
    for k, frame in enumerate(MODEL.frame_names):
        poses = read_topic(tmp_path / 'out', f'/dq_fk_node/pose/{frame}')
        assert len(poses) == len(q)
        for i in (0, 77, len(q) - 1):
            t, msg = poses[i]
            assert t == stamps[i] and stamp_ns(msg.header) == stamps[i]
            expected = MODEL.chain.forward_all(q[i])
            from dq_fk_ros.kinematics.dh import homogeneous_from_dq
            np.testing.assert_allclose(htf.pose_matrix(msg.pose),
                                       homogeneous_from_dq(expected[k]), atol=1e-12)
    tf = read_topic(tmp_path / 'out', '/tf')
    static = read_topic(tmp_path / 'out', '/tf_static')
    assert len(tf) == len(q) and len(static) == 1
    transforms = static[0][1].transforms + tf[123][1].transforms
    np.testing.assert_allclose(htf.compose(transforms, 'world', 'eeCarry_seg6'),
                               MODEL.chain.forward(q[123]).to_matrix(), atol=1e-12)
    rows = np.loadtxt(tmp_path / 'ee.csv', delimiter=',', skiprows=1, dtype=object)
    assert [int(s) for s in rows[:, 0]] == stamps
    np.testing.assert_allclose(rows[5, 1:4].astype(float),
                               MODEL.chain.forward(q[5]).translation, atol=1e-15)


def test_tf_static_is_offered_transient_local(tmp_path):
    valid_bag(tmp_path / 'in', n=5)
    process_bag(tmp_path / 'in', tmp_path / 'out', RL15, progress=False)
    with Reader(tmp_path / 'out') as reader:
        qos = {c.topic: c.ext.offered_qos_profiles for c in reader.connections}
    assert qos['/tf_static'][0].durability == QosDurability.TRANSIENT_LOCAL
    assert qos['/tf'][0].durability == QosDurability.VOLATILE


def test_split_publishers_merge_as_the_node_does(tmp_path):
    """Two publishers (joints 1-3, joints 4-6) alternate; their clock restarts halfway."""
    q = trajectory(400)
    messages = []
    for k, row in enumerate(q):
        stamp = T0 + k * 10_000_000 - (5 * 10**9 if k >= 200 else 0)  # a jump back at 200
        part = slice(0, 3) if k % 2 == 0 else slice(3, 6)
        if k == 201:  # one publisher keeps going alone for a while after the jump
            part = slice(0, 3)
        messages.append((T0 + k * 10_000_000, js_bytes(NAMES[part], row[part], stamp)))
    write_bag(tmp_path / 'in', messages)
    summary = process_bag(tmp_path / 'in', tmp_path / 'out', RL15, progress=False, chunk=64)
    merger = JointStateMerger(MODEL.joint_names, MODEL.limits)  # the node's rules, one by one
    expected = []
    for _, raw in messages:
        stamp, names, positions, _ = parse_joint_state(raw)
        result = merger.merge(names, positions, stamp_ns=stamp)
        if result.status == PUBLISH:
            expected.append((stamp, result.q))
    # incomplete: the first message, and 200-202 after the reset (joints 4-6 unseen)
    assert summary.written == len(expected) == 396 and summary.incomplete == 4
    out = read_topic(tmp_path / 'out', '/dq_fk_node/pose/eeCarry_seg6')
    assert [stamp_ns(m.header) for _, m in out] == [s for s, _ in expected]
    for (_, msg), (_, joints) in zip(out, expected):
        np.testing.assert_allclose(htf.pose_matrix(msg.pose),
                                   MODEL.chain.forward(joints).to_matrix(), atol=1e-12)


def test_output_opens_in_the_official_mcap_reader(tmp_path):
    """Foxglove's mcap (CRCs checked) reads it and mcap_ros2 decodes it from its schemas."""
    q, stamps = valid_bag(tmp_path / 'in', n=150)
    process_bag(tmp_path / 'in', tmp_path / 'out', RL15, progress=False, chunk=32, poses='all')
    with open(tmp_path / 'out' / 'out.mcap', 'rb') as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()], validate_crcs=True)
        channels = {c.topic: c for c in reader.get_summary().channels.values()}
        assert 'transient_local' in channels['/tf_static'].metadata['offered_qos_profiles']
        assert all(c.metadata['topic_type_hash'].startswith('RIHS01_')
                   for c in channels.values())
        counts = {}
        ee = []
        for _, channel, _, decoded in reader.iter_decoded_messages(log_time_order=True):
            counts[channel.topic] = counts.get(channel.topic, 0) + 1
            if channel.topic == '/dq_fk_node/pose/eeCarry_seg6':
                ee.append(decoded.pose)
            if channel.topic == '/robot_description':
                urdf = decoded.data
        assert 'transient_local' in channels['/robot_description'].metadata[
            'offered_qos_profiles']
    # the URDF for Foxglove's 3D panel, once, as the node publishes it
    assert counts.pop('/robot_description') == 1 and urdf == robot_to_urdf(MODEL)
    assert counts.pop('/tf_static') == 1 and counts.pop('/tf') == len(q)
    assert len(counts) == len(MODEL.frame_names) and set(counts.values()) == {len(q)}
    np.testing.assert_allclose(htf.pose_matrix(ee[99]), MODEL.chain.forward(q[99]).to_matrix(),
                               atol=1e-12)
    info = yaml.safe_load((tmp_path / 'out' / 'metadata.yaml').read_text())
    info = info['rosbag2_bagfile_information']
    assert info['version'] == 9 and info['storage_identifier'] == 'mcap'
    assert info['message_count'] == 2 + len(q) * (1 + len(MODEL.frame_names))


def test_bad_content_is_skipped_counted_and_nothing_valid_lost(tmp_path):
    q = trajectory(100)
    messages, valid_stamps = [], []
    for k, row in enumerate(q):
        s = T0 + k * 10_000_000
        if k % 10 == 3:
            messages.append((s, js_bytes(NAMES, row[:5], s)))          # lengths differ
        elif k % 10 == 5:
            bad = row.copy()
            bad[2] = math.nan
            messages.append((s, js_bytes(NAMES, bad, s)))              # NaN
        elif k % 10 == 7:
            messages.append((s, js_bytes(NAMES, row, s)[:-12]))        # truncated CDR
        else:
            messages.append((s, js_bytes(NAMES + ['gripper'], list(row) + [0.0], s)))
            valid_stamps.append(s)
    write_bag(tmp_path / 'in', messages, extra_topic=True)
    summary = process_bag(tmp_path / 'in', tmp_path / 'out', RL15, copy_input=True,
                          progress=False)
    assert summary.read == 100 and summary.written == len(valid_stamps) == 70
    assert summary.rejected == {'length_mismatch': 10, 'non_finite': 10,
                                'malformed_cdr': 10}
    assert summary.unknown_joints == ['gripper']
    out = read_topic(tmp_path / 'out', '/dq_fk_node/pose/eeCarry_seg6')
    assert [stamp_ns(m.header) for _, m in out] == valid_stamps
    with Reader(tmp_path / 'out') as reader:  # copied through, broken ones included
        counts = {c.topic: c.msgcount for c in reader.connections}
    assert counts['/chatter'] == 100 and counts['/joint_states'] == 100


def run_cli(capsys, *argv):
    rc = bag_main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return rc, out, err


def run_process(capsys, *argv):
    """``dq_fk_bag process --robot rl15 ...`` (the bags of these tests are RL15 bags)."""
    return run_cli(capsys, 'process', '--robot', 'rl15', *argv)


def test_copy_input_keeps_custom_types_with_their_definition(tmp_path):
    store = get_typestore(Stores.ROS2_JAZZY)
    store.register(get_types_from_msg('float64 x\nstring label', 'my_pkg/msg/Thing'))
    thing = store.types['my_pkg/msg/Thing']
    things = [bytes(store.serialize_cdr(thing(x=k / 3, label=f'#{k}'), 'my_pkg/msg/Thing'))
              for k in range(20)]
    q = trajectory(20)
    with Writer(tmp_path / 'in', version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        js = writer.add_connection('/joint_states', 'sensor_msgs/msg/JointState', typestore=TS)
        custom = writer.add_connection('/thing', 'my_pkg/msg/Thing', typestore=store)
        for k in range(20):
            writer.write(js, T0 + k, js_bytes(NAMES, q[k], T0 + k))
            writer.write(custom, T0 + k, things[k])
    process_bag(tmp_path / 'in', tmp_path / 'out', RL15, copy_input=True, progress=False)
    with Reader(tmp_path / 'out') as reader:
        conn = next(c for c in reader.connections if c.topic == '/thing')
        assert conn.digest == store.hash_rihs01('my_pkg/msg/Thing')
        assert 'string label' in conn.msgdef.data
        assert [bytes(raw) for _, _, raw in reader.messages([conn])] == things


def test_copy_input_of_a_type_without_definition_is_refused_cleanly(tmp_path, capsys):
    with Writer(tmp_path / 'in', version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        js = writer.add_connection('/joint_states', 'sensor_msgs/msg/JointState', typestore=TS)
        odd = writer.add_connection('/odd', 'other_pkg/msg/Odd', msgdef='', rihs01='RIHS01_0')
        writer.write(js, T0, js_bytes(NAMES, np.zeros(6), T0))
        writer.write(odd, T0, b'\x00\x01\x00\x00')
    rc, _, err = run_process(capsys, tmp_path / 'in', tmp_path / 'out', '--quiet', '--copy-input')
    assert rc == 2 and err.count('\n') == 1
    assert 'cannot copy /odd' in err and 'other_pkg/msg/Odd' in err
    assert not (tmp_path / 'out').exists()


def test_user_errors_are_one_line(tmp_path, capsys):
    valid_bag(tmp_path / 'in', n=3, extra_topic=True)
    cases = [
        ((tmp_path / 'nope', tmp_path / 'o1'), 'no such bag'),
        ((tmp_path / 'in', tmp_path / 'o2', '--topic', '/missing'),
         "has no topic '/missing'; its topics: /joint_states (sensor_msgs/msg/JointState), "
         '/chatter (std_msgs/msg/String)'),
        ((tmp_path / 'in', tmp_path / 'o3', '--topic', '/chatter'),
         "topic '/chatter' has type std_msgs/msg/String, not sensor_msgs/msg/JointState"),
    ]
    for args, words in cases:
        rc, _, err = run_process(capsys, *args, '--quiet')
        assert rc == 2 and err.startswith('dq_fk_bag: ') and err.count('\n') == 1, err
        assert words in err
    corrupt = tmp_path / 'corrupt'
    corrupt.mkdir()
    (corrupt / 'metadata.yaml').write_text('not: [a bag')
    rc, _, err = run_process(capsys, corrupt, tmp_path / 'o4', '--quiet')
    assert rc == 2 and 'not a readable rosbag2' in err
    (tmp_path / 'exists').mkdir()
    rc, _, err = run_process(capsys, tmp_path / 'in', tmp_path / 'exists', '--quiet')
    assert rc == 2 and 'exists; use --overwrite' in err
    rc, out, _ = run_process(capsys, tmp_path / 'in', tmp_path / 'exists', '--quiet',
                             '--overwrite')
    assert rc == 0 and '3 JointState messages, 3 written' in out


def messages_in_chunks_before(mcap_bytes, cut):
    """Log times of the messages in the chunks that end before byte ``cut`` (mcap's index)."""
    reader = make_reader(io.BytesIO(mcap_bytes))
    complete = [c for c in reader.get_summary().chunk_indexes
                if c.chunk_start_offset + c.chunk_length <= cut]
    assert complete, 'the cut must leave at least one complete chunk'
    last = max(c.message_end_time for c in complete)
    return [m.log_time for _, _, m in reader.iter_messages(log_time_order=True)
            if m.log_time <= last]


def test_recording_cut_short_keeps_every_complete_chunk(tmp_path, capsys):
    """A recording killed on the robot: no metadata.yaml, the MCAP ends mid-chunk."""
    q, stamps = valid_bag(tmp_path / 'in', n=30000)
    mcap = next((tmp_path / 'in').glob('*.mcap'))
    data = mcap.read_bytes()
    cut = int(len(data) * 0.6)
    expected = messages_in_chunks_before(data, cut)
    mcap.write_bytes(data[:cut])
    (tmp_path / 'in' / 'metadata.yaml').unlink()
    rc, out, err = run_process(capsys, tmp_path / 'in', tmp_path / 'out', '--quiet')
    assert rc == 1
    assert 'not a complete rosbag2' in err and 'record by record' in err
    assert f'{mcap} ends early or is damaged' in err
    assert len(err.strip().splitlines()) == 2  # the note and the damage, a line each
    assert 0 < len(expected) < len(q) and f'{len(expected)} written' in out
    poses = read_topic(tmp_path / 'out', '/dq_fk_node/pose/eeCarry_seg6')
    assert [stamp_ns(m.header) for _, m in poses] == expected == stamps[:len(expected)]


def test_a_bare_mcap_file_or_a_folder_without_metadata_is_read_whole(tmp_path, capsys):
    q, stamps = valid_bag(tmp_path / 'in', n=500, extra_topic=True)
    mcap = next((tmp_path / 'in').glob('*.mcap'))
    rc, out, err = run_process(capsys, mcap, tmp_path / 'out1', '--quiet', '--copy-input')
    assert rc == 0 and err == '' and '500 written' in out
    with Reader(tmp_path / 'out1') as reader:
        counts = {c.topic: c.msgcount for c in reader.connections}
    assert counts['/chatter'] == 500 and counts['/joint_states'] == 500
    (tmp_path / 'in' / 'metadata.yaml').unlink()
    rc, out, err = run_process(capsys, tmp_path / 'in', tmp_path / 'out2', '--quiet')
    assert rc == 0 and 'not a complete rosbag2' in err and '500 written' in out
    assert read_topic(tmp_path / 'out2', '/tf') == read_topic(tmp_path / 'out1', '/tf')


def test_recovered_recording_replays(tmp_path, capsys):
    valid_bag(tmp_path / 'in', n=30000)
    mcap = next((tmp_path / 'in').glob('*.mcap'))
    data = mcap.read_bytes()
    expected = messages_in_chunks_before(data, len(data) * 2 // 3)
    mcap.write_bytes(data[:len(data) * 2 // 3])
    (tmp_path / 'in' / 'metadata.yaml').unlink()
    from dq_fk_ros.storage.reading import open_reader
    reader = open_reader(tmp_path / 'in')
    assert [t for _, t, _ in reader.messages()] == expected
    conn = reader.connections[0]
    assert (conn.topic, conn.msgtype, conn.msgcount) == \
        ('/joint_states', 'sensor_msgs/msg/JointState', len(expected))
    assert 'string[] name' in conn.msgdef.data  # the schema the file carries
    start = reader.start_time + 10**9  # --start 1 s
    assert [t for _, t, _ in reader.messages([conn], start=start, stop=start + 10**8)] == \
        [t for t in expected if start <= t < start + 10**8]


def test_split_recording_without_metadata_is_read_in_split_order(tmp_path, capsys):
    q = trajectory(12 * 50)
    folder = tmp_path / 'rec'
    folder.mkdir()
    for split in range(12):  # rec_0 .. rec_11: rec_10 must come after rec_9, not rec_1
        rows = range(split * 50, split * 50 + 50)
        stamps = [T0 + k * 10_000_000 for k in rows]
        write_bag(tmp_path / f'part{split}', [(s, js_bytes(NAMES, q[k], s))
                                              for s, k in zip(stamps, rows)])
        next((tmp_path / f'part{split}').glob('*.mcap')).rename(folder / f'rec_{split}.mcap')
    rc, out, err = run_process(capsys, folder, tmp_path / 'out', '--quiet')
    assert rc == 0 and 'rec_0.mcap, rec_1.mcap, rec_2.mcap' in err and '600 written' in out
    assert 'rec_9.mcap, rec_10.mcap, rec_11.mcap' in err
    poses = read_topic(tmp_path / 'out', '/dq_fk_node/pose/eeCarry_seg6')
    assert [stamp_ns(m.header) for _, m in poses] == [T0 + k * 10_000_000 for k in range(600)]


def test_damaged_sqlite3_bag_is_a_clear_error_and_writes_nothing(tmp_path, capsys):
    valid_bag(tmp_path / 'in', n=3000, storage='sqlite3')
    db = next((tmp_path / 'in').glob('*.db3'))
    data = db.read_bytes()
    db.write_bytes(data[:100] + b'\xff' * (len(data) - 100))
    rc, _, err = run_process(capsys, tmp_path / 'in', tmp_path / 'out', '--quiet')
    assert rc == 2 and 'not a readable rosbag2' in err and len(err.splitlines()) == 1
    assert not (tmp_path / 'out').exists()


def messages_outside(mcap_bytes, lo, hi):
    """Log times of the messages of every chunk that has no byte in ``[lo, hi)`` (mcap)."""
    reader = make_reader(io.BytesIO(mcap_bytes))
    chunks = reader.get_summary().chunk_indexes
    hit = [c for c in chunks if c.chunk_start_offset < hi and
           lo < c.chunk_start_offset + c.chunk_length]
    assert hit and len(hit) < len(chunks), 'the damage must hit some chunks, not all'
    lost = {(c.message_start_time, c.message_end_time) for c in hit}
    return [m.log_time for _, _, m in reader.iter_messages(log_time_order=True)
            if not any(a <= m.log_time <= b for a, b in lost)]


def test_a_damaged_chunk_is_skipped_and_every_intact_chunk_processed(tmp_path, capsys):
    q, stamps = valid_bag(tmp_path / 'in', n=30000)
    mcap = next((tmp_path / 'in').glob('*.mcap'))
    data = bytearray(mcap.read_bytes())
    middle = len(data) // 2
    expected = messages_outside(bytes(data), middle, middle + 2000)
    data[middle:middle + 2000] = b'\xff' * 2000
    mcap.write_bytes(bytes(data))
    rc, out, err = run_process(capsys, tmp_path / 'in', tmp_path / 'out', '--quiet')
    assert rc == 1 and 'is damaged' in err and 'skipped' in err
    assert len(err.strip().splitlines()) == 2  # how it was read, what was damaged
    lost = len(q) - len(expected)
    assert f'/joint_states: {lost})' in err  # the damage line counts what it skipped
    poses = read_topic(tmp_path / 'out', '/dq_fk_node/pose/eeCarry_seg6')
    assert [stamp_ns(m.header) for _, m in poses] == expected
    assert expected[-1] == stamps[-1]  # the chunks after the damage are there


@pytest.mark.integration
def test_replay_into_the_node_gives_the_offline_poses(tmp_path, processes, ros_domain_id):
    """The node's poses and twists of a replayed bag are the ones the bag tool wrote."""
    q, stamps = valid_bag(tmp_path / 'in', n=200, velocities=True)
    process_bag(tmp_path / 'in', tmp_path / 'out', RL15, progress=False)
    offline = {stamp_ns(m.header): m for _, m in
               read_topic(tmp_path / 'out', '/dq_fk_node/pose/eeCarry_seg6')}
    offline_twists = {stamp_ns(m.header): m for _, m in
                      read_topic(tmp_path / 'out', '/dq_fk_node/twist/eeCarry_seg6')}
    assert len(offline_twists) == 200
    listener = Harness()
    try:
        poses = listener.listen(PoseStamped, '/dq_fk_node/pose/eeCarry_seg6', 1000)
        twists = listener.listen(TwistStamped, '/dq_fk_node/twist/eeCarry_seg6', 1000)
        diagnostics = listener.listen(DiagnosticArray, '/diagnostics')
        # a reliable input: a bag replay should lose nothing (best effort, the default,
        # may drop messages under load)
        processes.start(executable('dq_fk_node') + ['--ros-args', '--log-level', 'warn', '-p',
                                                    'joint_states_reliability:=reliable'])
        assert listener.spin_until(lambda: listener.probe.count_publishers(
            '/dq_fk_node/pose/eeCarry_seg6') >= 1, timeout_s=20)
        player = processes.start(executable('dq_fk_bag') + ['play', str(tmp_path / 'in'),
                                                            '--rate', '2', '--quiet',
                                                            '--wait-for-subscribers', '1'])
        player.wait(timeout=60)

        def published():
            status = diagnostics[-1].status[0].values if diagnostics else []
            return {v.key: v.value for v in status}.get('updates_published')
        # the node took every message; the listener may miss a few while its own
        # subscription is still being matched, so it only has to see most of them
        assert listener.spin_until(lambda: published() == '200' and len(poses) >= 150 and
                                   len(twists) >= 150, timeout_s=30), (published(), len(poses))
    finally:
        listener.close()
    assert player.returncode == 0
    for msg in poses:
        ref = offline[stamp_ns(msg.header)]
        np.testing.assert_allclose(htf.pose_matrix(msg.pose), htf.pose_matrix(ref.pose),
                                   atol=1e-12)
    for msg in twists:   # the same twist topic: the same values to the bit
        ref = offline_twists[stamp_ns(msg.header)]
        values = [getattr(getattr(m.twist, part), axis) for m in (msg, ref)
                  for part in ('linear', 'angular') for axis in 'xyz']
        assert msg.header.frame_id == ref.header.frame_id and values[:6] == values[6:]


def test_play_with_clock_and_bad_rate(tmp_path, capsys):
    valid_bag(tmp_path / 'in', n=3)
    for args, words in [(('--rate', '0'), '--rate must be a positive number'),
                        (('--rate', 'nan'), "argument --rate: 'nan' is not a finite number"),
                        (('--start', '1e12'), '--start 1e+12 s is after the end of'),
                        (('--start', '-1'), '--start must be 0 or more seconds'),
                        (('--duration', '0'), '--duration must be a positive number')]:
        try:
            rc, _, err = run_cli(capsys, 'play', tmp_path / 'in', *args)
        except SystemExit as exc:  # argparse refuses the value itself
            rc, err = exc.code, capsys.readouterr().err
        assert rc == 2 and words in err, err


@pytest.mark.integration
def test_play_publishes_recorded_messages_and_clock(tmp_path, processes, ros_domain_id):
    from rosgraph_msgs.msg import Clock
    from sensor_msgs.msg import JointState as RosJointState
    _, stamps = valid_bag(tmp_path / 'in', n=50)
    listener = Harness()
    try:
        joints = listener.listen(RosJointState, '/joint_states', 1000)
        clock = listener.listen(Clock, '/clock', 1000)
        player = processes.start(executable('dq_fk_bag') + [
            'play', str(tmp_path / 'in'), '--clock', '--rate', '5', '--start', '0.1',
            '--quiet', '--wait-for-subscribers', '1'])

        def clock_ns():
            return [c.clock.sec * 10**9 + c.clock.nanosec for c in clock]
        assert listener.spin_until(lambda: len(joints) == 40 and clock_ns()[-1:] == stamps[-1:],
                                   timeout_s=30), (len(joints), clock_ns()[-1:])
        player.wait(timeout=30)
    finally:
        listener.close()
    assert player.returncode == 0
    assert [stamp_ns(m.header) for m in joints] == stamps[10:]  # --start 0.1 s skips 10
    assert clock_ns() == stamps[10:]


def test_a_robot_with_no_moving_joint_gets_tf_static_and_poses_only(tmp_path):
    """A sensor rig's URDF (fixed joints only) was refused; rsp publishes /tf_static alone."""
    rig = tmp_path / 'rig.urdf'
    rig.write_text('<robot name="rig"><link name="mount"/><link name="camera"/>'
                   '<joint name="j" type="fixed"><parent link="mount"/><child link="camera"/>'
                   '<origin xyz="0.1 0.2 0.3"/></joint></robot>')
    write_bag(tmp_path / 'in', [(T0 + k, js_bytes(['wheel'], [0.0], T0 + k)) for k in range(4)])
    summary = process_bag(tmp_path / 'in', tmp_path / 'out', str(rig), progress=False,
                          frame_prefix='r1/')
    assert summary.written == 4 and summary.error is None
    static = read_topic(tmp_path / 'out', '/tf_static')
    edges = {(t.header.frame_id, t.child_frame_id): t.transform.translation
             for t in static[0][1].transforms}
    camera = edges[('r1/mount', 'r1/camera')]
    assert (camera.x, camera.y, camera.z) == (0.1, 0.2, 0.3)
    assert read_topic(tmp_path / 'out', '/tf') == []
    poses = read_topic(tmp_path / 'out', '/dq_fk_node/pose/camera')
    assert len(poses) == 4 and poses[0][1].header.frame_id == 'r1/mount'


def test_the_example_bag_holds_the_sweep_it_says(tmp_path, capsys):
    from rosbags.rosbag2 import Reader
    from rosbags.typesys import get_typestore, Stores
    from dq_fk_ros.cli.dq_fk_bag import main
    from dq_fk_ros.description.loading import load_robot
    from dq_fk_ros.ros.fake_joint_publisher import JointMotion
    out = tmp_path / 'example'
    assert main(['example', str(out), '--robot', 'panda', '--seconds', '1', '--rate', '50']) == 0
    assert capsys.readouterr().out == f'{out}: 50 JointState messages of panda on /joint_states\n'
    assert sorted(os.listdir(out)) == ['example.mcap', 'metadata.yaml']  # MCAP, as Jazzy's
    model = load_robot('panda').model
    motion = JointMotion('sine', model.limits)
    store = get_typestore(Stores.ROS2_JAZZY)
    with Reader(out) as reader:
        (conn,) = reader.connections
        assert (conn.topic, conn.msgtype) == ('/joint_states', 'sensor_msgs/msg/JointState')
        msgs = [(t, store.deserialize_cdr(raw, conn.msgtype))
                for _, t, raw in reader.messages()]
    assert len(msgs) == 50
    for k, (t, msg) in enumerate(msgs):
        assert list(msg.name) == list(model.joint_names)
        assert t == msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec
        assert t - msgs[0][0] == k * 20_000_000
        positions, velocities = motion.sample(k / 50)
        np.testing.assert_allclose(msg.position, positions, rtol=0, atol=1e-15)
        np.testing.assert_allclose(msg.velocity, velocities, rtol=0, atol=1e-15)
    assert main(['example', str(out)]) == 2  # never over an existing path


def test_a_tree_bag_writes_what_the_node_publishes_message_for_message(tmp_path):
    """
    One output plan: each /tf of the bag is the node's own /tf bytes for that state.

    The dual arm's branches appear one by one (torso, then left arm, then everything), under
    a frame prefix; the node's serializer (FrameBytes of FrameMessages, shown the optional
    joints the merger has seen, as DqFkNode does) gives each expected message, and the
    node's /tf_static is the bag's, byte for byte.
    """
    from dq_fk_ros.ros.conversions import FrameBytes, FrameMessages, ns_to_stamp
    model = load_robot_description(shipped_robot_path('dual_arm'))
    groups = [['waist'], ['waist', 'left_shoulder_pitch', 'left_elbow', 'left_wrist_roll'],
              list(model.joint_names)]
    rng = np.random.default_rng(7)
    messages = []
    for k in range(30):
        names = groups[min(k // 10, 2)]
        stamp = T0 + k * 10_000_000
        messages.append((stamp, names, rng.uniform(-0.5, 0.5, len(names)) * 0.05 + 0.01))
    write_bag(tmp_path / 'in', [(s, js_bytes(n, v, s)) for s, n, v in messages])
    process_bag(tmp_path / 'in', tmp_path / 'out', model, frame_prefix='r1/', progress=False)

    merger = JointStateMerger(model.joint_names, model.limits, 'warn',
                              required=len(model.required_joints))
    expected = []
    for stamp, names, values in messages:
        result = merger.merge(names, values, [], stamp)
        assert result.status == PUBLISH
        out = FrameBytes(FrameMessages(model, 'r1/', merger.seen_optional))
        if out.sends_tf:
            sec, nanosec = divmod(stamp, 10**9)
            expected.append(bytes(out.tf(sec, nanosec, model.transform_poses(result.q),
                                         result.q)))
    with Reader(tmp_path / 'out') as reader:
        by_topic = {}
        for conn, _, raw in reader.messages():
            by_topic.setdefault(conn.topic, []).append(bytes(raw))
    # the same messages, frames in the same order; values to rounding (the bag computes
    # a chunk at once, the node one state at a time: test_chains.py holds those equal)
    assert len(expected) == 30 and len(by_topic['/tf']) == 30
    for got, want in zip(by_topic['/tf'], expected):
        got, want = (TS.deserialize_cdr(m, 'tf2_msgs/msg/TFMessage').transforms
                     for m in (got, want))
        assert [(t.header.frame_id, t.child_frame_id, t.header.stamp.sec,
                 t.header.stamp.nanosec) for t in got] == \
            [(t.header.frame_id, t.child_frame_id, t.header.stamp.sec,
              t.header.stamp.nanosec) for t in want]
        assert np.allclose([htf.transform_matrix(t.transform) for t in got],
                           [htf.transform_matrix(t.transform) for t in want], atol=1e-12)
    assert [len(TS.deserialize_cdr(m, 'tf2_msgs/msg/TFMessage').transforms)
            for m in by_topic['/tf'][::10]] == [1, 1 + 3, 1 + 3 + 3 + 2]  # moving joints
    # /tf_static: the node's message objects, every field equal
    written = TS.deserialize_cdr(by_topic['/tf_static'][0], 'tf2_msgs/msg/TFMessage')
    static = FrameMessages(model, 'r1/').static_tf(ns_to_stamp(T0))

    def fields(transforms):
        return [(t.header.stamp.sec, t.header.stamp.nanosec, t.header.frame_id,
                 t.child_frame_id, htf.transform_matrix(t.transform).tolist())
                for t in transforms]
    assert len(by_topic['/tf_static']) == 1
    assert fields(written.transforms) == fields(static.transforms)


def test_a_floating_base_urdf_bag_has_robot_state_publishers_tf_and_poses_in_its_root(
        tmp_path, capsys):
    """solo12 under a floating joint: the bag's /tf is the node's, RSP's edges, no DH frame."""
    from test_rsp_parity import rsp_edges, with_joint
    from vendor_urdfs import robots_dir
    text = with_joint(open(os.path.join(robots_dir(), 'solo_description/robots/solo12.urdf'))
                      .read(), 'floating', 'root')
    urdf = tmp_path / 'solo12_floating.urdf'
    urdf.write_text(text)
    moving, fixed = rsp_edges(text)
    joints = sorted({c.replace('_UPPER_LEG', '_HFE').replace('_LOWER_LEG', '_KFE')
                     .replace('_SHOULDER', '_HAA') for _, c in moving})
    assert len(joints) == 12  # solo12's joints are named after their child links
    rng = np.random.default_rng(3)
    states = [(T0 + k * 10_000_000, rng.uniform(-0.5, 0.5, 12)) for k in range(20)]
    write_bag(tmp_path / 'in', [(s, js_bytes(joints, v, s)) for s, v in states])
    for dh_frames in (False, True):
        out = tmp_path / f'out_{dh_frames}'
        rc, _, err = run_process(capsys, str(tmp_path / 'in'), str(out), '--robot', str(urdf),
                                 '--poses', 'all', *(['--dh-frames'] if dh_frames else []))
        assert rc == 0, err
        tf = read_topic(out, '/tf')
        static = read_topic(out, '/tf_static')
        edges = {(t.header.frame_id, t.child_frame_id) for t in tf[-1][1].transforms}
        static_edges = {(t.header.frame_id, t.child_frame_id) for t in static[0][1].transforms}
        if not dh_frames:
            assert len(tf) == 20 and edges == moving and static_edges == fixed
        else:  # the DH frames beside the links, never the floating edge
            assert edges > moving and static_edges > fixed
            assert not any(c == 'base_link' for _, c in edges | static_edges)
        with Reader(out) as reader:
            poses = {c.topic for c in reader.connections if '/pose/' in c.topic}
        links = {f'/dq_fk_node/pose/{c}' for _, c in moving | fixed}
        assert (poses == links) if not dh_frames else (poses > links)
        foot = read_topic(out, '/dq_fk_node/pose/FL_FOOT')[-1][1]
        assert foot.header.frame_id == 'base_link'  # the root of its TF tree
        transforms = tf[-1][1].transforms + static[0][1].transforms
        np.testing.assert_allclose(htf.pose_matrix(foot.pose),
                                   htf.compose(transforms, 'base_link', 'FL_FOOT'), atol=1e-12)


def test_by_default_the_output_is_tf_and_the_end_effector_pose_and_says_its_size(
        tmp_path, capsys):
    valid_bag(tmp_path / 'in', n=200)
    sizes = {}
    for poses in ('end', 'all'):
        out = tmp_path / poses
        extra = ['--poses', 'all'] if poses == 'all' else []   # 'end': nothing given
        rc, text, err = run_process(capsys, tmp_path / 'in', out, '--quiet',
                                    *extra)
        assert rc == 0, err
        with Reader(out) as reader:
            topics = {c.topic for c in reader.connections}
        sizes[poses] = sum(f.stat().st_size for f in out.rglob('*') if f.is_file())
        # the closing line says how big the output is, as the disk has it
        shown = f'{sizes[poses] / 1e6:.1f} MB' if sizes[poses] >= 100_000 else \
            f'{sizes[poses] / 1e3:.1f} kB'
        assert f'written to {out} ({shown})' in text, text
        if poses == 'end':
            assert topics == {'/tf', '/tf_static', '/robot_description',
                              '/dq_fk_node/pose/eeCarry_seg6'}
        else:
            assert topics >= {f'/dq_fk_node/pose/{f}' for f in MODEL.frame_names}
    assert sizes['all'] > 1.5 * sizes['end']   # 7 frames; an iCub's 8.7 GB from 332 MB


@pytest.mark.parametrize('storage', ['mcap', 'sqlite3'])
def test_joint_states_with_velocities_give_the_twist_topics(tmp_path, storage):
    """The twist topics appear with the first velocities, as many messages as JointStates."""
    q, stamps = valid_bag(tmp_path / 'in', n=120, velocities=True)
    summary = process_bag(tmp_path / 'in', tmp_path / 'out', RL15, storage=storage,
                          progress=False, chunk=50)
    assert summary.written == 120
    twists = read_topic(tmp_path / 'out', '/dq_fk_node/twist/eeCarry_seg6')
    assert [t for t, _ in twists] == stamps
    assert {m.header.frame_id for _, m in twists} == {'world'}
    process_bag(tmp_path / 'in', tmp_path / 'none', RL15, storage=storage, progress=False,
                poses='none')
    with Reader(tmp_path / 'none') as reader:
        assert not [c for c in reader.connections if '/twist/' in c.topic]


def test_play_output_topic_that_is_no_topic_name_is_one_line(tmp_path, capsys):
    from dq_fk_ros.cli import dq_fk_bag
    bag = tmp_path / 'joints'
    assert dq_fk_bag.main(['example', str(bag), '--seconds', '0.2', '--rate', '10']) == 0
    capsys.readouterr()
    for name in ('bad name!', 'x\ny', 'a' * 5000):
        assert dq_fk_bag.main(['play', str(bag), '--output-topic', name, '--quiet']) == 2
        err = capsys.readouterr().err
        assert err.count('\n') == 1 and 'not a ROS topic name' in err, err
        assert 'Traceback' not in err and len(err) < 300
