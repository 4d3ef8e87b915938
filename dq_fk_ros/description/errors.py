"""
The package's errors: one base, :class:`DqFkError`, whose message is one line for the user.

Under it: :class:`RobotDescriptionError` (a robot file, URDF or xacro), :class:`ParameterError`
(a node parameter), and in their layers ``BagError`` (a bag) and ``CdrError`` (a serialized
message). :func:`first_line` is how any exception becomes one line.
"""


class DqFkError(Exception):
    """Something a user gave that the package cannot use; the message is one line."""


class RobotDescriptionError(DqFkError, ValueError):
    """
    A robot description file that cannot be used; the message is one line for the user.

    ``public`` is the same without any text of the file: what may be told to someone who
    only named the file (a remote parameter client). It differs from the message only where
    the file did not parse as a robot description (it may be any file, a secret one).
    """

    def __init__(self, message, public=None):
        """Take the message for the user, and the one without file text if it differs."""
        super().__init__(message)
        self.public = message if public is None else public


class ParameterError(RobotDescriptionError):
    """
    A node parameter that cannot be used (a rate out of range, an unknown choice): one line.

    A kind of :class:`RobotDescriptionError` for the code that catches both (a parameter
    change names the robot or how to publish it).
    """


def first_line(exc, limit=None):
    """Return the first line of an exception's message (its type's name if it has none)."""
    lines = str(exc).strip().splitlines()
    text = lines[0] if lines else type(exc).__name__
    return text if limit is None else text[:limit]


__all__ = ['DqFkError', 'first_line', 'ParameterError', 'RobotDescriptionError']
