"""Finding ROS packages as ROS does, and a xacro's ``$(find)`` on a pip-only install."""

import os

from dq_fk_ros.cli import dq_fk
from dq_fk_ros.description.loading import FileAccess, load_robot
from dq_fk_ros.description.packages import PackageNotFound, PackageResolver, parse_package_option
from dq_fk_ros.description.urdf_reader import read_urdf_text
from dq_fk_ros.errors import RobotDescriptionError
import pytest

SEGMENT = ('<?xml version="1.0"?><robot xmlns:xacro="http://www.ros.org/wiki/xacro">'
           '<xacro:macro name="seg" params="n parent"><link name="l${n}"/>'
           '<joint name="j${n}" type="revolute"><parent link="${parent}"/><child link="l${n}"/>'
           '<origin xyz="0 0 ${xacro.load_yaml(\'$(find arm_description)/config/arm.yaml\')'
           '[\'length\']}"/><axis xyz="0 1 0"/><limit lower="-1" upper="1" effort="1" '
           'velocity="1"/></joint></xacro:macro></robot>')
ARM = ('<?xml version="1.0"?><robot name="arm" xmlns:xacro="http://www.ros.org/wiki/xacro">'
       '<xacro:include filename="$(find arm_description)/urdf/seg.xacro"/><link name="base"/>'
       '<xacro:seg n="1" parent="base"/><xacro:seg n="2" parent="l1"/></robot>')


def make_package(folder, name='arm_description'):
    """Write a description package (package.xml, a macro, its YAML) into ``folder``."""
    (folder / 'urdf').mkdir(parents=True)
    (folder / 'config').mkdir()
    (folder / 'package.xml').write_text(f'<package format="3"><name>{name}</name></package>')
    (folder / 'urdf' / 'seg.xacro').write_text(SEGMENT)
    (folder / 'config' / 'arm.yaml').write_text('length: 0.3\n')
    return folder


@pytest.fixture
def layouts(tmp_path, monkeypatch):
    """Make the four places a package may be, and a robot xacro outside all of them."""
    monkeypatch.delenv('AMENT_PREFIX_PATH', raising=False)
    monkeypatch.delenv('ROS_PACKAGE_PATH', raising=False)
    places = {}
    places['explicit'] = make_package(tmp_path / 'given' / 'anything')
    prefix = tmp_path / 'install'
    places['ament'] = make_package(prefix / 'share' / 'arm_description')
    index = prefix / 'share' / 'ament_index' / 'resource_index' / 'packages'
    index.mkdir(parents=True)
    (index / 'arm_description').write_text('')
    # ROS 1's crawl: the folder's name is not the package's; an ignored copy is skipped
    places['ros_package_path'] = make_package(tmp_path / 'ws' / 'src' / 'vendor_repo' / 'arm')
    make_package(tmp_path / 'ws' / 'src' / 'old' / 'arm')
    (tmp_path / 'ws' / 'src' / 'old' / 'CATKIN_IGNORE').write_text('')
    robot = tmp_path / 'robots' / 'arm.urdf.xacro'
    robot.parent.mkdir()
    robot.write_text(ARM)
    places['above'] = make_package(tmp_path / 'robots' / 'arm_description')
    return tmp_path, robot, places, prefix


def test_each_rule_finds_the_package_in_its_order(layouts, monkeypatch):
    tmp_path, robot, places, prefix = layouts
    environ = {'AMENT_PREFIX_PATH': str(prefix), 'ROS_PACKAGE_PATH': str(tmp_path / 'ws')}
    given = {'arm_description': str(places['explicit'])}
    assert PackageResolver(given, robot, environ=environ).find('arm_description') == \
        str(places['explicit'])
    assert PackageResolver({}, robot, environ=environ).find('arm_description') == \
        str(places['ament'])
    assert PackageResolver({}, robot, environ={'ROS_PACKAGE_PATH': str(tmp_path / 'ws')}) \
        .find('arm_description') == str(places['ros_package_path'])
    assert PackageResolver({}, robot, environ={}).find('arm_description') == \
        str(places['above'])


def test_an_unknown_package_is_one_line_naming_it_and_the_places(layouts):
    tmp_path, robot, places, prefix = layouts
    resolver = PackageResolver({}, robot, environ={'AMENT_PREFIX_PATH': str(prefix)})
    with pytest.raises(PackageNotFound) as caught:
        resolver.find('gripper_description')
    message = str(caught.value)
    assert message.startswith("package 'gripper_description' not found; searched: ")
    assert str(prefix) in message and 'ROS_PACKAGE_PATH (not set)' in message
    assert f'the folders above {robot}' in message and '\n' not in message


def test_package_uris_resolve_inside_their_package_only(layouts):
    tmp_path, robot, places, prefix = layouts
    resolver = PackageResolver({}, robot, environ={})
    assert resolver.resolve('package://arm_description/urdf/seg.xacro') == \
        str(places['above'] / 'urdf' / 'seg.xacro')
    with pytest.raises(ValueError, match='leaves package'):
        resolver.resolve('package://arm_description/../../../etc/passwd')
    with pytest.raises(ValueError, match='only package:// and file://'):
        resolver.resolve('http://example.org/mesh.stl')
    assert resolver.resolve('file:///opt/mesh.stl') == '/opt/mesh.stl'


def test_the_search_above_a_run_time_file_stays_in_its_folders(layouts):
    tmp_path, robot, places, prefix = layouts
    inside = PackageResolver({}, robot, within=[tmp_path / 'robots'], environ={})
    assert inside.find('arm_description') == str(places['above'])
    outside = PackageResolver({}, tmp_path / 'robots' / 'arm_description' / 'urdf' / 'x.xacro',
                              within=[tmp_path / 'robots' / 'arm_description' / 'urdf'],
                              environ={})
    with pytest.raises(PackageNotFound):
        outside.find('arm_description')


@pytest.mark.parametrize('rule', ['explicit', 'ament', 'ros_package_path', 'above'])
def test_a_xacro_finds_its_package_each_way(layouts, monkeypatch, rule):
    """Every vendor xacro with $(find ...) failed: AMENT_PREFIX_PATH is not set."""
    tmp_path, robot, places, prefix = layouts
    packages = {}
    if rule != 'above':
        (tmp_path / 'robots' / 'arm_description' / 'package.xml').unlink()
    if rule == 'explicit':
        packages = {'arm_description': str(places['explicit'])}
    elif rule == 'ament':
        monkeypatch.setenv('AMENT_PREFIX_PATH', str(prefix))
    elif rule == 'ros_package_path':
        monkeypatch.setenv('ROS_PACKAGE_PATH', str(tmp_path / 'ws'))
    text = read_urdf_text(robot, packages=packages)
    assert '<origin xyz="0 0 0.3"/>' in text
    model = load_robot(str(robot), packages=packages).model
    assert model.dof == 2


def test_the_cli_takes_package_options(layouts, capsys):
    tmp_path, robot, places, prefix = layouts
    (tmp_path / 'robots' / 'arm_description' / 'package.xml').unlink()
    assert dq_fk.main(['validate', str(robot)]) == 1
    assert "package 'arm_description' not found" in capsys.readouterr().err
    option = f'arm_description={places["explicit"]}'
    for argv in (['validate', str(robot), '--package', option],
                 ['fk', str(robot), '--package', option, '--json'],
                 ['from-urdf', str(robot), '--package', option]):
        assert dq_fk.main(argv) == 0, argv
    with pytest.raises(SystemExit):
        dq_fk.main(['validate', str(robot), '--package', 'arm_description'])
    assert 'give NAME=DIR' in capsys.readouterr().err


def test_a_run_time_xacro_finds_packages_only_within_its_folders(layouts):
    tmp_path, robot, places, prefix = layouts
    access = FileAccess((str(tmp_path / 'robots'),), xacro=True)
    assert load_robot(str(robot), access=access).model.dof == 2
    (tmp_path / 'robots' / 'arm_description' / 'package.xml').unlink()
    make_package(tmp_path / 'arm_description')          # above, but outside the folders
    with pytest.raises(RobotDescriptionError, match='xacro failed'):
        load_robot(str(robot), access=access)


@pytest.mark.parametrize('text, words', [('nameonly', 'give NAME=DIR'),
                                         ('=/tmp', 'give NAME=DIR'),
                                         ('a b=/tmp', 'give NAME=DIR'),
                                         ('pkg=/no/such/folder', 'no such folder')])
def test_package_options_are_checked(text, words):
    with pytest.raises(ValueError, match=words):
        parse_package_option(text)
    assert parse_package_option(f'pkg={os.sep}') == ('pkg', os.sep)


def test_broken_or_huge_package_xml_files_name_no_package(tmp_path):
    """A package.xml the crawl cannot read names nothing: it is not a crash."""
    root = tmp_path / 'ws'
    for folder, text in (('empty_name', '<package><name/></package>'),
                         ('no_name', '<package></package>'),
                         ('not_xml', '<package><name>arm_description'),
                         ('entity', '<!DOCTYPE p [<!ENTITY x "arm_description">]>'
                                    '<package><name>&x;</name></package>'),
                         ('huge', '<package><name>arm_description</name>' + ' ' * (1 << 20)
                          + '</package>')):
        (root / folder).mkdir(parents=True)
        (root / folder / 'package.xml').write_text(text)
    resolver = PackageResolver({'other': str(tmp_path)}, environ={'ROS_PACKAGE_PATH': str(root)})
    with pytest.raises(PackageNotFound, match="^package 'arm_description' not found; "
                       'searched: --package other; '):
        resolver.find('arm_description')


def test_a_package_several_folders_above_the_file_is_found(tmp_path):
    package = make_package(tmp_path / 'arm_description')
    deep = package / 'robots' / 'variants' / 'left'
    deep.mkdir(parents=True)
    robot = deep / 'arm.urdf.xacro'
    robot.write_text(ARM)
    assert PackageResolver(near=robot, environ={}).find('arm_description') == str(package)
    with pytest.raises(PackageNotFound):
        PackageResolver(near=robot, environ={}).find('gripper_description')


def test_packages_this_python_carries_are_found_with_nothing_set(tmp_path, monkeypatch):
    # example-robot-data's cmeel wheel: site-packages/cmeel.prefix/share/NAME and its index
    import sys
    import sysconfig
    from dq_fk_ros.description import packages
    site = tmp_path / 'venv' / 'lib' / 'site-packages'
    prefix = site / 'cmeel.prefix'
    (prefix / 'share' / 'ament_index' / 'resource_index' / 'packages').mkdir(parents=True)
    (prefix / 'share' / 'ament_index' / 'resource_index' / 'packages' / 'robot-data').touch()
    (prefix / 'share' / 'robot-data' / 'meshes').mkdir(parents=True)
    (site / 'other.prefix' / 'share').mkdir(parents=True)   # no index: not a prefix of ours
    monkeypatch.setattr(sys, 'prefix', str(tmp_path / 'venv'))
    monkeypatch.setattr(sysconfig, 'get_paths', lambda: {'purelib': str(site)})
    packages.python_prefixes.cache_clear()
    try:
        assert packages.python_prefixes() == (str(prefix),)
        resolver = PackageResolver(environ={})
        assert resolver.find('robot-data') == str(prefix / 'share' / 'robot-data')
        assert 'the ament index of this Python' in resolver.searched()
        # after the sources of today: a --package of that name comes first
        assert PackageResolver({'robot-data': str(tmp_path)}, environ={}).find(
            'robot-data') == str(tmp_path)
        with pytest.raises(PackageNotFound):
            PackageResolver(environ={}, python=()).find('robot-data')
        from dq_fk_ros.description.xacro_sandbox import ros_package_roots
        assert str(prefix / 'share') in ros_package_roots({})
    finally:
        packages.python_prefixes.cache_clear()


def test_the_readme_ur5_resolves_from_this_venv_with_nothing_set():
    resolver = PackageResolver(environ={})
    folder = resolver.find('example-robot-data')   # the URDFs' name; the index's too
    assert os.path.isfile(os.path.join(folder, 'robots', 'ur_description', 'urdf',
                                       'ur5_robot.urdf'))


def _package(folder, name):
    folder.mkdir(parents=True, exist_ok=True)
    (folder / 'package.xml').write_text(f'<package format="3"><name>{name}</name></package>')


def test_the_crawl_goes_six_folders_down_and_no_further(tmp_path):
    from dq_fk_ros.description import packages
    assert packages.MAX_SEARCH_DEPTH == 6
    six = tmp_path.joinpath(*[f'e{k}' for k in range(1, 7)])
    seven = tmp_path.joinpath(*[f'f{k}' for k in range(1, 8)])
    _package(six, 'six_down')      # the crawl's last level
    _package(seven, 'seven_down')  # one past it
    resolver = PackageResolver(environ={'ROS_PACKAGE_PATH': str(tmp_path)})
    assert resolver.find('six_down') == str(six)
    with pytest.raises(PackageNotFound):
        resolver.find('seven_down')
    _package(tmp_path / 'outer', 'outer')
    _package(tmp_path / 'outer' / 'inner', 'inner')   # a package's folders are not crawled
    resolver = PackageResolver(environ={'ROS_PACKAGE_PATH': str(tmp_path)})
    assert resolver.find('outer') == str(tmp_path / 'outer')
    with pytest.raises(PackageNotFound):
        resolver.find('inner')


def test_the_crawl_looks_at_a_bounded_number_of_folders_in_name_order(tmp_path, monkeypatch):
    from dq_fk_ros.description import packages
    monkeypatch.setattr(packages, 'MAX_SEARCH_FOLDERS', 5)   # the root and four more
    for name in 'jihgfedcba':
        _package(tmp_path / name, f'pkg_{name}')
    found = [os.path.basename(f) for f in packages._package_folders(str(tmp_path))]
    assert found == ['a', 'b', 'c', 'd']


def test_the_ament_index_and_the_share_folder_are_both_needed(tmp_path):
    prefix = tmp_path / 'install'
    index = prefix / 'share' / 'ament_index' / 'resource_index' / 'packages'
    index.mkdir(parents=True)
    (index / 'listed_only').write_text('')            # no share/listed_only
    _package(prefix / 'share' / 'folder_only', 'folder_only')   # not in the index
    resolver = PackageResolver(environ={'AMENT_PREFIX_PATH': str(prefix)})
    for name in ('listed_only', 'folder_only'):
        with pytest.raises(PackageNotFound):
            resolver.find(name)


@pytest.mark.parametrize('name', ['../etc', 'a/b', '', '.hidden', 'x' * 300 + '/'])
def test_a_name_that_is_no_package_name_is_refused_as_such(tmp_path, name):
    resolver = PackageResolver(environ={'ROS_PACKAGE_PATH': str(tmp_path)})
    with pytest.raises(PackageNotFound) as caught:
        resolver.find(name)
    assert str(caught.value) == f'package {name[:80]!r}: not a package name'   # 80 at most


def test_where_find_looks_is_said_exactly(tmp_path):
    resolver = PackageResolver({'b_pkg': str(tmp_path), 'a_pkg': str(tmp_path)},
                               environ={'AMENT_PREFIX_PATH': f'/opt/one{os.pathsep}/opt/two',
                                        'ROS_PACKAGE_PATH': '/ws/src'}, python=[])
    assert resolver.searched() == (f'--package a_pkg, b_pkg; the ament index of '
                                   f'AMENT_PREFIX_PATH (/opt/one{os.pathsep}/opt/two); '
                                   f'ROS_PACKAGE_PATH (/ws/src)')
    bare = PackageResolver(environ={}, python=[])
    assert bare.searched() == ('the ament index of AMENT_PREFIX_PATH (not set); '
                               'ROS_PACKAGE_PATH (not set)')


@pytest.mark.parametrize('text', ['x' * 200, 'pkg=' + '/nowhere' * 30])
def test_a_bad_package_option_is_shown_in_80_characters(text):
    with pytest.raises(ValueError) as caught:
        parse_package_option(text, what='--pkg')
    message = str(caught.value)
    if '=' in text:
        assert message == f'--pkg pkg={text[4:][:80]}: no such folder'
    else:
        assert message.startswith(f'--pkg {text[:80]!r}: give NAME=DIR')


def test_a_folder_holding_an_equals_sign_is_a_package_option(tmp_path):
    folder = tmp_path / 'a=b'
    folder.mkdir()
    assert parse_package_option(f'pkg={folder}') == ('pkg', str(folder))


def test_a_package_xml_of_the_bound_is_read_and_one_byte_more_is_not(tmp_path):
    from dq_fk_ros.description.packages import MAX_PACKAGE_XML_BYTES, package_xml_name
    head, tail = '<package format="3"><name>big</name><!-- ', ' --></package>'
    for size, expected in ((MAX_PACKAGE_XML_BYTES, 'big'), (MAX_PACKAGE_XML_BYTES + 1, None)):
        folder = tmp_path / str(size)
        folder.mkdir()
        pad = 'x' * (size - len(head) - len(tail))
        (folder / 'package.xml').write_text(head + pad + tail)
        assert (folder / 'package.xml').stat().st_size == size
        assert package_xml_name(str(folder)) == expected, size


def test_every_entry_of_the_search_paths_is_searched_and_the_first_find_wins(tmp_path):
    first, second = tmp_path / 'one', tmp_path / 'two'
    _package(second / 'arm_description', 'arm_description')
    _package(first / 'other', 'other_pkg')
    _package(second / 'other', 'other_pkg')
    environ = {'ROS_PACKAGE_PATH': f'{first}{os.pathsep}{second}'}
    resolver = PackageResolver(environ=environ, python=[])
    assert resolver.find('arm_description') == str(second / 'arm_description')
    assert resolver.find('other_pkg') == str(first / 'other')   # ROS 1: the first entry's
    prefix = tmp_path / 'install'
    index = prefix / 'share' / 'ament_index' / 'resource_index' / 'packages'
    index.mkdir(parents=True)
    (index / 'gripper').write_text('')
    _package(prefix / 'share' / 'gripper', 'gripper')
    resolver = PackageResolver(environ={'AMENT_PREFIX_PATH': f'/opt/none{os.pathsep}{prefix}'},
                               python=[])
    assert resolver.find('gripper') == str(prefix / 'share' / 'gripper')


def test_a_package_option_names_its_option_by_default():
    with pytest.raises(ValueError, match="^--package 'nameonly': give NAME=DIR"):
        parse_package_option('nameonly')


def test_a_package_xml_is_read_only_up_to_its_bound(tmp_path, monkeypatch):
    """A crawl past a huge package.xml (a sparse 64 MiB file here) reads 1 MiB and a byte."""
    from dq_fk_ros.description import packages
    huge = tmp_path / 'huge'
    huge.mkdir()
    with open(huge / 'package.xml', 'wb') as stream:
        stream.truncate(64 << 20)   # sparse: no disk used
    asked = []

    def reading(path, mode='r', *args, **kwargs):
        stream = open(path, mode, *args, **kwargs)
        read = stream.read
        stream.read = lambda n=-1: asked.append(n) or read(n)
        return stream
    monkeypatch.setattr(packages, 'open', reading, raising=False)
    assert packages.package_xml_name(str(huge)) is None
    assert asked == [packages.MAX_PACKAGE_XML_BYTES + 1]


def test_the_crawl_spends_its_bound_on_folders_and_skips_hidden_linked_and_unreadable_ones(
        tmp_path, monkeypatch):
    from dq_fk_ros.description import packages
    root, outside = tmp_path / 'root', tmp_path / 'outside'
    for k in range(5):                                  # files cost nothing of the bound
        (root / 'files').mkdir(parents=True, exist_ok=True)
        (root / 'files' / f'a{k}').write_text('')
    _package(root / 'files' / 'zz', 'zz')
    _package(root / '.hidden' / 'secret', 'secret')     # a dot folder is not crawled
    _package(outside / 'elsewhere', 'elsewhere')
    os.symlink(outside, root / 'linked')                # nor a link out of the root
    _package(root / 'unreadable' / 'pkg', 'behind')
    _package(root / 'y_after', 'after')
    real_listdir = os.listdir

    def listdir(folder):
        if os.path.basename(folder) == 'unreadable':
            raise PermissionError(13, 'Permission denied', folder)
        return real_listdir(folder)
    monkeypatch.setattr(packages.os, 'listdir', listdir)
    monkeypatch.setattr(packages, 'MAX_SEARCH_FOLDERS', 5)  # root, files, zz, unreadable, y_after
    found = [os.path.relpath(f, root) for f in packages._package_folders(str(root))]
    assert found == [os.path.join('files', 'zz'), 'y_after']


def test_a_refused_uri_is_named_in_its_first_120_characters(tmp_path):
    _package(tmp_path / 'arm', 'arm')
    resolver = PackageResolver({'arm': str(tmp_path / 'arm')}, environ={})
    for uri, why in (('package://arm/' + '../' * 60 + 'etc/passwd', ': leaves package'),
                     ('http://' + 'h' * 150 + '/a.stl', ': only package:// and file:// are')):
        with pytest.raises(ValueError) as caught:
            resolver.resolve(uri)
        assert str(caught.value).startswith(uri[:120] + why)
