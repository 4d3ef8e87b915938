"""
tf2's exceptions, under the names tf2_ros re-exports (``tf2_ros.LookupException``...).

:class:`TransformException` is the base (a :class:`~dq_fk_ros.errors.DqFkError` too); code
written for tf2_ros catches the same names from :mod:`dq_fk_ros.tf`.
"""

from dq_fk_ros.errors import DqFkError


class TransformException(DqFkError):
    """A transform that cannot be given (tf2's ``TransformException``)."""


class LookupException(TransformException):
    """A frame that does not exist, or a tree with a loop (tf2's ``LookupException``)."""


class ConnectivityException(TransformException):
    """Two frames in trees that are not connected (tf2's ``ConnectivityException``)."""


class ExtrapolationException(TransformException):
    """A time outside what an edge holds (tf2's ``ExtrapolationException``)."""


class InvalidArgumentException(TransformException):
    """A frame id tf2 refuses: empty, or with a leading ``/`` (``InvalidArgumentException``)."""


class TimeoutException(TransformException):
    """A wait for a transform that ran out (tf2's ``TimeoutException``)."""


__all__ = ['ConnectivityException', 'ExtrapolationException', 'InvalidArgumentException',
           'LookupException', 'TimeoutException', 'TransformException']
