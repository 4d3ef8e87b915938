"""Text read from a bag, made safe for a one-line message (names, an exception's reason)."""

from dq_fk_ros.errors import first_line


def printable(text, limit=80) -> str:
    """Return a name read from a bag safe for a one-line message (escaped, shortened)."""
    text = str(text)
    if not text.isprintable():
        text = text.encode('unicode_escape').decode('ascii')
    return text if len(text) <= limit else text[:limit - 15] + '...' + text[-12:]


def one_line(exc) -> str:
    """Return an exception's first line, escaped and at most 200 characters."""
    text = first_line(exc)
    return printable(text, 200) if str(exc).strip() else text


__all__ = ['one_line', 'printable']
