"""
A fleet of bags in one command: every bag under the inputs, on every core or a Dask cluster.

:func:`process_fleet` (``dq_fk_bag process IN [IN ...] --output-dir OUT``) finds the bags
(:mod:`dq_fk_ros.bag.discover`), skips those whose output is complete (the manifest,
:mod:`dq_fk_ros.bag.manifest`), cuts large MCAP bags into windows
(:mod:`dq_fk_ros.bag.windows`), runs every unit of work
(:func:`~dq_fk_ros.bag.fleet_units.run_unit`: a whole bag, or one window) on a pool of worker
processes or on a Dask ``distributed`` cluster, joins the windows of a bag in order
(:mod:`dq_fk_ros.bag.join`) and moves each finished output into place. Tasks carry paths and
options, never message data. The output of every bag is the one-bag command's, message for
message (test_fleet.py holds them equal).

A bag that fails (damaged, empty, another robot's, unreadable) does not stop the others: it
is reported, its partial output removed, and :attr:`FleetSummary.failed` counts it. A run
killed at any point leaves nothing the next run would take as complete: outputs are written
in ``OUT/.dq_fk_fleet/work`` and renamed into place, then recorded in the manifest.
"""

from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from dataclasses import asdict, dataclass, field, replace
import math
import multiprocessing
import os
import shutil
import sys
import time

from dq_fk_ros.bag.child_processes import (exit_with_parent, prepare_children,
                                           run_with_sigint_blocked, signals_blocked,
                                           stop_children)
from dq_fk_ros.bag.discover import find_bags
from dq_fk_ros.bag.fleet_units import RobotSpec, run_unit, Unit, UnitResult
from dq_fk_ros.bag.join import join_bags
from dq_fk_ros.bag.manifest import check_bag_name, FleetState
from dq_fk_ros.bag.process import ProcessOptions, set_progress_counter
from dq_fk_ros.bag.progress import Progress
from dq_fk_ros.bag.windows import chunk_counts, plan_windows
from dq_fk_ros.errors import BagError
from dq_fk_ros.storage.reading import joint_state_connections, open_reader
from dq_fk_ros.storage.text import one_line, printable

MIN_WINDOW_MESSAGES = 100_000  # a bag is cut into windows of at least this many JointStates
MAX_TRIES = 2                  # a unit whose worker died is run once more, then reported
FLEET_LOG_INTERVAL_S = 5.0     # the progress line's period when stderr is not a terminal


@dataclass
class BagReport:
    """
    One bag of the fleet: ``status`` is ``done``, ``skipped`` (complete before) or ``failed``.

    ``messages_in``: JointStates read; ``tf_out``: /tf messages written; ``problems``: one
    line each; ``units``: windows it was cut into (1: whole).
    """

    bag: str
    input: str  # noqa: A003 (the report's field name)
    output: str = None
    status: str = 'failed'
    messages_in: int = 0
    tf_out: int = 0
    problems: list = field(default_factory=list)
    seconds: float = 0.0
    units: int = 1


@dataclass
class FleetSummary:
    """What :func:`process_fleet` did: a :class:`BagReport` per bag, and the totals."""

    bags: list
    seconds: float = 0.0
    workers: int = 1
    notes: list = field(default_factory=list)  # one line each (a manifest set aside)

    @property
    def failed(self) -> int:
        """Count the bags that failed."""
        return sum(b.status == 'failed' for b in self.bags)

    @property
    def messages_in(self) -> int:
        """Count the JointStates read this run (skipped bags not counted)."""
        return sum(b.messages_in for b in self.bags if b.status == 'done')

    def as_dict(self) -> dict:
        """Return the summary as plain data (the ``--report`` JSON)."""
        return {'bags': [asdict(b) for b in self.bags], 'seconds': self.seconds,
                'workers': self.workers, 'failed': self.failed,
                'done': sum(b.status == 'done' for b in self.bags),
                'skipped': sum(b.status == 'skipped' for b in self.bags),
                'messages_in': self.messages_in, 'notes': list(self.notes)}


def process_fleet(inputs, output_dir, robot, options=None, jobs=None, scheduler=None,
                  force=False, progress=True, window_messages=None, base=None, tip=None,
                  packages=None, say=None) -> FleetSummary:
    """
    Process every bag under ``inputs`` into ``output_dir``; return a :class:`FleetSummary`.

    :param inputs: bag folders, bag files, or folders holding bags (found recursively).
    :param robot: a robot file or shipped name (``base``, ``tip``, ``packages`` as for
        :func:`~dq_fk_ros.description.loading.load_robot`): each worker loads it.
    :param options: a :class:`ProcessOptions` for every bag (``csv_path``, ``csv_only`` and
        ``overwrite`` do not apply).
    :param jobs: worker processes (default: the CPUs this process may use); 1: in this
        process. With ``scheduler``: ignored (the cluster's workers count).
    :param scheduler: ``'local'`` (a Dask ``LocalCluster`` of ``jobs`` processes) or a Dask
        scheduler address (``tcp://host:8786``); None: a local process pool.
    :param force: redo bags whose output is complete.
    :param window_messages: JointStates per window of a large MCAP bag (default: the fleet's
        messages over four units per worker, at least :data:`MIN_WINDOW_MESSAGES`).
    :param say: called with each one-line note for the user before the work starts (a
        manifest set aside); default: printed on stderr as ``dq_fk_bag: ...``.
    :raises BagError: for a command that cannot run (paths, options, a bag named as the
        fleet's state folder); a bag's own problems are reported in its :class:`BagReport`.
    """
    start = time.perf_counter()
    say = say or (lambda line: print(f'dq_fk_bag: {line}', file=sys.stderr))
    options = options or ProcessOptions()
    if options.csv_path or options.csv_only:
        raise BagError('--csv and --csv-only write one file per bag: not with --output-dir')
    spec = RobotSpec(os.fspath(robot), base, tip, tuple(sorted((packages or {}).items())))
    spec.load()  # a robot file that cannot be used stops the command before any work
    found = find_bags(inputs)
    for bag in found:
        check_bag_name(bag.name)
    _check_output_dir(output_dir, [os.fspath(p) for p in inputs] + [b.path for b in found])
    os.makedirs(output_dir, exist_ok=True)
    with FleetState(output_dir, spec, options) as state:
        reports, units = {}, []
        for bag in found:
            report = reports[bag.name] = BagReport(bag.name, bag.path,
                                                   os.path.join(output_dir, bag.name))
            if not force and state.complete(bag.name, bag.path, report.output):
                report.status = 'skipped'
                report.tf_out = state.bags[bag.name]['output'].get('/tf', 0)
                continue
            units += _plan(bag, state.work_folder(bag.name), spec, options)
        for note in state.notes:
            say(note)
        runner = _Runner(units, reports, state, jobs, scheduler, window_messages, progress)
        runner.run()
        return FleetSummary([reports[b.name] for b in found],
                            time.perf_counter() - start, runner.workers, state.notes)


def _check_output_dir(output_dir, inputs):
    out = os.path.realpath(output_dir)
    for path in inputs:
        real = os.path.realpath(path)
        if out == real or out.startswith(real + os.sep):
            raise BagError(f'--output-dir {output_dir} is inside the input {path}; choose '
                           f'another folder (its outputs would be read as inputs next time)')
        if real.startswith(out + os.sep):
            raise BagError(f'the input {path} is inside --output-dir {output_dir}; choose '
                           f'another folder')
    if os.path.lexists(output_dir) and not os.path.isdir(output_dir):
        raise BagError(f'--output-dir {output_dir} is not a folder')


def _plan(bag, work, spec, options):
    """Return the units of one bag: the whole bag, or windows of a large MCAP (see Unit)."""
    whole = Unit(bag.name, bag.path, os.path.join(work, os.path.basename(bag.name)), spec,
                 options)
    try:
        reader = open_reader(bag.path)
    except Exception:   # one bag's problem never ends a fleet: its worker reports it, as
        return [whole]  # the one-bag command does
    try:
        if not reader.windowable or options.copy_input:
            return [whole]
        conns = joint_state_connections(reader, bag.path, options.topic)
        messages = sum(c.msgcount for c in conns)
        return [replace(whole, messages=messages, window=_WholeBag(conns[0].topic))]
    except Exception:
        return [whole]
    finally:
        reader.close()


@dataclass(frozen=True)
class _WholeBag:
    """A bag that may still be cut into windows, once the fleet's size is known."""

    topic: str


class _Runner:
    """Runs the units on a pool or a cluster, and finishes each bag as its units complete."""

    def __init__(self, units, reports, state, jobs, scheduler, window_messages, progress):
        self.reports, self.state = reports, state
        self.jobs = jobs or len(os.sched_getaffinity(0))
        self.client = self.cluster = None   # (a LocalCluster it started, or None)
        if scheduler is not None:
            self.client, self.cluster = _dask_client(scheduler, self.jobs)
            self.workers = max(1, len(self.client.scheduler_info()['workers']))
        else:
            self.workers = self.jobs
        total = sum(u.messages for u in units)
        size = window_messages or max(MIN_WINDOW_MESSAGES,
                                      math.ceil(total / (4 * self.workers)))
        self.units = []
        for unit in units:
            self.units += self._cut(unit, size)
        self.pending = {}  # bag -> units not finished
        for unit in self.units:
            self.pending.setdefault(unit.bag, []).append(unit)
        self.results = {}  # bag -> results so far
        self.meter = Progress(total, 'dq_fk_bag fleet', enabled=progress)
        if not self.meter.terminal:
            self.meter.interval = FLEET_LOG_INTERVAL_S  # a line every few seconds in a log
        self.done_messages = 0

    def _cut(self, unit, size):
        """Cut a unit that may be cut (``_WholeBag``) into windows if it is large enough."""
        if not isinstance(unit.window, _WholeBag):
            return [unit]
        whole = replace(unit, window=None)
        count = unit.messages // size
        if self.workers < 2 or count < 2:
            return [whole]
        try:
            counts = chunk_counts(unit.path, unit.window.topic)
        except Exception:   # read again by its worker, which reports what it finds
            counts = None
        if counts is None:
            return [whole]
        windows = plan_windows(counts, count)
        if len(windows) < 2:
            return [whole]
        work = os.path.dirname(unit.output)
        self.reports[unit.bag].units = len(windows)
        return [replace(unit, window=w, output=os.path.join(work, f'part_{w.index}'),
                        messages=counts.count_before(w.stop_ns) - w.first_message)
                for w in windows]

    def run(self):
        """Run every unit; finish each bag when its last unit completes."""
        try:
            if self.client is not None:
                self._run_dask()
            elif self.jobs == 1 or len(self.units) <= 1:
                counter = multiprocessing.Value('q', 0)  # as the pool's workers count
                set_progress_counter(counter)
                try:
                    for unit in self.units:
                        self._finish(run_unit(unit), counter.value)
                finally:
                    set_progress_counter(None)
            else:
                self._run_pool()
        except BaseException:  # Ctrl-C, SIGTERM: every worker stops at once, quietly
            if self.client is not None:
                _abandon_cluster()
            raise
        try:
            self._close_client()
        except BaseException:  # interrupted while the cluster closes
            _abandon_cluster()
            raise
        self.meter.update(self.done_messages, force=True)

    def _close_client(self, timeout=None):
        if self.client is not None:
            client, self.client = self.client, None
            cluster, self.cluster = self.cluster, None
            client.close(timeout=timeout)
            if cluster is not None:
                cluster.close(timeout=timeout)

    def _run_pool(self):
        prepare_children()  # before the counter's lock starts the resource tracker unquiet
        ctx = multiprocessing.get_context('spawn')
        counter = ctx.Value('q', 0)
        todo = list(self.units)
        tries = {}
        while todo:
            pool = None
            try:
                with signals_blocked():  # no Ctrl-C for the workers; no signal mid-spawn
                    pool = ProcessPoolExecutor(max_workers=min(self.jobs, len(todo)),
                                               mp_context=ctx, initializer=_start_pool_worker,
                                               initargs=(counter, os.getpid()))
                    futures = {pool.submit(run_unit, u): u for u in todo}
                todo = self._drain(futures, tries, counter)
            except BaseException:  # Ctrl-C, SIGTERM: the workers go first, then we do
                stop_children()
                if pool is not None:
                    pool.shutdown(wait=False, cancel_futures=True)
                raise
            pool.shutdown()

    def _drain(self, futures, tries, counter):
        """Finish the pool's units as they complete; return those to run again."""
        todo = []
        while futures:
            finished, _ = wait(futures, timeout=0.5, return_when=FIRST_COMPLETED)
            for future in finished:
                unit = futures.pop(future)
                try:
                    result = future.result()
                except BrokenProcessPool:  # a worker died (killed, out of memory)
                    tries[unit] = tries.get(unit, 0) + 1
                    if tries[unit] < MAX_TRIES:
                        todo.append(unit)
                        continue
                    result = UnitResult(unit, problem='the worker processing it '
                                        'died (killed or out of memory)')
                self._finish(result, counter.value)
            self._show(counter.value)
        return todo

    def _run_dask(self):
        from distributed import as_completed
        futures = self.client.map(run_unit, self.units, pure=False)
        for future in as_completed(futures):
            try:
                result = future.result()
            except Exception as exc:  # the cluster gave up on it (workers kept dying)
                unit = self.units[futures.index(future)]
                result = UnitResult(unit, problem=f'the cluster could not run it: '
                                    f'{one_line(exc)}')
            self._finish(result, None)

    def _show(self, counted):
        if counted is not None:
            self.done_messages = max(self.done_messages, counted)
        done = len(self.reports) - sum(map(bool, self.pending.values()))
        self.meter.label = f'dq_fk_bag fleet: {done}/{len(self.reports)} bags'
        self.meter.update(self.done_messages)

    def _finish(self, result, counted):
        """Note a unit's result; when it is a bag's last, move the bag's output into place."""
        unit = result.unit
        self.results.setdefault(unit.bag, []).append(result)
        self.pending[unit.bag].remove(unit)
        if counted is None:
            self.done_messages += unit.messages or (result.summary.read if result.summary
                                                    else 0)
        if not self.pending[unit.bag]:
            self._finish_bag(unit.bag)
        self._show(counted)

    def _finish_bag(self, name):
        report = self.reports[name]
        results = sorted(self.results.pop(name),
                         key=lambda r: getattr(r.unit.window, 'index', 0))
        report.seconds = sum(r.seconds for r in results)
        work = os.path.dirname(results[0].unit.output)
        problems = [r.problem for r in results if r.problem]
        summaries = [r.summary for r in results if r.summary is not None]
        report.messages_in = sum(s.read for s in summaries)
        windowed = results[0].unit.window is not None
        if windowed and not problems and _needs_whole_run(summaries):
            # a time jump or the first output past the first window: the serial run decides
            unit = replace(results[0].unit, window=None,
                           output=os.path.join(work, os.path.basename(name)))
            self.pending[name] = [unit]
            report.units = 1
            self._finish(run_unit(unit), None)
            return
        if problems:
            report.problems = list(dict.fromkeys(problems))
            shutil.rmtree(work, ignore_errors=True)
            self.state.forget(name)
            return
        try:
            if windowed:
                joined = os.path.join(work, os.path.basename(name))
                join_bags([r.unit.output for r in results], joined)
            else:
                joined = results[0].unit.output
            counts = self.state.place(name, report.input, joined, report.output)
        except Exception as exc:   # (OSError, BagError, a damaged part's metadata)
            report.problems = [f'{report.output}: cannot be put in place ({one_line(exc)})']
            shutil.rmtree(work, ignore_errors=True)
            return
        report.status = 'done'
        report.tf_out = counts.get('/tf', 0)


def _start_pool_worker(counter, parent_pid):
    """Set up a pool worker: count into ``counter``; exit when ``parent_pid`` is gone."""
    set_progress_counter(counter)
    exit_with_parent(parent_pid)


def _needs_whole_run(summaries):
    """
    Whether the serial run must decide: stamps that jumped back, or no output in window 0.

    The first output past the first window needs /tf_static there; none at all, the
    one-bag command's line saying why nothing could be used.
    """
    return any(s.time_jumps for s in summaries) or summaries[0].written == 0


ABANDONED = []  # a Dask client given up on an interrupt: this process must exit at once
_LOCAL_CLUSTERS = []  # the LocalClusters this process started


def _abandon_cluster():
    """
    Stop a LocalCluster's workers at once, quietly, and leave its client unclosed.

    Closing a Dask client whose workers are gone waits for its timeouts (10 s and more);
    the command that was interrupted exits instead (``os._exit`` once its own state is
    saved, :data:`ABANDONED` tells it).
    """
    import logging
    logging.getLogger('distributed').setLevel(logging.CRITICAL + 1)
    from distributed.core import Status
    for cluster in _LOCAL_CLUSTERS:  # a nanny would start a new worker for one stopped
        for nanny in list(getattr(cluster, 'workers', {}).values()):
            nanny.status = Status.closing
    stop_children(at_once=True, for_good=True)
    ABANDONED.append(True)


def _dask_client(scheduler, jobs):
    """
    Connect to a Dask scheduler, or start a LocalCluster of ``jobs`` processes.

    Returns ``(client, cluster)``: the cluster started here (None: a scheduler's).
    """
    try:
        from distributed import Client, LocalCluster
    except ImportError:
        raise BagError("--scheduler needs Dask's distributed: pip install 'dq_fk_ros[cluster]' "
                       "(or pip install 'dask[distributed]')") from None
    if scheduler == 'local':
        def make():  # its threads and workers never see the terminal's Ctrl-C: we stop them
            # the scheduler serves HTTP (health, metrics) even without a dashboard, on 8787
            # unless told: a free loopback port (8787 taken printed a UserWarning)
            made = LocalCluster(n_workers=jobs, threads_per_worker=1, processes=True,
                                dashboard_address=None, host='127.0.0.1',
                                scheduler_kwargs={'dashboard_address': '127.0.0.1:0'})
            _LOCAL_CLUSTERS.append(made)
            return made, Client(made)
        try:
            cluster, client = run_with_sigint_blocked(make)
        except BaseException:  # Ctrl-C while it starts: its workers stop too
            _abandon_cluster()
            raise
        return client, cluster
    try:
        return Client(scheduler, timeout=30), None
    except (OSError, ValueError, TypeError) as exc:  # unreachable, or not an address
        raise BagError(f'--scheduler {scheduler}: cannot reach the scheduler ({one_line(exc)})'
                       ) from None


def report_table(summary) -> str:
    """Return the closing table: bag, messages in, /tf out, problems, seconds."""
    rows = [('bag', 'messages in', '/tf out', 'problems', 'seconds')]
    for b in summary.bags:
        problems = '; '.join(b.problems) if b.problems else (
            'skipped: output complete' if b.status == 'skipped' else '')
        rows.append((printable(b.bag, 80), f'{b.messages_in:,}', f'{b.tf_out:,}',
                     problems or '-', f'{b.seconds:.1f}'))
    widths = [max(len(r[k]) for r in rows) for k in range(4)]
    lines = ['  '.join(r[k].ljust(widths[k]) if k in (0, 3) else r[k].rjust(widths[k])
                       for k in range(4)) + '  ' + r[4] for r in rows]
    rate = summary.messages_in / summary.seconds if summary.seconds else 0.0
    done = sum(b.status == 'done' for b in summary.bags)
    skipped = sum(b.status == 'skipped' for b in summary.bags)
    lines.append(f'{len(summary.bags)} bags: {done} done, {skipped} skipped, '
                 f'{summary.failed} failed; {summary.messages_in:,} JointStates in '
                 f'{summary.seconds:.1f} s ({rate:,.0f}/s, {summary.workers} workers)')
    return '\n'.join(lines)


__all__ = ['BagReport', 'FleetSummary', 'process_fleet', 'report_table', 'run_unit']
