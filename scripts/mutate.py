#!/usr/bin/env python3
"""
Mutation testing of the pure modules: does some unit test fail when a line is wrong?

For each module, every mutation site is listed from its syntax tree (comparisons flipped,
arithmetic swapped, constants changed, conditions negated, ``and``/``or`` exchanged,
statements dropped, the first two arguments of a call swapped); a seeded sample is taken;
each mutant is written into a copy of the package (the repository stays untouched) and the
module's unit tests run against it (``PYTHONPATH`` puts the copy first). A mutant is
*killed* when the tests fail or hang (time limit), and *survives* when they pass. Mutants
judged equivalent (they change nothing a caller can see) are listed in
``scripts/mutate_equivalent.txt`` by module, source line and mutation (so that they stay
found when lines move) and skipped.

    scripts/mutate.py [--modules dh cdr ...] [--per-module 60] [--seed 1] [--jobs 2]

Prints the kill rate per module and every survivor (file:line, what changed). Exit code 0
(a report, not a gate). ``make mutate`` runs it on every module; it is not part of
``make test`` (minutes, not seconds).
"""

import argparse
import ast
from concurrent.futures import ThreadPoolExecutor
import os
import random
import shutil
import subprocess
import sys
import tempfile
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
EQUIVALENT = os.path.join(ROOT, 'scripts', 'mutate_equivalent.txt')
UNIT = 'test/unit/'
MODULES = {
    'dual_quaternion': ('dq_fk_ros/kinematics/dual_quaternion.py',
                        ['test_dual_quaternion.py', 'test_dh.py', 'test_papers.py']),
    'tree': ('dq_fk_ros/kinematics/tree.py', ['test_tree.py', 'test_view_state.py']),
    'dh': ('dq_fk_ros/kinematics/dh.py',
           ['test_dh.py', 'test_papers.py', 'test_shipped_robots.py', 'test_links.py']),
    'robot_model': ('dq_fk_ros/description/robot_model.py',
                    ['test_robot_model.py', 'test_links.py', 'test_chains.py',
                     'test_shipped_robots.py']),
    'schema': ('dq_fk_ros/description/schema.py',
               ['test_robot_model.py', 'test_links.py', 'test_chains.py',
                'test_fuzz_robot_description.py']),
    'meshes': ('dq_fk_ros/description/meshes.py', ['test_meshes.py']),
    'urdf': ('dq_fk_ros/description/to_urdf.py', ['test_urdf.py', 'test_links.py']),
    'from_urdf': ('dq_fk_ros/description/from_urdf.py', ['test_from_urdf.py']),
    'urdf_reader': ('dq_fk_ros/description/urdf_reader.py', ['test_from_urdf.py']),
    'dh_fit': ('dq_fk_ros/description/dh_fit.py', ['test_from_urdf.py']),
    'loading': ('dq_fk_ros/description/loading.py', ['test_loading.py', 'test_cli.py']),
    'plot': ('dq_fk_ros/description/plot.py', ['test_plot.py']),
    'packages': ('dq_fk_ros/description/packages.py', ['test_packages.py']),
    'xacro_sandbox': ('dq_fk_ros/description/xacro_sandbox.py',
                      ['test_xacro_sandbox.py', 'test_packages.py']),
    'joint_states': ('dq_fk_ros/messages/joint_states.py', ['test_joint_states.py']),
    'cdr': ('dq_fk_ros/messages/cdr.py', ['test_cdr.py', 'test_frame_bytes.py']),
    'conversions': ('dq_fk_ros/ros/conversions.py',
                    ['test_ros_conversions.py', 'test_frame_bytes.py', 'test_links.py']),
}
COMPARE_SWAPS = {ast.Lt: ast.LtE, ast.LtE: ast.Lt, ast.Gt: ast.GtE, ast.GtE: ast.Gt,
                 ast.Eq: ast.NotEq, ast.NotEq: ast.Eq, ast.Is: ast.IsNot, ast.IsNot: ast.Is,
                 ast.In: ast.NotIn, ast.NotIn: ast.In}
BINOP_SWAPS = {ast.Add: ast.Sub, ast.Sub: ast.Add, ast.Mult: ast.Div, ast.Div: ast.Mult,
               ast.FloorDiv: ast.Mult, ast.Mod: ast.FloorDiv, ast.Pow: ast.Mult}


def sites(tree):
    """Yield ``(index, kind, line, description)`` of every mutation site in walk order."""
    docstrings = {id(n.body[0].value) for n in ast.walk(tree)
                  if isinstance(n, (ast.Module, ast.FunctionDef, ast.ClassDef))
                  and n.body and isinstance(n.body[0], ast.Expr)
                  and isinstance(n.body[0].value, ast.Constant)}
    for index, node in enumerate(ast.walk(tree)):
        line = getattr(node, 'lineno', 0)
        if isinstance(node, ast.Compare) and type(node.ops[0]) in COMPARE_SWAPS:
            new = COMPARE_SWAPS[type(node.ops[0])].__name__
            yield index, 'compare', line, f'{type(node.ops[0]).__name__} -> {new}'
        elif isinstance(node, ast.BinOp) and type(node.op) in BINOP_SWAPS:
            new = BINOP_SWAPS[type(node.op)].__name__
            yield index, 'binop', line, f'{type(node.op).__name__} -> {new}'
        elif isinstance(node, ast.BoolOp):
            yield index, 'boolop', line, f'{type(node.op).__name__} -> the other'
        elif isinstance(node, ast.UnaryOp) and isinstance(node.op, (ast.USub, ast.Not)):
            yield index, 'unary', line, f'drop {type(node.op).__name__}'
        elif isinstance(node, ast.Constant) and id(node) not in docstrings and \
                isinstance(node.value, (bool, int, float)):
            yield index, 'constant', line, f'{node.value!r} -> {_changed(node.value)!r}'
        elif isinstance(node, (ast.If, ast.While)) and not isinstance(node.test, ast.Constant):
            yield index, 'negate', line, 'condition negated'
        elif isinstance(node, ast.AugAssign) or (isinstance(node, ast.Expr) and
                                                 isinstance(node.value, ast.Call)):
            yield index, 'drop', line, 'statement dropped'
        elif isinstance(node, ast.Call) and len(node.args) >= 2 and \
                not any(isinstance(a, ast.Starred) for a in node.args[:2]):
            yield index, 'swap', line, 'first two arguments swapped'


def _changed(value):
    if isinstance(value, bool):
        return not value
    if isinstance(value, (int, float)):
        return value + 1 if value != -1 else 0
    return value


def mutate(source, index):
    """Return the source with the mutation at walk position ``index`` applied."""
    tree = ast.parse(source)
    for k, node in enumerate(ast.walk(tree)):
        if k != index:
            continue
        if isinstance(node, ast.Compare):
            node.ops[0] = COMPARE_SWAPS[type(node.ops[0])]()
        elif isinstance(node, ast.BinOp):
            node.op = BINOP_SWAPS[type(node.op)]()
        elif isinstance(node, ast.BoolOp):
            node.op = ast.Or() if isinstance(node.op, ast.And) else ast.And()
        elif isinstance(node, ast.UnaryOp):
            node.op = ast.UAdd() if isinstance(node.op, ast.USub) else _Identity()
        elif isinstance(node, ast.Constant):
            node.value = _changed(node.value)
        elif isinstance(node, (ast.If, ast.While)):
            node.test = ast.UnaryOp(op=ast.Not(), operand=node.test)
        elif isinstance(node, (ast.AugAssign, ast.Expr)):
            _replace_statement(tree, node)
        elif isinstance(node, ast.Call):
            node.args[0], node.args[1] = node.args[1], node.args[0]
        break
    tree = _IdentityRemover().visit(tree)
    return ast.unparse(ast.fix_missing_locations(tree))


class _Identity(ast.unaryop):
    """A placeholder: ``not x`` becomes ``x``."""


class _IdentityRemover(ast.NodeTransformer):
    def visit_UnaryOp(self, node):
        self.generic_visit(node)
        return node.operand if isinstance(node.op, _Identity) else node


def _replace_statement(tree, target):
    for parent in ast.walk(tree):
        for field in ('body', 'orelse', 'finalbody'):
            block = getattr(parent, field, None)
            if isinstance(block, list) and target in block:
                block[block.index(target)] = ast.Pass()
                return


def site_key(name, source_lines, line, description, occurrence=0):
    """
    Name a mutant by module, its line's code (no inline comment) and what it changes.

    ``occurrence`` tells apart the same change at several places of one line (the n-th in
    the syntax tree's walk order, from 0; written as ``[n]`` from the second on).
    """
    code = source_lines[line - 1].split('  #')[0].strip() if 0 < line <= len(source_lines) \
        else ''
    return f'{name} | {code} | {description}' + (f' [{occurrence}]' if occurrence else '')


def keyed_sites(name, source):
    """Return ``[(site, key)]`` for every mutation site of a module's source."""
    lines = source.splitlines()
    seen = {}
    out = []
    for site in sites(ast.parse(source)):
        _, _, line, what = site
        occurrence = seen.get((line, what), 0)
        seen[(line, what)] = occurrence + 1
        out.append((site, site_key(name, lines, line, what, occurrence)))
    return out


def load_equivalent():
    """Return the reviewed equivalent mutants: ``module | code | what || reason`` per line."""
    if not os.path.exists(EQUIVALENT):
        return set()
    with open(EQUIVALENT, encoding='utf-8') as stream:
        return {line.split(' || ')[0].strip() for line in stream
                if line.strip() and not line.startswith('#')}


def run_tests(copy, tests, timeout_s):
    """Run ``tests`` against the package copy; return 'killed', 'hang' or 'survived'."""
    # the copy first; PYTHONSAFEPATH: not the repository itself from the working directory
    env = dict(os.environ, PYTHONPATH=copy, PYTHONSAFEPATH='1', PYTHONDONTWRITEBYTECODE='1')
    argv = [sys.executable, '-m', 'pytest', '-x', '-q', '-p', 'no:cacheprovider',
            '--timeout', str(timeout_s)] + [UNIT + t for t in tests]
    try:
        done = subprocess.run(argv, cwd=ROOT, env=env, stdout=subprocess.DEVNULL,
                              stderr=subprocess.DEVNULL, timeout=timeout_s + 30)
    except subprocess.TimeoutExpired:
        return 'hang'
    return 'survived' if done.returncode == 0 else 'killed'


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.strip().splitlines()[0])
    parser.add_argument('--modules', nargs='+', choices=sorted(MODULES), default=list(MODULES))
    parser.add_argument('--per-module', type=int, default=60)
    parser.add_argument('--seed', type=int, default=1)
    parser.add_argument('--timeout', type=int, default=120, help='seconds per test run')
    parser.add_argument('--jobs', type=int, default=os.cpu_count() or 1,
                        help='mutants tested at once (one package copy each)')
    parser.add_argument('--keys', metavar='LINE', type=int,
                        help='only print the keys of every mutant on this line of the first '
                        'module (to review and list equivalents)')
    args = parser.parse_args(argv)
    if args.keys is not None:
        name = args.modules[0]
        with open(os.path.join(ROOT, MODULES[name][0]), encoding='utf-8') as stream:
            for (_, kind, line, what), key in keyed_sites(name, stream.read()):
                if line == args.keys:
                    print(f'{kind}: {key}')
        return 0
    equivalent = load_equivalent()
    works = [tempfile.mkdtemp(prefix='dq_fk_mutate-') for _ in range(max(args.jobs, 1))]
    free = list(works)
    try:
        for work in works:
            shutil.copytree(os.path.join(ROOT, 'dq_fk_ros'), os.path.join(work, 'dq_fk_ros'))
            shutil.copytree(os.path.join(ROOT, 'config'), os.path.join(work, 'config'))
        report = []
        for name in args.modules:
            path, tests = MODULES[name]
            with open(os.path.join(ROOT, path), encoding='utf-8') as stream:
                source = stream.read()
            if run_tests(works[0], tests, args.timeout) != 'survived':
                raise SystemExit(f'mutate: the tests of {name} fail without any mutant')
            every = keyed_sites(name, source)
            keys = dict((site, key) for site, key in every)
            candidates = [site for site, key in every if key not in equivalent]
            skipped = len(every) - len(candidates)
            sample = random.Random(f'{args.seed}:{name}').sample(
                candidates, min(args.per_module, len(candidates)))
            start = time.monotonic()

            def attempt(site):
                index, kind, line, what = site
                work = free.pop()
                try:
                    with open(os.path.join(work, path), 'w', encoding='utf-8') as stream:
                        stream.write(mutate(source, index))
                    return site, run_tests(work, tests, args.timeout)
                finally:
                    with open(os.path.join(work, path), 'w', encoding='utf-8') as stream:
                        stream.write(source)
                    free.append(work)

            with ThreadPoolExecutor(len(works)) as pool:
                results = list(pool.map(attempt, sorted(sample, key=lambda s: s[2])))
            outcome = {'killed': 0, 'hang': 0, 'survived': 0}
            survivors = []
            for (index, kind, line, what), result in results:
                outcome[result] += 1
                if result == 'survived':
                    survivors.append((f'{path}:{line}: {kind}: {what}',
                                      keys[(index, kind, line, what)]))
            tried = len(sample)
            killed = outcome['killed'] + outcome['hang']
            report.append((name, tried, killed, outcome['hang'], skipped, survivors,
                           time.monotonic() - start))
            print(f'{name}: {killed}/{tried} killed ({100.0 * killed / max(tried, 1):.1f} %, '
                  f'{outcome["hang"]} by the time limit), {skipped} equivalent skipped, '
                  f'{time.monotonic() - start:.0f} s', flush=True)
            for where, key in survivors:
                print(f'  survived: {where}\n    key: {key}', flush=True)
    finally:
        for work in works:
            shutil.rmtree(work, ignore_errors=True)
    print('\n| module | mutants | killed | kill rate | equivalent skipped |')
    print('|---|---|---|---|---|')
    for name, tried, killed, _, skipped, _, _ in report:
        print(f'| {name} | {tried} | {killed} | {100.0 * killed / max(tried, 1):.1f} % '
              f'| {skipped} |')
    return 0


if __name__ == '__main__':
    sys.exit(main())
