#!/usr/bin/env python3
"""
Mutation testing of the pure modules with mutmut, and what mutmut does not give: a kill rate
per module against a target, less the mutants reviewed as equivalent.

mutmut (its ``[mutmut]`` section of setup.cfg names the modules and the unit tests that
judge them) copies the package to ``mutants/``, makes every mutant of every function there
and runs, for each, the tests that reach that function (it records which at the start). The
modules run on their Python paths (``DQ_FK_PURE_PYTHON=1``): with the compiled kernel, the C
CDR and MCAP code loaded, a mutant of a Python reference that the C code stands in for would
survive untested.

    scripts/mutate.py [run] [--jobs 2] [--target 90]   # mutmut run, then the report
    scripts/mutate.py report [--survivors MODULE]       # the last run's figures again

A mutant is killed when a test fails, times out or crashes on it; it survives when every
test passes, and counts as survived also when no test reaches it (``no tests``). Mutants
judged equivalent (no caller can tell them from the code) are listed in
``scripts/mutate_equivalent.txt``, one a line: ``mutmut's mutant name || why``; they leave
the count. ``mutmut show NAME`` prints a mutant's change; ``mutmut results`` all survivors.

What mutmut cannot do and the old sampler of this script did: mutate code outside
functions (a module's constants, such as a bound); those are read back by tests that hold
the bound to docs/security.md. The exit code is 0 (a report, not a gate); every module under
the target is marked ``BELOW``.
"""

import argparse
import glob
import json
import os
import subprocess
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
EQUIVALENT = os.path.join(ROOT, 'scripts', 'mutate_equivalent.txt')
KILLED = {1, 3, 36, 37, -24, 24, 152, 255, -11, -9}   # mutmut's stats.status_by_exit_code
SURVIVED = {0}                                        # every test reaching it passed
UNREACHED = {5, 33}                                   # no test reaches it: not killed either


def equivalents(path=None) -> dict:
    """Return ``{mutant name: why}`` of the reviewed equivalent mutants."""
    path = path or EQUIVALENT
    found = {}
    if os.path.exists(path):
        for line in open(path, encoding='utf-8'):
            if line.strip() and not line.startswith('#'):
                name, _, why = line.partition('||')
                found[name.strip()] = why.strip()
    return found


def results(root=None) -> dict:
    """Return ``{module: {mutant name: exit code or None}}`` from mutmut's ``.meta`` files."""
    root = root or ROOT
    by_module = {}
    top = os.path.join(root, 'mutants')
    for meta in glob.glob(os.path.join(top, '**', '*.py.meta'), recursive=True):
        module = os.path.relpath(meta, top)[:-len('.py.meta')].replace(os.sep, '.')
        with open(meta, encoding='utf-8') as stream:
            by_module[module] = dict(json.load(stream)['exit_code_by_key'])
    return by_module


def tally(codes: dict, equivalent: dict) -> dict:
    """Count one module's mutants: killed, survived, equivalent, not run, survivors' names."""
    counts = {'killed': 0, 'survived': 0, 'unreached': 0, 'equivalent': 0, 'not run': 0,
              'survivors': []}
    for name, code in sorted(codes.items()):
        if name in equivalent:
            counts['equivalent'] += 1
        elif code in KILLED:
            counts['killed'] += 1
        elif code in SURVIVED or code in UNREACHED:
            counts['survived' if code in SURVIVED else 'unreached'] += 1
            counts['survivors'].append(name)
        else:
            counts['not run'] += 1
    return counts


def report(target: float, survivors_of=None) -> int:
    """Print the rate per module against ``target`` (%); return the number below it."""
    by_module, equivalent = results(), equivalents()
    if not by_module:
        print('mutate: no mutmut results under mutants/ (run: scripts/mutate.py run)')
        return 0
    below = 0
    print(f'{"module":40s} {"killed":>7s} {"surv.":>6s} {"unre.":>6s} {"equiv.":>6s} '
          f'{"rate":>7s}  (target {target:g} %; unre.: no test reaches it, counted as not '
          f'killed)')
    for module in sorted(by_module):
        c = tally(by_module[module], equivalent)
        judged = c['killed'] + c['survived'] + c['unreached']
        rate = 100.0 * c['killed'] / judged if judged else None
        mark = '' if rate is None or rate >= target else '  BELOW'
        below += bool(mark)
        extra = f'  ({c["not run"]} not run)' if c['not run'] else ''
        shown = '   -  ' if rate is None else f'{rate:6.1f}'
        print(f'{module:40s} {c["killed"]:7d} {c["survived"]:6d} {c["unreached"]:6d} '
              f'{c["equivalent"]:6d} {shown} %{mark}{extra}')
        if survivors_of and module.endswith(survivors_of):
            for name in c['survivors']:
                print(f'    {name}')
    print(f'mutate: {below} module(s) below {target:g} %')
    return below


def main(argv=None) -> int:
    """Run mutmut (``run``) and print the report, or the report alone (``report``)."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('action', nargs='?', choices=('run', 'report'), default='run')
    parser.add_argument('--jobs', type=int, default=os.cpu_count() or 2)
    parser.add_argument('--target', type=float, default=90.0)
    parser.add_argument('--survivors', metavar='MODULE', help='list this module\'s survivors')
    args = parser.parse_args(argv)
    if args.action == 'run':
        mutmut = os.path.join(os.path.dirname(sys.executable), 'mutmut')
        env = dict(os.environ, DQ_FK_PURE_PYTHON='1')
        rc = subprocess.call([mutmut, 'run', '--max-children', str(args.jobs)], cwd=ROOT,
                             env=env, stdout=subprocess.DEVNULL)
        if rc != 0:
            print(f'mutate: mutmut run exited {rc} (see: mutmut run, in {ROOT})',
                  file=sys.stderr)
            return rc
    report(args.target, args.survivors)
    return 0


if __name__ == '__main__':
    sys.exit(main())
