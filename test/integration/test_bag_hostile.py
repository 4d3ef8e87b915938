"""
dq_fk_bag against misuse and damage.

Refused outputs, user errors, empty results, ROS 1 bags, and fuzzed MCAP damage (every
intact chunk must be processed).
"""

import io
import os
import sys

from dq_fk_ros.cli.dq_fk_bag import main as bag_main
from dq_fk_ros.storage import mcap_writer as bag_writer
from dq_fk_ros.storage.rosbags_writer import RosbagsWriter
from hypothesis import given, HealthCheck, settings, strategies as st
from mcap.reader import make_reader
import numpy as np
import pytest
from test_bag import js_bytes, MODEL, NAMES, RL15, T0, trajectory, TS, valid_bag

JS_TYPE = 'sensor_msgs/msg/JointState'


def run(capsys, *argv):
    rc = bag_main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return rc, out, err


def one_line_error(rc, err, code=2):
    assert rc == code, (rc, err)
    assert err.startswith('dq_fk_bag: ') and err.count('\n') == 1, err
    assert 'Traceback' not in err


# -- outputs that would destroy the input or go where nobody meant ------------------------
def test_outputs_that_are_contain_or_lie_in_the_input_are_refused(
        tmp_path, capsys, monkeypatch):
    valid_bag(tmp_path / 'in', n=20)
    before = sorted((p.name, p.stat().st_size) for p in (tmp_path / 'in').iterdir())
    mcap = next((tmp_path / 'in').glob('*.mcap'))
    (tmp_path / 'link').symlink_to(tmp_path / 'in')
    cases = [
        (('in', 'in', '--overwrite'), 'would overwrite the input bag'),
        (('in', 'link', '--overwrite'), 'would overwrite the input bag'),  # via a symlink
        (('in', 'in/sub', '--overwrite'), 'would overwrite the input bag'),
        (('in/' + mcap.name, 'in', '--overwrite'), 'contains the input bag'),
        (('in', '.', '--overwrite'), 'contains the input bag'),
        (('in', 'out', '--csv', 'in/metadata.yaml', '--overwrite'),
         '--csv in/metadata.yaml would overwrite the input bag'),
        (('in', 'out', '--csv', 'out/ee.csv'), '--csv out/ee.csv would be inside OUT_BAG'),
    ]
    monkeypatch.chdir(tmp_path)
    for args, words in cases:
        rc, out, err = run(capsys, 'process', *args, '--robot', 'rl15', '--quiet')
        one_line_error(rc, err)
        assert words in err, err
    assert sorted((p.name, p.stat().st_size) for p in (tmp_path / 'in').iterdir()) == before
    assert not (tmp_path / 'out').exists()


def test_symlinks_existing_files_and_directories_as_outputs(tmp_path, capsys, monkeypatch):
    valid_bag(tmp_path / 'in', n=20)
    target = tmp_path / 'precious.txt'
    target.write_text('keep me')
    (tmp_path / 'csv_link').symlink_to(target)
    (tmp_path / 'bag_link').symlink_to(tmp_path / 'elsewhere')     # dangling
    (tmp_path / 'old.csv').write_text('old')
    (tmp_path / 'adir').mkdir()
    cases = [
        (('out1', '--csv', 'csv_link', '--overwrite'), 'is a symbolic link; not following'),
        (('out2', '--csv', 'csv_link'), 'is a symbolic link; not following'),
        (('bag_link',), 'is a symbolic link; not following'),
        (('out3', '--csv', 'old.csv'), 'old.csv exists; use --overwrite'),
        (('out4', '--csv', 'adir', '--overwrite'), '--csv adir is a directory'),
        (('out5', '--csv', 'no/such/dir/ee.csv'), 'does not exist'),
        (('no/such/dir/out',), 'does not exist'),
    ]
    monkeypatch.chdir(tmp_path)
    for args, words in cases:
        rc, _, err = run(capsys, 'process', 'in', *args, '--robot', 'rl15', '--quiet')
        one_line_error(rc, err)
        assert words in err, err
        assert not any((tmp_path / f'out{k}').exists() for k in range(1, 6))  # nothing left
    assert target.read_text() == 'keep me' and (tmp_path / 'old.csv').read_text() == 'old'
    assert not (tmp_path / 'elsewhere').exists()


def test_user_errors_are_one_line_and_exit_2(tmp_path, capsys):
    valid_bag(tmp_path / 'in', n=20)
    text = open(RL15, encoding='utf-8').read()
    huge, deep = tmp_path / 'huge.yaml', tmp_path / 'deep.yaml'
    huge.write_text(text.replace('a: 200', 'a: ' + '9' * 400, 1))
    deep.write_text(text.replace('a: 200', 'a: ' + '[' * 5000 + ']' * 5000, 1))
    for robot, words in [(huge, "field 'a' must be a finite number"),
                         (deep, 'nested too deeply'), ('no_such_robot', 'no shipped robot')]:
        rc, _, err = run(capsys, 'process', tmp_path / 'in', tmp_path / 'out', '--robot',
                         robot, '--quiet')
        one_line_error(rc, err)
        assert words in err
    with pytest.raises(SystemExit) as info:  # a bag does not say which robot recorded it
        bag_main(['process', str(tmp_path / 'in'), str(tmp_path / 'out')])
    assert info.value.code == 2 and 'the following arguments are required: --robot' in \
        capsys.readouterr().err
    assert not (tmp_path / 'out').exists()


# -- nothing usable is not a success -------------------------------------------------------
def test_a_bag_of_another_robot_is_an_error_that_names_both_joint_sets(tmp_path, capsys):
    ur = ['shoulder_pan_joint', 'shoulder_lift_joint', 'elbow_joint', 'wrist_1_joint',
          'wrist_2_joint', 'wrist_3_joint']
    stamps = [T0 + k * 10**7 for k in range(30)]
    from test_bag import write_bag
    write_bag(tmp_path / 'in', [(s, js_bytes(ur, np.zeros(6), s)) for s in stamps])
    rc, out, err = run(capsys, 'process', tmp_path / 'in', tmp_path / 'out', '--robot', 'rl15',
                       '--csv', tmp_path / 'ee.csv', '--quiet')
    assert rc == 1 and '30 JointState messages, 0 written' in out
    assert err.count('\n') == 1 and 'no JointState message could be used (nothing written)' \
        in err
    assert '/joint_states has 30 messages and names joints shoulder_pan_joint' in err
    assert 'robot rl15' in err and 'needs joint_1, joint_2' in err
    assert not (tmp_path / 'out').exists() and not (tmp_path / 'ee.csv').exists()
    rc, out, _ = run(capsys, 'process', tmp_path / 'in', tmp_path / 'out2', '--robot', 'ur5e',
                     '--quiet')
    assert rc == 0 and '30 written' in out


def test_an_empty_joint_state_topic_is_an_error(tmp_path, capsys):
    from test_bag import write_bag
    write_bag(tmp_path / 'in', [])
    rc, out, err = run(capsys, 'process', tmp_path / 'in', tmp_path / 'out', '--robot', 'rl15',
                       '--quiet')
    assert rc == 1 and 'has 0 messages and names no joints' in err
    assert not (tmp_path / 'out').exists()


# -- ROS 1 bags ------------------------------------------------------------------------------
def write_ros1_bag(path, n):
    from rosbags.rosbag1 import Writer as Ros1Writer
    from rosbags.typesys import get_typestore, Stores
    ts1 = get_typestore(Stores.ROS1_NOETIC)
    js, header, time = (ts1.types[JS_TYPE], ts1.types['std_msgs/msg/Header'],
                        ts1.types['builtin_interfaces/msg/Time'])
    q = trajectory(n)
    stamps = [T0 + k * 10**7 for k in range(n)]
    with Ros1Writer(path) as writer:
        conn = writer.add_connection('/joint_states', JS_TYPE, typestore=ts1)
        chat = writer.add_connection('/chatter', 'std_msgs/msg/String', typestore=ts1)
        for k, s in enumerate(stamps):
            msg = js(header=header(seq=k, stamp=time(sec=s // 10**9, nanosec=s % 10**9),
                                   frame_id='base'),
                     name=NAMES, position=q[k], velocity=np.zeros(0), effort=np.zeros(0))
            writer.write(conn, s, ts1.serialize_ros1(msg, JS_TYPE))
            writer.write(chat, s, ts1.serialize_ros1(
                ts1.types['std_msgs/msg/String'](data='x'), 'std_msgs/msg/String'))
    return q, stamps


def test_a_ros1_bag_is_processed_directly(tmp_path, capsys):
    """ROS 1 .bag files were refused ("Unrecognized storage format"); rosbags reads them."""
    q, stamps = write_ros1_bag(tmp_path / 'old.bag', 50)
    rc, out, err = run(capsys, 'process', tmp_path / 'old.bag', tmp_path / 'out', '--robot',
                       'rl15', '--csv', tmp_path / 'ee.csv', '--quiet')
    assert rc == 0 and '50 JointState messages, 50 written' in out, (out, err)
    assert 'a ROS 1 bag; its JointState messages are converted to ROS 2' in err
    rows = np.loadtxt(tmp_path / 'ee.csv', delimiter=',', skiprows=1, dtype=object)
    assert [int(s) for s in rows[:, 0]] == stamps
    np.testing.assert_allclose(rows[:, 1:4].astype(float),
                               [MODEL.chain.forward(r).translation for r in q], atol=1e-12)
    rc, _, err = run(capsys, 'process', tmp_path / 'old.bag', tmp_path / 'out2', '--robot',
                     'rl15', '--copy-input', '--quiet')
    one_line_error(rc, err)
    assert 'rosbags-convert --src' in err


# -- MCAP damage, fuzzed ---------------------------------------------------------------------
@pytest.fixture(scope='module')
def small_mcap(tmp_path_factory):
    """Write a rosbag2 MCAP of 240 RL15 joint states in ~12 chunks; return its layout."""
    folder = tmp_path_factory.mktemp('fuzz') / 'in'
    old = bag_writer.CHUNK_BYTES
    bag_writer.CHUNK_BYTES = 4000
    try:
        q = trajectory(240)
        stamps = [T0 + k * 10**7 for k in range(240)]
        writer = RosbagsWriter(folder, 'mcap')
        writer.open()
        conn = writer.add_connection('/joint_states', JS_TYPE, typestore=TS)
        for s, row in zip(stamps, q):
            writer.write(conn, s, js_bytes(NAMES, row, s))
        writer.close()
    finally:
        bag_writer.CHUNK_BYTES = old
    mcap = next(folder.glob('*.mcap'))
    data = mcap.read_bytes()
    chunks = []   # (start, end, stamps of its messages), from mcap's own chunk index
    reader = make_reader(io.BytesIO(data))
    times = [m.log_time for _, _, m in reader.iter_messages()]
    for index in reader.get_summary().chunk_indexes:
        start, end = index.chunk_start_offset, index.chunk_start_offset + index.chunk_length
        chunks.append((start, end, [t for t in times if index.message_start_time <= t
                                    <= index.message_end_time]))
    assert len(chunks) >= 10 and sum(len(c[2]) for c in chunks) == 240
    definitions = [(s, e) for s, e in record_spans(data) if data[s] in (0x03, 0x04)]
    assert len(definitions) == 2  # the schema and the channel of /joint_states
    summary_start = int.from_bytes(data[-8 - 20:-8 - 12], 'little')
    return folder, mcap, data, chunks, definitions, summary_start


def record_spans(data):
    """(start, end) of every top-level record of the pristine file's data section."""
    spans, pos = [], 8
    while pos < len(data) - 8:
        length = int.from_bytes(data[pos + 1:pos + 9], 'little')
        spans.append((pos, pos + 9 + length))
        if data[pos] == 0x0F:  # data end
            break
        pos += 9 + length
    return spans


@settings(suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(flips=st.lists(st.tuples(st.floats(0, 1, exclude_max=True), st.integers(1, 255)),
                      min_size=0, max_size=3),
       cut=st.one_of(st.none(), st.floats(0.05, 1.0)))
def test_byte_damage_and_truncation_keep_every_intact_chunk(
        small_mcap, tmp_path_factory, capsys, flips, cut):
    """Exit 0 or 1 with one line per problem, and every message of every intact chunk."""
    folder, mcap, data, chunks, definitions, summary_start = small_mcap
    damaged = bytearray(data)
    hit = []
    for where, xor in flips:
        at = int(where * len(data))
        damaged[at] ^= xor
        hit.append(at)
    size = len(data) if cut is None else max(int(cut * len(data)), 1)
    damaged = bytes(damaged[:size])
    work = tmp_path_factory.mktemp('case')
    (work / 'in').mkdir()
    (work / 'in' / 'metadata.yaml').write_bytes((folder / 'metadata.yaml').read_bytes())
    (work / 'in' / mcap.name).write_bytes(damaged)
    rc, out, err = run(capsys, 'process', work / 'in', work / 'out', '--robot', 'rl15',
                       '--csv', work / 'ee.csv', '--csv-only', '--quiet')
    assert rc in (0, 1), err
    assert all(line.startswith('dq_fk_bag: ') for line in err.splitlines()), err
    assert len(err.splitlines()) <= 2, err  # how the bag was read, what was damaged
    # /joint_states is known if its schema and channel records survive in the data section,
    # or the summary (which repeats them) does
    definitions_intact = all(not any(s <= h < e for h in hit) and e <= size
                             for s, e in definitions) or \
        (size == len(data) and not any(h >= summary_start for h in hit))
    expected = [t for start, end, times in chunks
                if end <= size and not any(start <= h < end for h in hit) for t in times]
    if not definitions_intact or not expected:
        return
    got = [int(line.split(',')[0]) for line in (work / 'ee.csv').read_text().splitlines()[1:]]
    assert set(expected) <= set(got), (len(expected), len(got), err)
    if not hit and cut is None:
        assert rc == 0 and len(got) == 240 and err == ''


def play_and_listen(processes, folder, expected, prefix=()):
    """
    Play ``folder`` at 10x (``prefix`` before the command); return (rc, output, stamps).

    The messages are taken as bytes (their stamps read after): a subscriber that
    deserializes each in Python falls behind the player on a loaded machine, and a reliable
    writer's history of 100 then drops what it was not acknowledged (lost to the test, not
    to the player).
    """
    from ros_harness import Harness
    from sensor_msgs.msg import JointState as RosJointState
    from rclpy.serialization import deserialize_message
    from test_bag import stamp_ns
    from dq_fk_ros.ros.executables import executable
    listener = Harness()
    raws = []
    try:
        listener.probe.create_subscription(RosJointState, '/joint_states', raws.append, 20000,
                                           raw=True)
        player = processes.start(list(prefix) + executable('dq_fk_bag') + [
            'play', str(folder), '--rate', '10', '--quiet', '--wait-for-subscribers', '1'])
        listener.spin_until(lambda: player.poll() is not None and
                            len(raws) >= len(expected), timeout_s=90)
        player.wait(timeout=30)
        output = player.stdout.read()
    finally:
        listener.close()
    stamps = []
    for raw in raws:   # (a message rclpy cannot read is skipped, as its subscription does)
        try:
            stamps.append(stamp_ns(deserialize_message(raw, RosJointState).header))
        except Exception:
            pass
    return player.returncode, output, stamps


@pytest.mark.integration
def test_play_goes_on_past_a_damaged_chunk(tmp_path, processes, ros_domain_id):
    """Rosbags stops inside the damaged chunk; play goes on with the intact ones (exit 1)."""
    from test_bag import messages_outside
    _, stamps = valid_bag(tmp_path / 'in', n=12000)
    mcap = next((tmp_path / 'in').glob('*.mcap'))
    data = bytearray(mcap.read_bytes())
    at = len(data) // 3  # (rosbags writes no chunk CRCs: damage the structure itself)
    expected = messages_outside(bytes(data), at, at + 2000)
    data[at:at + 2000] = b'\xff' * 2000
    mcap.write_bytes(bytes(data))
    rc, output, got = play_and_listen(processes, tmp_path / 'in', expected)
    assert rc == 1, output
    assert 'is damaged' in output and 'published ' in output
    # every message of every intact chunk, in order, none twice (the damaged chunk's
    # messages before the damage may come too: rosbags read them before it stopped)
    assert set(expected) <= set(got) and got == sorted(set(got)) and set(got) <= set(stamps)
    assert len(got) < len(stamps) and got[-1] == stamps[-1]


# -- outputs that are the input under another name (symlinks, hard links) -----------------
def test_an_input_that_links_into_the_output_is_not_destroyed(tmp_path, capsys):
    """The .mcap of the input was a symlink into OUT: --overwrite deleted the recording."""
    valid_bag(tmp_path / 'real', n=20)
    mcap = next((tmp_path / 'real').glob('*.mcap'))
    (tmp_path / 'out').mkdir()
    recording = tmp_path / 'out' / 'recording.mcap'
    mcap.rename(recording)
    (tmp_path / 'in').mkdir()
    (tmp_path / 'in' / 'metadata.yaml').write_bytes((tmp_path / 'real' / 'metadata.yaml')
                                                    .read_bytes())
    (tmp_path / 'in' / mcap.name).symlink_to(recording)
    before = recording.read_bytes()
    rc, out, err = run(capsys, 'process', tmp_path / 'in', tmp_path / 'out', '--robot', 'rl15',
                       '--overwrite', '--quiet')
    one_line_error(rc, err)
    assert 'a file the input bag' in err and recording.read_bytes() == before


def test_a_csv_that_is_a_hard_link_of_the_input_is_refused(tmp_path, capsys):
    valid_bag(tmp_path / 'in', n=20)
    mcap = next((tmp_path / 'in').glob('*.mcap'))
    os.link(mcap, tmp_path / 'ee.csv')
    (tmp_path / 'out_dir').mkdir()
    os.link(mcap, tmp_path / 'out_dir' / 'old.mcap')
    before = mcap.read_bytes()
    for args in (('--csv', tmp_path / 'ee.csv', '--overwrite'),
                 ('--csv', tmp_path / 'ee.csv', '--csv-only', '--overwrite')):
        rc, _, err = run(capsys, 'process', tmp_path / 'in', tmp_path / 'out', '--robot',
                         'rl15', '--quiet', *args)
        one_line_error(rc, err)
        assert 'hard link to a file of the input' in err
    rc, _, err = run(capsys, 'process', tmp_path / 'in', tmp_path / 'out_dir', '--robot',
                     'rl15', '--quiet', '--overwrite')
    one_line_error(rc, err)
    assert mcap.read_bytes() == before


# -- decompression bombs ----------------------------------------------------------------------
def zstd_rle_bomb(size):
    """Return a zstd frame of RLE blocks (4 bytes each) expanding to ``size`` zero bytes."""
    block = 128 * 1024
    frame = bytearray(b'\x28\xb5\x2f\xfd\x00\x38')   # no content size, 128 KiB window
    count = size // block
    for k in range(count):
        last = 1 if k == count - 1 else 0
        frame += ((block << 3) | (1 << 1) | last).to_bytes(3, 'little') + b'\x00'
    return bytes(frame)


def lz4_bomb(size):
    """Return an lz4 frame expanding to ``size`` zero bytes (about size / 250 of them)."""
    import lz4.frame
    packer = lz4.frame.LZ4FrameCompressor()
    return packer.begin() + b''.join(packer.compress(bytes(1 << 20))
                                     for _ in range(size >> 20)) + packer.flush()


def chunk_record(data, compression, declared, start, end):
    body = (start.to_bytes(8, 'little') + end.to_bytes(8, 'little') +
            declared.to_bytes(8, 'little') + b'\x00' * 4 +
            len(compression).to_bytes(4, 'little') + compression.encode() +
            len(data).to_bytes(8, 'little') + data)
    return b'\x06' + len(body).to_bytes(8, 'little') + body


@pytest.fixture(scope='module')
def bomb_bags(tmp_path_factory, small_mcap):
    """Bare .mcap files: the small bag with a bomb chunk put between two of its chunks."""
    folder, mcap, data, chunks, definitions, summary_start = small_mcap
    out = tmp_path_factory.mktemp('bombs')
    at = chunks[len(chunks) // 2][0]           # before the middle chunk
    start, end = chunks[0][2][0], chunks[-1][2][-1]
    lz4_data = lz4_bomb(1 << 30)
    bombs = {
        'zstd 4 GiB, declared': chunk_record(zstd_rle_bomb(4 << 30), 'zstd', 4 << 30, start,
                                             end),
        'zstd 4 GiB, declared 1 KiB': chunk_record(zstd_rle_bomb(4 << 30), 'zstd', 1024,
                                                   start, end),
        'zstd, declared 100 GB': chunk_record(zstd_rle_bomb(1 << 20), 'zstd', 100 * 10**9,
                                              start, end),
        'lz4 1 GiB, declared 1 KiB': chunk_record(lz4_data, 'lz4', 1024, start, end),
    }
    files = {}
    for name, record in bombs.items():
        path = out / (name.replace(' ', '_').replace(',', '') + '.mcap')
        path.write_bytes(data[:at] + record + data[at:])
        files[name] = path
    return files, chunks


def rosbags_bomb_bag(folder, small_mcap, compression):
    """
    Write a rosbag2 folder rosbags opens (metadata, summary intact), its third chunk a bomb.

    Written with mcap's own writer, its compressor swapped for one chunk: the chunk index
    declares the real size, the data expands to 4 GiB (zstd) or 1 GiB (lz4). Returns the
    log times of the messages in intact chunks.
    """
    import mcap.writer as mcap_writer
    from mcap.writer import CompressionType, Writer
    source_folder, mcap, data, _, _, _ = small_mcap
    folder.mkdir()
    (folder / 'metadata.yaml').write_bytes((source_folder / 'metadata.yaml').read_bytes())
    reader = make_reader(io.BytesIO(data))
    summary = reader.get_summary()
    module = mcap_writer.zstandard if compression == 'zstd' else mcap_writer.lz4.frame
    real, count = module.compress, [0]
    bomb = zstd_rle_bomb(4 << 30) if compression == 'zstd' else lz4_bomb(1 << 30)

    def compress(chunk):
        count[0] += 1
        return bomb if count[0] == 3 else real(chunk)
    module.compress = compress
    try:
        with open(folder / mcap.name, 'wb') as stream:
            writer = Writer(stream, chunk_size=4000, compression=CompressionType.ZSTD if
                            compression == 'zstd' else CompressionType.LZ4)
            writer.start(profile='ros2', library='test')
            ids = {}
            for schema in summary.schemas.values():
                ids[schema.id] = writer.register_schema(schema.name, schema.encoding,
                                                        schema.data)
            channels = {}
            for channel in summary.channels.values():
                channels[channel.id] = writer.register_channel(
                    channel.topic, channel.message_encoding, ids[channel.schema_id],
                    channel.metadata)
            for _, channel, message in reader.iter_messages():
                writer.add_message(channels[channel.id], message.log_time, message.data,
                                   message.publish_time)
            writer.finish()
    finally:
        module.compress = real
    written = make_reader(io.BytesIO((folder / mcap.name).read_bytes())).get_summary()
    lost = sorted(written.chunk_indexes, key=lambda c: c.chunk_start_offset)[2]
    assert lost.compression == compression
    return [m.log_time for _, _, m in make_reader(io.BytesIO(data)).iter_messages()
            if not lost.message_start_time <= m.log_time <= lost.message_end_time]


def process_under_a_memory_cap(path, out):
    """Run dq_fk_bag process in a child limited to 1 GiB of address space."""
    import subprocess
    code = ('import resource, sys\n'
            'resource.setrlimit(resource.RLIMIT_AS, (1 << 30, 1 << 30))\n'
            'from dq_fk_ros.cli.dq_fk_bag import main\n'
            f'sys.exit(main(["process", {str(path)!r}, {str(out / "bag")!r}, "--robot",'
            f' "rl15", "--csv", {str(out / "ee.csv")!r}, "--csv-only", "--quiet"]))\n')
    proc = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True,
                          timeout=120)
    assert proc.returncode in (0, 1), proc.stderr[-2000:]
    assert 'Traceback' not in proc.stderr and 'MemoryError' not in proc.stderr, proc.stderr
    return [int(line.split(',')[0]) for line in (out / 'ee.csv').read_text().splitlines()[1:]]


@pytest.mark.parametrize('compression', ['zstd', 'lz4'])
def test_a_bomb_rosbags_opens_is_skipped_within_a_memory_cap(small_mcap, tmp_path, compression):
    """Rosbags decompressed a chunk whole: a 131 KB chunk expanding to 4 GiB took 8.3 GB."""
    expected = rosbags_bomb_bag(tmp_path / 'in', small_mcap, compression)
    from rosbags.rosbag2 import Reader
    with Reader(tmp_path / 'in') as reader:   # rosbags itself opens this bag
        assert len(reader.connections) == 1
    got = process_under_a_memory_cap(tmp_path / 'in', tmp_path)
    assert sorted(got) == sorted(expected) and len(expected) < 240


@pytest.mark.parametrize('name', ['zstd 4 GiB, declared', 'zstd 4 GiB, declared 1 KiB',
                                  'zstd, declared 100 GB', 'lz4 1 GiB, declared 1 KiB'])
def test_decompression_bombs_in_a_damaged_recording_are_skipped(bomb_bags, tmp_path, name):
    """The record-by-record reader: 100 GB declared raised MemoryError and lost the rest."""
    files, chunks = bomb_bags
    got = process_under_a_memory_cap(files[name], tmp_path)
    expected = [t for _, _, times in chunks for t in times]
    assert sorted(got) == sorted(expected), (len(got), len(expected))


# -- ROS 1 bags whose index is damaged ------------------------------------------------------
@pytest.mark.parametrize('damage', ['cut', 'bytes', 'index_pos 2**62', 'index_pos 0'])
def test_a_ros1_bag_with_a_damaged_index_is_read_chunk_by_chunk(tmp_path, capsys, damage):
    """All 12 000 messages were lost to a damaged index although every chunk was intact."""
    import struct
    q, stamps = write_ros1_bag(tmp_path / 'old.bag', 12_000)
    data = (tmp_path / 'old.bag').read_bytes()
    at = data.index(b'index_pos=') + len(b'index_pos=')
    index_pos = struct.unpack_from('<Q', data, at)[0]
    assert index_pos > 0
    if damage == 'cut':
        data = data[:index_pos + 30]
    elif damage == 'bytes':
        flipped = bytes(b ^ 0x5A for b in data[index_pos + 8:index_pos + 400])
        data = data[:index_pos + 8] + flipped + data[index_pos + 400:]
    else:
        value = 2**62 if damage == 'index_pos 2**62' else 0
        data = data[:at] + struct.pack('<Q', value) + data[at + 8:]
    (tmp_path / 'damaged.bag').write_bytes(data)
    rc, out, err = run(capsys, 'process', tmp_path / 'damaged.bag', tmp_path / 'out', '--robot',
                       'rl15', '--csv', tmp_path / 'ee.csv', '--quiet')
    assert rc in (0, 1) and '12000 JointState messages, 12000 written' in out, (out, err)
    assert 'read chunk by chunk' in err and 'Traceback' not in err
    rows = np.loadtxt(tmp_path / 'ee.csv', delimiter=',', skiprows=1, dtype=object)
    assert [int(s) for s in rows[:, 0]] == stamps
    np.testing.assert_allclose(rows[:, 1:4].astype(float),
                               [MODEL.chain.forward(r).translation for r in q], atol=1e-12)


def test_a_ros1_chunk_is_decompressed_within_the_limit():
    import bz2
    from dq_fk_ros.storage.decompress import ChunkRefused, decompress_chunk
    bomb = bz2.compress(bytes(64 << 20))
    with pytest.raises(ChunkRefused, match='more bytes than the 1024 it declares'):
        decompress_chunk(bomb, 'bz2', 1024)
    with pytest.raises(ChunkRefused, match='chunks over 256 MiB are skipped'):
        decompress_chunk(bomb, 'bz2', 10**11)
    assert decompress_chunk(bz2.compress(b'abc'), 'bz2', 3) == b'abc'


@pytest.mark.parametrize('compression', ['zstd', 'lz4'])
def test_rosbags_decompresses_through_the_bound_once_it_opens_a_bag(tmp_path, compression):
    """
    Under a 1 GiB cap rosbags' own decompressor raised MemoryError on a 4 GiB chunk.

    The folder is opened through rosbags (the reference reader, as for every folder the
    reader without rosbags leaves to it; that one imports no rosbag2 module of rosbags:
    test_rosbag2_metadata.py).
    """
    import subprocess
    valid_bag(tmp_path / 'in', n=5)
    bomb = zstd_rle_bomb(4 << 30) if compression == 'zstd' else lz4_bomb(1 << 30)
    (tmp_path / 'bomb').write_bytes(bomb)
    code = ('import resource\n'
            'resource.setrlimit(resource.RLIMIT_AS, (1 << 30, 1 << 30))\n'
            'from dq_fk_ros.storage.reading import open_reader\n'
            'from rosbags.rosbag2 import storage_mcap\n'
            f'open_reader({str(tmp_path / "in")!r}, reference=True).close()\n'
            f'data = open({str(tmp_path / "bomb")!r}, "rb").read()\n'
            'try:\n'
            f'    storage_mcap.decompress(data, {compression!r}, 4096, 0)\n'
            'except Exception as exc:\n'
            '    print(type(exc).__name__, exc)\n')
    proc = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True,
                          timeout=120)
    assert proc.stdout.startswith('ChunkRefused it decompresses to more bytes than the '
                                  '4096'), (proc.stdout, proc.stderr[-1000:])


def test_the_csv_is_closed_when_processing_fails(tmp_path, monkeypatch):
    """The --csv file handle stayed open when an exception went through process_bag."""
    import builtins
    from dq_fk_ros.bag import process as process_module
    valid_bag(tmp_path / 'in', n=20)
    opened = []

    def tracking_open(*args, **kwargs):
        opened.append(builtins.open(*args, **kwargs))
        return opened[-1]

    def broken(*args, **kwargs):
        raise RuntimeError('broken on purpose')
    monkeypatch.setattr(process_module, 'open', tracking_open, raising=False)
    monkeypatch.setattr(process_module.JointStateMerger, 'merge_many', broken)
    with pytest.raises(RuntimeError, match='broken on purpose'):
        process_module.process_bag(tmp_path / 'in', tmp_path / 'out', 'rl15',
                                   csv_path=tmp_path / 'ee.csv', csv_only=True, progress=False)
    assert len(opened) == 1 and opened[0].closed


def test_play_skips_a_bomb_within_a_memory_cap(small_mcap, tmp_path, processes,
                                               ros_domain_id):
    """Play decompressed a bomb chunk whole, as process did."""
    expected = rosbags_bomb_bag(tmp_path / 'in', small_mcap, 'zstd')
    rc, output, got = play_and_listen(processes, tmp_path / 'in', expected,
                                      ['prlimit', f'--as={1 << 30}'])
    assert rc == 1 and 'MemoryError' not in output, output
    assert 'it decompresses to more bytes than' in output, output
    assert set(expected) <= set(got), (len(expected), len(got), output)
