"""
Finding the bags of a fleet: every bag under the paths a user names, and where its output goes.

A path is a bag (a file or folder that a row of :data:`~dq_fk_ros.storage.formats.FORMATS`
finds: a rosbag2 folder, ``metadata.yaml`` or ``.mcap``/``.db3`` files in it; a ``.mcap`` or
ROS 1 ``.bag`` file; any other file named is taken as a bag and its reader says what it is)
or a folder holding bags at any depth. Each bag
keeps its place under the named folder in the output folder: ``IN/site_a/run_3`` ->
``OUT/site_a/run_3``; a bag named directly lands at ``OUT/<its name>`` (a file bag without its
extension: the output is a rosbag2 folder). Symbolic links to folders are not followed (a
link loop or a link out of the archive cannot make the walk endless or leave it).
"""

from dataclasses import dataclass
import os

from dq_fk_ros.errors import BagError
from dq_fk_ros.storage.formats import is_bag_file, is_bag_folder, strip_suffix


MAX_BAGS = 1_000_000  # a walk that finds more is refused (a wrong folder, say)


@dataclass(frozen=True)
class FoundBag:
    """One input bag: ``path`` to read, ``name`` its place under the output folder."""

    path: str
    name: str


def find_bags(paths) -> list:
    """
    Return every bag under ``paths`` as :class:`FoundBag`, in a stable (sorted) order.

    A bag found twice (named twice, or inside a folder also named) is listed once, with the
    name it got first.

    :raises BagError: a path that does not exist, two bags that would share an output name,
        a bag without a name of its own (``/``), or a walk finding more than
        :data:`MAX_BAGS`.
    """
    found = []
    for path in paths:
        path = os.fspath(path)
        if not os.path.lexists(path):
            raise BagError(f'{path}: no such bag or folder')
        top = os.path.basename(os.path.abspath(path))  # '.' and 'in/..' by their own names
        if os.path.isfile(path):
            found.append(FoundBag(path, strip_suffix(top)))
        elif is_bag_folder(path):
            found.append(FoundBag(path, top))
        else:
            found += _walk(path)
        if len(found) > MAX_BAGS:
            raise BagError(f'{path}: more than {MAX_BAGS} bags; name fewer folders')
    unique, seen = [], set()
    for bag in found:  # the same bag named twice (in/run in/run, or in in/run): once
        real = os.path.realpath(bag.path)
        if real not in seen:
            seen.add(real)
            unique.append(bag)
    found = unique
    names = {}
    for bag in found:
        if not bag.name or bag.name in (os.curdir, os.pardir):
            raise BagError(f'{bag.path}: a bag needs a name of its own for its output; name '
                           f'its parent folder instead')
        other = names.setdefault(bag.name, bag.path)
        if other != bag.path:
            raise BagError(f'{other} and {bag.path} would both be written to {bag.name}; '
                           f'name their parent folder instead')
    return sorted(found, key=lambda b: b.name)


def _walk(root):
    """Yield the bags under folder ``root`` (not following folder links)."""
    out = []
    for folder, dirs, files in os.walk(root, followlinks=False):
        dirs.sort()
        rel = os.path.relpath(folder, root)
        if folder != root and is_bag_folder(folder):
            out.append(FoundBag(folder, rel))
            dirs[:] = []  # a bag's own files are not bags of their own
            continue
        for name in sorted(files):
            path = os.path.join(folder, name)
            if is_bag_file(path):  # a ROS 1 bag: one file (.mcap/.db3 make a bag folder)
                out.append(FoundBag(path, os.path.normpath(
                    os.path.join(rel, strip_suffix(name)))))
        if len(out) > MAX_BAGS:
            break
    return out


__all__ = ['find_bags', 'FoundBag']
