"""docs/performance.md from the benchmarks' recorded figures (bench_results, performance_doc)."""

import importlib.util
import json
import os

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def load(path, name):
    spec = importlib.util.spec_from_file_location(name, os.path.join(ROOT, path))
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


bench_results = load('benchmarks/bench_results.py', 'bench_results')
performance_doc = load('scripts/performance_doc.py', 'performance_doc')


def record_some(tmp_path, monkeypatch, capsys):
    path = tmp_path / 'results.jsonl'
    monkeypatch.setenv(bench_results.RESULTS_VARIABLE, str(path))
    figure = bench_results.figure
    figure('tiago_dual: every output', 135.9, 'us per update', '<= 60 us', False,
           group='the node')
    figure('tiago_dual: /tf alone', 22.4, 'us per update', '<= 129 us', True, group='the node')
    figure('tiago_dual: rclpy publishes one message', 0.78, 'us', group='the node')
    figure('rl15: FK, every frame', 0.7, 'us', group='the node', show=False)
    for rate, p99 in ((100, 1.2), (1000, 2.8), (5000, 7.5)):
        figure(f'rl15: p99 latency at {rate:g} Hz', p99, 'ms', group='end to end', show=False)
    for name, rate in (('many, --jobs 1', 100000), ('many, --jobs 2', 190000)):
        figure(f'{name}: throughput', rate, 'JointStates/s', group='the fleet', show=False)
    return path, capsys.readouterr().out


def test_a_figure_prints_its_line_and_records_it(tmp_path, monkeypatch, capsys):
    path, printed = record_some(tmp_path, monkeypatch, capsys)
    assert printed.splitlines() == [
        '- tiago_dual: every output: 135.9 us per update (target <= 60 us: NOT met)',
        '- tiago_dual: /tf alone: 22.4 us per update (target <= 129 us: met)',
        '- tiago_dual: rclpy publishes one message: 0.78 us']
    records = [json.loads(line) for line in path.read_text().splitlines()]
    assert len(records) == 9
    assert records[0]['what'] == 'tiago_dual: every output' and records[0]['met'] is False
    assert records[2]['target'] is None and records[0]['command'].startswith('.venv/bin/python')


def test_numpy_figures_are_recorded_as_plain_numbers(tmp_path, monkeypatch, capsys):
    import numpy as np
    path = tmp_path / 'results.jsonl'
    monkeypatch.setenv(bench_results.RESULTS_VARIABLE, str(path))
    bench_results.figure('lost', np.int64(0), 'messages', '0', np.bool_(True))
    bench_results.figure('p99', np.float64(2.5), 'ms', '< 5 ms', np.float64(2.5) < 5.0)
    records = [json.loads(line) for line in path.read_text().splitlines()]
    assert [(r['value'], r['met']) for r in records] == [(0, True), (2.5, True)]


def test_without_a_results_file_nothing_is_written(tmp_path, monkeypatch, capsys):
    monkeypatch.delenv(bench_results.RESULTS_VARIABLE, raising=False)
    bench_results.figure('x', 1, 'us', '<= 2 us', True)
    assert capsys.readouterr().out == '- x: 1 us (target <= 2 us: met)\n'
    assert list(tmp_path.iterdir()) == []


def test_the_document_has_a_table_per_group_and_the_plots(tmp_path, monkeypatch, capsys):
    path, _ = record_some(tmp_path, monkeypatch, capsys)
    out = tmp_path / 'docs' / 'performance.md'
    out.parent.mkdir()
    assert performance_doc.main([str(path), str(out)]) == 0
    text = out.read_text()
    assert '2 figures against targets, 1 met, 1 NOT met' in text
    assert '| tiago_dual: every output | 135.9 us per update | <= 60 us | **NOT met** |' in text
    assert '| tiago_dual: /tf alone | 22.4 us per update | <= 129 us | met |' in text
    assert '| tiago_dual: rclpy publishes one message | 0.78 us |' in text
    assert text.index('## The node') < text.index('## End to end') < text.index('## The fleet')
    for plot in ('latency_against_rate.png', 'throughput_against_jobs.png'):
        assert f'(img/{plot})' in text
        assert (out.parent / 'img' / plot).read_bytes()[:8] == b'\x89PNG\r\n\x1a\n'


def test_a_damaged_results_file_is_named_with_its_line(tmp_path):
    path = tmp_path / 'results.jsonl'
    path.write_text('{"what": "x"}\n{not json\n')
    with pytest.raises(SystemExit, match=r'results.jsonl:2: not a JSON object'):
        performance_doc.read_results(path)
