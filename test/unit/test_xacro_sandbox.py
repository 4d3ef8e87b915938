"""
xacro files are programs: what they may do here (read their package, compute) and not.

Every escape below ran a command or read a file through xacro 2.1.1 as it comes (the first
test shows one does); expanded through the package, none does, and each is one line.
"""

import os
import threading

from dq_fk_ros.description.from_urdf import load_urdf_description
from dq_fk_ros.description.urdf_reader import read_urdf_text
from dq_fk_ros.description.xacro_sandbox import (
    check_expression, expand_xacro, TIME_LIMIT_S, XacroRefused)
from dq_fk_ros.errors import RobotDescriptionError
import pytest
from xacro_texts import ESCAPES, escapes, HEAD, link, TAIL, write


@pytest.mark.parametrize('name', ESCAPES)
def test_each_escape_runs_code_in_xacro_as_it_comes(tmp_path, name):
    """The attacks the sandbox stops: stock xacro runs them (so the test below can fail)."""
    import xacro
    marker = tmp_path / 'marker'
    path = write(tmp_path, 'evil.xacro', escapes(marker)[name])
    xacro.process_file(str(path))
    assert marker.exists()


@pytest.mark.parametrize('name', ESCAPES)
def test_escapes_are_refused_and_nothing_runs(tmp_path, name):
    marker = tmp_path / 'marker'
    path = write(tmp_path, 'evil.urdf.xacro', escapes(marker)[name])
    with pytest.raises(RobotDescriptionError) as caught:
        read_urdf_text(path)
    message = str(caught.value)
    assert message.startswith(f'{path}: xacro failed: ') and '\n' not in message, message
    assert not marker.exists()


@pytest.mark.parametrize('expression', [
    '[c for x in [()] for c in x.__class__.__mro__]',
    'lambda: __import__',
    "'__globals__'",
    'f(__x=1)',
    'lambda __a: 1',
    "b'__'",
])
def test_check_expression_refuses_double_underscores_anywhere(expression):
    with pytest.raises(XacroRefused):
        check_expression(expression)


@pytest.mark.parametrize('expression', ['1 + 2', 'pi / 2', "'link_' + str(3)",
                                        '[x * 2 for x in range(3)]', 'radians(90)',
                                        "dict(a=1)['a']", 'a_b'])
def test_check_expression_lets_ordinary_xacro_through(expression):
    check_expression(expression)


def test_reads_outside_the_package_and_the_environment_are_refused(tmp_path, monkeypatch):
    secret = tmp_path / 'secret.yaml'
    secret.write_text('password: hunter2\n')
    robot = tmp_path / 'pkg'
    robot.mkdir()
    monkeypatch.setenv('DQ_FK_TEST_SECRET', 'hunter2')
    cases = {
        'load_yaml': f'<link name="${{xacro.load_yaml(\'{secret}\')[\'password\']}}"/>',
        'include': f'<xacro:include filename="{secret}"/><link name="a"/>',
        'env': '<link name="$(env DQ_FK_TEST_SECRET)"/>',
        'optenv': '<link name="x$(optenv DQ_FK_TEST_SECRET)"/><link name="a"/>',
    }
    for name, body in cases.items():
        path = write(robot, f'{name}.urdf.xacro', HEAD + body + TAIL)
        try:
            text = read_urdf_text(path, read_roots=[robot])
        except RobotDescriptionError as exc:
            assert 'hunter2' not in str(exc), name
        else:
            assert 'hunter2' not in text, name


def test_the_package_and_its_yaml_are_readable(tmp_path):
    """What xacro files really do: include their package's files and read its YAML."""
    package = tmp_path / 'arm_description'
    (package / 'urdf').mkdir(parents=True)
    (package / 'config').mkdir()
    (package / 'package.xml').write_text('<package><name>arm_description</name></package>')
    (package / 'config' / 'arm.yaml').write_text('length: 0.25\n')
    write(package / 'urdf', 'link.xacro', '<?xml version="1.0"?>\n<robot xmlns:xacro='
          '"http://www.ros.org/wiki/xacro"><xacro:macro name="seg" params="n parent">'
          '<link name="l${n}"/><joint name="j${n}" type="revolute"><parent link="${parent}"/>'
          '<child link="l${n}"/><origin xyz="0 0 ${cfg.length}"/><axis xyz="0 0 1"/>'
          '<limit lower="-1" upper="1" effort="1" velocity="1"/></joint></xacro:macro>'
          '</robot>\n')
    path = write(package / 'urdf', 'arm.urdf.xacro', HEAD +
                 '<xacro:property name="cfg" value="${xacro.load_yaml(\'../config/arm.yaml\')}"/>'
                 '<xacro:include filename="link.xacro"/><link name="base"/>'
                 '<xacro:seg n="1" parent="base"/><xacro:seg n="2" parent="l1"/>' + TAIL)
    conversion, text = load_urdf_description(path)
    assert '<origin xyz="0 0 0.25"/>' in text and conversion.tip == 'l2'


def macro_bomb(levels=9):
    """Nested macros: 10**levels links from a few hundred bytes."""
    lines = ['<xacro:macro name="m0"><link name="x"/></xacro:macro>']
    for k in range(1, levels + 1):
        lines.append(f'<xacro:macro name="m{k}">' + f'<xacro:m{k - 1}/>' * 10 +
                     '</xacro:macro>')
    return HEAD + '\n'.join(lines) + f'\n<xacro:m{levels}/>\n' + TAIL


@pytest.mark.parametrize('name, body', [
    ('macros', macro_bomb()),
    ('power', HEAD + '<link name="${2**2**40}"/>' + TAIL),
    ('long string', HEAD + '<xacro:property name="s" value="${\'x\' * 10**8}"/>'
     '<xacro:property name="t" value="${s * 100}"/><link name="${t}"/>' + TAIL),
])
def test_bombs_are_stopped_within_the_limits(tmp_path, name, body):
    path = write(tmp_path, 'bomb.urdf.xacro', body)
    caught = []

    def expand():
        try:
            expand_xacro(path, [tmp_path], time_limit_s=3.0)
        except XacroRefused as refused:
            caught.append(refused)
    expanding = threading.Thread(target=expand, daemon=True)
    expanding.start()
    expanding.join(3.0 + 30.0)   # the deadline: a bomb not stopped by its limits fails here
    assert not expanding.is_alive(), f'{name}: still expanding 33 s later'
    assert len(caught) == 1 and '\n' not in str(caught[0])


def test_the_default_limit_is_what_the_docs_say():
    readme = open(os.path.join(os.path.dirname(__file__), '..', '..', 'docs', 'security.md'),
                  encoding='utf-8').read()
    assert f'{TIME_LIMIT_S:g} s' in readme and '1 GiB' in readme


def test_should_stop_ends_the_expansion_early(tmp_path):
    path = write(tmp_path, 'bomb.urdf.xacro', macro_bomb())
    asked = []

    def stop():
        asked.append(1)
        return len(asked) > 3
    with pytest.raises(XacroRefused, match='shutting down'):
        expand_xacro(path, [tmp_path], time_limit_s=30.0, should_stop=stop)
    assert len(asked) == 4  # not before it said so, and by it (30 s limit: 'shutting down')


def test_a_relative_path_is_expanded(tmp_path, monkeypatch):
    """The child runs in the file's folder: a relative path was looked up twice over."""
    (tmp_path / 'robots').mkdir()
    write(tmp_path / 'robots', 'r.urdf.xacro', HEAD + '<xacro:property name="n" value="a"/>'
          '<link name="${n}"/>' + TAIL)
    monkeypatch.chdir(tmp_path)
    assert '<link name="a"/>' in read_urdf_text('robots/r.urdf.xacro')


def test_a_read_of_python_internals_is_refused_by_the_check_itself(tmp_path):
    """The check runs before xacro evaluates: a harmless-looking read of __subclasses__."""
    path = write(tmp_path, 'peek.urdf.xacro', link(
        '${[c.__name__ for c in ().__class__.__base__.__subclasses__()][0]}'))
    with pytest.raises(XacroRefused, match="uses '__name__': names with __ reach Python "
                       'internals and are not evaluated'):
        expand_xacro(path, [tmp_path])


def test_a_xacro_error_is_said_once_without_its_class(tmp_path):
    path = write(tmp_path, 'env.urdf.xacro', link('$(env DQ_FK_NOT_SET_ANYWHERE)'))
    with pytest.raises(XacroRefused) as caught:
        expand_xacro(path, [tmp_path])
    assert str(caught.value) == "environment variable 'DQ_FK_NOT_SET_ANYWHERE' is not set"


def test_a_macro_that_calls_itself_is_one_line(tmp_path):
    path = write(tmp_path, 'loop.urdf.xacro', HEAD + '<xacro:macro name="m"><xacro:m/>'
                 '</xacro:macro><xacro:m/>' + TAIL)
    with pytest.raises(XacroRefused) as caught:
        expand_xacro(path, [tmp_path])
    assert str(caught.value) == 'xacro nested too deeply (macros or expressions)'


@pytest.mark.parametrize('body, refused', [
    ('<xacro:include filename="/etc/passwd"/><link name="a"/>', '/etc/passwd'),
    ('<link name="${xacro.load_yaml(\'/etc/hostname\')}"/>', '/etc/hostname'),
])
def test_a_refused_read_says_what_and_why_in_one_line(tmp_path, body, refused):
    """Nothing is read; the user sees the file refused and the rule, not a TypeError."""
    robot = tmp_path / 'pkg'
    robot.mkdir()
    path = write(robot, 'r.urdf.xacro', HEAD + body + TAIL)
    with pytest.raises(RobotDescriptionError) as caught:
        read_urdf_text(path, read_roots=[robot])
    message = str(caught.value)
    assert '\n' not in message and refused in message, message
    assert "outside the robot's package" in message and 'NoneType' not in message, message
    assert message.count('outside') == 1, message


def test_links_are_followed_out_of_the_package_only_if_every_one_keeps_its_name(tmp_path):
    # a folder link with another name, and a renamed link in the middle of a chain, had let
    # xacro read files outside the package: only the first and the last names were compared
    outside = tmp_path / 'outside'
    (outside / 'stuff').mkdir(parents=True)
    write(outside / 'stuff', 'secret.yaml', 'password: hunter2\n')
    write(outside / 'stuff', 'part.xacro', '<robot xmlns:xacro="http://www.ros.org/wiki/xacro">'
          '<link name="hunter2"/></robot>\n')
    write(outside, 'middle.yaml', 'password: hunter2\n')
    package = tmp_path / 'pkg'
    (package / 'urdf').mkdir(parents=True)
    (package / 'package.xml').write_text('<package><name>pkg</name></package>')
    os.symlink(outside / 'stuff', package / 'config')   # a folder link: config -> stuff
    os.symlink(outside / 'middle.yaml', outside / 'secret.yaml')   # secret -> middle
    os.symlink(outside / 'secret.yaml', package / 'urdf' / 'secret.yaml')   # chain
    cases = {
        'folder load_yaml': "${xacro.load_yaml('../config/secret.yaml')['password']}",
        'folder include': '<xacro:include filename="../config/part.xacro"/>',
        'chain load_yaml': "${xacro.load_yaml('secret.yaml')['password']}",
    }
    for name, body in cases.items():
        text = body if body.startswith('<') else f'<link name="{body}"/>'
        path = write(package / 'urdf', f'{name.replace(" ", "_")}.urdf.xacro',
                     HEAD + text + '<link name="a"/>' + TAIL)
        with pytest.raises(RobotDescriptionError, match='refused, outside') as caught:
            read_urdf_text(path, read_roots=[package])
        assert 'hunter2' not in str(caught.value), name
    # what a build makes is still followed: share/pkg/urdf/x -> src/pkg/urdf/x, and a
    # folder link that keeps its name (src/pkg -> a clone named pkg)
    clone = tmp_path / 'clones' / 'pkg'
    (clone / 'urdf').mkdir(parents=True)
    (clone / 'package.xml').write_text('<package><name>pkg</name></package>')
    write(clone / 'urdf', 'part.xacro', '<robot xmlns:xacro="http://www.ros.org/wiki/xacro">'
          '<link name="from_the_clone"/></robot>\n')
    share = tmp_path / 'install' / 'share' / 'pkg' / 'urdf'
    share.mkdir(parents=True)
    (share.parent / 'package.xml').write_text('<package><name>pkg</name></package>')
    (tmp_path / 'ws' / 'src').mkdir(parents=True)
    os.symlink(clone, tmp_path / 'ws' / 'src' / 'pkg')
    os.symlink(tmp_path / 'ws' / 'src' / 'pkg' / 'urdf' / 'part.xacro', share / 'part.xacro')
    path = write(share, 'robot.urdf.xacro', HEAD + '<xacro:include filename="part.xacro"/>'
                 + '<link name="a"/>' + TAIL)
    assert 'from_the_clone' in read_urdf_text(path, read_roots=[share.parent])
