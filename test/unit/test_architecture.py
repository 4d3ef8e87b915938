"""
The layers of the package (docs/architecture.md): who may import whom.

Every module of ``dq_fk_ros`` is parsed (not imported) and every import in it, also those
inside functions, is checked against the layer rules.
"""

import ast
import os
import sys

import pytest

PACKAGE = os.path.join(os.path.dirname(os.path.dirname(os.path.dirname(
    os.path.abspath(__file__)))), 'dq_fk_ros')
# bottom up: a layer may import its own modules and those of the layers before it; at the
# bottom the package's errors (one module, dq_fk_ros/errors.py, that every layer imports)
LAYERS = ('errors', 'kinematics', 'description', 'messages', 'transforms', 'storage', 'bag',
          'calibration', 'ros', 'viewers', 'cli', 'testing', 'compat')
# modules beside the layers: the package's surfaces, which may import any layer
SURFACES = ('__init__.py', 'tf.py')
# what each layer may import from outside the standard library and the package
THIRD_PARTY = {
    'errors': set(),
    'kinematics': {'numpy'},
    'description': {'numpy', 'yaml', 'ament_index_python', 'matplotlib', 'xacro'},
    'messages': {'numpy'},
    'transforms': {'numpy'},
    # zstd (the stdlib's compression.zstd from 3.14, its backport before) and lz4: rosbags' own
    # decompressors, called directly to bound a chunk's size
    # zlib_ng: zlib's CRC-32 with SIMD (optional: zlib's is the fallback)
    'storage': {'numpy', 'rosbags', 'mcap', 'compression', 'backports', 'lz4', 'yaml',
                'zlib_ng'},
    'bag': {'numpy', 'rosbags', 'mcap', 'yaml', 'distributed'},
    # scipy: Levenberg-Marquardt; ruamel: the robot file written back with its comments
    'calibration': {'numpy', 'scipy', 'ruamel', 'matplotlib'},
    'ros': {'numpy', 'rclpy', 'aiohttp', 'foxglove', 'ament_index_python', 'builtin_interfaces',
            'diagnostic_msgs', 'geometry_msgs',
            'rcl_interfaces', 'rosgraph_msgs', 'sensor_msgs', 'std_msgs', 'tf2_msgs'},
    'viewers': {'numpy', 'rclpy', 'aiohttp', 'foxglove', 'geometry_msgs', 'sensor_msgs',
                'std_msgs', 'tf2_msgs'},
    'cli': {'numpy'},
    # the pytest plugin users get: its fixtures start the programs and read TF back
    'testing': {'pytest', 'rclpy', 'geometry_msgs', 'sensor_msgs'},
    # the tf2 compat path (dq_fk tf compat-path): re-exports of the layers' names only
    'compat': set(),
}


def modules():
    """Yield (layer, path relative to the package) of every module."""
    for folder, _, files in os.walk(PACKAGE):
        for name in sorted(files):
            if name.endswith('.py'):
                rel = os.path.relpath(os.path.join(folder, name), PACKAGE)
                parts = rel.split(os.sep)
                layer = parts[0] if len(parts) > 1 else 'errors' if rel == 'errors.py' else None
                yield layer, rel


def imported(path, at_run_time_only=False):
    """
    Every module name an ``import`` or ``from ... import`` in the file names.

    :param at_run_time_only: leave out those under ``if TYPE_CHECKING:`` (for annotations
        only: they never run, so they make no import cycle).
    """
    with open(os.path.join(PACKAGE, path), encoding='utf-8') as stream:
        tree = ast.parse(stream.read())
    skipped = set()
    if at_run_time_only:
        for node in ast.walk(tree):
            if isinstance(node, ast.If) and getattr(node.test, 'id', None) == 'TYPE_CHECKING':
                skipped.update(id(n) for n in ast.walk(node))
    for node in ast.walk(tree):
        if id(node) in skipped:
            continue
        if isinstance(node, ast.Import):
            yield from (alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            assert node.level == 0, f'{path}: relative import; use dq_fk_ros.<layer>...'
            if node.module == 'dq_fk_ros':   # the package itself: each name it gives
                yield from (f'dq_fk_ros.{alias.name}' for alias in node.names)
            else:
                yield node.module


def test_every_module_is_in_a_layer():
    stray = [rel for layer, rel in modules() if layer is None and rel not in SURFACES]
    assert stray == []
    for surface in SURFACES:   # a surface gives the layers' names and imports nothing else
        assert all(name.split('.')[0] == 'dq_fk_ros' or name in sys.stdlib_module_names
                   for name in imported(surface)), surface
    assert {layer for layer, _ in modules() if layer} == set(LAYERS)


@pytest.mark.parametrize('layer, path', [m for m in modules() if m[0]])
def test_imports_follow_the_layers(layer, path):
    below = set(LAYERS[:LAYERS.index(layer) + 1])
    for name in imported(path):
        top = name.split('.')[0]
        if top == 'dq_fk_ros':
            target = name.split('.')[1] if '.' in name else None
            # the package's version (dq_fk_ros/__init__.py) is below every layer
            assert target in below | {'__version__'}, f'{path} (layer {layer}) imports {name}'
        elif top not in sys.stdlib_module_names:
            assert top in THIRD_PARTY[layer], f'{path} (layer {layer}) imports {name}'


def test_the_rules_catch_a_breach(tmp_path, monkeypatch):
    """The check above fails on a kinematics module that imports rclpy or the ROS layer."""
    bad = tmp_path / 'kinematics'
    bad.mkdir()
    (bad / 'leak.py').write_text('import numpy\n\n\ndef f():\n    import rclpy\n')
    (bad / 'up.py').write_text('from dq_fk_ros.ros.node import DqFkNode\n')
    (bad / 'surface.py').write_text('from dq_fk_ros import __version__, process_bag\n')
    monkeypatch.setattr(sys.modules[__name__], 'PACKAGE', str(tmp_path))
    for path in ('kinematics/leak.py', 'kinematics/up.py', 'kinematics/surface.py'):
        with pytest.raises(AssertionError, match='imports'):
            test_imports_follow_the_layers('kinematics', path)


def test_the_surface_imports_what_it_names_and_the_errors_have_one_base():
    import subprocess
    import dq_fk_ros
    for name in dq_fk_ros.__all__:
        assert getattr(dq_fk_ros, name).__name__ == name
    for error in ('RobotDescriptionError', 'ParameterError', 'BagError', 'CdrError'):
        assert issubclass(getattr(dq_fk_ros, error), dq_fk_ros.DqFkError), error
        assert getattr(dq_fk_ros, error).__module__ == 'dq_fk_ros.errors', error
    # a parameter is not a robot description
    assert not issubclass(dq_fk_ros.ParameterError, dq_fk_ros.RobotDescriptionError)
    # importing the package loads neither ROS nor rosbags
    code = ('import sys, dq_fk_ros; dq_fk_ros.load_robot; print(sorted(m for m in sys.modules '
            "if m.split('.')[0] in ('rclpy', 'rosbags', 'matplotlib')))")
    out = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True,
                         check=True).stdout
    assert out.strip() == '[]'


def import_graph():
    """
    Return ``{module: {dq_fk_ros modules it imports}}`` of every module of the package.

    Imports under ``if TYPE_CHECKING:`` count: a cycle hidden there is a cycle of design.
    """
    graph = {}
    for _, rel in modules():
        name = 'dq_fk_ros.' + rel[:-3].replace(os.sep, '.')
        name = name[:-len('.__init__')] if name.endswith('.__init__') else name
        graph[name] = {m for m in imported(rel) if m and m.startswith('dq_fk_ros.')}
    return graph


def test_no_import_cycle_between_modules():
    graph = import_graph()
    state = {}

    def visit(node, path):
        state[node] = 'open'
        for target in graph.get(node, ()):
            assert state.get(target) != 'open', ' -> '.join(path + [target])
            if target not in state:
                visit(target, path + [target])
        state[node] = 'done'
    for node in graph:
        if node not in state:
            visit(node, [node])


def test_a_cycle_would_be_found(monkeypatch):
    """The walk above fails on two modules that import each other."""
    graph = {'dq_fk_ros.a': {'dq_fk_ros.b'}, 'dq_fk_ros.b': {'dq_fk_ros.a'}}
    monkeypatch.setattr(sys.modules[__name__], 'import_graph', lambda: graph)
    with pytest.raises(AssertionError, match='dq_fk_ros.a -> dq_fk_ros.b -> dq_fk_ros.a'):
        test_no_import_cycle_between_modules()


def test_docs_architecture_names_every_module():
    text = open(os.path.join(os.path.dirname(PACKAGE), 'docs', 'architecture.md'),
                encoding='utf-8').read()
    missing = [rel for layer, rel in modules() if layer and not rel.endswith('__init__.py')
               and f'`{rel}`' not in text]
    assert missing == []


MAX_MODULE_LINES = 500
MAX_C_LINES = 800


def c_sources():
    """Yield the package's C files (sources and headers), relative to the package."""
    for folder, _, names in os.walk(PACKAGE):
        for name in sorted(names):
            if name.endswith(('.c', '.h')):
                yield os.path.relpath(os.path.join(folder, name), PACKAGE)


def test_every_c_file_is_short_and_in_docs_architecture():
    text = open(os.path.join(os.path.dirname(PACKAGE), 'docs', 'architecture.md'),
                encoding='utf-8').read()
    sizes = {rel: open(os.path.join(PACKAGE, rel), encoding='utf-8').read().count('\n')
             for rel in c_sources()}
    assert len(sizes) >= 2
    assert [f'{rel} ({n} lines)' for rel, n in sizes.items() if n > MAX_C_LINES] == []
    assert [rel for rel in sizes if f'`{rel}`' not in text] == []


def test_no_module_is_long():
    sizes = {rel: open(os.path.join(PACKAGE, rel), encoding='utf-8').read().count('\n')
             for _, rel in modules()}
    assert {rel: n for rel, n in sizes.items() if n > MAX_MODULE_LINES} == {}


MAX_FOLDER_SHARE = 0.22   # of the package's Python lines


def test_no_folder_holds_more_than_its_share_of_the_package():
    lines = {}
    for layer, rel in modules():
        with open(os.path.join(PACKAGE, rel), encoding='utf-8') as stream:
            lines[layer or '.'] = lines.get(layer or '.', 0) + stream.read().count('\n')
    total = sum(lines.values())
    assert {k: f'{n / total:.1%}' for k, n in lines.items() if n > MAX_FOLDER_SHARE * total} \
        == {}


# attributes named with one underscore that the standard library documents as public:
# os._exit, and a namedtuple's _replace (the underscore keeps it apart from field names)
PUBLIC_UNDERSCORED = {'_exit', '_replace'}
MAX_FOREIGN_PRIVATE = 10


def foreign_private_attributes(rel):
    """Yield ``path:line name`` of each read or write of another object's ``_private``."""
    with open(os.path.join(PACKAGE, rel), encoding='utf-8') as stream:
        tree = ast.parse(stream.read())
    for node in ast.walk(tree):
        if isinstance(node, ast.Attribute) and node.attr.startswith('_') and \
                not node.attr.startswith('__') and node.attr not in PUBLIC_UNDERSCORED and \
                not (isinstance(node.value, ast.Name) and node.value.id in ('self', 'cls')):
            yield f'{rel}:{node.lineno} {ast.unparse(node)}'


def test_objects_keep_their_private_state_to_themselves():
    """At most a few reads of another object's private parts: xacro's hooks, rclpy's."""
    found = [line for _, rel in modules() for line in foreign_private_attributes(rel)]
    assert len(found) <= MAX_FOREIGN_PRIVATE, found


def test_a_foreign_private_attribute_would_be_found(tmp_path, monkeypatch):
    (tmp_path / 'bag').mkdir()
    (tmp_path / 'bag' / 'reach.py').write_text(
        'def f(chain, self):\n    self._ok = chain._table\n    os._exit(0)\n'
        '    return chain.__class__, c._replace(a=1)\n')
    monkeypatch.setattr(sys.modules[__name__], 'PACKAGE', str(tmp_path))
    assert list(foreign_private_attributes('bag/reach.py')) == ['bag/reach.py:2 chain._table']


def unannotated(rel):
    """Yield ``name (what is missing)`` of each public function or method without hints."""
    with open(os.path.join(PACKAGE, rel), encoding='utf-8') as stream:
        tree = ast.parse(stream.read())

    def check(function, owner=''):
        if function.name.startswith('_') and function.name != '__init__':
            return
        args = function.args.posonlyargs + function.args.args + function.args.kwonlyargs
        missing = [a.arg for a in args if a.arg not in ('self', 'cls') and a.annotation is None]
        if function.returns is None and function.name != '__init__':
            missing.append('return')
        if missing:
            yield f'{rel}:{function.lineno} {owner}{function.name} ({", ".join(missing)})'
    for node in tree.body:
        if isinstance(node, ast.FunctionDef):
            yield from check(node)
        elif isinstance(node, ast.ClassDef) and not node.name.startswith('_'):
            for item in node.body:
                if isinstance(item, ast.FunctionDef):
                    yield from check(item, node.name + '.')


def test_the_public_functions_of_kinematics_and_description_have_type_hints():
    missing = [line for layer, rel in modules() if layer in ('kinematics', 'description')
               for line in unannotated(rel)]
    assert missing == []


def test_every_public_function_of_every_layer_says_what_it_returns():
    missing = [line for _, rel in modules() for line in unannotated(rel)
               if line.endswith(('(return)', ', return)'))]
    assert missing == []


def test_a_missing_hint_would_be_found(tmp_path, monkeypatch):
    (tmp_path / 'kinematics').mkdir()
    (tmp_path / 'kinematics' / 'bare.py').write_text(
        'def forward(q):\n    return q\n\n\ndef _private(q):\n    return q\n')
    monkeypatch.setattr(sys.modules[__name__], 'PACKAGE', str(tmp_path))
    assert list(unannotated('kinematics/bare.py')) == ['kinematics/bare.py:1 forward (q, return)']


# the bag reader interface (storage/reader_interface.py's BagReader): only the adapters know the
# classes
READER_ADAPTERS = ('storage/reading.py', 'storage/reader_interface.py', 'storage/formats.py',
                   'storage/rosbag2_reader.py', 'storage/mcap_chunks.py',
                   'storage/mcap_stream.py', 'storage/ros1_bag.py', 'storage/ros1_scan.py')
READER_CLASSES = {'Reader', 'Rosbag2Reader', 'McapChunkReader', 'McapStreamBag', 'Ros1Bag',
                  'Ros1ChunkScan'}
READER_MEMBERS = {'connections', 'all_topics', 'start_time', 'end_time', 'note', 'damage',
                  'copies_messages', 'windowable', 'messages', 'message_batches', 'fallback',
                  'close'}


def reader_breaches(rel):
    """Yield where a module outside the adapters tests a reader's class or patches a reader."""
    with open(os.path.join(PACKAGE, rel), encoding='utf-8') as stream:
        tree = ast.parse(stream.read())
    for node in sorted((n for n in ast.walk(tree) if hasattr(n, 'lineno')),
                       key=lambda n: n.lineno):
        if isinstance(node, ast.Call) and getattr(node.func, 'id', None) == 'isinstance' \
                and len(node.args) == 2:
            kinds = node.args[1].elts if isinstance(node.args[1], ast.Tuple) \
                else [node.args[1]]
            named = {getattr(k, 'id', getattr(k, 'attr', None)) for k in kinds}
            if named & READER_CLASSES:
                yield f'{rel}:{node.lineno} isinstance on a reader class'
        targets = node.targets if isinstance(node, ast.Assign) else \
            [node.target] if isinstance(node, (ast.AugAssign, ast.AnnAssign)) else []
        for target in targets:
            if isinstance(target, ast.Attribute) and target.attr in READER_MEMBERS and \
                    ast.unparse(target.value).split('.')[-1].endswith('reader'):
                yield f'{rel}:{node.lineno} {ast.unparse(target)} patched on a reader'


def test_no_module_outside_the_bag_adapters_tests_or_patches_a_reader():
    breaches = [line for _, rel in modules() if rel not in READER_ADAPTERS
                for line in reader_breaches(rel)]
    assert breaches == []


def test_a_reader_breach_would_be_found(tmp_path, monkeypatch):
    (tmp_path / 'bag').mkdir()
    (tmp_path / 'bag' / 'user.py').write_text(
        'def use(reader, Ros1Bag):\n'
        '    if isinstance(reader, (int, Ros1Bag)):\n'
        '        reader.note = None\n'
        '    self.reader.damage = "x"\n')
    monkeypatch.setattr(sys.modules[__name__], 'PACKAGE', str(tmp_path))
    assert list(reader_breaches('bag/user.py')) == [
        'bag/user.py:2 isinstance on a reader class',
        'bag/user.py:3 reader.note patched on a reader',
        'bag/user.py:4 self.reader.damage patched on a reader']


# the domain classes a newcomer reads first hold data and rules; their engines live beside
DOMAIN_CLASSES = {'description/robot_model.py': 'RobotModel',
                  'kinematics/dh.py': 'KinematicChain',
                  'messages/joint_states.py': 'JointStateMerger',
                  'kinematics/tree_kinematics.py': 'TreeKinematics'}
MAX_DOMAIN_CLASS_LINES = 300
MAX_CLASS_LINES = {'KinematicChain': 150}   # a facade: its table and its engine do the work


def test_the_domain_classes_stay_short():
    sizes = {}
    for rel, name in DOMAIN_CLASSES.items():
        with open(os.path.join(PACKAGE, rel), encoding='utf-8') as stream:
            tree = ast.parse(stream.read())
        node = next(n for n in tree.body if isinstance(n, ast.ClassDef) and n.name == name)
        sizes[name] = node.end_lineno - node.lineno + 1
    assert {n: s for n, s in sizes.items()
            if s > MAX_CLASS_LINES.get(n, MAX_DOMAIN_CLASS_LINES)} == {}
