"""What ``pip install dq_fk_ros`` needs, declared where pip reads it (setup.py, pyproject.toml)."""

import ast
import os
import re
import runpy
import tomllib

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
OPTIONAL = {'ruamel.yaml.clib', 'zlib-ng', 'scipy'}   # speed-ups, and calibrate's extra


def pins(path):
    """Return ``{name: requirement}`` of a requirements file (comments dropped)."""
    found = {}
    for line in open(os.path.join(ROOT, path), encoding='utf-8'):
        line = line.split('#')[0].strip()
        if line:
            found[re.split(r'[\[=<>]', line)[0].lower()] = line
    return found


def install_requires():
    tree = ast.parse(open(os.path.join(ROOT, 'setup.py'), encoding='utf-8').read())
    call = next(n for n in ast.walk(tree) if isinstance(n, ast.Call) and
                getattr(n.func, 'id', '') == 'setup')
    value = next(k.value for k in call.keywords if k.arg == 'install_requires')
    return {re.split(r'[\[=<>]', e.value)[0].lower() for e in value.elts}


def test_pip_install_brings_every_runtime_requirement_but_the_optional_ones():
    runtime = set(pins('requirements/runtime.txt'))
    assert runtime - OPTIONAL <= install_requires(), runtime - OPTIONAL - install_requires()


def test_the_isolated_build_has_what_rosidl_needs_for_tf2_msgs_at_the_same_pins():
    with open(os.path.join(ROOT, 'pyproject.toml'), 'rb') as stream:
        system = tomllib.load(stream)['build-system']
    # no backend named: setuptools' legacy one, which make setup's setup.py develop needs
    assert 'build-backend' not in system
    requires = system['requires']
    wanted = list(pins('requirements/tf2_msgs-build.txt').values())
    runtime = pins('requirements/runtime.txt')
    wanted += [runtime['ros-jazzy-rclpy'], runtime['ros-jazzy-common-interfaces']]
    assert set(wanted) <= set(requires), set(wanted) - set(requires)


@pytest.fixture()
def tf2_msgs_build():
    return runpy.run_path(os.path.join(ROOT, 'scripts', 'tf2_msgs_build.py'))


def test_nothing_is_built_where_tf2_msgs_is_importable_or_skipped(tf2_msgs_build, monkeypatch):
    # this venv has tf2_msgs (make setup): a ROS install, colcon and make setup build nothing
    assert tf2_msgs_build['wanted']() is False
    monkeypatch.setenv('DQ_FK_TF2_MSGS', 'skip')
    assert tf2_msgs_build['wanted']() is False


def test_make_setup_builds_nothing_into_a_venv_whose_tf2_msgs_it_did_not_build(
        tf2_msgs_build, tmp_path, capsys):
    # this venv's tf2_msgs is importable; a venv without our marker: a ROS install's
    assert tf2_msgs_build['main'](['--into', str(tmp_path)]) == 0
    assert capsys.readouterr().out == \
        'tf2_msgs is provided by the environment; not building the vendored copy\n'
    assert list(tmp_path.iterdir()) == []


def test_an_installed_prefix_goes_into_the_wheel_as_package_libraries_and_share(
        tf2_msgs_build, tmp_path, monkeypatch):
    prefix = tmp_path / 'build' / 'tf2_msgs' / 'prefix'
    package = prefix / 'lib' / 'python3.11' / 'site-packages' / 'tf2_msgs'
    (package / 'msg').mkdir(parents=True)
    for path in (package / '__init__.py', package / 'msg' / '_tf_message.py',
                 package / 'tf2_msgs_s__rosidl_typesupport_c.so',
                 prefix / 'lib' / 'libtf2_msgs__rosidl_generator_c.so',
                 prefix / 'share' / 'tf2_msgs' / 'package.xml',
                 prefix / 'share' / 'ament_index' / 'resource_index' / 'packages' / 'tf2_msgs'):
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text('')
    monkeypatch.chdir(tmp_path)
    parts = tf2_msgs_build['wheel_parts'](str(prefix))
    where = 'build/tf2_msgs/prefix/lib/python3.11/site-packages/tf2_msgs'
    kinds = ['msg', 'srv', 'action']   # TFMessage, TF2Error; FrameGraph; LookupTransform
    assert parts['packages'] == ['tf2_msgs'] + [f'tf2_msgs.{k}' for k in kinds]
    assert parts['package_dir'] == dict({'tf2_msgs': where},
                                        **{f'tf2_msgs.{k}': f'{where}/{k}' for k in kinds})
    assert parts['package_data'] == dict({'tf2_msgs': ['*.so']},
                                         **{f'tf2_msgs.{k}': ['*.py'] for k in kinds})
    assert sorted(parts['data_files']) == [
        ('lib', ['build/tf2_msgs/prefix/lib/libtf2_msgs__rosidl_generator_c.so']),
        ('share/ament_index/resource_index/packages',
         ['build/tf2_msgs/prefix/share/ament_index/resource_index/packages/tf2_msgs']),
        ('share/tf2_msgs', ['build/tf2_msgs/prefix/share/tf2_msgs/package.xml'])]
