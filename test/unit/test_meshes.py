"""The meshes dq_fk_view may serve: exactly the files the URDF's visuals name, nothing else."""

import os

from dq_fk_ros.description.meshes import (
    MAX_MESH_BYTES, mesh_allow_list, MeshAssets, visual_mesh_uris)
from dq_fk_ros.description.packages import PackageResolver
from dq_fk_ros.viewers.view_state import ViewState
import pytest


def robot(*meshes, collision='package://arm/meshes/secret.stl'):
    """Write a URDF with one link per mesh URI (and a collision mesh, never served)."""
    links = ''.join(f'<link name="l{k}"><visual><geometry><mesh filename="{uri}" '
                    f'scale="0.001 0.001 0.001"/></geometry></visual></link>'
                    for k, uri in enumerate(meshes))
    return (f'<robot name="r">{links}<link name="c"><collision><geometry><mesh '
            f'filename="{collision}"/></geometry></collision></link></robot>')


@pytest.fixture
def arm(tmp_path):
    """Make a package ``arm`` with meshes, a file outside it and a symbolic link out of it."""
    package = tmp_path / 'arm'
    (package / 'meshes').mkdir(parents=True)
    (package / 'package.xml').write_text('<package><name>arm</name></package>')
    for name in ('base.stl', 'upper.dae', 'hand.obj', 'secret.stl'):
        (package / 'meshes' / name).write_text('solid x\nendsolid x\n')
    (tmp_path / 'outside.stl').write_text('solid secret\nendsolid secret\n')
    os.symlink(tmp_path / 'outside.stl', package / 'meshes' / 'escape.stl')
    (package / 'meshes' / 'notes.txt').write_text('not a mesh')
    return package


def test_the_visuals_meshes_are_listed_once_and_collisions_left_out():
    text = robot('package://arm/meshes/base.stl', 'package://arm/meshes/base.stl',
                 'file:///m/a.obj')
    assert visual_mesh_uris(text) == ['package://arm/meshes/base.stl', 'file:///m/a.obj']
    assert visual_mesh_uris('not xml <') == []


def test_only_files_inside_their_package_or_an_allowed_folder_are_served(arm, tmp_path):
    extra = tmp_path / 'extra'
    extra.mkdir()
    (extra / 'tool.stl').write_text('solid t\nendsolid t\n')
    uris = ['package://arm/meshes/base.stl', 'package://arm/meshes/upper.dae',
            'package://arm/meshes/hand.obj', 'package://arm/../outside.stl',
            'package://arm/meshes/escape.stl', 'package://arm/meshes/notes.txt',
            'package://nobody/meshes/x.stl', f'file://{tmp_path}/outside.stl',
            f'file://{extra}/tool.stl', 'meshes/base.stl', 'http://example.com/a.stl',
            'package://arm/meshes/missing.stl']
    resolver = PackageResolver({'arm': str(arm)}, environ={})
    listed = mesh_allow_list(robot(*uris), resolver, [str(extra)])
    served = {m.uri: m.path for m in listed if m.path}
    assert served == {
        'package://arm/meshes/base.stl': str(arm / 'meshes' / 'base.stl'),
        'package://arm/meshes/upper.dae': str(arm / 'meshes' / 'upper.dae'),
        'package://arm/meshes/hand.obj': str(arm / 'meshes' / 'hand.obj'),
        f'file://{extra}/tool.stl': str(extra / 'tool.stl')}
    problems = {m.uri: m.problem for m in listed if not m.path}
    assert 'leaves package' in problems['package://arm/../outside.stl']
    assert problems['package://arm/meshes/escape.stl'].endswith('outside its package')
    assert 'not a mesh this page draws' in problems['package://arm/meshes/notes.txt']
    assert "package 'nobody' not found; searched: --package arm" in \
        problems['package://nobody/meshes/x.stl']
    assert problems[f'file://{tmp_path}/outside.stl'].endswith('outside the --mesh-dir folders')
    assert 'a relative path' in problems['meshes/base.stl']
    assert 'only package:// and file://' in problems['http://example.com/a.stl']
    assert 'cannot be read (No such file or directory)' in \
        problems['package://arm/meshes/missing.stl']
    assert all('\n' not in p and 'solid' not in p for p in problems.values())
    # the page fetches /mesh/<index>/<file name>; the collision mesh is never listed
    assert [m.url for m in listed[:3]] == ['/mesh/0/base.stl', '/mesh/1/upper.dae',
                                           '/mesh/2/hand.obj']
    assert all('secret' not in m.uri for m in listed)


def test_a_file_mesh_without_a_mesh_dir_is_refused(tmp_path):
    (tmp_path / 'a.stl').write_text('solid\n')
    (listed,) = mesh_allow_list(robot(f'file://{tmp_path}/a.stl'), PackageResolver(environ={}))
    assert listed.path is None and listed.problem.endswith(
        'outside a folder given with --mesh-dir (none given)')


def test_a_mesh_too_big_is_not_served(arm):
    with open(arm / 'meshes' / 'base.stl', 'wb') as stream:
        stream.truncate(MAX_MESH_BYTES + 1)
    (listed,) = mesh_allow_list(robot('package://arm/meshes/base.stl'),
                                PackageResolver({'arm': str(arm)}, environ={}))
    assert listed.path is None and listed.problem.endswith('larger than 64 MiB')


def test_the_server_serves_the_current_list_only(arm, tmp_path):
    lines = []
    state = ViewState(resolver=PackageResolver({'arm': str(arm)}, environ={}),
                      log=lines.append)
    state.take_description(robot('package://arm/meshes/base.stl',
                                 'package://arm/meshes/escape.stl'))
    assert state.mesh_path(0, 'base.stl') == str(arm / 'meshes' / 'base.stl')
    assert lines == ['mesh package://arm/meshes/escape.stl: outside its package (a grey box '
                     'stands for it)']
    for index, name in ((1, 'escape.stl'), (0, 'upper.dae'), (2, 'base.stl'), (-1, 'base.stl'),
                        (0, '../base.stl'), (0, '%2e%2e')):
        assert state.mesh_path(index, name) is None, (index, name)
    # replaced by a link out of the package after the list was made: refused then too
    (arm / 'meshes' / 'base.stl').unlink()
    os.symlink(tmp_path / 'outside.stl', arm / 'meshes' / 'base.stl')
    assert state.mesh_path(0, 'base.stl') is None
    # a new robot: the list follows it
    state.take_description(robot('package://arm/meshes/upper.dae'))
    assert state.mesh_path(0, 'upper.dae') == str(arm / 'meshes' / 'upper.dae')
    assert state.mesh_path(0, 'base.stl') is None
    message = state.robot_message()
    assert '"meshes": {"package://arm/meshes/upper.dae": "/mesh/0/upper.dae"}' in message


def test_a_description_the_urdf_reader_would_refuse_names_no_mesh():
    text = robot('package://arm/meshes/base.stl')
    assert visual_mesh_uris(text) == ['package://arm/meshes/base.stl']
    bomb = text.replace('<robot name="r">', '<!DOCTYPE r [<!ENTITY a "x">]><robot name="r">')
    assert visual_mesh_uris(bomb) == []
    from dq_fk_ros.description.urdf_reader import MAX_URDF_BYTES
    assert visual_mesh_uris(text + ' ' * MAX_URDF_BYTES) == []


def test_a_mesh_is_read_from_the_descriptor_it_was_checked_by(tmp_path):
    """A link in the mesh's place (or on its way), a FIFO, a folder: refused; never followed."""
    import threading
    from dq_fk_ros.description.meshes import read_mesh_file
    secret = tmp_path / 'secret.txt'
    secret.write_bytes(b'root:x:0:0\n')
    good = tmp_path / 'pkg' / 'meshes' / 'arm.stl'
    good.parent.mkdir(parents=True)
    good.write_bytes(b'solid arm\nendsolid arm\n')
    assert read_mesh_file(str(good)) == good.read_bytes()
    link = tmp_path / 'pkg' / 'meshes' / 'link.stl'
    link.symlink_to(secret)
    fifo = tmp_path / 'pkg' / 'meshes' / 'fifo.stl'
    os.mkfifo(fifo)
    (tmp_path / 'away').symlink_to(tmp_path / 'pkg')
    for path, why in ((link, r'cannot be opened \(Too many levels of symbolic links\)'),
                      (fifo, 'not a regular file'), (good.parent, 'not a regular file'),
                      (tmp_path / 'away' / 'meshes' / 'arm.stl', 'reached through a link')):
        with pytest.raises(ValueError, match=f'^{why}$'):   # O_NOFOLLOW, O_NONBLOCK, fstat
            read_mesh_file(str(path))
    flipping = tmp_path / 'pkg' / 'meshes' / 'flip.stl'
    flipping.write_bytes(b'solid flip\nendsolid flip\n')
    stop = threading.Event()

    def flip():  # the file and a link to the secret, in turn, as fast as it goes
        while not stop.is_set():
            os.replace(secret, tmp_path / 'secret.hold')
            os.symlink(tmp_path / 'secret.hold', tmp_path / 'new.stl')
            os.replace(tmp_path / 'new.stl', flipping)
            (tmp_path / 'file.stl').write_bytes(b'solid flip\nendsolid flip\n')
            os.replace(tmp_path / 'file.stl', flipping)
            os.replace(tmp_path / 'secret.hold', secret)
    thread = threading.Thread(target=flip)
    thread.start()
    try:
        for _ in range(3000):
            try:
                data = read_mesh_file(str(flipping))
            except ValueError:
                continue
            assert b'root' not in data
    finally:
        stop.set()
        thread.join()
    # each turn ends with the file in place: served once the race is over (how many reads
    # came between the flips depends on the scheduler: a loaded run's came at none)
    assert read_mesh_file(str(flipping)) == b'solid flip\nendsolid flip\n'


def test_relative_paths_resolve_in_the_folder_of_a_urdf_file_the_user_chose(tmp_path):
    # pybullet_data's URDFs name meshes by paths relative to the URDF
    folder = tmp_path / 'kuka'
    (folder / 'meshes').mkdir(parents=True)
    (folder / 'meshes' / 'link_0.stl').write_bytes(b'solid a\nendsolid a\n')
    (tmp_path / 'secret.stl').write_bytes(b'solid secret\nendsolid\n')
    text = robot('meshes/link_0.stl', '../secret.stl', 'meshes/%2e%2e/%2e%2e/secret.stl',
                 'file://meshes/link_0.stl')
    chosen = mesh_allow_list(text, PackageResolver(environ={}), urdf_dir=str(folder))
    assert chosen[0].path == str(folder / 'meshes' / 'link_0.stl') and not chosen[0].problem
    assert [m.path for m in chosen[1:]] == [None, None, None]
    assert 'outside the URDF' in chosen[1].problem
    # a URDF from DDS (no file the user chose): nothing relative is resolved
    from_dds = mesh_allow_list(text, PackageResolver(environ={}), mesh_dirs=[str(folder)])
    assert all(m.path is None and 'relative path' in m.problem for m in from_dds)
    assets = MeshAssets(PackageResolver(environ={}), urdf_dir=str(folder))
    assets.replace(text)
    assert assets.fetch('meshes/link_0.stl') == b'solid a\nendsolid a\n'
    assert assets.fetch('../secret.stl') is None


def test_a_mesh_reached_through_a_link_that_renames_is_not_served(tmp_path):
    # a folder link with another name (meshes -> /elsewhere/stuff), or a renamed link in the
    # middle of a chain, had served files outside the package to a URDF any peer sends
    outside = tmp_path / 'outside'
    (outside / 'stuff').mkdir(parents=True)
    (outside / 'stuff' / 'a.stl').write_text('solid secret\nendsolid secret\n')
    (outside / 'mid.stl').write_text('solid secret\nendsolid secret\n')
    os.symlink(outside / 'mid.stl', outside / 'b.stl')       # b.stl -> mid.stl: renames
    package = tmp_path / 'arm'
    (package / 'parts').mkdir(parents=True)
    (package / 'package.xml').write_text('<package><name>arm</name></package>')
    os.symlink(outside / 'stuff', package / 'meshes')        # meshes -> stuff: renames
    os.symlink(outside / 'b.stl', package / 'parts' / 'b.stl')   # b -> b -> mid
    # what a build makes: a file link keeping its name, into a clone whose folder link
    # keeps its name too
    clone = tmp_path / 'clones' / 'arm' / 'parts'
    clone.mkdir(parents=True)
    (clone / 'c.stl').write_text('solid c\nendsolid c\n')
    (tmp_path / 'src').mkdir()
    os.symlink(tmp_path / 'clones' / 'arm', tmp_path / 'src' / 'arm')
    os.symlink(tmp_path / 'src' / 'arm' / 'parts' / 'c.stl', package / 'parts' / 'c.stl')
    resolver = PackageResolver({'arm': str(package)}, environ={})
    uris = ['package://arm/meshes/a.stl', 'package://arm/parts/b.stl',
            'package://arm/parts/c.stl']
    listed = {m.uri: m for m in mesh_allow_list(robot(*uris), resolver)}
    assert listed['package://arm/meshes/a.stl'].problem.endswith('outside its package')
    assert listed['package://arm/parts/b.stl'].problem.endswith('outside its package')
    assert listed['package://arm/parts/c.stl'].path == str(clone / 'c.stl')
    assets = MeshAssets(resolver)
    assets.replace(robot(*uris))
    assert assets.fetch('package://arm/meshes/a.stl') is None
    assert assets.fetch('package://arm/parts/c.stl') == b'solid c\nendsolid c\n'


def test_a_mesh_is_read_whole_up_to_the_bound_and_never_past_it(tmp_path, monkeypatch):
    """The bound holds on the bytes read, also for a file that grows after its fstat."""
    from dq_fk_ros.description import meshes
    monkeypatch.setattr(meshes, 'MAX_MESH_BYTES', (3 << 20) + 5)   # 3 MiB and 5 bytes
    exact = tmp_path / 'exact.stl'
    exact.write_bytes(os.urandom((3 << 20) + 5))
    assert meshes.read_mesh_file(str(exact)) == exact.read_bytes()   # read in 1 MiB reads
    over = tmp_path / 'over.stl'
    over.write_bytes(os.urandom((3 << 20) + 6))
    with pytest.raises(ValueError, match='^larger than 3 MiB$'):
        meshes.read_mesh_file(str(over))
    with pytest.raises(ValueError, match='^larger than 3 MiB$'):
        meshes.check_mesh_file(str(over))
    meshes.check_mesh_file(str(exact))   # at the bound: allowed
    with pytest.raises(ValueError, match='^not a regular file$'):
        meshes.check_mesh_file(str(tmp_path))
    with pytest.raises(ValueError, match=r'^cannot be read \(No such file or directory\)$'):
        meshes.check_mesh_file(str(tmp_path / 'none.stl'))
    # the bound at a read's end: 3 MiB read in three reads, then one byte more
    monkeypatch.setattr(meshes, 'MAX_MESH_BYTES', 3 << 20)
    (tmp_path / 'grown.stl').write_bytes(os.urandom((3 << 20) + 1))
    real_fstat = os.fstat

    def fstat_before_growth(fd):   # as if the file grew after it was checked
        info = real_fstat(fd)
        return os.stat_result(info[:6] + (10,) + info[7:10])
    monkeypatch.setattr(os, 'fstat', fstat_before_growth)
    for path in (over, tmp_path / 'grown.stl'):
        with pytest.raises(ValueError, match='^larger than 3 MiB$'):
            meshes.read_mesh_file(str(path))


def test_a_listed_meshs_size_is_what_a_fetch_returns_and_anything_else_is_zero(arm, monkeypatch):
    from dq_fk_ros.description import meshes
    assets = MeshAssets(PackageResolver({'arm': str(arm)}, environ={}))
    assert assets.size('package://arm/meshes/base.stl') == 0   # no URDF yet: nothing listed
    assets.replace(robot('package://arm/meshes/base.stl', 'package://arm/meshes/upper.dae'))
    uri = 'package://arm/meshes/base.stl'
    assert assets.size(uri) == len(assets.fetch(uri)) == len('solid x\nendsolid x\n')
    for other in ('package://arm/meshes/secret.stl', 'package://arm/meshes/nowhere.stl',
                  None, 5, b'package://arm/meshes/base.stl', ['unhashable']):
        assert assets.size(other) == 0 and assets.fetch(other) is None
    monkeypatch.setattr(meshes, 'MAX_MESH_BYTES', 4)   # a file grown past the bound
    assert assets.size(uri) == 4
    (arm / 'meshes' / 'upper.dae').unlink()            # gone since it was listed
    assert assets.size('package://arm/meshes/upper.dae') == 0


def test_a_refused_meshs_problem_names_it_in_200_characters_and_the_reason(arm):
    long = 'package://arm/meshes/' + 'd' * 300 + '.stl'
    (listed,) = mesh_allow_list(robot(long), PackageResolver({'arm': str(arm)}, environ={}))
    assert listed.path is None
    assert listed.problem.startswith(f'mesh {long[:200]}: ')
    assert long[:201] not in listed.problem and len(listed.problem) <= 5 + 200 + 2 + 300
    (listed,) = mesh_allow_list(robot('meshes/base.stl'), PackageResolver(environ={}))
    assert listed.problem == ('mesh meshes/base.stl: a relative path: resolved only against '
                              'the folder of a URDF file given on the command line, never for '
                              'one from DDS')
    (listed,) = mesh_allow_list(robot('http://host/a.stl'), PackageResolver(environ={}))
    assert listed.problem == \
        'mesh http://host/a.stl: only package:// and file:// meshes are served'
    (listed,) = mesh_allow_list(robot('package://arm/meshes/notes.txt'),
                                PackageResolver({'arm': str(arm)}, environ={}))
    assert listed.problem.endswith('not a mesh this page draws (' +
                                   ', '.join(meshes_extensions()) + ')')


def meshes_extensions():
    from dq_fk_ros.description.meshes import MESH_EXTENSIONS
    return MESH_EXTENSIONS


def test_a_urdf_of_the_largest_size_names_its_meshes_and_one_character_more_none():
    from dq_fk_ros.description.meshes import visual_mesh_uris
    from dq_fk_ros.description.urdf_reader import MAX_URDF_BYTES
    text = robot('package://arm/meshes/base.stl')
    text = text.replace('</robot>', '<!--' + 'x' * (MAX_URDF_BYTES - len(text) - 7) +
                        '--></robot>')
    assert len(text) == MAX_URDF_BYTES
    assert visual_mesh_uris(text) == ['package://arm/meshes/base.stl']
    assert visual_mesh_uris(text.replace('<!--', '<!-- ')) == []
