"""
Serialized messages on several publishers in one call: the node's poses and /tf.

The fast path is ``_rcl_publish.Publishers`` (C, rcl's ``rcl_publish_serialized_message``
for every message of a call, 0.35-0.41 us a message here); the reference is each publisher's
``publish_raw`` (:func:`~dq_fk_ros.ros.raw_input.raw_publisher`, ~0.75 us), which runs where
the extension was not built (no rcl headers at install) or with ``DQ_FK_PURE_PYTHON`` set.
test/integration/test_publisher_group.py holds the two equal: a subscriber receives the same
bytes from both.
"""

from typing import Sequence

from dq_fk_ros.kinematics.kernel import load_compiled
from dq_fk_ros.ros.raw_input import raw_publisher
import rclpy  # noqa: F401  (loads librcl before the extension that links it)

_RCL, WHY = load_compiled('dq_fk_ros.ros._rcl_publish', 'publish_raw')
COMPILED = _RCL is not None


class PublisherGroup:
    """
    Publish message i (``bytes``) on publisher i, for a fixed list of rclpy publishers.

    The compiled group holds each publisher's handle as ``with publisher.handle:`` does: a
    publisher destroyed meanwhile (``Node.destroy_publisher``) is destroyed only when
    :meth:`close` lets go of it. Close a group before, or right after, destroying its
    publishers; the node does both under its lock, as it publishes. The GIL is held while
    rcl publishes, as for ``publish_raw``: meant for KEEP_LAST publishers (the node's, whose
    writes never wait for room in the history).
    """

    def __init__(self, publishers: Sequence, compiled: bool = True):
        """
        Hold ``publishers`` (rclpy ``Publisher`` objects), in order.

        :param compiled: use the C path where it was built (False: ``publish_raw`` each).
        """
        self.publishers = list(publishers)
        self.closed = False
        self._compiled_asked = compiled
        self.compiled = bool(compiled and COMPILED)
        self._group = _RCL.Publishers([pub.handle for pub in publishers]) if self.compiled \
            else None
        self._each = None if self.compiled else [raw_publisher(pub) for pub in publishers]
        self.publish = self._group.publish if self.compiled else self._publish_each

    def __len__(self) -> int:
        return len(self.publishers)

    def _publish_each(self, messages):
        """Publish ``messages`` (a list or tuple of bytes) one ``publish_raw`` each."""
        if len(messages) != len(self._each):
            raise ValueError(f'PublisherGroup.publish: {len(messages)} messages for '
                             f'{len(self._each)} publishers')
        for send, data in zip(self._each, messages):
            send(data)

    def regroup(self, publishers: Sequence) -> 'PublisherGroup':
        """
        Return this group if it is open and holds ``publishers`` (same order), else a new one.

        A new group closes this one first (the publishers it held are let go).
        """
        if not self.closed and list(publishers) == self.publishers:
            return self
        self.close()
        return PublisherGroup(publishers, self._compiled_asked)

    def close(self) -> None:
        """Let go of the publishers (idempotent); publishing afterwards raises."""
        if self._group is not None:
            self._group.close()
        self._each = []
        self.publishers = []
        self.closed = True
