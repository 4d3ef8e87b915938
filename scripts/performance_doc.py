#!/usr/bin/env python3
"""
Write docs/performance.md from the figures ``make bench`` recorded (benchmarks/bench_results.py).

Usage: performance_doc.py RESULTS.jsonl OUT.md [--plots DIR]

One short table per benchmark group (figure, value, target, met or not), the commands that
printed them, and two plots where a curve says more than a table: end-to-end latency against
the input rate (bench_e2e.py) and the fleet's throughput per configuration (bench_fleet.py).
Figures recorded more than once (a benchmark run for several robots) all appear; a figure
without a target is a measurement (a floor, a peer) and says so.
"""

import argparse
from collections import OrderedDict
import json
import os
import re
import sys

GROUP_ORDER = ('the compiled kernel', 'the node', 'end to end', 'dq_fk_foxglove',
               'dq_fk_bag process', 'the fleet', 'TF without tf2')


def read_results(path):
    """Return the recorded figures, in the order they were recorded (one JSON per line)."""
    records = []
    with open(path, encoding='utf-8') as stream:
        for number, line in enumerate(stream, 1):
            if line.strip():
                try:
                    records.append(json.loads(line))
                except json.JSONDecodeError as exc:
                    raise SystemExit(f'{path}:{number}: not a JSON object ({exc.msg})')
    return records


def shown(value):
    """Return a figure as text: thousands separated, no trailing zeros."""
    if isinstance(value, float):
        return f'{value:,.3f}'.rstrip('0').rstrip('.')
    return f'{value:,}'


def with_unit(record):
    """Return a figure with its unit (``2.09x``, ``4.12 ms``)."""
    unit = record['unit']
    return f"{shown(record['value'])}{unit}" if unit == 'x' else \
        f"{shown(record['value'])} {unit}".rstrip()


def plotted(record):
    """Say whether a figure is drawn in one of the plots (and so left out of the tables)."""
    return bool(re.search(r': p(50|99) latency at [0-9.]+ Hz$', record['what'])) or \
        record['what'].endswith(': throughput')


def heading(group):
    """Return a group's heading: capitalised, except a program's name."""
    return group if group.startswith('dq_fk') else group[0].upper() + group[1:]


def verdict(record):
    """Return the met column: met, NOT met, or a dash for a figure without a target."""
    if record.get('target') is None:
        return '-'
    return 'met' if record.get('met') else '**NOT met**'


def group_tables(records):
    """Return markdown: per group, the commands and one table of its figures with targets."""
    groups = OrderedDict((g, []) for g in GROUP_ORDER)
    for record in records:
        groups.setdefault(record.get('group') or 'other', []).append(record)
    out = []
    for group, members in groups.items():
        if not members:
            continue
        out.append(f'## {heading(group)}\n')
        commands = list(OrderedDict.fromkeys(r['command'] for r in members))
        out.append('Printed by ' + ', '.join(f'`{c}`' for c in commands) + '.\n')
        targeted = [r for r in members if r.get('target') is not None]
        measured = [r for r in members if r.get('target') is None and not plotted(r)]
        drawn = sum(plotted(r) for r in members)
        if targeted:
            out.append('| figure | measured | target | |')
            out.append('|---|---|---|---|')
            for r in targeted:
                out.append(f"| {r['what']} | {with_unit(r)} | {r['target']} | {verdict(r)} |")
            out.append('')
        if measured and len(measured) <= 40:
            out.append('| also measured (no target) | |')
            out.append('|---|---|')
            for r in measured:
                out.append(f"| {r['what']} | {with_unit(r)} |")
            out.append('')
        elif measured:
            out.append(f'({len(measured)} more figures without a target are in the results '
                       f'file.)\n')
        if drawn:
            out.append(f'({drawn} figures of every run are drawn in the plots above.)\n')
    return '\n'.join(out)


def latency_series(records):
    """Return ``{robot label: {rate: [p99, ...]}}`` from bench_e2e.py's per-run figures."""
    series = {}
    pattern = re.compile(r'^(.*): p99 latency at ([0-9.]+) Hz$')
    for r in records:
        found = pattern.match(r['what'])
        if found:
            label, rate = found[1], float(found[2])
            series.setdefault(label, {}).setdefault(rate, []).append(float(r['value']))
    return series


def throughput_series(records):
    """Return ``[(configuration, JointStates/s), ...]`` from bench_fleet.py."""
    return [(r['what'][:-len(': throughput')], float(r['value'])) for r in records
            if r['what'].endswith(': throughput')]


def write_plots(records, folder):
    """Draw the two plots into ``folder``; return their file names (none without data)."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    os.makedirs(folder, exist_ok=True)
    made = []
    series = latency_series(records)
    if series:
        fig, ax = plt.subplots(figsize=(6, 3.6), dpi=100)
        for k, (label, by_rate) in enumerate(series.items()):
            color = f'C{k}'
            rates = sorted(by_rate)
            for rate in rates:  # every repetition a point, the median joined by a line
                ax.scatter([rate] * len(by_rate[rate]), by_rate[rate], color=color, s=14,
                           alpha=0.7)
            medians = [sorted(by_rate[r])[len(by_rate[r]) // 2] for r in rates]
            ax.plot(rates, medians, color=color, marker='o', label=f'{label} (median)')
        ax.axhline(5.0, color='grey', linestyle='--', linewidth=1, label='target p99 5 ms')
        ax.set(xscale='log', ylim=(0, None), xlabel='JointState rate (Hz)',
               ylabel='p99 latency (ms)', title='end to end: p99 latency against rate')
        ax.legend(fontsize=7)
        fig.tight_layout()
        fig.savefig(os.path.join(folder, 'latency_against_rate.png'))
        plt.close(fig)
        made.append('latency_against_rate.png')
    rows = throughput_series(records)
    if rows:
        fig, ax = plt.subplots(figsize=(6, 3.0), dpi=100)
        names = [n for n, _ in rows]
        ax.barh(range(len(rows)), [v / 1e3 for _, v in rows], color='tab:blue')
        ax.set_yticks(range(len(rows)), names, fontsize=8)
        ax.invert_yaxis()
        ax.set(xlabel='thousand JointStates/s', title='the fleet: throughput against jobs')
        fig.tight_layout()
        fig.savefig(os.path.join(folder, 'throughput_against_jobs.png'))
        plt.close(fig)
        made.append('throughput_against_jobs.png')
    return made


def performance_doc(records, plots, plot_folder_rel):
    """Return the whole of docs/performance.md."""
    dates = sorted({r.get('date', '') for r in records} - {''})
    when = dates[0] if len(dates) == 1 else (f'{dates[0]} to {dates[-1]}' if dates else '?')
    targets = [r for r in records if r.get('target') is not None]
    missed = [r for r in targets if not r.get('met')]
    lines = ['# Performance', '',
             f'Generated by `make bench` ({when}; `scripts/performance_doc.py` from the '
             f'figures each benchmark records): {len(targets)} figures against targets, '
             f'{len(targets) - len(missed)} met, {len(missed)} NOT met. The machine: 2 cores, '
             'no GPU, other processes running; figures move between runs (the kernel by up to '
             '2x on a noisy machine), so each table is one run, not a promise. What every '
             'figure means, and the earlier runs with their dates, are in '
             '[performance-history.md](performance-history.md).', '']
    for name in plots:
        title = name[:-4].replace('_', ' ')
        lines += [f'![{title}]({plot_folder_rel}/{name})', '']
    lines.append(group_tables(records))
    return '\n'.join(lines).rstrip() + '\n'


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.strip().splitlines()[0])
    parser.add_argument('results', help="the JSON lines file make bench's benchmarks wrote")
    parser.add_argument('out', help='the markdown file to write (docs/performance.md)')
    parser.add_argument('--plots', default=None,
                        help='folder for the plots (default: img/ beside OUT)')
    args = parser.parse_args(argv)
    records = read_results(args.results)
    if not records:
        print(f'performance_doc: {args.results} holds no figures', file=sys.stderr)
        return 1
    folder = args.plots or os.path.join(os.path.dirname(os.path.abspath(args.out)), 'img')
    plots = write_plots(records, folder)
    rel = os.path.relpath(folder, os.path.dirname(os.path.abspath(args.out)))
    with open(args.out, 'w', encoding='utf-8') as stream:
        stream.write(performance_doc(records, plots, rel))
    print(f'performance_doc: wrote {args.out} ({len(records)} figures, {len(plots)} plots)')
    return 0


if __name__ == '__main__':
    sys.exit(main())
