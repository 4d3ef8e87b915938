"""mcap_stream's summary check (the record-by-record reader itself: test_bag_readers.py)."""

import struct
import zlib

from dq_fk_ros.storage.mcap_summary import summary_intact
import pytest

MAGIC = b'\x89MCAP0\r\n'


def file_with_summary(path, summary_bytes, crc=None):
    """Write an MCAP file's shape: magic, a summary of ``summary_bytes`` bytes, footer, magic."""
    summary = bytes(range(256)) * (summary_bytes // 256)
    footer_head = struct.pack('<BQQQ', 0x02, 20, 8, 0)   # summary at 8, no summary offsets
    if crc is None:  # the MCAP spec's: CRC-32 of the summary through the footer before it
        crc = zlib.crc32(summary + footer_head)
    path.write_bytes(MAGIC + summary + footer_head + struct.pack('<I', crc) + MAGIC)
    return path


@pytest.mark.parametrize('size', [256, 3 << 20])   # one read, several 1 MiB blocks
def test_a_summary_crc_is_checked_over_the_whole_summary(tmp_path, size):
    assert summary_intact(file_with_summary(tmp_path / 'ok.mcap', size))
    good = zlib.crc32(bytes(range(256)) * (size // 256) + struct.pack('<BQQQ', 2, 20, 8, 0))
    assert not summary_intact(file_with_summary(tmp_path / 'bad.mcap', size, good ^ 1))
    damaged = bytearray(file_with_summary(tmp_path / 'late.mcap', size).read_bytes())
    damaged[8 + size - 1] ^= 0xFF   # the summary's last byte, in its last block
    (tmp_path / 'late.mcap').write_bytes(bytes(damaged))
    assert not summary_intact(tmp_path / 'late.mcap')
