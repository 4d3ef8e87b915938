"""
``tf2_msgs`` built into dq_fk_ros's wheel, where ``pip install`` has no other (PyPI only).

tf2_msgs is not on PyPI, and dq_fk_ros publishes and reads ``tf2_msgs/msg/TFMessage``. A
``pip install dq_fk_ros`` builds the package in an isolated environment holding the build
requirements of pyproject.toml (rosidl's generators and ament_cmake from the ROS 2 Jazzy
wheels); there :func:`build` runs rosidl on ``vendor/tf2_msgs`` (upstream's definitions of
TFMessage, TF2Error, FrameGraph and LookupTransform) and setup.py puts what it installed
into the wheel: the ``tf2_msgs`` Python package, its libraries (``lib/``, where
the ROS wheels' loader looks) and ``share/tf2_msgs``.

Nothing is built where ``tf2_msgs`` is already importable (a sourced ROS 2, ``make setup``'s
venv, colcon), where rosidl's generators are not (a plain ``setup.py`` run), or with
``DQ_FK_TF2_MSGS=skip``. On a ROS 2 install the system's tf2_msgs stays first on the path.

``make setup`` runs it as a program, to install tf2_msgs into its venv the same way::

    VENV/bin/python scripts/tf2_msgs_build.py --into VENV
"""

import argparse
import glob
import importlib.util
import os
import shutil
import subprocess
import sys
import tempfile

HERE = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SOURCE = os.path.join(HERE, 'vendor', 'tf2_msgs')
MARKER = 'built_by_dq_fk_ros'   # in share/tf2_msgs of every prefix this script built


def wanted() -> bool:
    """Return True where this build should carry tf2_msgs (see the module's docstring)."""
    if os.environ.get('DQ_FK_TF2_MSGS', '') == 'skip':
        return False
    if importlib.util.find_spec('tf2_msgs') is not None:
        return False
    return importlib.util.find_spec('rosidl_adapter') is not None and \
        shutil.which('cmake') is not None


def _build_prefix() -> str:
    """Return the prefix the build requirements were installed into (pip's overlay)."""
    spec = importlib.util.find_spec('rosidl_adapter')
    # <prefix>/lib/pythonX.Y/site-packages/rosidl_adapter/__init__.py
    return os.path.abspath(os.path.join(os.path.dirname(spec.origin), *['..'] * 4))


def build(work: str, prefix: str | None = None) -> str:
    """
    Build and install vendor/tf2_msgs; return its install prefix.

    :param work: a scratch folder (kept between pip's calls of setup.py: built once).
    :param prefix: where to install (default: ``work/prefix``, once).
    """
    work = os.path.abspath(work)
    if prefix is None:
        prefix = os.path.join(work, 'prefix')
        if os.path.exists(os.path.join(prefix, 'share', 'tf2_msgs', MARKER)):
            return prefix
    shutil.rmtree(work, ignore_errors=True)
    overlay = _build_prefix()
    paths = os.pathsep.join(p for p in (overlay, os.environ.get('AMENT_PREFIX_PATH')) if p)
    env = dict(os.environ, AMENT_PREFIX_PATH=paths, CMAKE_PREFIX_PATH=paths,
               PATH=os.pathsep.join([os.path.join(overlay, 'bin'), os.environ.get('PATH', '')]),
               LD_LIBRARY_PATH=os.pathsep.join(
                   p for p in (os.path.join(overlay, 'lib'), os.environ.get('LD_LIBRARY_PATH'))
                   if p))
    tree = os.path.join(work, 'build')
    generator = ['-G', 'Ninja'] if shutil.which('ninja', path=env['PATH']) else []
    for command in (['cmake', '-S', SOURCE, '-B', tree, *generator,
                     f'-DCMAKE_INSTALL_PREFIX={prefix}', f'-DPython3_EXECUTABLE={sys.executable}',
                     '-DBUILD_TESTING=OFF'],
                    ['cmake', '--build', tree], ['cmake', '--install', tree]):
        subprocess.run(command, env=env, check=True, stdout=sys.stderr)
    with open(os.path.join(prefix, 'share', 'tf2_msgs', MARKER), 'w', encoding='utf-8'):
        pass
    return prefix


def wheel_parts(prefix: str) -> dict:
    """
    Return setup()'s arguments that carry an installed tf2_msgs prefix into the wheel.

    :param prefix: what :func:`build` returned.
    :return: ``packages``, ``package_dir``, ``package_data`` and ``data_files`` to add.
    """
    python = glob.glob(os.path.join(prefix, 'lib', 'python*', 'site-packages', 'tf2_msgs'))[0]
    here = os.getcwd()
    rel = os.path.relpath(python, here)
    data_files = [('lib', sorted(os.path.relpath(p, here) for p in
                                 glob.glob(os.path.join(prefix, 'lib', '*.so'))))]
    for folder, _, files in os.walk(os.path.join(prefix, 'share')):
        if files:
            data_files.append((os.path.relpath(folder, prefix),
                               sorted(os.path.relpath(os.path.join(folder, f), here)
                                      for f in files)))
    kinds = ('msg', 'srv', 'action')
    return {'packages': ['tf2_msgs'] + [f'tf2_msgs.{k}' for k in kinds],
            'package_dir': dict({'tf2_msgs': rel},
                                **{f'tf2_msgs.{k}': os.path.join(rel, k) for k in kinds}),
            'package_data': dict({'tf2_msgs': ['*.so']}, **{f'tf2_msgs.{k}': ['*.py']
                                                           for k in kinds}),
            'data_files': data_files}


def main(argv=None) -> int:
    """Install tf2_msgs into a venv unless the environment provides it (``make setup``)."""
    parser = argparse.ArgumentParser(description='Provide tf2_msgs in a Python environment.')
    parser.add_argument('--into', required=True, metavar='VENV', help='the environment')
    venv = os.path.abspath(parser.parse_args(argv).into)
    if not os.path.exists(os.path.join(venv, 'share', 'tf2_msgs', MARKER)) and \
            importlib.util.find_spec('tf2_msgs') is not None:
        print('tf2_msgs is provided by the environment; not building the vendored copy')
        return 0
    if shutil.which('cmake') is None:
        print('error: cmake not found (needed to build tf2_msgs)', file=sys.stderr)
        return 1
    subprocess.run([sys.executable, '-m', 'pip', 'install', '--disable-pip-version-check',
                    '-r', os.path.join(HERE, 'requirements', 'tf2_msgs-build.txt')], check=True)
    importlib.invalidate_caches()
    work = tempfile.mkdtemp(prefix='tf2_msgs_build_')
    try:
        build(work, venv)
    finally:
        shutil.rmtree(work, ignore_errors=True)
    subprocess.run([sys.executable, '-c', 'from tf2_msgs.msg import TFMessage; TFMessage(); '
                    'from tf2_msgs.action import LookupTransform; LookupTransform.Goal(); '
                    'from tf2_msgs.srv import FrameGraph; FrameGraph.Request()'],
                   check=True)
    print(f'built and installed vendored tf2_msgs into {venv}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
