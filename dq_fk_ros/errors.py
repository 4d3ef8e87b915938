"""
The package's errors, one base whose message is one line, and the helpers for that line.

Every error a user may see, in one module every layer imports (the bottom of the layers):

* :class:`DqFkError`: something a user gave that the package cannot use; one line;

  * :class:`RobotDescriptionError`: a robot file, URDF or xacro (also a ``ValueError``);
  * :class:`ParameterError`: a node parameter (also a ``ValueError``);
  * :class:`BagError`: a bag, and under it :class:`BagDamaged`: nothing in it usable;
  * :class:`CdrError`: a serialized message (also a ``ValueError``).

:func:`first_line`, :func:`printable_line`, :func:`listing`, :func:`short` and
:func:`describe` make an exception, any text, a list of names or a value fit one line.
"""

from collections.abc import Iterable


class DqFkError(Exception):
    """
    Something a user gave that the package cannot use; the message is one line.

    ``public`` is the same without any text of a file the user named: what may be told to
    someone who only named the file (a remote parameter client). It differs from the
    message only where a file did not parse as what it should be (it may be any file, a
    secret one).
    """

    def __init__(self, message: str = '', public: str | None = None):
        """Take the message for the user, and the one without file text if it differs."""
        super().__init__(message)
        self.public = message if public is None else public


class RobotDescriptionError(DqFkError, ValueError):
    """A robot description file (DH YAML, URDF, xacro) that cannot be used; one line."""


class ParameterError(DqFkError, ValueError):
    """A node parameter that cannot be used (a rate out of range, an unknown choice): one line."""


class BagError(DqFkError):
    """A bag problem for the user; the message is one line."""


class BagDamaged(BagError):
    """The bag is damaged so badly that nothing in it can be used; the message is one line."""


class CdrError(DqFkError, ValueError):
    """A serialized message that cannot be read."""


def describe(value: object) -> str:
    """Describe a YAML value briefly for an error message (one line, at most ~80 chars)."""
    if value is None:
        return 'nothing'
    if isinstance(value, bool):
        return f'{value!r} (a boolean)'
    if isinstance(value, (dict, list)):
        kind = 'a mapping' if isinstance(value, dict) else f'a list of {len(value)}'
        return kind
    if isinstance(value, int) and abs(value) > 10**15:
        try:
            return f'an integer of {len(str(abs(value)))} digits'
        except ValueError:  # beyond Python's int-to-text limit
            return f'an integer of about {int(value.bit_length() * 0.30103)} digits'
    return f'{short(value)} ({type(value).__name__})'


def listing(names: Iterable[str], at_most: int = 20) -> str:
    """Join names for an error message: at most ``at_most`` of them, then how many more."""
    names = list(names)
    text = ', '.join(names[:at_most])
    return text + (f' ... ({len(names) - at_most} more)' if len(names) > at_most else '')


def printable_line(text: object, at_most: int | None = None) -> str:
    """Return ``text`` for one line of a message or log: every unprintable character as ``?``."""
    text = ''.join(c if c.isprintable() else '?' for c in str(text))
    return text if at_most is None else text[:at_most]


def short(value: object) -> str:
    """``repr(value)``, shortened to about 60 characters."""
    text = repr(value)
    return text if len(text) <= 60 else text[:40] + '...' + text[-12:]


def first_line(exc: BaseException, limit: int | None = None) -> str:
    """Return the first line of an exception's message (its type's name if it has none)."""
    lines = str(exc).strip().splitlines()
    text = lines[0] if lines else type(exc).__name__
    return text if limit is None else text[:limit]


__all__ = ['BagDamaged', 'BagError', 'CdrError', 'describe', 'DqFkError', 'first_line',
           'listing', 'ParameterError', 'printable_line', 'RobotDescriptionError', 'short']
