"""
The benchmarks' figures as data: each target line printed and recorded as JSON.

A benchmark calls :func:`figure` for every figure it reports against a target (or as a
floor, with no target): the line is printed as before (``- what: value (target ...: met)``)
and, when ``DQ_FK_BENCH_JSON`` names a file (``make bench`` sets it), appended to it as one
JSON object per line: benchmark, command, what, value, unit, target, met, date.
``scripts/performance_doc.py`` makes docs/performance.md from that file.
"""

import datetime
import json
import os
import shlex
import sys

RESULTS_VARIABLE = 'DQ_FK_BENCH_JSON'


def command_line():
    """Return the command that ran this benchmark, as a user would type it."""
    script = os.path.relpath(sys.argv[0])
    return ' '.join(['.venv/bin/python', script] + [shlex.quote(a) for a in sys.argv[1:]])


def figure(what, value, unit, target=None, met=None, text=None, group='', show=True):
    """
    Print one figure's line and record it.

    :param what: what was measured (``'tiago_dual, every output'``).
    :param value: the figure (a number).
    :param unit: its unit (``'us'``, ``'%'``, ``'x'``, ``'M cfg/s'``).
    :param target: the target as text (``'<= 60 us'``), None for a figure without one.
    :param met: whether the target is met (None: no target).
    :param text: the line to print, if not the default ``- what: value unit (target: met)``.
    :param group: a heading the figure belongs under (a robot, a table), '' for none.
    :param show: print the line (False: a figure already printed in a table, recorded only).
    """
    value = value.item() if hasattr(value, 'item') else value  # a numpy scalar
    met = None if met is None else bool(met)
    if text is None:
        shown = f'{value:,.2f}'.rstrip('0').rstrip('.') if isinstance(value, float) \
            else f'{value:,}'
        text = f'- {what}: {shown}{unit}' if unit == 'x' else f'- {what}: {shown} {unit}'.rstrip()
        if target is not None:
            text += f" (target {target}: {'met' if met else 'NOT met'})"
    if show:
        print(text, flush=True)
    path = os.environ.get(RESULTS_VARIABLE)
    if not path:
        return
    record = {'benchmark': os.path.basename(sys.argv[0]), 'command': command_line(),
              'group': group, 'what': what, 'value': value, 'unit': unit, 'target': target,
              'met': met, 'date': datetime.date.today().isoformat()}
    with open(path, 'a', encoding='utf-8') as stream:
        stream.write(json.dumps(record) + '\n')
