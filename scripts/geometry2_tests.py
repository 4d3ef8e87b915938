"""
geometry2's own Python tests, unchanged, run against dq_fk_ros through the compat path.

The tests stay geometry2's: they are read from a checkout of ros2/geometry2 given by path
(its ``jazzy`` branch; ``git clone https://github.com/ros2/geometry2``), copied into a scratch
folder and run there with ``dq_fk tf compat-path`` first on ``PYTHONPATH``: tf2_ros_py/test,
tf2_py/test, tf2_geometry_msgs/test, tf2_sensor_msgs/test (the 30 that run without PyKDL,
the ``ros2`` command and the C++ launch tests). As geometry2's CMake makes an importable
``test_tf2_py`` of its build for tf2_py's test, the scratch folder holds one that re-exports
``tf2_py._tf2_py``.

``--real ENV_LINE`` runs the same tests against the real tf2 instead: the ``export`` line
``../shared/tools/build_real_tf2.sh`` prints last (its library folders first); the real
tf2_geometry_msgs and tf2_sensor_msgs come from the same checkout and sensor_msgs_py from a
checkout of ros2/common_interfaces (``--common-interfaces``). Prints each folder's pass and
fail counts and the total against the target (every test the real tf2 passes)::

    .venv/bin/python scripts/geometry2_tests.py ~/src/geometry2/.git
"""

import argparse
import os
import re
import shlex
import subprocess
import sys
import tempfile

HERE = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
FOLDERS = ('tf2_ros_py', 'tf2_py', 'tf2_geometry_msgs', 'tf2_sensor_msgs')
TARGET = 30   # what the real tf2 passes on a machine of PyPI wheels (no PyKDL, no ros2 CLI)


def git_dir(path: str) -> str:
    """Return the git directory of a checkout or bare repository ``path``."""
    inner = os.path.join(path, '.git')
    return inner if os.path.isdir(inner) else path


def extract(repository: str, branch: str, paths, into: str) -> None:
    """Write ``paths`` of ``branch`` of ``repository`` under ``into`` (git archive)."""
    archive = subprocess.run(['git', '--git-dir', git_dir(repository), 'archive', branch,
                              *paths], check=True, capture_output=True).stdout
    subprocess.run(['tar', '-x', '-C', into], input=archive, check=True)


def scratch(geometry2: str, work: str, common_interfaces: str | None) -> dict:
    """
    Lay out the tests under ``work/tests`` and the real pure-Python packages under ``work/real``.

    Apart: pytest puts a test folder's parent on the path, where a package of geometry2's own
    would shadow the one under test.
    """
    tests, real = os.path.join(work, 'tests'), os.path.join(work, 'real')
    os.makedirs(tests)
    os.makedirs(real)
    extract(geometry2, 'jazzy', [f'{f}/test' for f in FOLDERS], tests)
    extract(geometry2, 'jazzy', ['tf2_geometry_msgs/src', 'tf2_sensor_msgs/tf2_sensor_msgs'],
            real)
    if common_interfaces:
        extract(common_interfaces, 'jazzy', ['sensor_msgs_py/sensor_msgs_py'], real)
    importable = os.path.join(work, 'importable', 'test_tf2_py')
    os.makedirs(importable)
    open(os.path.join(importable, '__init__.py'), 'w').close()
    with open(os.path.join(importable, '_tf2_py.py'), 'w', encoding='utf-8') as stream:
        stream.write('from tf2_py._tf2_py import *  # noqa: F401,F403\n')
    return {'importable': os.path.dirname(importable), 'tests': tests,
            'real': [os.path.join(real, 'tf2_geometry_msgs', 'src'),
                     os.path.join(real, 'tf2_sensor_msgs'), os.path.join(real, 'sensor_msgs_py')]}


def real_env(line: str, base: dict, sources: list) -> dict:
    """
    Return ``build_real_tf2.sh``'s export line's paths before ``base``'s, with geometry2's sources.

    Its folders go first; the venv's own (its wheels' library folders) stay after them.
    """
    env = {}
    for word in shlex.split(line):
        if '=' in word and word != 'export':
            key, value = word.split('=', 1)
            env[key] = os.pathsep.join(p for p in (value, base.get(key, '')) if p)
    env['PYTHONPATH'] = os.pathsep.join([env.get('PYTHONPATH', '')] + sources)
    return env


def run_folder(folder: str, tests: str, env: dict) -> tuple:
    """Run one folder's tests; return ``(passed, failed or errors, last line)``."""
    tests = os.path.join(tests, folder)
    done = subprocess.run([sys.executable, '-m', 'pytest', '-q', '-p', 'no:randomly', '-p',
                           'no:cacheprovider', '-p', 'no:dq_fk_ros', 'test'], cwd=tests,
                          env=env, capture_output=True, text=True, timeout=600)
    last = (done.stdout.strip().splitlines() or [''])[-1]
    counts = {k: int(n) for n, k in re.findall(r'(\d+) (passed|failed|error)', last)}
    return counts.get('passed', 0), counts.get('failed', 0) + counts.get('error', 0), last


def origins(env: dict, cwd: str) -> list:
    """Return ``name: file`` of each package under test, as the tests' processes import it."""
    code = ('import importlib\n'
            "for n in ('tf2_ros', 'tf2_py', 'tf2_geometry_msgs', 'tf2_sensor_msgs', "
            "'sensor_msgs_py.point_cloud2'):\n"
            "    print(n + ': ' + importlib.import_module(n).__file__)\n")
    done = subprocess.run([sys.executable, '-c', code], cwd=cwd, env=env, capture_output=True,
                          text=True, timeout=120)
    return done.stdout.splitlines() or [done.stderr.strip().splitlines()[-1]]


def main(argv=None) -> int:
    """Run the four folders; print the counts and the target; 0 if every test passed."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('geometry2', help='a checkout (or git dir) of ros2/geometry2')
    parser.add_argument('--real', metavar='ENV_LINE', help="build_real_tf2.sh's last line")
    parser.add_argument('--common-interfaces', help='a checkout of ros2/common_interfaces '
                        '(sensor_msgs_py, for --real)')
    args = parser.parse_args(argv)
    sys.path.insert(0, HERE)
    from dq_fk_ros.cli.compat_path import compat_folders
    from dq_fk_ros.testing.domains import claim_domain, isolate_environment
    with tempfile.TemporaryDirectory(prefix='geometry2_tests_') as work, \
            claim_domain() as claim:
        layout = scratch(args.geometry2, work, args.common_interfaces)
        env = dict(os.environ)
        isolate_environment(env, claim.domain_id)
        if args.real:
            env.update(real_env(args.real, env, layout['real']))
            env['PYTHONPATH'] = os.pathsep.join([layout['importable'], env['PYTHONPATH']])
            what = 'the real tf2'
        else:
            env['PYTHONPATH'] = os.pathsep.join([layout['importable']] + compat_folders())
            what = 'dq_fk_ros through the compat path'
        for line in origins(env, os.path.join(layout['tests'], FOLDERS[0])):
            print(f'  {line}')
        total = failed = 0
        for folder in FOLDERS:
            passed, bad, last = run_folder(folder, layout['tests'], env)
            total, failed = total + passed, failed + bad
            print(f'{folder + "/test":24s} {passed:3d} passed {bad:3d} failed   ({last})')
    print(f'geometry2 jazzy Python tests on {what}: {total} passed, {failed} failed '
          f'(target: the {TARGET} the real tf2 passes)')
    return 0 if failed == 0 and total >= TARGET else 1


if __name__ == '__main__':
    sys.exit(main())
