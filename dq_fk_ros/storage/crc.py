"""
zlib's CRC-32 (the MCAP chunks'), as fast as this machine computes it.

:func:`crc32` is zlib-ng's (``zlib-ng`` on PyPI: SIMD, some ten times zlib's speed on a
chunk) where it is installed, else the standard library's ``zlib.crc32``: the same function,
the same values (test_mcap_chunks.py's ``test_the_fast_crc_is_zlibs``).
"""

try:
    from zlib_ng.zlib_ng import crc32
except ImportError:  # not installed: zlib's, the same values, slower
    from zlib import crc32

__all__ = ['crc32']
