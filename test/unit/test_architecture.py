"""
The layers of the package (README "Architecture"): who may import whom.

Every module of ``dq_fk_ros`` is parsed (not imported) and every import in it, also those
inside functions, is checked against the layer rules.
"""

import ast
import os
import sys

import pytest

PACKAGE = os.path.join(os.path.dirname(os.path.dirname(os.path.dirname(
    os.path.abspath(__file__)))), 'dq_fk_ros')
# bottom up: a layer may import its own modules and those of the layers before it
LAYERS = ('kinematics', 'description', 'messages', 'bag', 'ros', 'cli')
# what each layer may import from outside the standard library and the package
THIRD_PARTY = {
    'kinematics': {'numpy'},
    'description': {'numpy', 'yaml', 'ament_index_python', 'matplotlib', 'xacro'},
    'messages': {'numpy'},
    # zstd (the stdlib's compression.zstd from 3.14, its backport before) and lz4: rosbags' own
    # decompressors, called directly to bound a chunk's size
    'bag': {'numpy', 'rosbags', 'mcap', 'compression', 'backports', 'lz4'},
    'ros': {'numpy', 'rclpy', 'aiohttp', 'ament_index_python', 'builtin_interfaces',
            'diagnostic_msgs', 'geometry_msgs',
            'rcl_interfaces', 'rosgraph_msgs', 'sensor_msgs', 'std_msgs', 'tf2_msgs'},
    'cli': {'numpy'},
}


def modules():
    """Yield (layer, path relative to the package) of every module."""
    for folder, _, files in os.walk(PACKAGE):
        for name in sorted(files):
            if name.endswith('.py'):
                rel = os.path.relpath(os.path.join(folder, name), PACKAGE)
                parts = rel.split(os.sep)
                yield (parts[0] if len(parts) > 1 else None), rel


def imported(path):
    """Every module name an ``import`` or ``from ... import`` in the file names."""
    with open(os.path.join(PACKAGE, path), encoding='utf-8') as stream:
        tree = ast.parse(stream.read())
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            yield from (alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            assert node.level == 0, f'{path}: relative import; use dq_fk_ros.<layer>...'
            yield node.module


def test_every_module_is_in_a_layer():
    stray = [rel for layer, rel in modules() if layer is None and rel != '__init__.py']
    assert stray == []
    assert {layer for layer, _ in modules() if layer} == set(LAYERS)


@pytest.mark.parametrize('layer, path', [m for m in modules() if m[0]])
def test_imports_follow_the_layers(layer, path):
    below = set(LAYERS[:LAYERS.index(layer) + 1])
    for name in imported(path):
        top = name.split('.')[0]
        if top == 'dq_fk_ros':
            target = name.split('.')[1] if '.' in name else None
            assert target in below, f'{path} (layer {layer}) imports {name}'
        elif top not in sys.stdlib_module_names:
            assert top in THIRD_PARTY[layer], f'{path} (layer {layer}) imports {name}'


def test_the_rules_catch_a_breach(tmp_path, monkeypatch):
    """The check above fails on a kinematics module that imports rclpy or the ROS layer."""
    bad = tmp_path / 'kinematics'
    bad.mkdir()
    (bad / 'leak.py').write_text('import numpy\n\n\ndef f():\n    import rclpy\n')
    (bad / 'up.py').write_text('from dq_fk_ros.ros.node import DqFkNode\n')
    monkeypatch.setattr(sys.modules[__name__], 'PACKAGE', str(tmp_path))
    for path in ('kinematics/leak.py', 'kinematics/up.py'):
        with pytest.raises(AssertionError, match='imports'):
            test_imports_follow_the_layers('kinematics', path)
