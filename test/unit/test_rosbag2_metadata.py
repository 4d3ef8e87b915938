"""
A rosbag2 MCAP folder opened without rosbags gives what rosbags' Reader gives; else rosbags.

``open_mcap_folder`` (``dq_fk_bag process``'s start) against rosbags' ``Reader`` on the same
folders: every field of every connection (definitions, hashes, QoS profiles, counts), the
times and the messages; the QoS parser against rosbags' ``parse_qos`` on generated
profiles; and the folders it leaves to rosbags. The command itself imports none of
rosbags' rosbag2 modules, ruamel or the ``mcap`` library.
"""

import shutil
import subprocess
import sys

from dq_fk_ros.description.loading import load_robot
from dq_fk_ros.errors import BagError
from dq_fk_ros.storage.mcap_chunks import McapChunkReader
from dq_fk_ros.storage.mcap_folder import McapFolder, open_mcap_folder
from dq_fk_ros.storage.reading import open_reader
from dq_fk_ros.storage.rosbag2_metadata import (
    MAX_METADATA_BYTES, MAX_QOS_PROFILES, MAX_TOPICS, mcap_folder, NotTaken, parse_qos,
    read_information)
from hypothesis import given, settings, strategies as st
import numpy as np
import pytest
from rosbags.interfaces import (
    Qos, QosDurability, QosHistory, QosLiveliness, QosReliability, QosTime)
from rosbags.rosbag2 import Reader, StoragePlugin, Writer
from rosbags.rosbag2.metadata import parse_qos as rosbags_parse_qos
from rosbags.typesys import get_typestore, Stores
import yaml

TS = get_typestore(Stores.ROS2_JAZZY)
JOINTS = list(load_robot('rl15').model.joint_names)
T0 = 1_700_000_000_000_000_000
NEVER = QosTime(sec=0, nsec=0)
PROFILE_TEXT = {'history': 'keep_last', 'depth': 1, 'reliability': 'reliable',
                'durability': 'volatile', 'deadline': {'sec': 0, 'nsec': 0},
                'lifespan': {'sec': 0, 'nsec': 0}, 'liveliness': 'automatic',
                'liveliness_lease_duration': {'sec': 0, 'nsec': 0},
                'avoid_ros_namespace_conventions': False}
PROFILES = [Qos(QosHistory.KEEP_LAST, 7, QosReliability.BEST_EFFORT, QosDurability.VOLATILE,
                QosTime(1, 2), NEVER, QosLiveliness.MANUAL_BY_TOPIC, QosTime(3, 4), True)]


def write_bag(path, version=9, n=50, storage=StoragePlugin.MCAP):
    """Three topics (two of one type, one with QoS profiles) written by rosbags' Writer."""
    string = 'std_msgs/msg/String'
    with Writer(path, version=version, storage_plugin=storage) as writer:
        chat = writer.add_connection('/chatter', string, typestore=TS)
        quiet = writer.add_connection('/quiet', string, typestore=TS,
                                      offered_qos_profiles=PROFILES)
        joints = writer.add_connection('/joint_states', 'sensor_msgs/msg/JointState',
                                       typestore=TS)
        state = TS.serialize_cdr(TS.types['sensor_msgs/msg/JointState'](
            header=TS.types['std_msgs/msg/Header'](
                stamp=TS.types['builtin_interfaces/msg/Time'](sec=1, nanosec=2), frame_id=''),
            name=JOINTS, position=np.zeros(len(JOINTS)), velocity=np.array([], float),
            effort=np.array([], float)), 'sensor_msgs/msg/JointState')
        for i in range(n):
            t = T0 + i * 1_000_000
            writer.write(chat, t, bytes(TS.serialize_cdr(TS.types[string](data=f'{i}'),
                                                         string)))
            writer.write(joints, t, bytes(state))
        writer.write(quiet, T0 + n * 1_000_000, bytes(TS.serialize_cdr(
            TS.types[string](data='last'), string)))
    return path


def split_bag(tmp_path):
    """One folder of two MCAP files (rosbag2's splits), its metadata naming both."""
    first, second = write_bag(tmp_path / 'one'), write_bag(tmp_path / 'two', n=20)
    folder = tmp_path / 'split'
    folder.mkdir()
    shutil.copy(first / 'one.mcap', folder / 'split_0.mcap')
    shutil.copy(second / 'two.mcap', folder / 'split_1.mcap')
    info = yaml.safe_load((first / 'metadata.yaml').read_text())
    inner = info['rosbag2_bagfile_information']
    inner['relative_file_paths'] = ['split_0.mcap', 'split_1.mcap']
    (folder / 'metadata.yaml').write_text(yaml.safe_dump(info))
    return folder


def rosbags_reading(path):
    with Reader(path) as reader:
        conns = [c._replace(owner=None) for c in reader.connections]
        return conns, reader.start_time, reader.end_time, [
            (c.id, t, bytes(raw)) for c, t, raw in reader.messages()]


def our_reading(path):
    reader = open_mcap_folder(str(path))
    assert isinstance(reader, McapChunkReader)
    assert isinstance(reader._reference, McapFolder)
    try:
        return list(reader.connections), reader.start_time, reader.end_time, [
            (c.id, t, raw) for c, t, raw in reader.messages()]
    finally:
        reader.close()


@pytest.mark.parametrize('case', ['v9', 'v8', 'split', 'empty'])
def test_a_folder_opens_as_rosbags_reader_opens_it(tmp_path, case):
    path = {'v9': lambda: write_bag(tmp_path / 'bag'),
            'v8': lambda: write_bag(tmp_path / 'bag', version=8),   # QoS profiles as text
            'split': lambda: split_bag(tmp_path),
            'empty': lambda: write_bag(tmp_path / 'bag', n=0)}[case]()
    ours, reference = our_reading(path), rosbags_reading(path)
    assert ours == reference
    conns = ours[0]
    assert [c.topic for c in conns] == ['/chatter', '/quiet', '/joint_states']
    assert conns[1].ext.offered_qos_profiles == PROFILES
    assert conns[0].msgdef.data  # the schema's text, not empty
    assert all(c.digest.startswith('RIHS01_') for c in conns)


def test_open_reader_takes_the_folder_without_rosbags(tmp_path):
    reader = open_reader(write_bag(tmp_path / 'bag'))
    try:
        assert isinstance(reader, McapChunkReader) and isinstance(reader._reference, McapFolder)
    finally:
        reader.close()


def change_metadata(path, change):
    text = (path / 'metadata.yaml').read_text()
    info = yaml.safe_load(text)
    change(info['rosbag2_bagfile_information'])
    (path / 'metadata.yaml').write_text(yaml.safe_dump(info))


def _topic(info):
    return info['topics_with_message_count'][0]['topic_metadata']


LEFT_TO_ROSBAGS = {
    'version 10': lambda i: i.update(version=10),
    'sqlite3': lambda i: i.update(storage_identifier='sqlite3'),
    'file compression': lambda i: i.update(compression_mode='FILE', compression_format='zstd'),
    'a missing file': lambda i: i.update(relative_file_paths=['gone.mcap']),
    'not cdr': lambda i: _topic(i).update(serialization_format='json'),
    'a count as text': lambda i: i['topics_with_message_count'][0].update(message_count='9'),
    'a bad QoS profile': lambda i: _topic(i).update(offered_qos_profiles=[{'depth': 1}]),
    'no duration': lambda i: i.pop('duration'),
    'a name as a number': lambda i: _topic(i).update(name=7),
}


@pytest.mark.parametrize('case', sorted(LEFT_TO_ROSBAGS))
def test_what_is_not_sure_is_left_to_rosbags(tmp_path, case):
    path = write_bag(tmp_path / 'bag')
    change_metadata(path, LEFT_TO_ROSBAGS[case])
    assert open_mcap_folder(str(path)) is None
    with pytest.raises(NotTaken):
        mcap_folder(str(path), read_information(str(path)))
    if case in ('version 10', 'a missing file'):   # rosbags refuses it too: its reading
        return
    reader = open_reader(path)
    try:  # rosbags read it (or not) as before: never our folder reader
        assert not isinstance(getattr(reader, '_reference', None), McapFolder)
    finally:
        reader.close()


def test_a_broken_metadata_file_is_left_to_rosbags(tmp_path):
    path = write_bag(tmp_path / 'bag')
    for text in (b'[unclosed', b'- a list', b'rosbag2_bagfile_information: 3', b'\xff\xfe'):
        (path / 'metadata.yaml').write_bytes(text)
        with pytest.raises(NotTaken):
            read_information(str(path))
    (path / 'metadata.yaml').unlink()
    assert open_mcap_folder(str(path)) is None


@pytest.mark.parametrize('reference', [False, True])
def test_metadata_larger_than_rosbag2_writes_is_refused_before_rosbags_reads_it(tmp_path,
                                                                                reference):
    """One line, by either reader: a rosbags Reader would make a connection of each topic."""
    path = write_bag(tmp_path / 'bag')
    text = (path / 'metadata.yaml').read_text()
    cases = {
        # YAML aliases: 10 001 topics in 110 KB
        'lists 10001 topics': lambda i: i.update(
            topics_with_message_count=i['topics_with_message_count'][:1] * (MAX_TOPICS + 1)),
        'lists 65 QoS profiles': lambda i: _topic(i).update(
            offered_qos_profiles=[PROFILE_TEXT] * (MAX_QOS_PROFILES + 1)),
    }
    for message, change in cases.items():
        (path / 'metadata.yaml').write_text(text)
        change_metadata(path, change)
        assert (path / 'metadata.yaml').stat().st_size < 200_000   # (aliases: ~11 bytes each)
        with pytest.raises(BagError, match=f'^{path}: metadata.yaml {message}; a bag is '):
            open_reader(path, reference=reference)
    (path / 'metadata.yaml').write_bytes(b'#' * (MAX_METADATA_BYTES + 1))
    with pytest.raises(BagError, match='larger than 16 MiB'):
        open_reader(path, reference=reference)


NAMES = st.sampled_from(['keep_last', 'KEEP_ALL', 'Reliable', 'best_effort', 'volatile',
                         'transient_local', 'automatic', 'manual_by_topic', 'system_default',
                         'unknown', 'nonsense', ''])
POLICY = st.one_of(NAMES, st.integers(-2, 6))
TIME = st.fixed_dictionaries({'sec': st.integers(0, 2 ** 31), 'nsec': st.integers(0, 10 ** 9)})
PROFILE = st.fixed_dictionaries(
    {'depth': st.integers(0, 1000), 'deadline': TIME, 'lifespan': TIME,
     'liveliness_lease_duration': TIME, 'avoid_ros_namespace_conventions': st.booleans()},
    optional={'history': POLICY, 'reliability': POLICY, 'durability': POLICY,
              'liveliness': POLICY})


@settings(max_examples=200, deadline=None)
@given(profiles=st.lists(PROFILE, max_size=3), as_text=st.booleans())
def test_qos_profiles_parse_as_rosbags_parses_them(profiles, as_text):
    given_ = yaml.safe_dump(profiles) if as_text and profiles else profiles
    assert parse_qos(given_) == rosbags_parse_qos(given_)


def test_the_command_imports_no_rosbag2_module_of_rosbags_nor_ruamel_nor_mcap(tmp_path):
    path = write_bag(tmp_path / 'bag')
    script = (
        'import sys\n'
        'from dq_fk_ros.cli.dq_fk_bag import main\n'
        f"code = main(['process', {str(path)!r}, {str(tmp_path / 'out')!r}, '--robot', "
        "'rl15', '--quiet'])\n"
        "print(code, sorted(m for m in sys.modules if m.startswith(('rosbags.rosbag2', "
        "'ruamel', 'mcap', 'importlib.metadata'))))\n")
    done = subprocess.run([sys.executable, '-c', script], capture_output=True, text=True,
                          timeout=120)
    assert done.stdout.split('\n')[-2] == '0 []', done.stdout + done.stderr
    assert (tmp_path / 'out' / 'metadata.yaml').is_file()
