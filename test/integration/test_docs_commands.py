"""
Every shell example of the README and docs/ runs as written (after ``make demo``).

The fenced blocks marked ``sh`` are the runnable ones: each runs as one bash script (``set
-e``) from the repository's root, on this run's private DDS domain; ``make`` lines are the
Makefile's own (``make test`` runs this test) and are left out. Blocks marked ``python``
run with the set-up's Python, in file order after the shell blocks before them. Other
blocks (``text``, ``yaml``, output) are not commands.
"""

import glob
import os
import re
import subprocess

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
FENCE = re.compile(r'^```(\w*)\n(.*?)^```', re.S | re.M)


def shell_blocks(kinds=('sh',)):
    """Yield ``(file:line, script)`` of every ``sh`` block of README.md and docs/*.md."""
    for path in ['README.md'] + sorted(glob.glob(os.path.join(ROOT, 'docs', '*.md'))):
        text = open(os.path.join(ROOT, path), encoding='utf-8').read()
        for match in FENCE.finditer(text):
            if match.group(1) in kinds:
                line = text[:match.start()].count('\n') + 1
                place = f'{os.path.relpath(os.path.join(ROOT, path), ROOT)}:{line}'
                yield (place if match.group(1) == 'sh' else f'{place}:python'), match.group(2)


def test_the_docs_have_runnable_examples():
    places = [place for place, _ in shell_blocks()]
    assert len(places) >= 8 and any(p.startswith('docs/') for p in places), places


EXAMPLES = list(shell_blocks(('sh', 'python')))


def test_the_docs_have_python_examples():
    assert len([p for p, _ in EXAMPLES if p.endswith(':python')]) >= 2


@pytest.mark.parametrize('place, script', EXAMPLES, ids=[place for place, _ in EXAMPLES])
def test_a_shell_example_runs_as_written(place, script, ros_domain_id, tmp_path):
    env = dict(os.environ, ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST', HOME=str(tmp_path))
    if place.endswith(':python'):
        command = [os.path.join(ROOT, '.venv', 'bin', 'python'), '-c', script]
    else:
        lines = [line for line in script.splitlines() if not line.startswith('make ')]
        if not any(line.strip() for line in lines):
            return  # a block of make commands only: the Makefile's own (CI runs them)
        command = ['bash', '-c', 'set -e\n' + '\n'.join(lines)]
    run = subprocess.run(command, cwd=ROOT, env=env, capture_output=True, text=True,
                         timeout=180)
    assert run.returncode == 0, f'{place}: exit {run.returncode}\n{run.stdout[-2000:]}\n' \
                                f'{run.stderr[-2000:]}'
