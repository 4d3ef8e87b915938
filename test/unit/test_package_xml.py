"""package.xml declares every third-party module the package imports at run time."""

import ast
import os
import re
import sys
import xml.etree.ElementTree as ET

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
# module name -> the rosdep key that provides it (ROS packages are their own key)
ROSDEP = {'numpy': 'python3-numpy', 'yaml': 'python3-yaml', 'matplotlib': 'python3-matplotlib',
          'mpl_toolkits': 'python3-matplotlib', 'aiohttp': 'python3-aiohttp',
          'scipy': 'python3-scipy', 'pytest': 'python3-pytest'}


def third_party_imports():
    found = set()
    for folder, _, files in os.walk(os.path.join(ROOT, 'dq_fk_ros')):
        for name in files:
            if name.endswith('.py'):
                with open(os.path.join(folder, name), encoding='utf-8') as stream:
                    tree = ast.parse(stream.read())
                for node in ast.walk(tree):
                    names = [a.name for a in node.names] if isinstance(node, ast.Import) else \
                        [node.module] if isinstance(node, ast.ImportFrom) else []
                    found.update(n.split('.')[0] for n in names)
    return {m for m in found if m not in sys.stdlib_module_names and m != 'dq_fk_ros'}


def test_every_runtime_import_is_declared():
    text = open(os.path.join(ROOT, 'package.xml'), encoding='utf-8').read()
    declared = {e.text for e in ET.fromstring(text).iter('exec_depend')}
    pip_only = set(re.search(r'pip-only: ([\w ]+)', text)[1].split())
    missing = [m for m in sorted(third_party_imports())
               if ROSDEP.get(m, m) not in declared and m not in pip_only]
    assert missing == []


def test_one_version_for_the_package_its_metadata_and_package_xml():
    from importlib.metadata import version
    import dq_fk_ros
    text = open(os.path.join(ROOT, 'package.xml'), encoding='utf-8').read()
    assert ET.fromstring(text).find('version').text == dq_fk_ros.__version__
    assert version('dq_fk_ros') == dq_fk_ros.__version__
