"""
Every shell example of the README and docs/ runs as written (after ``make demo``).

The fenced blocks marked ``sh`` are the runnable ones: each runs as one bash script (``set
-e``) from the repository's root, on this run's private DDS domain; ``make`` lines are the
Makefile's own (``make test`` runs this test) and are left out. Other blocks (``text``,
``yaml``, ``python``, output) are not commands.
"""

import glob
import os
import re
import subprocess

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
FENCE = re.compile(r'^```(\w*)\n(.*?)^```', re.S | re.M)


def shell_blocks():
    """Yield ``(file:line, script)`` of every ``sh`` block of README.md and docs/*.md."""
    for path in ['README.md'] + sorted(glob.glob(os.path.join(ROOT, 'docs', '*.md'))):
        text = open(os.path.join(ROOT, path), encoding='utf-8').read()
        for match in FENCE.finditer(text):
            if match.group(1) == 'sh':
                line = text[:match.start()].count('\n') + 1
                yield f'{os.path.relpath(os.path.join(ROOT, path), ROOT)}:{line}', match.group(2)


def test_the_docs_have_runnable_examples():
    places = [place for place, _ in shell_blocks()]
    assert len(places) >= 8 and any(p.startswith('docs/') for p in places), places


@pytest.mark.parametrize('place, script', list(shell_blocks()),
                         ids=[place for place, _ in shell_blocks()])
def test_a_shell_example_runs_as_written(place, script, ros_domain_id, tmp_path):
    lines = [line for line in script.splitlines() if not line.startswith('make ')]
    if not any(line.strip() for line in lines):
        return  # a block of make commands only: the Makefile's own (CI runs them)
    env = dict(os.environ, ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST', HOME=str(tmp_path))
    run = subprocess.run(['bash', '-c', 'set -e\n' + '\n'.join(lines)], cwd=ROOT, env=env,
                         capture_output=True, text=True, timeout=180)
    assert run.returncode == 0, f'{place}: exit {run.returncode}\n{run.stdout[-2000:]}\n' \
                                f'{run.stderr[-2000:]}'
