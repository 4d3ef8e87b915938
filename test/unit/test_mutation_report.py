"""scripts/mutate.py: the per-module kill rates it makes of mutmut's results."""

import importlib.util
import json
import os

import pytest

SCRIPT = os.path.join(os.path.dirname(__file__), '..', '..', 'scripts', 'mutate.py')
_spec = importlib.util.spec_from_file_location('mutate_script', SCRIPT)
mutate = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(mutate)


def write_meta(root, module, codes):
    path = root / 'mutants' / (module.replace('.', '/') + '.py.meta')
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps({'exit_code_by_key': codes}))


def test_rates_are_killed_over_judged_less_the_listed_equivalents(tmp_path, monkeypatch, capsys):
    write_meta(tmp_path, 'pkg.description.xacro_sandbox', {   # '.x' inside a module's name
        'pkg.description.xacro_sandbox.x_f__mutmut_1': 1,     # killed
        'pkg.description.xacro_sandbox.x_f__mutmut_2': 36,    # a timeout: killed
        'pkg.description.xacro_sandbox.x_f__mutmut_3': 0,     # survived
        'pkg.description.xacro_sandbox.x_f__mutmut_4': 0,     # survived, listed equivalent
        'pkg.description.xacro_sandbox.x_f__mutmut_5': 33,    # no test reaches it: survived
        'pkg.description.xacro_sandbox.x_f__mutmut_6': None,  # not run
    })
    write_meta(tmp_path, 'pkg.kinematics.dh', {f'pkg.kinematics.dh.x_g__mutmut_{k}': 1
                                               for k in range(1, 10)})
    listed = tmp_path / 'equivalent.txt'
    listed.write_text('# a comment\npkg.description.xacro_sandbox.x_f__mutmut_4 || why\n')
    monkeypatch.setattr(mutate, 'ROOT', str(tmp_path))
    monkeypatch.setattr(mutate, 'EQUIVALENT', str(listed))
    assert mutate.equivalents(str(listed)) == {
        'pkg.description.xacro_sandbox.x_f__mutmut_4': 'why'}
    by_module = mutate.results(str(tmp_path))
    assert sorted(by_module) == ['pkg.description.xacro_sandbox', 'pkg.kinematics.dh']
    counts = mutate.tally(by_module['pkg.description.xacro_sandbox'], mutate.equivalents(
        str(listed)))
    assert (counts['killed'], counts['survived'], counts['unreached'], counts['equivalent'],
            counts['not run']) == (2, 1, 1, 1, 1)
    assert counts['survivors'] == ['pkg.description.xacro_sandbox.x_f__mutmut_3',
                                   'pkg.description.xacro_sandbox.x_f__mutmut_5']
    assert mutate.report(90.0, survivors_of='xacro_sandbox') == 1
    lines = capsys.readouterr().out.splitlines()
    row = next(line for line in lines if line.startswith('pkg.description.xacro_sandbox'))
    assert row.split()[1:6] == ['2', '1', '1', '1', '50.0'] and row.endswith('BELOW  (1 not run)')
    assert 'pkg.kinematics.dh' in next(line for line in lines if '100.0 %' in line)
    assert '    pkg.description.xacro_sandbox.x_f__mutmut_5' in lines
    assert lines[-1] == 'mutate: 1 module(s) below 90 %'


@pytest.mark.parametrize('target, below', [(50.0, 0), (50.1, 1)])
def test_the_target_is_a_floor_that_a_module_at_it_meets(tmp_path, monkeypatch, target, below):
    write_meta(tmp_path, 'pkg.m', {'pkg.m.x_f__mutmut_1': 1, 'pkg.m.x_f__mutmut_2': 0})
    monkeypatch.setattr(mutate, 'ROOT', str(tmp_path))
    monkeypatch.setattr(mutate, 'EQUIVALENT', str(tmp_path / 'none.txt'))
    assert mutate.report(target) == below


def test_a_mutant_killed_by_either_build_is_killed(tmp_path, monkeypatch):
    """The C build's tests never run a reference's lines, the Python build's never the C's."""
    names = [f'pkg.m.x_f__mutmut_{k}' for k in range(1, 6)]
    compiled = {names[0]: 1, names[1]: 0, names[2]: 0, names[3]: 33, names[4]: 33}
    pure = {names[0]: 0, names[1]: 1, names[2]: 0, names[3]: 0, names[4]: 33}
    for mode, codes in (('compiled', compiled), ('pure', pure)):
        write_meta(tmp_path, 'pkg.m', codes)
        mutate.keep(mode, str(tmp_path))
    merged = mutate.results(str(tmp_path))['pkg.m']
    assert [merged[n] for n in names] == [1, 1, 0, 0, 33]
    assert sorted(os.listdir(tmp_path / '.mutation')) == ['compiled', 'pure']
    (tmp_path / 'mutants' / 'pkg' / 'm.py.meta').unlink()
    mutate.restore('compiled', str(tmp_path))   # a later run of some mutants goes on from it
    restored = json.loads((tmp_path / 'mutants' / 'pkg' / 'm.py.meta').read_text())
    assert restored['exit_code_by_key'] == compiled
    assert mutate.not_killed('compiled', str(tmp_path)) == names[1:]   # survived, unreached


def test_a_results_file_cut_off_while_written_leaves_the_kept_one(tmp_path, capsys):
    """A .meta cut off by a stop (SIGTERM) while mutmut wrote it: the results kept stay."""
    write_meta(tmp_path, 'pkg.m', {'pkg.m.x_f__mutmut_1': 1, 'pkg.m.x_f__mutmut_2': 0})
    write_meta(tmp_path, 'pkg.n', {'pkg.n.x_g__mutmut_1': None})
    mutate.keep('pure', str(tmp_path))
    meta = tmp_path / 'mutants' / 'pkg' / 'm.py.meta'
    meta.write_text(meta.read_text()[:-20])   # the tail never written
    write_meta(tmp_path, 'pkg.n', {'pkg.n.x_g__mutmut_1': 1})
    mutate.keep('pure', str(tmp_path))
    kept = mutate.results(str(tmp_path))
    assert kept['pkg.m'] == {'pkg.m.x_f__mutmut_1': 1, 'pkg.m.x_f__mutmut_2': 0}
    assert kept['pkg.n'] == {'pkg.n.x_g__mutmut_1': 1}   # the others are kept as usual
    assert 'mutants/pkg/m.py.meta was cut off while written' in capsys.readouterr().err


def test_continue_runs_mutmut_without_names_on_the_kept_results_and_ctrl_c_keeps_them(
        tmp_path, monkeypatch):
    """Without names, mutmut runs only the mutants without a result."""
    name = 'pkg.m.x_f__mutmut_1'
    write_meta(tmp_path, 'pkg.m', {name: 1, 'pkg.m.x_f__mutmut_2': None})
    mutate.keep('pure', str(tmp_path))
    monkeypatch.setattr(mutate, 'ROOT', str(tmp_path))
    monkeypatch.setattr(mutate, 'report', lambda *args: 0)
    calls = []

    def mutmut(argv, cwd, env, stdout):
        calls.append((argv[1:], env.get('DQ_FK_PURE_PYTHON')))
        meta = tmp_path / 'mutants' / 'pkg' / 'm.py.meta'
        codes = json.loads(meta.read_text())['exit_code_by_key']   # restored for it
        assert codes == {name: 1, 'pkg.m.x_f__mutmut_2': None}
        meta.write_text(json.dumps({'exit_code_by_key': dict(codes, **{
            'pkg.m.x_f__mutmut_2': 0})}))
        raise KeyboardInterrupt   # stopped by the user after one more mutant
    monkeypatch.setattr(mutate.subprocess, 'call', mutmut)
    assert mutate.main(['run', '--modes', 'pure', '--continue', '--jobs', '1']) == 130
    assert calls == [(['run', '--max-children', '1'], '1')]
    assert mutate.results(str(tmp_path))['pkg.m'] == {name: 1, 'pkg.m.x_f__mutmut_2': 0}


@pytest.fixture
def mutmut_names(tmp_path, monkeypatch):
    """Run mutate.py on ``tmp_path``; the list of the mutant names each mutmut run was given."""
    monkeypatch.setattr(mutate, 'ROOT', str(tmp_path))
    monkeypatch.setattr(mutate, 'report', lambda *args: 0)
    calls = []
    monkeypatch.setattr(mutate.subprocess, 'call', lambda argv, **k: calls.append(argv[4:]) or 0)
    return calls


def test_continue_with_patterns_names_only_their_mutants_not_run_yet(tmp_path, mutmut_names):
    calls = mutmut_names
    write_meta(tmp_path, 'pkg.a', {'pkg.a.x_f__mutmut_1': 1, 'pkg.a.x_f__mutmut_2': None})
    write_meta(tmp_path, 'pkg.b', {'pkg.b.x_g__mutmut_1': None})
    mutate.keep('compiled', str(tmp_path))
    assert mutate.main(['run', '--modes', 'compiled', '--continue', '--only', 'pkg.a*']) == 0
    assert calls == [['pkg.a.x_f__mutmut_2']]
    calls.clear()
    write_meta(tmp_path, 'pkg.a', {'pkg.a.x_f__mutmut_1': 1, 'pkg.a.x_f__mutmut_2': 0})
    mutate.keep('compiled', str(tmp_path))
    assert mutate.main(['run', '--modes', 'compiled', '--continue', '--only', 'pkg.a*']) == 0
    assert calls == []   # nothing of pkg.a left to run: mutmut is not started


def test_survivors_again_with_patterns_runs_their_survivors_alone(
        tmp_path, mutmut_names, monkeypatch):
    calls = mutmut_names
    write_meta(tmp_path, 'pkg.a', {'pkg.a.x_f__mutmut_1': 0, 'pkg.a.x_f__mutmut_2': 1})
    write_meta(tmp_path, 'pkg.b', {'pkg.b.x_g__mutmut_1': 0})
    mutate.keep('pure', str(tmp_path))
    assert mutate.main(['run', '--modes', 'pure', '--survivors-again', '--only', 'pkg.a*']) == 0
    assert calls == [['pkg.a.x_f__mutmut_1']]
    calls.clear()
    assert mutate.main(['run', '--modes', 'pure', '--survivors-again']) == 0
    assert calls == [['pkg.a.x_f__mutmut_1', 'pkg.b.x_g__mutmut_1']]
    calls.clear()   # a reviewed equivalent survives every run: not run again
    listed = tmp_path / 'equivalent.txt'
    listed.write_text('pkg.b.x_g__mutmut_1 || why\n')
    monkeypatch.setattr(mutate, 'EQUIVALENT', str(listed))
    assert mutate.main(['run', '--modes', 'pure', '--survivors-again']) == 0
    assert calls == [['pkg.a.x_f__mutmut_1']]


def write_mutants(root, body):
    path = root / 'mutants' / 'pkg' / 'm.py'
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(body)


ORIGINAL = 'def x_f__mutmut_orig(a):\n    b = 2\n    return a + b\n'


def test_an_equivalent_whose_mutant_changed_is_not_counted_and_is_named(
        tmp_path, monkeypatch, capsys):
    write_meta(tmp_path, 'pkg.m', {'pkg.m.x_f__mutmut_1': 0, 'pkg.m.x_f__mutmut_2': 1})
    write_mutants(tmp_path, ORIGINAL + 'def x_f__mutmut_1(a):\n    b = 2\n    return a - b\n'
                  'def x_f__mutmut_2(a):\n    b = 3\n    return a + b\n')
    listed = tmp_path / 'equivalent.txt'
    listed.write_text('pkg.m.x_f__mutmut_1 || why\npkg.m.x_f__mutmut_9 || gone\n')
    monkeypatch.setattr(mutate, 'ROOT', str(tmp_path))
    monkeypatch.setattr(mutate, 'EQUIVALENT', str(listed))
    assert mutate.fill_fingerprints() == 1   # the one whose mutant exists
    text = listed.read_text()
    assert text.startswith('pkg.m.x_f__mutmut_1 || why || fp=') and 'mutmut_9 || gone\n' in text
    assert mutate.equivalents() == {'pkg.m.x_f__mutmut_1': 'why', 'pkg.m.x_f__mutmut_9': 'gone'}
    assert mutate.still_equivalent()[1] == []
    # a change elsewhere in the function keeps the fingerprint; another mutation does not
    write_mutants(tmp_path, ORIGINAL.replace('b = 2', 'b = 2  # two') +
                  'def x_f__mutmut_1(a):\n    b = 2  # two\n    return a - b\n')
    assert mutate.still_equivalent()[1] == []
    write_mutants(tmp_path, ORIGINAL + 'def x_f__mutmut_1(a):\n    b = 5\n    return a + b\n')
    kept, stale = mutate.still_equivalent()
    assert stale == ['pkg.m.x_f__mutmut_1'] and list(kept) == ['pkg.m.x_f__mutmut_9']
    assert mutate.report(90.0) == 1   # the mutant counts as survived again
    lines = capsys.readouterr().out.splitlines()
    assert lines[-2] == ('mutate: 1 listed equivalent(s) no longer the mutant reviewed (the '
                         'function changed; not counted, review again): pkg.m.x_f__mutmut_1')


def test_a_second_run_in_the_same_checkout_is_refused(tmp_path, monkeypatch, capsys):
    """Two runs at once rewrite each other's mutants/ (a whole build's results were lost so)."""
    monkeypatch.setattr(mutate, 'ROOT', str(tmp_path))
    held = mutate.one_run_at_a_time()
    try:
        assert mutate.main(['run', '--modes', 'pure', '--continue']) == 2
        assert 'another mutate.py run is going on' in capsys.readouterr().err
    finally:
        held.close()
    assert mutate.one_run_at_a_time() is not None   # released with its holder


def test_the_action_is_named_never_a_run_by_default(capsys):
    """``mutate.py --survivors X`` (report's option) once started a whole run of both builds."""
    with pytest.raises(SystemExit):
        mutate.main(['--survivors', 'schema'])
