"""
Which symbolic links a file named inside a package may be reached through.

docs/security.md's rule: a name must lie in its root (a package, an allowed folder) as text;
the file it resolves to may lie elsewhere only if every link on the way keeps the name it
stands for (``share/PKG/meshes/a.stl`` -> ``src/PKG/meshes/a.stl``, what ``colcon build
--symlink-install`` makes; ``src/PKG`` -> ``~/clones/PKG``). Such links are made by whoever
owns the workspace, never by what names the file (a URDF from a DDS peer, a xacro): a link
to another name (``meshes`` -> ``/etc``, ``link.stl`` -> ``secret.stl``), anywhere on the
way, in a folder or in the middle of a chain, is not followed out of the root. Plain
Python, no ROS.
"""

import os

MAX_LINKS = 40   # links followed for one name at most (the kernel's own bound)


def follow_keeping_names(root: str, named: str) -> str | None:
    """
    Return the file ``named`` resolves to if every link below ``root`` keeps its name.

    ``named`` must lie under ``root`` as text (made absolute and normalised); the folders of
    ``root`` itself are the user's and resolved as they are. Each component below it is
    walked as the kernel walks it; a symbolic link met there, and every link its target
    passes through, must end in the link's own name. None: ``named`` is not under ``root``,
    a link on the way renames, or more than ``MAX_LINKS`` links.
    """
    root = os.path.normpath(os.path.abspath(root))
    named = os.path.normpath(os.path.abspath(named))
    rel = os.path.relpath(named, root)
    if rel == os.pardir or rel.startswith(os.pardir + os.sep):
        return None
    current = os.path.realpath(root)
    pending = [] if rel == os.curdir else rel.split(os.sep)
    hops = 0
    while pending:
        part = pending.pop(0)
        if part in ('', os.curdir):
            continue
        if part == os.pardir:
            current = os.path.dirname(current)
            continue
        candidate = os.path.join(current, part)
        if not os.path.islink(candidate):
            current = candidate
            continue
        hops += 1
        if hops > MAX_LINKS:
            return None
        try:
            target = os.readlink(candidate)
        except OSError:
            return None
        if os.path.basename(os.path.normpath(target)) != part:
            return None   # (a target ending in '..' or '.' renames too)
        if os.path.isabs(target):
            current = os.sep
        pending[:0] = [p for p in target.split(os.sep) if p]
    return current


def inside(path: str, folder: str) -> bool:
    """Whether ``path`` is ``folder`` or lies in it (both taken as given, no links resolved)."""
    return path == folder or path.startswith(folder.rstrip(os.sep) + os.sep)


__all__ = ['follow_keeping_names', 'inside', 'MAX_LINKS']
