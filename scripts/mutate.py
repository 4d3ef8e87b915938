#!/usr/bin/env python3
"""
Mutation testing of the pure modules with mutmut, and what mutmut does not give: a kill rate
per module against a target, less the mutants reviewed as equivalent.

mutmut (its ``[mutmut]`` section of setup.cfg names the modules and the unit tests that
judge them) copies the package to ``mutants/``, makes every mutant of every function there
and runs, for each, the tests that reach that function (it records which at the start).

The package has two builds of its hot paths: the C extensions and the Python references they
are held equal to (``DQ_FK_PURE_PYTHON=1``). A mutant in the lines that call the C code is
never run by the tests of the Python build, and one in a reference never by those of the C
build. So ``run`` runs mutmut once for each (``--modes``), keeps each build's results in
``.mutation/<build>/``, and the report counts a mutant killed if either build's tests kill
it: what mutmut, one build a run, cannot do.

    scripts/mutate.py [run] [--modes compiled pure] [--jobs 2]   # mutmut, then the report
    scripts/mutate.py run --only 'dq_fk_ros.ros.conversions*'   # some mutants again
    scripts/mutate.py run --modes pure --survivors-again [--only PATTERN]   # after new tests
    scripts/mutate.py run --modes pure --continue   # what a build has not run yet; Ctrl-C
                                                    # or SIGTERM stops it, keeping what ran
    scripts/mutate.py run --continue --only 'dq_fk_ros.kinematics.dh*'   # of some modules
    scripts/mutate.py report [--target 90] [--survivors MODULE]   # the last figures again

A mutant is killed when a test fails, times out or crashes on it; it survives when every
test passes, and counts as survived also when no test reaches it (``no tests``). Mutants
judged equivalent (no caller can tell them from the code) are listed in
``scripts/mutate_equivalent.txt``, one a line: ``mutmut's mutant name || why``; they leave
the count. ``mutmut show NAME`` prints a mutant's change; ``mutmut results`` all survivors.

Neither judges code outside functions (mutmut does not mutate a module's constants, such as
a bound: tests hold those to docs/security.md) nor code run in a child process (mutmut
records which tests reach a function in the test process only: the xacro sandbox's child
shows as unreached). The exit code is 0 (a report, not a gate); every module under the
target is marked ``BELOW``.
"""

import argparse
import ast
import difflib
import fnmatch
import glob
import hashlib
import json
import os
import shutil
import signal
import subprocess
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
EQUIVALENT = os.path.join(ROOT, 'scripts', 'mutate_equivalent.txt')
MODES = {'compiled': {}, 'pure': {'DQ_FK_PURE_PYTHON': '1'}}   # build -> its environment
KILLED = {1, 3, 36, 37, -24, 24, 152, 255, -11, -9}   # mutmut's stats.status_by_exit_code
SURVIVED = {0}                                        # every test reaching it passed
UNREACHED = {5, 33}                                   # no test reaches it: not killed either


def _listed(path=None) -> dict:
    """Return ``{mutant name: (why, fingerprint or None)}`` of the equivalents file."""
    path = path or EQUIVALENT
    found = {}
    if os.path.exists(path):
        for line in open(path, encoding='utf-8'):
            if line.strip() and not line.startswith('#'):
                name, _, rest = line.partition('||')
                why, _, mark = rest.rpartition('|| fp=') if '|| fp=' in rest else (rest, '', '')
                found[name.strip()] = (why.strip(), mark.strip() or None)
    return found


def equivalents(path=None) -> dict:
    """Return ``{mutant name: why}`` of the reviewed equivalent mutants."""
    return {name: why for name, (why, _) in _listed(path).items()}


def _mutant_sources(module, root=None) -> dict:
    """Return ``{function name: source}`` of every function in mutants/'s copy of ``module``."""
    path = os.path.join(root or ROOT, 'mutants', *module.split('.')) + '.py'
    if not os.path.exists(path):
        return {}
    text = open(path, encoding='utf-8').read()
    lines = text.splitlines()
    return {node.name: '\n'.join(lines[node.lineno - 1:node.end_lineno])
            for node in ast.walk(ast.parse(text))
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef))}


def fingerprint(name, sources) -> str | None:
    """
    Return a short hash of what mutant ``name`` changes (its removed and added lines).

    ``sources``: :func:`_mutant_sources` of its module. None: no such mutant there. A change
    elsewhere in the function keeps it; a mutant of another line (mutmut numbers them anew
    when the function changes) does not.
    """
    function = name.rpartition('.')[2]
    base = function.split('__mutmut_')[0]
    mutant, original = sources.get(function), sources.get(base + '__mutmut_orig')
    if mutant is None or original is None:
        return None
    mutant, original = (mutant.replace(function, base, 1),
                        original.replace(base + '__mutmut_orig', base, 1))
    lines = [line for line in difflib.unified_diff(original.splitlines(), mutant.splitlines(),
                                                   lineterm='', n=0)
             if line[:1] in '+-' and not line.startswith(('+++', '---'))]
    return hashlib.sha1('\n'.join(line.strip() for line in lines).encode()).hexdigest()[:10]


def still_equivalent(path=None, root=None) -> tuple[dict, list]:
    """
    Return ``({name: why}, stale)``: the listed equivalents whose mutant is the one reviewed.

    An entry whose fingerprint no longer matches the mutant of that name (the function
    changed and mutmut numbered its mutants anew) is ``stale``: not counted, to be reviewed
    again. Without mutants/ (no run here yet) the entries are taken as listed.
    """
    listed, kept, stale, sources = _listed(path), {}, [], {}
    for name, (why, mark) in listed.items():
        module = name.rpartition('.')[0]
        if module not in sources:
            sources[module] = _mutant_sources(module, root)
        if sources[module] and mark is not None and fingerprint(name, sources[module]) != mark:
            stale.append(name)
        else:
            kept[name] = why
    return kept, stale


def fill_fingerprints(path=None, root=None) -> int:
    """Write the fingerprint of every entry that has none (from mutants/); return how many."""
    path = path or EQUIVALENT
    lines, sources, filled = open(path, encoding='utf-8').read().splitlines(), {}, 0
    for k, line in enumerate(lines):
        if not line.strip() or line.startswith('#') or '|| fp=' in line:
            continue
        name = line.partition('||')[0].strip()
        module = name.rpartition('.')[0]
        if module not in sources:
            sources[module] = _mutant_sources(module, root)
        mark = fingerprint(name, sources[module])
        if mark is None:
            print(f'mutate: {name}: no such mutant in mutants/ (left as it is)', file=sys.stderr)
            continue
        lines[k] = f'{line.rstrip()} || fp={mark}'
        filled += 1
    with open(path, 'w', encoding='utf-8') as stream:
        stream.write('\n'.join(lines) + '\n')
    return filled


def results(root=None) -> dict:
    """
    Return ``{module: {mutant name: exit code or None}}`` over the kept builds' results.

    Each build's ``.meta`` files (mutmut's) are read from ``.mutation/<build>/`` (or, with
    none kept, from ``mutants/``); a mutant takes the first killing code of any build, else
    the first that ran it, else None.
    """
    root = root or ROOT
    tops = sorted(glob.glob(os.path.join(root, '.mutation', '*'))) or \
        [os.path.join(root, 'mutants')]
    by_module = {}
    for top in tops:
        for meta in glob.glob(os.path.join(top, '**', '*.py.meta'), recursive=True):
            module = os.path.relpath(meta, top)[:-len('.py.meta')].replace(os.sep, '.')
            with open(meta, encoding='utf-8') as stream:
                codes = json.load(stream)['exit_code_by_key']
            merged = by_module.setdefault(module, {})
            for name, code in codes.items():
                old = merged.get(name)
                if old is None or (old not in KILLED and code in KILLED) or \
                        (old in UNREACHED and code in SURVIVED):
                    merged[name] = code if code is not None else old
    return by_module


def _kept_names(mode, codes_wanted, root=None) -> list:
    """Return the names of the mutants ``.mutation/<mode>/`` holds with one of ``codes_wanted``."""
    root = root or ROOT
    names = []
    kept = os.path.join(root, '.mutation', mode)
    for meta in glob.glob(os.path.join(kept, '**', '*.py.meta'), recursive=True):
        with open(meta, encoding='utf-8') as stream:
            codes = json.load(stream)['exit_code_by_key']
        names += [name for name, code in codes.items() if code in codes_wanted]
    return sorted(names)


def not_killed(mode, root=None) -> list:
    """Return the names of the mutants ``.mutation/<mode>/`` holds as survived or unreached."""
    return _kept_names(mode, SURVIVED | UNREACHED, root)


def not_run(mode, root=None) -> list:
    """Return the names of the mutants ``.mutation/<mode>/`` holds without a result."""
    return _kept_names(mode, {None}, root)


def _matching(names, patterns) -> list:
    """Return the ``names`` any of ``patterns`` (globs) matches; all of them without any."""
    return [n for n in names if not patterns or any(fnmatch.fnmatch(n, p) for p in patterns)]


def restore(mode, root=None) -> None:
    """Copy ``.mutation/<mode>/``'s kept results back into ``mutants/`` (mutmut goes on)."""
    root = root or ROOT
    kept = os.path.join(root, '.mutation', mode)
    for meta in glob.glob(os.path.join(kept, '**', '*.py.meta'), recursive=True):
        destination = os.path.join(root, 'mutants', os.path.relpath(meta, kept))
        os.makedirs(os.path.dirname(destination), exist_ok=True)
        shutil.copy2(meta, destination)


def keep(mode, root=None) -> None:
    """
    Copy mutmut's ``.meta`` results of ``mutants/`` to ``.mutation/<mode>/``.

    A ``.meta`` that does not read as JSON (mutmut stopped while writing it) is not copied:
    the kept one stays, and one line says so (its mutants since then run again).
    """
    root = root or ROOT
    target = os.path.join(root, '.mutation', mode)
    top = os.path.join(root, 'mutants')
    for meta in glob.glob(os.path.join(top, '**', '*.py.meta'), recursive=True):
        destination = os.path.join(target, os.path.relpath(meta, top))
        try:
            with open(meta, encoding='utf-8') as stream:
                json.load(stream)
        except ValueError:
            print(f'mutate: {os.path.relpath(meta, root)} was cut off while written; the '
                  'results kept before stay', file=sys.stderr)
            continue
        os.makedirs(os.path.dirname(destination), exist_ok=True)
        shutil.copy2(meta, destination)


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
    by_module, (equivalent, stale) = results(), still_equivalent()
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
    if stale:
        print(f'mutate: {len(stale)} listed equivalent(s) no longer the mutant reviewed (the '
              f'function changed; not counted, review again): ' + ', '.join(stale))
    print(f'mutate: {below} module(s) below {target:g} %')
    return below


def one_run_at_a_time(root=None):
    """
    Return the held lock of ``.mutation/run.lock`` (an open file), or None if a run holds it.

    Two runs at once rewrite each other's ``mutants/`` and keep each other's half-made
    results (a whole build's were lost so). The lock goes with the process.
    """
    import fcntl
    folder = os.path.join(root or ROOT, '.mutation')
    os.makedirs(folder, exist_ok=True)
    stream = open(os.path.join(folder, 'run.lock'), 'w')
    try:
        fcntl.flock(stream, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        stream.close()
        return None
    return stream


def main(argv=None) -> int:
    """Run mutmut (``run``) and print the report, or the report alone (``report``)."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    # no default: 'mutate.py --survivors X' once started a whole run of both builds
    parser.add_argument('action', choices=('run', 'report', 'fingerprint'))
    parser.add_argument('--modes', nargs='+', choices=sorted(MODES), default=sorted(MODES))
    parser.add_argument('--only', nargs='+', metavar='PATTERN', default=[],
                        help="mutmut's mutant names to run (globs: 'dq_fk_ros.ros.conversions*')")
    parser.add_argument('--survivors-again', action='store_true',
                        help="run again what the build's kept results have not killed")
    parser.add_argument('--continue', dest='resume', action='store_true',
                        help="run only what the build's kept results have not run (mutmut's "
                             'order: the quickest first); Ctrl-C or SIGTERM stops it and keeps '
                             'what ran')
    parser.add_argument('--jobs', type=int, default=os.cpu_count() or 2)
    parser.add_argument('--target', type=float, default=90.0)
    parser.add_argument('--survivors', metavar='MODULE', help='list this module\'s survivors')
    args = parser.parse_args(argv)
    if args.action == 'fingerprint':   # after reviewing new entries of the equivalents file
        print(f'mutate: {fill_fingerprints()} fingerprint(s) written')
        return 0
    if args.action == 'run':
        lock = one_run_at_a_time()
        if lock is None:
            print('mutate: another mutate.py run is going on in this checkout (mutants/ and '
                  '.mutation/ are shared); wait for it or stop it', file=sys.stderr)
            return 2
        # Ctrl-C, or a SIGTERM (a run left in the background, where SIGINT is ignored), stops
        # mutmut and keeps what it finished
        before = {sig: signal.signal(sig, signal.default_int_handler)
                  for sig in (signal.SIGINT, signal.SIGTERM)}
        try:
            rc = _run(args)
        finally:
            for sig, handler in before.items():
                signal.signal(sig, handler)
            lock.close()
        if rc:
            return rc
    report(args.target, args.survivors)
    return 0


def _run(args) -> int:
    """Run mutmut for each build of ``args.modes``; return 0, or the first failure's code."""
    mutmut = os.path.join(os.path.dirname(sys.executable), 'mutmut')
    listed = still_equivalent()[0]   # (checked against mutants/ before it is made anew)
    for mode in args.modes:
        # a fresh start, or (--only) this build's earlier results carried on
        shutil.rmtree(os.path.join(ROOT, 'mutants'), ignore_errors=True)
        names = list(args.only)
        if args.resume and names:   # the named modules' mutants not run yet, alone
            names = _matching(not_run(mode), names)
            if not names:
                continue
        if args.survivors_again:   # (with --only: the named modules' survivors alone),
            # less the reviewed equivalents: they survive every run, each after all its tests
            names = [n for n in _matching(not_killed(mode), args.only) if n not in listed]
            if not names:
                continue
        if names or args.resume:
            restore(mode)   # (without names mutmut runs only the mutants not run yet)
        print(f'mutate: mutmut run, {mode} build ({len(names) or "all"} mutants'
              f'{", those not run yet" if args.resume and not names else ""})', flush=True)
        try:
            rc = subprocess.call([mutmut, 'run', '--max-children', str(args.jobs)] + names,
                                 cwd=ROOT,
                                 env=dict({k: v for k, v in os.environ.items()
                                           if k != 'DQ_FK_PURE_PYTHON'}, **MODES[mode]),
                                 stdout=subprocess.DEVNULL)
        except KeyboardInterrupt:   # mutmut saved every mutant it finished: keep them
            keep(mode)
            print(f'mutate: stopped; the {mode} build\'s results so far are kept',
                  file=sys.stderr)
            return 130
        if rc != 0:
            print(f'mutate: mutmut run ({mode}) exited {rc} (see: mutmut run, in {ROOT})',
                  file=sys.stderr)
            return rc
        keep(mode)
    return 0


if __name__ == '__main__':
    sys.exit(main())
