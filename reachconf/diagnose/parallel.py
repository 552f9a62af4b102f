"""The diagnosis's independent fits on forked worker processes.

The diagnosis fits some 40 candidate models whose fits do not depend on each
other within a stage (the screens, the cross-fits of the best singles, the
pairs; then the named model's per-group fits, the base's disturbance trace of
each case and each model's *how far* boxes).  :class:`FitMap` runs one stage's fits on ``workers`` processes
*forked* from the calling one, so that they start with everything the caller
has built — the prepared cases, the compiled models, the candidates' models —
and nothing but the results travels (a model as its build recipe,
:meth:`reachconf.Model.__reduce__`; an effect by its registered name,
:meth:`reachconf.diagnose.effects.Effect.__reduce__`).  Each fit computes
exactly what it computes in the calling process, so the report is the same
with any number of workers.

The fits run in the calling process where processes are not forked (other
systems than Linux: Windows has no ``fork``, and on macOS a forked process
may crash in Apple's libraries), inside a worker process (one started by
``multiprocessing``, ``concurrent.futures`` or a Dask nanny: its pool
already spreads the work over the cores), and when a candidate's effect
cannot be pickled (an unregistered effect with lambdas).
"""

from __future__ import annotations

import multiprocessing as mp
import os
import signal
import sys
import threading
import warnings
from concurrent.futures import ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool

from reachconf.checks import check_workers
from reachconf.errors import OptionsError

__all__ = ["FitMap", "auto_workers", "picklable", "MAX_AUTO_WORKERS"]

#: processes ``workers=None`` uses at most (one per core up to this)
MAX_AUTO_WORKERS = 8

_JOBS: list | None = None  # the stage's jobs, set before the workers fork (they inherit it)
_IN_WORKER = False
_STAGE_LOCK = threading.Lock()


def _can_fork() -> bool:
    # Linux only: on macOS a forked child of a process that has used Apple's frameworks (Accelerate) may crash,
    # which is why Python starts processes there by spawning; spawned workers would rebuild everything
    return sys.platform.startswith("linux") and "fork" in mp.get_all_start_methods()


def auto_workers() -> int:
    """``workers=None``: ``$REACHCONF_DIAGNOSE_WORKERS`` if set, else one process per core this process may use
    (at most :data:`MAX_AUTO_WORKERS`); 1 in a process started by ``multiprocessing`` (a pool worker) or where
    processes cannot be forked."""
    if _IN_WORKER or mp.parent_process() is not None or not _can_fork():
        return 1
    text = os.environ.get("REACHCONF_DIAGNOSE_WORKERS")
    if text:
        try:
            return check_workers(int(text), "REACHCONF_DIAGNOSE_WORKERS")
        except ValueError:
            raise OptionsError(f"REACHCONF_DIAGNOSE_WORKERS must be a positive integer, got {text!r}") from None
    try:
        cores = len(os.sched_getaffinity(0))
    except (AttributeError, OSError):  # pragma: no cover - not Linux
        cores = os.cpu_count() or 1
    return max(1, min(cores, MAX_AUTO_WORKERS))


def picklable(objects) -> bool:
    """Whether every object can travel between processes (a registered effect always can)."""
    import pickle

    try:
        for obj in objects:
            pickle.dumps(obj)
    except Exception:  # noqa: BLE001 - any failure to pickle (lambdas, local functions, locks)
        return False
    return True


def _worker_init():
    global _IN_WORKER
    _IN_WORKER = True
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the calling process's: it stops the pool


def _run(i):
    return _JOBS[i]()


def _here(jobs, out, done):
    """Run the jobs after the ``len(out)`` finished ones in this process, appending to ``out``."""
    for i in range(len(out), len(jobs)):
        out.append(jobs[i]())
        if done is not None:
            done(i, out[-1])
    return out


class FitMap:
    """Run a stage's independent jobs (callables without arguments) on forked processes, results in order.

    Parameters
    ----------
    workers : int or None
        Number of processes (None: :func:`auto_workers`; 1: this process).
    """

    def __init__(self, workers=None):
        if workers is None:
            self.workers = auto_workers()
        else:
            self.workers = check_workers(workers, "diagnose: workers")
            if self.workers > 1 and (not _can_fork() or _IN_WORKER):
                self.workers = 1

    def __call__(self, jobs, done=None) -> list:
        """``[job() for job in jobs]``, on the processes when there is more than one job and one process.

        ``done(i, result)`` is called in this process as each result arrives (in job order).
        """
        global _JOBS
        jobs = list(jobs)
        n = min(self.workers, len(jobs))
        out = []
        # one stage at a time forks (the jobs are a module global the workers inherit): a stage of another
        # thread's diagnosis meanwhile runs in the calling process
        if n <= 1 or _IN_WORKER or not _STAGE_LOCK.acquire(blocking=False):
            return _here(jobs, out, done)
        _JOBS = jobs
        try:
            with ProcessPoolExecutor(n, mp_context=mp.get_context("fork"), initializer=_worker_init) as pool:
                for res in pool.map(_run, range(len(jobs))):
                    out.append(res)
                    if done is not None:
                        done(len(out) - 1, res)
        except BrokenProcessPool:  # a worker died (killed, out of memory): the rest runs here, nothing is lost
            warnings.warn(f"diagnose: a fit worker process died; the {len(jobs) - len(out)} remaining fits of this "
                          f"stage run in the calling process", RuntimeWarning, stacklevel=2)  # fmt: skip
            _here(jobs, out, done)
        finally:
            _JOBS = None
            _STAGE_LOCK.release()
        return out
