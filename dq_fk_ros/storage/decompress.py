"""
A bag's chunks decompressed within a bound: what a decompression bomb cannot get past.

One chunk is held in memory uncompressed. :func:`decompress_chunk` decompresses it to at
most the size it declares and at most :data:`MAX_CHUNK_BYTES` (``ros2 bag record`` writes
chunks of about 1 MiB; a bomb declares gigabytes, or expands far beyond what it declares),
whatever compression the bag uses (MCAP: ``''``, ``zstd``, ``lz4``; ROS 1: ``none``,
``bz2``, ``lz4``). :func:`bound_rosbags` makes rosbags' own readers do the same.
"""

MAX_CHUNK_BYTES = 256 << 20


class ChunkRefused(ValueError):
    """A chunk that cannot be decompressed within its declared size and the limit."""


def _at_most(data, compression, limit):
    """Decompress ``data`` to at most ``limit + 1`` bytes (one more says: too much)."""
    if compression in ('', 'none'):
        return bytes(data[:limit + 1])
    if compression == 'zstd':
        try:
            from compression import zstd
        except ImportError:  # before Python 3.14: the backport (a dependency of rosbags)
            from backports import zstd
        try:
            return zstd.ZstdDecompressor().decompress(data, max_length=limit + 1)
        except zstd.ZstdError as exc:
            raise ChunkRefused(f'its zstd data is damaged ({exc})') from None
    if compression == 'lz4':
        import lz4.frame
        try:
            return lz4.frame.LZ4FrameDecompressor().decompress(data, max_length=limit + 1)
        except (RuntimeError, ValueError) as exc:
            raise ChunkRefused(f'its lz4 data is damaged ({exc})') from None
    if compression == 'bz2':
        import bz2
        try:
            return bz2.BZ2Decompressor().decompress(data, max_length=limit + 1)
        except (OSError, EOFError, ValueError) as exc:
            raise ChunkRefused(f'its bz2 data is damaged ({exc})') from None
    raise ChunkRefused(f'unsupported compression {compression[:20]!r}')


def decompress_chunk(data, compression, size) -> bytes:
    """
    Return a chunk's records: ``data`` decompressed to exactly ``size`` bytes (as declared).

    Raises :class:`ChunkRefused` (one line) for a chunk declaring more than
    :data:`MAX_CHUNK_BYTES`, or decompressing to more or fewer bytes than it declares;
    memory stays within ``size`` whatever the data holds.
    """
    if size > MAX_CHUNK_BYTES:
        raise ChunkRefused(f'it declares {size} bytes uncompressed; chunks over '
                           f'{MAX_CHUNK_BYTES >> 20} MiB are skipped')
    # uncompressed: its length says it, no copy needed to find out
    found = len(data) if compression in ('', 'none') else None
    raw = None if found is not None and found != size else _at_most(data, compression, size)
    found = len(raw) if raw is not None else found
    if found != size:
        raise ChunkRefused(f'it decompresses to {"more" if found > size else "fewer"} bytes '
                           f'than the {size} it declares')
    return raw


def _within_limit(data, compression):
    """Decompress up to the limit (for readers that pass no size); more is refused."""
    raw = _at_most(data, compression, MAX_CHUNK_BYTES)
    if len(raw) > MAX_CHUNK_BYTES:
        raise ChunkRefused(f'a chunk decompresses to more than {MAX_CHUNK_BYTES >> 20} MiB')
    return raw


def bound_rosbags(ros1: bool = False) -> None:
    """
    Make rosbags' MCAP readers (and with ``ros1`` its ROS 1 ones) decompress through here.

    rosbags decompresses a chunk whole, with no bound (a 131 KB zstd chunk can expand to
    4 GiB). Its MCAP decompressors are given the declared size (:func:`decompress_chunk`);
    its ROS 1 ones are not, so they are bounded by :data:`MAX_CHUNK_BYTES`. A refused
    chunk raises inside rosbags' reading, and the bag is read again record by record,
    skipping that chunk. The ROS 1 reader is bounded by the ROS 1 adapter, which alone
    imports it (a rosbag2 command does not load it).

    Its rosbag2 storages parse each topic's ``offered_qos_profiles`` text with ruamel, whose
    C composer recurses (a few KiB of ``[[[`` crash the process): they are given
    :func:`bounded_parse_qos`, which refuses text over the bounds of
    :func:`~dq_fk_ros.storage.rosbag2_metadata.parse_qos` first (rosbags' ``ReaderError``).
    """
    from rosbags.rosbag2 import reader, storage_mcap, storage_sqlite3
    for module in (reader, storage_mcap, storage_sqlite3):
        module.parse_qos = bounded_parse_qos
    for name in ('zstd', 'lz4'):
        storage_mcap.DECOMPRESSORS[name] = \
            lambda data, size, name=name: decompress_chunk(data, name, size)
    if ros1:
        from rosbags.rosbag1 import reader as ros1_reader
        for name in ('bz2', 'lz4'):
            ros1_reader.decompressors[name] = lambda data, name=name: _within_limit(data, name)


def bounded_parse_qos(profiles: 'list | str') -> list:
    """Return rosbags' ``parse_qos(profiles)``, text over the QoS bounds refused first."""
    from dq_fk_ros.storage.rosbag2_metadata import check_qos_text
    from dq_fk_ros.description.yaml_bounds import YamlTooLarge
    from rosbags.rosbag2.errors import ReaderError
    from rosbags.rosbag2.metadata import parse_qos
    if isinstance(profiles, str):
        try:
            check_qos_text(profiles)
        except YamlTooLarge as exc:
            raise ReaderError(str(exc)) from None
    return parse_qos(profiles)


__all__ = ['bound_rosbags', 'bounded_parse_qos', 'ChunkRefused', 'decompress_chunk',
           'MAX_CHUNK_BYTES']
