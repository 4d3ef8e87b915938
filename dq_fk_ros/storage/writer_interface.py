"""
What every bag writer offers (:class:`BagWriter`), beside :class:`BagReader`.

rosbags' ``Writer`` surface (``open``, ``add_connection``, ``write``, ``close``) plus what
``dq_fk_bag process`` needs of a writer: arrays of messages a call (``write_rows``,
``write_templates``) and ``abort`` (a cut run leaves no bag that looks finished). Both writers
of :data:`~dq_fk_ros.storage.formats.FORMATS` are one:
:class:`~dq_fk_ros.storage.mcap_bag_writer.McapBagWriter` and
:class:`~dq_fk_ros.storage.rosbags_writer.RosbagsWriter`; ``test_bag_writer.py`` checks both
against this Protocol.
"""

from typing import Protocol, runtime_checkable, Sequence

import numpy as np


@runtime_checkable
class BagWriter(Protocol):
    """
    A new bag being written; ``error`` is the exception class its misuses raise.

    Times are int nanoseconds; ``connections`` are what :meth:`add_connection` returned.
    """

    error: type

    def open(self) -> None:  # noqa: A003 (rosbags' Writer.open)
        """Create the bag (it must not exist)."""

    def add_connection(self, topic: str, msgtype: str, **kwargs) -> object:
        """Add a topic of a type (rosbags' keywords: typestore, msgdef, rihs01...)."""

    def write(self, connection: object, timestamp: int, data: bytes) -> None:
        """Write one serialized message at log time ``timestamp`` (ns)."""

    def write_rows(self, connections: Sequence, log_times_ns: np.ndarray,
                   payloads: Sequence) -> None:
        """Write N messages on each of K connections, K ``(N, size)`` uint8 arrays."""

    def write_templates(self, connections: Sequence, log_times_ns: np.ndarray,
                        stamps_ns: np.ndarray, templates: Sequence, values: Sequence) -> None:
        """Write N messages on each of K connections, each filled from its template."""

    def close(self) -> None:
        """Finish the bag (summary, ``metadata.yaml``)."""

    def abort(self) -> None:
        """Stop without finishing it: no metadata, a bag readers see as cut."""


__all__ = ['BagWriter']
