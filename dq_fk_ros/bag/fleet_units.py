"""
One unit of a fleet's work, and the function a worker runs on it (:func:`run_unit`).

A :class:`Unit` is a whole bag or one window of it, as paths and options only (a Dask task
carries nothing else); :func:`run_unit` loads the robot (once per process), processes the
unit with :func:`~dq_fk_ros.bag.process.process_bag` or
:func:`~dq_fk_ros.bag.process.process_window`, and returns a :class:`UnitResult`: its
summary, or the problem in one line. It never raises: one bag may not stop the fleet.
"""

from dataclasses import dataclass, replace
import time

from dq_fk_ros.bag.process import process_bag, process_window, ProcessOptions, ProcessSummary
from dq_fk_ros.description.loading import load_robot
from dq_fk_ros.errors import DqFkError
from dq_fk_ros.storage.text import one_line


@dataclass(frozen=True)
class RobotSpec:
    """The robot as a worker loads it: a file or shipped name, URDF options, packages."""

    robot: str
    base: str = None
    tip: str = None
    packages: tuple = ()

    def load(self) -> object:
        """Return the :class:`RobotModel` (cached per process)."""
        key = (self.robot, self.base, self.tip, self.packages)
        model = _ROBOTS.get(key)
        if model is None:
            model = _ROBOTS[key] = load_robot(self.robot, self.base, self.tip,
                                              packages=dict(self.packages)).model
        return model


_ROBOTS = {}


@dataclass(frozen=True)
class Unit:
    """
    One unit of work: a whole bag (``window`` None) or one window of it.

    ``output``: the bag folder the worker writes (in the work folder, renamed into place
    by the parent once the bag is complete).
    """

    bag: str
    path: str
    output: str
    robot: RobotSpec
    options: ProcessOptions
    window: object = None
    messages: int = 0


@dataclass
class UnitResult:
    """What a worker did with a :class:`Unit`: its summary or the problem, and its time."""

    unit: Unit
    summary: ProcessSummary = None
    problem: str = None
    seconds: float = 0.0


def run_unit(unit) -> UnitResult:
    """
    Process one unit of work in this process; never raises (a problem is reported).

    The function a pool worker or a Dask worker runs: its argument is paths and options.
    """
    _keep_freed_memory()
    start = time.perf_counter()
    summary, problem = None, None
    try:
        model = unit.robot.load()
        options = replace(unit.options, progress=False, overwrite=True)
        if unit.window is None:
            summary = process_bag(unit.path, unit.output, model, options)
        else:
            summary = process_window(unit.path, unit.output, model, options, unit.window)
        problem = summary.error
    except DqFkError as exc:
        problem = one_line(exc)
    except Exception as exc:  # one bag may not stop the fleet, whatever it holds
        problem = f'{type(exc).__name__}: {one_line(exc)}'
    return UnitResult(unit, summary, problem, time.perf_counter() - start)


_TUNED = []
MALLOC_THRESHOLD_BYTES = 32 << 20  # glibc's largest M_MMAP_THRESHOLD on 64-bit


def _keep_freed_memory():
    """
    Let glibc reuse freed blocks of up to 32 MiB instead of unmapping them (once).

    A worker allocates and frees arrays of a few MiB per chunk; in a Dask worker's task
    thread glibc mapped and unmapped each one, and the page faults doubled the time of a
    bag (measured: 2.5 s -> 1.3 s per 100 000 JointStates). A fixed threshold keeps them.
    Other C libraries: nothing is changed.
    """
    if _TUNED:
        return
    _TUNED.append(True)
    try:
        import ctypes
        libc = ctypes.CDLL(None)
        mallopt = libc.mallopt
    except (OSError, AttributeError):
        return
    m_trim_threshold, m_mmap_threshold = -1, -3
    mallopt(m_mmap_threshold, MALLOC_THRESHOLD_BYTES)
    mallopt(m_trim_threshold, 2 * MALLOC_THRESHOLD_BYTES)


__all__ = ['RobotSpec', 'run_unit', 'Unit', 'UnitResult']
