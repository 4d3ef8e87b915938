"""
A rosbag2 folder's ``metadata.yaml`` and QoS profiles, read and written without rosbags.

What rosbags' ``Reader`` and ``Writer`` (``rosbags.rosbag2``) do with them, with PyYAML's C
loader and dumper instead of ruamel (importing ``rosbags.rosbag2`` costs ~40 ms of every
``dq_fk_bag process``, its YAML dumps ~15 ms more). The two are held equal by
test_rosbag2_metadata.py: the same connections and times as rosbags' ``Reader`` from the same
folders, the same QoS profiles from the same text, the same ``metadata.yaml`` text as
rosbags' ``Writer`` (byte for byte).

:func:`read_information` reads only what it is sure of: a folder it does not take (a
storage other than MCAP, whole-file or per-message compression, a field of another type than
rosbag2 writes, a file larger than :data:`MAX_METADATA_BYTES`) raises :class:`NotTaken`, and
the caller opens the folder with rosbags, which says what is wrong, as before.
"""

import os

from dq_fk_ros.description.yaml_bounds import check_yaml_text, YamlTooLarge
from dq_fk_ros.errors import BagError
from rosbags.interfaces import (
    Connection, ConnectionExtRosbag2, MessageDefinition, MessageDefinitionFormat, Qos,
    QosDurability, QosHistory, QosLiveliness, QosReliability, QosTime)
import yaml

MAX_METADATA_BYTES = 16 << 20   # a larger metadata.yaml is refused (rosbag2's: kilobytes)
MAX_TOPICS = 10_000             # topics a metadata.yaml may list (rosbag2's list tens)
MAX_QOS_PROFILES = 64           # offered QoS profiles a topic may list (rosbag2's: one)
QOS_DEPTH = 8                   # nesting of QoS text (rosbag2's: 3, a list of maps of maps)
QOS_NODES = 64                  # nodes a QoS profile may have (rosbag2's: 25)
VERSION = 9                     # the version written (rosbags' latest; Jazzy's rosbag2)
_LOADER = getattr(yaml, 'CSafeLoader', yaml.SafeLoader)
_DUMPER = getattr(yaml, 'CSafeDumper', yaml.SafeDumper)


class NotTaken(Exception):
    """A folder (or field) this module leaves to rosbags; the message says why."""


def read_information(folder: str) -> dict:
    """
    Return the ``rosbag2_bagfile_information`` mapping of ``<folder>/metadata.yaml``.

    Raises :class:`NotTaken` where rosbags should read it (see the module's docstring), and
    :class:`~dq_fk_ros.errors.BagError` for one larger than rosbag2 writes (:func:`check_bounds`).
    """
    path = os.path.join(folder, 'metadata.yaml')
    try:
        with open(path, 'rb') as f:
            text = f.read(MAX_METADATA_BYTES + 1)
    except OSError as exc:
        raise NotTaken(f'{path}: {exc.strerror}') from None
    if len(text) > MAX_METADATA_BYTES:
        raise BagError(f'{path}: larger than {MAX_METADATA_BYTES >> 20} MiB; a rosbag2 '
                       f'metadata.yaml is read up to that')
    try:
        check_yaml_text(text, path)
    except YamlTooLarge as exc:   # before any loader: ours and rosbags' recurse in C
        raise BagError(str(exc)) from None
    try:
        document = yaml.load(text, Loader=_LOADER)
    except (yaml.YAMLError, ValueError, RecursionError) as exc:
        raise NotTaken(f'{path}: {type(exc).__name__}') from None
    info = document.get('rosbag2_bagfile_information') if isinstance(document, dict) else None
    if not isinstance(info, dict):
        raise NotTaken(f'{path}: no rosbag2_bagfile_information')
    check_bounds(info, folder)
    return info


def check_bounds(info: dict, folder: str) -> None:
    """
    Refuse a metadata mapping listing more topics or QoS profiles than a bag is read with.

    Raises :class:`~dq_fk_ros.errors.BagError` (one line): at most :data:`MAX_TOPICS` topics
    and :data:`MAX_QOS_PROFILES` profiles a topic (YAML aliases make a small file list
    millions; rosbags would make a connection of each), QoS text within the bounds of
    :func:`check_qos_text`. :func:`read_information` calls it:
    a folder is read once here, before either reader.
    """
    topics = info.get('topics_with_message_count')
    if isinstance(topics, list) and len(topics) > MAX_TOPICS:
        raise BagError(f'{folder}: metadata.yaml lists {len(topics)} topics; a bag is read '
                       f'with at most {MAX_TOPICS}')
    for entry in topics if isinstance(topics, list) else ():
        topic = entry.get('topic_metadata') if isinstance(entry, dict) else None
        profiles = topic.get('offered_qos_profiles') if isinstance(topic, dict) else None
        if isinstance(profiles, list) and len(profiles) > MAX_QOS_PROFILES:
            raise BagError(f'{folder}: metadata.yaml lists {len(profiles)} QoS profiles; a '
                           f'bag is read with at most {MAX_QOS_PROFILES} a topic')
        if isinstance(profiles, str):   # (version 8: YAML text in the YAML)
            try:
                check_qos_text(profiles)
            except YamlTooLarge as exc:
                raise BagError(f'{folder}: metadata.yaml: {exc}') from None


def _field(mapping, key, kind, default=None):
    """Return ``mapping[key]`` if it is exactly a ``kind``, else raise :class:`NotTaken`."""
    value = mapping.get(key, default) if isinstance(mapping, dict) else None
    if type(value) is not kind:
        raise NotTaken(f'{key}: a {type(value).__name__}, not a {kind.__name__}')
    return value


def mcap_folder(folder: str, info: dict) -> tuple:
    """
    Return ``(MCAP paths, connections, start_time, end_time)`` of a folder, as rosbags' Reader.

    Connections are rosbags ``Connection`` tuples as its ``Reader`` makes them from the
    metadata (ids from 1 in the metadata's order, ``msgcount`` the metadata's, ``owner``
    None), their message definitions still empty (the MCAP files' schemas give them: see
    :func:`with_definitions`). Times in ns, ``end_time`` past the last message. Raises
    :class:`NotTaken` for anything but an uncompressed-folder MCAP bag of version <= 9 with
    every file present and every topic CDR.
    """
    version = _field(info, 'version', int)
    if not 1 <= version <= VERSION:
        raise NotTaken(f'version {version}')
    if _field(info, 'storage_identifier', str) != 'mcap':
        raise NotTaken('not MCAP')
    if _field(info, 'compression_mode', str, '').lower() not in ('', 'none'):
        raise NotTaken('compressed files or messages')
    names = _field(info, 'relative_file_paths', list)
    paths = []
    for name in names:
        if type(name) is not str:
            raise NotTaken('a file path that is not text')
        # rosbags: the file's name in the folder, whatever directories the metadata gives
        path = os.path.join(folder, os.path.basename(name.replace('\\', '/')))
        if not path.endswith('.mcap') or not os.path.isfile(path):
            raise NotTaken(f'{name}: not an MCAP file of the folder')
        paths.append(path)
    connections = []
    for i, entry in enumerate(_field(info, 'topics_with_message_count', list)):
        topic = _field(entry, 'topic_metadata', dict)
        if _field(topic, 'serialization_format', str) != 'cdr':
            raise NotTaken('a topic that is not CDR')
        try:
            qos = parse_qos(topic.get('offered_qos_profiles', []))
        except (KeyError, TypeError, ValueError, AttributeError, yaml.YAMLError) as exc:
            raise NotTaken(f'offered_qos_profiles: {type(exc).__name__}') from None
        connections.append(Connection(
            id=i + 1, topic=_field(topic, 'name', str), msgtype=_field(topic, 'type', str),
            msgdef=MessageDefinition(MessageDefinitionFormat.NONE, ''),
            digest=_field(topic, 'type_description_hash', str, ''),
            msgcount=_field(entry, 'message_count', int),
            ext=ConnectionExtRosbag2(serialization_format='cdr', offered_qos_profiles=qos),
            owner=None))
    duration = _field(_field(info, 'duration', dict), 'nanoseconds', int)
    start = _field(_field(info, 'starting_time', dict), 'nanoseconds_since_epoch', int)
    if _field(info, 'message_count', int):
        return paths, connections, start, start + duration + 1
    return paths, connections, 2 ** 63 - 1, 0


def with_definitions(connections: list, schemas_of_files: list) -> list:
    """
    Return ``connections`` with the message definitions of the MCAP files' schemas.

    As rosbags' Reader: a connection takes the definition of the first channel, file by file
    in order, whose schema names its type and has one. ``schemas_of_files``: per file, its
    channels' ``(msgtype, encoding, definition text)`` in the summary's order. Raises
    :class:`NotTaken` for a schema encoding rosbags does not know.
    """
    formats = {'ros2msg': MessageDefinitionFormat.MSG, 'ros2idl': MessageDefinitionFormat.IDL,
               'omgidl': MessageDefinitionFormat.IDL, '': MessageDefinitionFormat.NONE}
    found = {}
    for schemas in schemas_of_files:
        for msgtype, encoding, text in schemas:
            if encoding not in formats:
                raise NotTaken(f'schema encoding {encoding!r}')
            if formats[encoding] != MessageDefinitionFormat.NONE:
                found.setdefault(msgtype, MessageDefinition(formats[encoding], text))
    return [c._replace(msgdef=found[c.msgtype]) if c.msgtype in found else c
            for c in connections]


def _enum(kind, item, key):
    """Read one QoS policy as rosbags does: its number, or its name in any case."""
    if key not in item:
        return kind(kind.UNKNOWN)
    value = item[key]   # (neither a number nor text: AttributeError, as in rosbags)
    try:
        return kind(value) if isinstance(value, int) else kind.__members__[value.upper()]
    except (KeyError, ValueError):
        return kind(kind.UNKNOWN)


def parse_qos(profiles) -> list:
    """
    Return rosbags ``Qos`` tuples of ``offered_qos_profiles`` (a list, or YAML text: v8).

    rosbags' ``parse_qos``: an unknown policy reads as UNKNOWN; a missing depth, time or
    flag raises KeyError. Text nested deeper than a profile list or standing for more than
    :data:`MAX_QOS_PROFILES` profiles' nodes (aliases expanded) raises
    :class:`~dq_fk_ros.description.yaml_bounds.YamlTooLarge` before it is loaded.
    """
    if not profiles:
        return []
    if isinstance(profiles, str):
        check_qos_text(profiles)
        items = yaml.load(profiles, Loader=_LOADER)
    else:
        items = profiles
    if not isinstance(items, list) or len(items) > MAX_QOS_PROFILES:
        raise YamlTooLarge(f'offered_qos_profiles: not a list of at most {MAX_QOS_PROFILES} '
                           f'profiles')
    out = []
    for item in items:
        times = [QosTime(item[k]['sec'], item[k]['nsec'])
                 for k in ('deadline', 'lifespan', 'liveliness_lease_duration')]
        out.append(Qos(_enum(QosHistory, item, 'history'), item['depth'],
                       _enum(QosReliability, item, 'reliability'),
                       _enum(QosDurability, item, 'durability'), times[0], times[1],
                       _enum(QosLiveliness, item, 'liveliness'), times[2],
                       item['avoid_ros_namespace_conventions']))
    return out


def check_qos_text(text: str) -> None:
    """
    Raise :class:`~dq_fk_ros.description.yaml_bounds.YamlTooLarge` for QoS text over the bounds.

    At most :data:`QOS_DEPTH` deep and :data:`MAX_QOS_PROFILES` profiles of
    :data:`QOS_NODES` nodes, aliases expanded (a 594 KiB text of aliases stood for millions
    of profiles).
    """
    check_yaml_text(text, 'offered_qos_profiles', max_depth=QOS_DEPTH,
                    max_nodes=MAX_QOS_PROFILES * QOS_NODES)


def dump_qos(qos) -> list:
    """Return QoS profiles as metadata version 9 writes them (rosbags' ``dump_qos_v9``)."""
    def time(t):
        return {'sec': t.sec, 'nsec': t.nsec}
    return [{'history': x.history.name.lower(), 'depth': x.depth,
             'reliability': x.reliability.name.lower(),
             'durability': x.durability.name.lower(), 'deadline': time(x.deadline),
             'lifespan': time(x.lifespan), 'liveliness': x.liveliness.name.lower(),
             'liveliness_lease_duration': time(x.liveliness_lease_duration),
             'avoid_ros_namespace_conventions': x.avoid_ros_namespace_conventions}
            for x in qos]


def to_yaml(value) -> str:
    """Return YAML text as rosbags writes it (block style, keys sorted)."""
    return yaml.dump(value, Dumper=_DUMPER, default_flow_style=False)


def information(connections, counts, start_ns, end_ns, file_name) -> dict:
    """
    Return the ``rosbag2_bagfile_information`` of a version 9 MCAP bag of one file.

    As rosbags' ``Writer.close``: ``counts`` connection id -> messages written, ``start_ns``
    and ``end_ns`` the first and last log times (``2**63 - 1`` and 0 when nothing was).
    """
    duration = max(0, end_ns - start_ns)
    count = sum(counts.values())
    return {
        'version': VERSION, 'storage_identifier': 'mcap', 'relative_file_paths': [file_name],
        'duration': {'nanoseconds': duration},
        'starting_time': {'nanoseconds_since_epoch': start_ns}, 'message_count': count,
        'topics_with_message_count': [
            {'topic_metadata': {'name': c.topic, 'type': c.msgtype,
                                'serialization_format': c.ext.serialization_format,
                                'offered_qos_profiles': dump_qos(c.ext.offered_qos_profiles),
                                'type_description_hash': c.digest},
             'message_count': counts[c.id]} for c in connections],
        'compression_format': '', 'compression_mode': '',
        'files': [{'path': file_name, 'starting_time': {'nanoseconds_since_epoch': start_ns},
                   'duration': {'nanoseconds': duration}, 'message_count': count}],
        # rosbags' Writer's value: the bags stay byte for byte what they were
        'custom_data': None, 'ros_distro': 'rosbags'}


__all__ = ['check_bounds', 'check_qos_text', 'dump_qos', 'information', 'MAX_METADATA_BYTES',
           'MAX_QOS_PROFILES', 'MAX_TOPICS', 'mcap_folder', 'NotTaken', 'parse_qos',
           'read_information', 'to_yaml', 'with_definitions']
