"""The tf2 compat path: ``import tf2_ros`` (and its kin) finds dq_fk_ros, by re-exports only."""

import ast
import os
import subprocess
import sys

from dq_fk_ros.cli import compat_path
import pytest

COMPAT = compat_path.HERE
MODULES = ['tf2_ros', 'tf2_ros.buffer', 'tf2_ros.transform_listener',
           'tf2_ros.transform_broadcaster', 'tf2_ros.static_transform_broadcaster',
           'tf2_ros.buffer_interface', 'tf2_ros.buffer_client', 'tf2_py', 'tf2_py._tf2_py',
           'tf2_geometry_msgs', 'tf2_geometry_msgs.tf2_geometry_msgs', 'tf2_sensor_msgs',
           'tf2_sensor_msgs.tf2_sensor_msgs', 'sensor_msgs_py.point_cloud2']


def run(code, pythonpath, cwd):
    env = dict(os.environ, PYTHONPATH=pythonpath)
    return subprocess.run([sys.executable, '-c', code], env=env, cwd=cwd, capture_output=True,
                          text=True, timeout=120)


def compat_files():
    for folder, _, files in os.walk(COMPAT):
        for name in files:
            if name.endswith('.py'):
                yield os.path.join(folder, name)


def test_every_compat_module_is_a_re_export_not_a_copy():
    found = list(compat_files())
    assert len(found) == 15
    for path in found:
        tree = ast.parse(open(path, encoding='utf-8').read())
        for node in tree.body:
            assert isinstance(node, (ast.Expr, ast.Import, ast.ImportFrom, ast.Assign)), \
                f'{path}: {type(node).__name__} (only imports and __all__ belong here)'
            if isinstance(node, ast.ImportFrom):
                assert node.module.startswith('dq_fk_ros.'), path


def test_the_printed_path_makes_every_tf2_module_resolve_to_dq_fk_ros(tmp_path):
    path = os.pathsep.join(compat_path.compat_folders())
    code = ('import importlib, sys\n'
            f'for name in {MODULES!r}:\n'
            '    module = importlib.import_module(name)\n'
            "    print(name, getattr(module, '__file__', ''))\n"
            'import tf2_ros, tf2_py, tf2_ros.buffer as b, tf2_geometry_msgs as g\n'
            'from dq_fk_ros import tf\n'
            'from dq_fk_ros.ros import tf_geometry, tf_message_core\n'
            'assert tf2_ros.Buffer is tf.Buffer is b.Buffer\n'
            'assert tf2_ros.LookupException is tf2_py.LookupException is tf.LookupException\n'
            'assert tf2_py.BufferCore is tf_message_core.MessageBufferCore\n'
            'assert g.do_transform_pose is tf_geometry.do_transform_pose\n'
            'assert tf2_ros.TransformBroadcaster.sendTransform\n')
    done = run(code, path, str(tmp_path))
    assert done.returncode == 0, done.stderr
    for line in done.stdout.splitlines():
        assert line.split()[1].startswith(COMPAT + os.sep), line


def test_without_the_path_nothing_named_tf2_is_importable_from_the_package(tmp_path):
    """Nothing is installed silently: the folders are not packages of dq_fk_ros's."""
    done = run('import importlib.util as u\n'
               "print([n for n in ('tf2_ros', 'tf2_py', 'tf2_geometry_msgs', "
               "'tf2_sensor_msgs', 'sensor_msgs_py') if u.find_spec(n)])",
               '', str(tmp_path))
    assert done.stdout.strip() == '[]', done.stderr
    assert not os.path.exists(os.path.join(COMPAT, '__init__.py'))


def fake_package(root, name):
    os.makedirs(os.path.join(root, name))
    open(os.path.join(root, name, '__init__.py'), 'w').close()


@pytest.mark.parametrize('own', [[], ['sensor_msgs_py'], ['tf2_ros', 'sensor_msgs_py']])
def test_sensor_msgs_py_is_offered_only_where_none_is_installed(tmp_path, own):
    for name in own:
        fake_package(str(tmp_path), name)
    done = subprocess.run([sys.executable, '-m', 'dq_fk_ros.cli.dq_fk', 'tf', 'compat-path'],
                          env=dict(os.environ, PYTHONPATH=str(tmp_path)), capture_output=True,
                          text=True, timeout=120, cwd=str(tmp_path))
    assert done.returncode == 0, done.stderr
    folders = done.stdout.strip().split(os.pathsep)
    assert folders[0] == os.path.join(COMPAT, 'tf2')
    assert (os.path.join(COMPAT, 'sensor_msgs_py') in folders) == ('sensor_msgs_py' not in own)
    assert ('note: this environment has its own tf2_ros' in done.stderr) == ('tf2_ros' in own)
