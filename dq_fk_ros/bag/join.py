"""
Joining the windows of one bag, each written as a bag of its own, into one rosbag2 bag.

The windows' storage files become the files of one split bag, in window order (as ``ros2 bag
record --max-bag-size`` writes them): ``<name>_0.mcap``, ``<name>_1.mcap``... and one
``metadata.yaml`` adds their message counts up. The files are moved, not copied: joining
costs a rename per window. Readers read a split bag's files in order, so the joined bag
reads as the one-bag command's output, message for message.
"""

import os

from dq_fk_ros.errors import BagError
from dq_fk_ros.storage.rosbag2_metadata import NotTaken, read_information
import yaml

INFO = 'rosbag2_bagfile_information'


def read_metadata(folder) -> dict:
    """
    Return the ``rosbag2_bagfile_information`` of a bag folder's metadata.yaml.

    Read as any bag's (:func:`~dq_fk_ros.storage.rosbag2_metadata.read_information`: at most
    16 MiB, bounded lists); a file that is not such a mapping raises
    :class:`~dq_fk_ros.errors.BagError` in one line. An earlier output's file is found
    damaged this way, and its bag redone (``Manifest.complete``).
    """
    try:
        return read_information(folder)
    except NotTaken as exc:
        raise BagError(f'{exc}: not a rosbag2 metadata.yaml') from None


def join_bags(parts, out_dir) -> dict:
    """
    Move the storage files of the bag folders ``parts`` into a new bag ``out_dir``, in order.

    Parts without messages are left out. ``out_dir`` must not exist; the parts are emptied.
    Returns the joined metadata (``rosbag2_bagfile_information``).
    """
    infos = [(part, read_metadata(part)) for part in parts]
    infos = [(part, info) for part, info in infos if info['message_count']] or infos[:1]
    if not infos:
        raise BagError(f'{out_dir}: nothing to join')
    os.mkdir(out_dir)
    name = os.path.basename(os.path.normpath(out_dir))
    joined = dict(infos[0][1])
    files, paths, topics = [], [], {}
    start, end = None, None
    for k, (part, info) in enumerate(infos):
        for f in info['files']:
            ext = os.path.splitext(f['path'])[1]
            new = f'{name}_{len(paths)}{ext}'
            os.rename(os.path.join(part, f['path']), os.path.join(out_dir, new))
            paths.append(new)
            files.append(dict(f, path=new))
        if info['message_count']:
            t0 = info['starting_time']['nanoseconds_since_epoch']
            t1 = t0 + info['duration']['nanoseconds']
            start = t0 if start is None else min(start, t0)
            end = t1 if end is None else max(end, t1)
        for entry in info['topics_with_message_count']:
            topic = entry['topic_metadata']['name']
            if topic in topics:
                topics[topic]['message_count'] += entry['message_count']
            else:
                topics[topic] = dict(entry)
    joined.update(
        relative_file_paths=paths, files=files,
        message_count=sum(info['message_count'] for _, info in infos),
        topics_with_message_count=list(topics.values()),
        starting_time={'nanoseconds_since_epoch': start or 0},
        duration={'nanoseconds': (end - start) if start is not None else 0})
    with open(os.path.join(out_dir, 'metadata.yaml'), 'w', encoding='utf-8') as stream:
        yaml.safe_dump({INFO: joined}, stream, sort_keys=False)
    return joined


def topic_counts(folder) -> dict:
    """Return ``{topic: messages}`` of a bag folder (from its metadata.yaml)."""
    return {e['topic_metadata']['name']: e['message_count']
            for e in read_metadata(folder)['topics_with_message_count']}


__all__ = ['join_bags', 'read_metadata', 'topic_counts']
