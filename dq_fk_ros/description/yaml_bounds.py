"""
Bounds on YAML text, checked before any YAML loader builds anything from it.

PyYAML's C loader (and ruamel's, which rosbags uses) compose nested collections by
recursing in C: a few tens of kilobytes of ``[[[[...`` overflow the C stack (SIGSEGV),
below any ``RecursionError``. Aliases make a small text stand for a huge tree
(``a: &a [*b, *b, ...]``) that whoever walks the result pays for. :func:`check_yaml_text`
walks libyaml's event stream instead (its parser keeps a stack of its own, so nesting
costs memory, not C stack), counts the depth and the nodes with every alias expanded, and
raises :class:`YamlTooLarge` (one line) past the bounds, before any loader runs.
"""

import yaml

MAX_DEPTH = 64          # collections inside collections (rosbag2's metadata: 6; QoS text: 3)
MAX_NODES = 1 << 22     # nodes with every alias expanded (a 16 MiB metadata.yaml: ~3 million)
_LOADER = getattr(yaml, 'CSafeLoader', yaml.SafeLoader)
_OPEN = (yaml.SequenceStartEvent, yaml.MappingStartEvent)
_CLOSE = (yaml.SequenceEndEvent, yaml.MappingEndEvent)


class YamlTooLarge(ValueError):
    """YAML text nested deeper, or standing for more nodes, than allowed; one line."""


def check_yaml_text(text: 'str | bytes', where: str, max_depth: int = MAX_DEPTH,
                    max_nodes: int = MAX_NODES) -> None:
    """
    Raise :class:`YamlTooLarge` if ``text`` nests deeper or expands to more nodes than allowed.

    :param text: the YAML text (``str`` or ``bytes``).
    :param where: names the text in the message (a file's path, a channel).
    :param max_depth: collections inside collections allowed.
    :param max_nodes: nodes allowed, every alias counted as the whole node it names.

    Text that is not valid YAML to libyaml passes (the loader says what is wrong with it)
    unless it opens more than ``max_depth`` brackets, or a line more than ``max_depth``
    block entries (``- - -``), anywhere: another parser (ruamel) may read past libyaml's
    error.
    """
    depth = 0
    sizes = [0]             # nodes of each open collection so far (sizes[0]: the document)
    anchored = {}           # anchor -> nodes of the node it names
    opened = []             # anchors of the open collections (None: none)
    total = 0
    try:
        for event in yaml.parse(text, Loader=_LOADER):
            if isinstance(event, _OPEN):
                depth += 1
                if depth > max_depth:
                    raise YamlTooLarge(f'{where}: YAML nested more than {max_depth} deep; '
                                       f'at most {max_depth} levels are read')
                sizes.append(1)
                opened.append(event.anchor)
                total += 1
                continue
            if isinstance(event, _CLOSE):
                depth -= 1
                size = sizes.pop()
                anchor = opened.pop()
                if anchor is not None:
                    anchored[anchor] = size
                sizes[-1] += size
                continue
            if isinstance(event, yaml.ScalarEvent):
                size = 1
                if event.anchor is not None:
                    anchored[event.anchor] = 1
            elif isinstance(event, yaml.AliasEvent):
                size = anchored.get(event.anchor, 1)
            else:
                continue
            sizes[-1] += size
            total += size
            if total > max_nodes:
                raise YamlTooLarge(f'{where}: YAML standing for more than {max_nodes} nodes '
                                   f'(aliases expanded); at most {max_nodes} are read')
    except yaml.YAMLError:   # another loader may read on where libyaml stopped: bound the
        _check_invalid_text(text, where, max_depth)   # nesting of the whole text roughly


def _check_invalid_text(text, where, max_depth):
    """Refuse text that is not YAML to libyaml but opens more flow collections than allowed."""
    if isinstance(text, bytes):
        text = text.decode('utf-8', 'replace')
    depth = deepest = 0
    for char in text:
        if char in '[{':
            depth += 1
            deepest = max(deepest, depth)
        elif char in ']}':
            depth = max(0, depth - 1)
    line_depth = max((len(line) - len(line.lstrip('- ')) for line in text.splitlines()),
                     default=0) // 2
    if max(deepest, line_depth) > max_depth:
        raise YamlTooLarge(f'{where}: YAML nested more than {max_depth} deep; '
                           f'at most {max_depth} levels are read')


__all__ = ['check_yaml_text', 'MAX_DEPTH', 'MAX_NODES', 'YamlTooLarge']
