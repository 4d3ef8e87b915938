"""
The frames a buffer holds, as tf2 writes them: ``allFramesAsYAML`` and view_frames' DOT text.

Both take ``BufferCore.frames_info`` (a list of dicts: frame, parent, broadcaster, rate,
most recent and oldest stamp, buffer length, delay), so they know nothing of the buffer.
"""

from dq_fk_ros.errors import printable_line
from dq_fk_ros.transforms.edges import display_time


def frames_yaml(info: list, now_ns: int = 0) -> str:
    """Return tf2's ``allFramesAsYAML`` of ``info`` (``now_ns``: also each frame's delay)."""
    if not info:
        return '[]'
    lines = []
    for f in info:
        lines += [f"{f['frame']}: ", f"  parent: '{f['parent']}'",
                  f"  broadcaster: '{f['broadcaster']}'", f"  rate: {f['rate']:.3f}",
                  f"  most_recent_transform: {display_time(f['most_recent'])}",
                  f"  oldest_transform: {display_time(f['oldest'])}"]
        if now_ns:
            lines.append(f"  transform_delay: {f['delay'] / 1e9:.3f}")
        lines.append(f"  buffer_length: {f['buffer_length'] / 1e9:.3f}")
    return '\n'.join(lines) + '\n'


def frames_dot(info: list, now_ns: int = 0) -> str:
    r"""
    Return the Graphviz text of view_frames (tf2's ``_allFramesAsDot``) of ``info``.

    Frame names and broadcasters are anyone's on the domain: quotes, backslashes and line
    breaks in them are escaped so that they stay names in the DOT text. A frame name is
    written whole (at most ``MAX_FRAME_ID`` characters), each character it cannot show as
    ``\xNN``: two frames are two nodes however alike their names.
    """
    def esc(text):
        return printable_line(text, 200).replace('\\', '\\\\').replace('"', '\\"')

    def q(text):
        return f'"{dot_name(text)}"'
    lines = ['digraph G {']
    if not info:
        lines.append('"no tf data recieved"')
    for f in info:
        age = f" ( {f['delay'] / 1e9:.3f} sec old)" if now_ns else ''
        label = (f"Broadcaster: {esc(f['broadcaster'])}\\nAverage rate: {f['rate']:.3f} "
                 f"Hz\\nMost recent transform: {display_time(f['most_recent'])}{age}\\n"
                 f"Buffer length: {f['buffer_length'] / 1e9:.3f} sec\\n")
        lines.append(f'{q(f["parent"])} -> {q(f["frame"])}[label="{label}"];')
    children = {f['frame'] for f in info}
    for f in info:
        if f['parent'] not in children:   # a root of a tree: the legend points at it
            children.add(f['parent'])
            legend = f'"Recorded at time: {display_time(now_ns)}"[ shape=plaintext ] ;\n ' \
                if now_ns else ''
            lines += ['edge [style=invis];',
                      ' subgraph cluster_legend { style=bold; color=black; label ='
                      f'"view_frames Result";\n{legend}}}->{q(f["parent"])};']
    lines.append('}')
    return '\n'.join(lines)


def dot_name(name: str) -> str:
    r"""
    Return ``name`` as the text of a DOT string, one to one: distinct names stay distinct.

    A backslash is doubled, a quote escaped, a character that is not printable written
    ``\xNN`` (``\uNNNN`` beyond 0xff): a single backslash, which no frame name's own
    backslash (written doubled) can make.
    """
    out = []
    for ch in name:
        if ch == '\\':
            out.append('\\\\')
        elif ch == '"':
            out.append('\\"')
        elif ch.isprintable():
            out.append(ch)
        else:
            out.append(f'\\x{ord(ch):02x}' if ord(ch) <= 0xff else f'\\u{ord(ch):04x}')
    return ''.join(out)


__all__ = ['dot_name', 'frames_dot', 'frames_yaml']
