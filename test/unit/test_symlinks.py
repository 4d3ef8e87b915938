"""Which links a name inside a package may be reached through (description/symlinks.py)."""

import os

from dq_fk_ros.description.symlinks import follow_keeping_names, MAX_LINKS


def test_links_that_keep_their_names_are_followed_and_others_are_not(tmp_path):
    root, away = tmp_path / 'pkg', tmp_path / 'away'
    (root / 'd').mkdir(parents=True)
    (away / 'd').mkdir(parents=True)
    (away / 'd' / 'f.stl').write_text('x')
    (root / 'd' / 'plain.stl').write_text('x')
    os.symlink(away / 'd' / 'f.stl', root / 'd' / 'f.stl')          # keeps its name
    os.symlink('../../away/d/f.stl', root / 'd' / 'g.stl')           # renames (relative)
    os.symlink(away / 'd', root / 'e')                               # a folder, renamed
    os.symlink(away / 'd', root / 'd2')                              # renamed too
    os.symlink('..', root / 'd' / 'up')                              # ends in '..'
    os.symlink(root / 'loop', root / 'loop')                         # a loop keeps its name
    assert follow_keeping_names(root, root / 'd' / 'plain.stl') == str(root / 'd' / 'plain.stl')
    assert follow_keeping_names(root, root / 'd' / 'f.stl') == str(away / 'd' / 'f.stl')
    assert follow_keeping_names(root, root / 'd' / 'g.stl') is None
    assert follow_keeping_names(root, root / 'e' / 'f.stl') is None
    assert follow_keeping_names(root, root / 'd' / 'up' / 'd' / 'plain.stl') is None
    assert follow_keeping_names(root, root / 'loop' / 'x') is None   # past MAX_LINKS
    assert follow_keeping_names(root, tmp_path / 'away' / 'd' / 'f.stl') is None   # not under
    assert follow_keeping_names(root, str(root) + '/../away/d/f.stl') is None
    assert MAX_LINKS == 40


def test_a_chain_is_checked_at_every_link_not_only_its_ends(tmp_path):
    root = tmp_path / 'pkg'
    root.mkdir()
    (tmp_path / 'c.stl').write_text('x')
    os.symlink(tmp_path / 'c.stl', tmp_path / 'b.stl')     # b -> c: renames
    os.symlink(tmp_path / 'b.stl', tmp_path / 'a.stl')     # a -> b: renames
    os.symlink(tmp_path / 'a.stl', root / 'c.stl')         # c -> a -> b -> c
    assert os.path.realpath(root / 'c.stl') == str(tmp_path / 'c.stl')
    assert follow_keeping_names(root, root / 'c.stl') is None
    (tmp_path / 'x').mkdir()
    (tmp_path / 'x' / 'c.stl').write_text('x')
    os.symlink(tmp_path / 'x' / 'c.stl', root / 'kept.stl')
    os.symlink(tmp_path / 'kept.stl', root / 'k.stl')
    assert follow_keeping_names(root, root / 'k.stl') is None
