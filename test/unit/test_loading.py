"""One way in: a DH file, a URDF (file or text) or a shipped robot's name."""

import dataclasses
import os

from dq_fk_ros.description.loading import (
    FileAccess, is_urdf, load_robot, LoadedRobot, resolve_robot, robot_from_urdf_text)
from dq_fk_ros.description.shipped import shipped_robot_path, shipped_robots
from dq_fk_ros.errors import RobotDescriptionError
import pytest

URDF = ('<robot name="two"><link name="b"/><link name="l1"/><link name="l2"/>'
        '<joint name="j1" type="continuous"><parent link="b"/><child link="l1"/>'
        '<axis xyz="0 0 1"/></joint>'
        '<joint name="j2" type="revolute"><parent link="l1"/><child link="l2"/>'
        '<origin xyz="0.3 0 0"/><axis xyz="0 1 0"/>'
        '<limit lower="-1" upper="1" effort="1" velocity="1"/></joint></robot>')


def test_names_and_paths_resolve(tmp_path):
    assert resolve_robot('rl15') == shipped_robot_path('rl15')
    assert resolve_robot('config/rl15.yaml') == 'config/rl15.yaml'
    assert resolve_robot('mine.urdf') == 'mine.urdf'  # a path: loading says what is wrong
    assert resolve_robot(tmp_path) == str(tmp_path)  # exists
    with pytest.raises(RobotDescriptionError) as caught:
        resolve_robot('rl16')
    assert str(caught.value) == (f'rl16: no such file, and no shipped robot of that name '
                                 f'(shipped: {", ".join(shipped_robots())})')
    assert is_urdf('a.URDF') and is_urdf('a.urdf.xacro') and not is_urdf('a.yaml')


def test_a_dh_file_loads_as_it_is():
    robot = load_robot('rl15')
    assert robot.urdf is None and robot.conversion is None and robot.summary() == ''
    assert robot.model.source == shipped_robot_path('rl15') and robot.model.urdf is None


def test_a_urdf_file_and_a_urdf_text_convert_alike(tmp_path):
    path = tmp_path / 'two.urdf'
    path.write_text(URDF)
    from_file = load_robot(path, tip='l2', convention='modified')
    from_text = robot_from_urdf_text(URDF, 'parameter robot_description', tip='l2',
                                     convention='modified')
    for robot, source in ((from_file, str(path)), (from_text, 'parameter robot_description')):
        assert robot.urdf == URDF and robot.model.urdf == URDF
        assert robot.model.source == source and robot.model.chain.convention == 'modified'
        assert robot.conversion.base == 'b' and robot.conversion.tip == 'l2'
        assert robot.summary() == (f'converted URDF {source}: chain b -> l2, 2 DH rows '
                                   f'(modified), 2 URDF links')
    assert from_file.model.frame_names == from_text.model.frame_names


@pytest.mark.parametrize('text', ['', '   \n', None, 3])
def test_an_empty_robot_description_is_one_line(text):
    with pytest.raises(RobotDescriptionError, match='^robot_description: empty; give URDF XML$'):
        robot_from_urdf_text(text)


def test_a_loaded_robot_cannot_be_changed():
    robot = load_robot('rl15')
    with pytest.raises(dataclasses.FrozenInstanceError):
        robot.urdf = 'x'
    assert isinstance(robot, LoadedRobot) and os.path.isfile(robot.model.source)


# -- a file named by someone else (a run-time parameter) ---------------------------------
def access_to(*folders, xacro=False):
    return FileAccess(tuple(str(f) for f in folders), xacro)


def test_files_outside_the_allowed_folders_are_not_opened(tmp_path):
    allowed, elsewhere = tmp_path / 'robots', tmp_path / 'private'
    allowed.mkdir()
    elsewhere.mkdir()
    secret = elsewhere / 'shadow'
    secret.write_text('root:*:20228:0:99999:7::\n')
    (allowed / 'link.yaml').symlink_to(secret)            # a symlink out of the folder
    (allowed / 'arm.yaml').write_text(open(shipped_robot_path('rl15')).read())
    for path in (secret, allowed / 'link.yaml', allowed / '..' / 'private' / 'shadow',
                 '/etc/passwd'):
        with pytest.raises(RobotDescriptionError, match='not in the folders robot files may '
                           'be read from') as caught:
            load_robot(str(path), access=access_to(allowed))
        assert 'root:' not in caught.value.public
    assert load_robot(str(allowed / 'arm.yaml'), access=access_to(allowed)).model.dof == 6


def test_a_file_in_the_folders_that_is_no_robot_is_not_quoted(tmp_path):
    for name, text in (('shadow', 'root:*:20228:0:99999:7::\n'), ('env.yaml', 'KEY: hunter2'),
                       ('key.urdf', '-----BEGIN KEY----- hunter2'),
                       ('notes.urdf', '<notes>hunter2</notes>')):
        (tmp_path / name).write_text(text)
        with pytest.raises(RobotDescriptionError) as caught:
            load_robot(str(tmp_path / name), access=access_to(tmp_path))
        assert 'hunter2' not in caught.value.public and 'root:' not in caught.value.public
        assert '\n' not in caught.value.public


def test_a_xacro_named_at_run_time_is_not_run_unless_allowed(tmp_path):
    marker = tmp_path / 'marker'
    path = tmp_path / 'arm.urdf.xacro'
    path.write_text('<?xml version="1.0"?><robot name="r" xmlns:xacro="http://www.ros.org/wiki/'
                    f'xacro"><link name="${{open(\'{marker}\', \'w\')}}"/></robot>')
    with pytest.raises(RobotDescriptionError, match='a .xacro file is a program'):
        load_robot(str(path), access=access_to(tmp_path))
    with pytest.raises(RobotDescriptionError, match='xacro failed') as caught:
        load_robot(str(path), access=access_to(tmp_path, xacro=True))
    assert caught.value.public == f'{path}: xacro failed'
    assert not marker.exists()
    path.write_text(f'<?xml version="1.0"?><robot name="r" xmlns:xacro="http://www.ros.org/'
                    f'wiki/xacro"><xacro:property name="l" value="0.5"/>{URDF[18:]}'
                    .replace('0.3 0 0', '${l} 0 0'))
    model = load_robot(str(path), access=access_to(tmp_path, xacro=True)).model
    assert model.dof == 2


@pytest.mark.parametrize('named', ['arm.urdf.xacro/.', 'arm.urdf.xacro/', 'arm.XACRO',
                                   'link.urdf', 'arm.urdf.xacro/./'])
def test_a_xacro_named_another_way_at_run_time_is_not_run_either(tmp_path, named):
    """The suffix of the name given and of the file read (a peer named 'x.xacro/.')."""
    marker = tmp_path / 'marker'
    program = tmp_path / ('arm.XACRO' if 'XACRO' in named else 'arm.urdf.xacro')
    program.write_text('<?xml version="1.0"?><robot name="r" xmlns:xacro="http://www.ros.org/'
                       f'wiki/xacro"><link name="${{open(\'{marker}\', \'w\')}}"/></robot>')
    (tmp_path / 'link.urdf').symlink_to(program)
    with pytest.raises(RobotDescriptionError, match='a .xacro file is a program'):
        load_robot(str(tmp_path) + '/' + named, access=access_to(tmp_path))
    assert not marker.exists()


def test_the_summary_keeps_every_name_on_one_line():
    urdf = URDF.replace('</robot>', '<link name="odd&#10;name"/><joint name="s&#10;j" '
                        'type="floating"><parent link="l2"/><child link="odd&#10;name"/>'
                        '</joint></robot>')
    summary = robot_from_urdf_text(urdf).summary()
    assert '\n' not in summary and 's?j -> odd?name' in summary


def test_a_fifo_or_a_device_is_refused_without_blocking(tmp_path):
    os.mkfifo(tmp_path / 'pipe.yaml')
    for path in (tmp_path / 'pipe.yaml', '/dev/zero'):
        with pytest.raises(RobotDescriptionError, match='not a regular file|not a file'):
            load_robot(str(path))
    with pytest.raises(RobotDescriptionError, match='not a file'):
        load_robot(str(tmp_path / 'pipe.yaml').replace('.yaml', '.urdf')
                   if os.mkfifo(tmp_path / 'pipe.urdf') is None else '')


def test_the_urdf_modules_are_imported_only_for_a_urdf():
    """A DH robot loads without the URDF modules (dq_fk_bag's start); the names agree."""
    import subprocess
    import sys
    code = ('import sys\n'
            'from dq_fk_ros.description.loading import load_robot, OPTIONS\n'
            'load_robot("rl15")\n'
            'print("dq_fk_ros.description.from_urdf" in sys.modules)\n'
            'from dq_fk_ros.description import from_urdf\n'
            'print(from_urdf.OPTIONS == OPTIONS)\n')
    out = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True,
                         check=True).stdout.split()
    assert out == ['False', 'True']


@pytest.mark.parametrize('suffix', ['', '/.', '/'])
@pytest.mark.parametrize('name', ['arm.urdf.xacro', 'ARM.URDF.XACRO', 'arm.Xacro'])
def test_a_link_named_xacro_to_a_urdf_is_refused_as_a_xacro(tmp_path, name, suffix):
    """The loader goes by the name given: a link called .xacro is run as one, so refused."""
    plain = tmp_path / 'plain.urdf'
    plain.write_text('<robot name="r"><link name="a"/></robot>')
    (tmp_path / name).symlink_to(plain)
    access = access_to(tmp_path)
    assert access.check(str(plain)) == os.path.realpath(plain)   # the file itself is allowed
    with pytest.raises(RobotDescriptionError, match=r'a \.xacro file is a program'):
        access.check(str(tmp_path / name) + suffix)


def test_a_refused_path_is_named_in_at_most_200_characters_and_the_folders_listed(tmp_path):
    allowed = [str(tmp_path / 'a'), str(tmp_path / 'b')]
    far = '/nowhere/' + 'x' * 400
    with pytest.raises(RobotDescriptionError) as caught:
        access_to(*allowed).check(far)
    message = str(caught.value)
    shown = message.split(': not in the folders')[0]
    assert len(shown) <= 200 and shown.startswith('/nowhere/xxx') and '\n' not in message
    assert message.endswith(f'(robot_description_dirs: {allowed[0]}, {allowed[1]})')


def test_a_name_that_says_xacro_is_refused_whatever_file_it_leads_to(tmp_path):
    """A link named like a xacro to a plain URDF: the name decides how it would be read."""
    (tmp_path / 'plain.urdf').write_text(URDF)
    (tmp_path / 'ARM.XACRO').symlink_to(tmp_path / 'plain.urdf')
    for named in ('ARM.XACRO', 'ARM.XACRO/.', 'ARM.XACRO/./'):
        with pytest.raises(RobotDescriptionError, match='a .xacro file is a program'):
            access_to(tmp_path).check(str(tmp_path) + '/' + named)
    assert access_to(tmp_path).check(str(tmp_path / 'plain.urdf')) == \
        os.path.realpath(tmp_path / 'plain.urdf')


def test_a_refusal_names_the_path_in_200_characters_and_every_allowed_folder(tmp_path):
    first, second = tmp_path / 'a', tmp_path / 'b'
    path = str(tmp_path / ('x' * 120) / ('y' * 120) / 'arm.yaml')
    with pytest.raises(RobotDescriptionError) as caught:
        access_to(first, second).check(path)
    assert str(caught.value) == (f'{path[:200]}: not in the folders robot files may be read '
                                 f'from (robot_description_dirs: {first}, {second})')


def test_the_summary_lists_skipped_branches_in_80_characters_a_name():
    j1, j2, child = 'k' * 100, 'm' * 90, 'bad name ' + 'c' * 90
    urdf = URDF.replace('</robot>', f'<link name="{child}"/><link name="bad two"/>'
                        f'<joint name="{j1}" type="fixed"><parent link="l2"/>'
                        f'<child link="{child}"/></joint><joint name="{j2}" type="fixed">'
                        '<parent link="l2"/><child link="bad two"/></joint></robot>')
    summary = robot_from_urdf_text(urdf).summary()
    assert summary.endswith(f'; skipped side branches: {j1[:80]} -> {child[:80]}, '
                            f'{j2[:80]} -> bad two')


def test_the_summary_of_a_tree_counts_its_chains_rows_and_links_below_the_base():
    limit = '<limit lower="-1" upper="1" effort="1" velocity="1"/>'
    joints = ''.join(f'<joint name="j{k}" type="revolute"><parent link="{p}"/><child '
                     f'link="{c}"/><axis xyz="0 0 1"/>{limit}</joint>'
                     for k, (p, c) in enumerate([('b', 'z'), ('b', 'a'), ('a', 'a2')]))
    urdf = ('<robot name="t"><link name="b"/><link name="z"/><link name="a"/><link name="a2"/>'
            + joints + '</robot>')
    assert robot_from_urdf_text(urdf, 'param').summary() == (
        'converted URDF param: 2 DH chains from b (the first to a2), 3 DH rows (standard), '
        '3 URDF links; each transform published once joint states name its joints')


def test_urdf_text_is_converted_from_the_base_to_the_tip_asked_for():
    robot = robot_from_urdf_text(URDF, 'param', base='l1', tip='l2')
    assert (robot.conversion.base, robot.conversion.tip) == ('l1', 'l2')
    assert robot.model.source == 'param' and robot.model.dof == 1
    from dq_fk_ros.description.from_urdf import NODE_OPTIONS
    with pytest.raises(RobotDescriptionError, match="^param: urdf_tip_link 'no' is not a link"):
        robot_from_urdf_text(URDF, 'param', tip='no', options=NODE_OPTIONS)


def test_a_name_with_a_robot_files_suffix_is_a_path_not_a_shipped_name():
    for name in ('nothere.yaml', 'nothere.urdf', 'nothere.urdf.xacro'):
        with pytest.raises(RobotDescriptionError, match=f'^{name}: no such file$'):
            load_robot(name)


@pytest.mark.parametrize('with_access', [False, True])
def test_a_urdf_files_base_tip_and_option_names_reach_the_conversion(tmp_path, with_access):
    from dq_fk_ros.description.from_urdf import NODE_OPTIONS
    path = tmp_path / 'two.urdf'
    path.write_text(URDF)
    access = access_to(tmp_path) if with_access else None
    robot = load_robot(str(path), base='l1', tip='l2', access=access)
    assert (robot.conversion.base, robot.conversion.tip, robot.model.dof) == ('l1', 'l2', 1)
    with pytest.raises(RobotDescriptionError,
                       match=f"^{path}: urdf_tip_link 'no' is not a link"):
        load_robot(str(path), tip='no', access=access, options=NODE_OPTIONS)


def xacro_arm(folder, body):
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / 'arm.urdf.xacro'
    path.write_text('<?xml version="1.0"?><robot name="r" xmlns:xacro="http://www.ros.org/'
                    f'wiki/xacro">{body}{URDF[18:]}')
    return path


def test_a_xacro_named_at_run_time_reads_only_in_the_allowed_folders(tmp_path):
    """Not in the rest of its package: the folders allowed, not the file's package, bound it."""
    package = tmp_path / 'pkg'
    (package / 'urdf').mkdir(parents=True)
    (package / 'package.xml').write_text('<package><name>pkg</name></package>')
    (package / 'secret.xacro').write_text('<?xml version="1.0"?><robot xmlns:xacro="http://'
                                          'www.ros.org/wiki/xacro"/>')
    path = xacro_arm(package / 'urdf', '<xacro:include filename="../secret.xacro"/>')
    with pytest.raises(RobotDescriptionError, match='xacro failed: refused, outside the robot'):
        load_robot(str(path), access=access_to(package / 'urdf', xacro=True))
    assert load_robot(str(path), access=access_to(package, xacro=True)).model.dof == 2


def test_a_xacro_named_at_run_time_finds_the_packages_given_and_stops_when_asked(tmp_path):
    helper = tmp_path / 'helper'
    helper.mkdir()
    (helper / 'length.xacro').write_text('<?xml version="1.0"?><robot xmlns:xacro="http://'
                                         'www.ros.org/wiki/xacro"><xacro:property name="l" '
                                         'value="0.5"/></robot>')
    body = '<xacro:include filename="$(find helper)/length.xacro"/>'
    path = xacro_arm(tmp_path / 'arm', body)
    access = access_to(tmp_path, xacro=True)
    robot = load_robot(str(path), access=access, packages={'helper': str(helper)})
    assert robot.model.dof == 2
    with pytest.raises(RobotDescriptionError, match="package 'helper' not found"):
        load_robot(str(path), access=access)   # no package of that name anywhere
    # a file that expands for ever (10**9 links): stopped by the FileAccess's should_stop
    # at its first question, never by finishing first
    bomb = ['<xacro:macro name="m0"><link name="x"/></xacro:macro>'] + [
        f'<xacro:macro name="m{k}">' + f'<xacro:m{k - 1}/>' * 10 + '</xacro:macro>'
        for k in range(1, 10)]
    path = xacro_arm(tmp_path / 'bomb', ''.join(bomb) + '<xacro:m9/>')
    stopping = dataclasses.replace(access, should_stop=lambda: True)
    with pytest.raises(RobotDescriptionError, match='xacro stopped: shutting down'):
        load_robot(str(path), access=stopping)
