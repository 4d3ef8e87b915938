"""
Every shell example of the README and docs/ runs as written (after ``make demo``).

The fenced blocks marked ``sh`` are the runnable ones: each runs as one bash script (``set
-e``) from the repository's root, on this run's private DDS domain; ``make`` lines are the
Makefile's own (``make test`` runs this test) and are left out. Blocks marked ``python``
run with the set-up's Python. One test a document: its blocks run in file order (a reader
runs them so, and a block may use what one before it made), whatever order the tests run in
(pytest-randomly) and on whichever worker. Other blocks (``text``, ``yaml``, output) are not
commands.

Two things are changed before a block runs, so that it touches nothing of another run or of
the user: ``/tmp/`` becomes a scratch folder of the document's test (the same for each of
its blocks), and the Dask scheduler's port 8799 a free port. While a block runs, every TCP
port it or a process it starts listens on must be on loopback.
"""

import glob
import os
import re
import signal
import socket
import subprocess
import time

from proc_table import in_session, listening
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


DOCS_PORT = '8799'  # the scheduler's port in the README


def free_port():
    """Return a TCP port free on loopback now: where a document's 8799 goes."""
    with socket.socket() as probe:
        probe.bind(('127.0.0.1', 0))
        return str(probe.getsockname()[1])


def made_private(script, scratch, port):
    """Return ``script`` with ``/tmp/`` in ``scratch`` and the port 8799 as ``port``."""
    script = script.replace('/tmp/', scratch.rstrip('/') + '/')
    return re.sub(rf'(?<=[ :]){DOCS_PORT}\b', port, script)


def test_made_private_moves_every_place_of_the_readme_fleet_example():
    script = next(s for _, s in EXAMPLES if DOCS_PORT in s)
    private = made_private(script, '/x/run', '40001')
    assert DOCS_PORT not in private and '/tmp/' not in private
    assert '--port 40001 ' in private and 'tcp://127.0.0.1:40001 ' in private
    assert '/x/run/fleet_in ' in private


def stop_left_behind(session, grace_s=10.0):
    """
    Stop what a block left running when a line of it failed (``dask worker ... &``).

    SIGTERM first, so that multiprocessing's resource tracker removes its semaphores from
    /dev/shm; SIGKILL what is still there after ``grace_s``.
    """
    deadline = time.monotonic() + grace_s
    for sig in (signal.SIGTERM, signal.SIGKILL):
        for pid in in_session(session):
            try:
                os.kill(pid, sig)
            except ProcessLookupError:
                pass
        while in_session(session) and time.monotonic() < deadline:
            time.sleep(0.05)


DOCUMENTS = sorted({place.split(':')[0] for place, _ in EXAMPLES},
                   key=lambda d: (d != 'README.md', d))


def test_every_example_belongs_to_a_document_test():
    assert sum(1 for place, _ in EXAMPLES if place.split(':')[0] in DOCUMENTS) == len(EXAMPLES)


@pytest.mark.parametrize('document', DOCUMENTS)
def test_a_documents_examples_run_as_written_in_order(document, ros_domain_id, tmp_path):
    scratch, port = tmp_path / 'tmp', free_port()
    scratch.mkdir()
    for number, (place, script) in enumerate(
            (p, s) for p, s in EXAMPLES if p.split(':')[0] == document):
        run_example(place, made_private(script, str(scratch), port), tmp_path / str(number))


def run_example(place, script, home):
    """Run one block (``place``: file:line[:python]) with ``home`` as HOME; assert it held."""
    home.mkdir()
    env = dict(os.environ, ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST', HOME=str(home))
    if place.endswith(':python'):
        command = [os.path.join(ROOT, '.venv', 'bin', 'python'), '-c', script]
    else:
        lines = [line for line in script.splitlines() if not line.startswith('make ')]
        if not any(line.strip() for line in lines):
            return  # a block of make commands only: the Makefile's own (CI runs them)
        command = ['bash', '-c', 'set -e\n' + '\n'.join(lines)]
    with open(home / 'stdout', 'w+') as out, open(home / 'stderr', 'w+') as err:
        run = subprocess.Popen(command, cwd=ROOT, env=env, stdout=out, stderr=err,
                               start_new_session=True)
        seen, deadline = set(), time.monotonic() + 180
        try:  # what it and everything it starts listen on, while it runs
            while run.poll() is None and time.monotonic() < deadline:
                seen |= listening(in_session(run.pid))
                time.sleep(0.05)
        finally:
            if run.poll() is None:
                os.killpg(run.pid, signal.SIGKILL)
            run.wait()
            stop_left_behind(run.pid)
        out.seek(0)
        err.seek(0)
        stdout, stderr = out.read(), err.read()
    assert run.returncode == 0, f'{place}: exit {run.returncode}\n{stdout[-2000:]}\n' \
                                f'{stderr[-2000:]}'
    # loopback only: 127.0.0.1, or a 127.x.y.z (dq_fk_foxglove's SDK server behind its gate)
    assert all(len(address) == 8 and int(address, 16) & 0xFF == 127
               for address, _ in seen), (place, seen)
