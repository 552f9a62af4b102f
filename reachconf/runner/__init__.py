"""Run independent jobs (one per test case) serially, in local processes or on a Dask cluster.

:class:`Pool` (:mod:`reachconf.runner.pool`) is the one set of workers of a
run; :func:`run_cases` maps a function over jobs on a given pool or on a pool
of its own.  Results come back in job order whichever way they run, so they
are identical.  A tqdm bar shows progress; Ctrl-C stops cleanly and raises
:class:`Interrupted` carrying the results finished so far (``None`` for the
others), so callers can save partial results; :class:`WorkersLost` does the
same when no worker is left.

Modules: :mod:`~reachconf.runner.pool` (the pool, tasks, errors),
:mod:`~reachconf.runner.local` (serial and local processes),
:mod:`~reachconf.runner.dask` (Dask), :mod:`~reachconf.runner.caches`
(compiled code shipped to workers).
"""

from __future__ import annotations

from reachconf.runner.address import DASK_SCHEMES, check_scheduler
from reachconf.runner.pool import (
    Interrupted,
    Pool,
    WorkersLost,
    check_workers,
    progress_bar,
    use_pool,
)

__all__ = ["run_cases", "process_pool", "Pool", "use_pool", "Interrupted", "WorkersLost", "progress_bar",
           "check_scheduler", "DASK_SCHEMES"]  # fmt: skip


def process_pool(workers: int) -> Pool:
    """A pool of ``workers`` local processes to pass to several calls (``pool=`` / ``executor=``).

    Kept for scripts written before :class:`Pool`; the same as ``Pool(workers=workers)``.
    """
    return Pool(workers=workers)


def run_cases(fn, jobs, workers=None, scheduler=None, desc="cases", progress=None, executor=None, pool=None):
    """Apply ``fn`` to every job and return the results in job order.

    Parameters
    ----------
    fn : callable
        A module-level function (it is pickled for processes and Dask).
    jobs : sequence
        Arguments, one per call (``fn(job)``).
    workers : int, optional
        Number of local processes (``None`` or 1: serial).
    scheduler : str or dask.distributed.Client, optional
        ``"tcp://host:port"`` of a Dask scheduler, or a Client; needs the
        ``reachconf[dask]`` extra.
    pool : Pool, optional
        Run on this pool (the run's one pool) instead of starting one;
        ``workers`` and ``scheduler`` are then ignored.
    executor : Pool or concurrent.futures.Executor, optional
        The older name of ``pool``.
    progress : bool, optional
        Show a progress bar (default: when there is more than one job and
        stderr is a terminal; ``REACHCONF_PROGRESS=1`` always, ``0`` never).

    Raises
    ------
    Interrupted
        On Ctrl-C, with the finished results in ``.partial``.
    WorkersLost
        When no worker is left (``.partial`` as above).
    """
    jobs = list(jobs)
    workers = check_workers(workers)
    pool = pool if pool is not None else executor
    if pool is None and scheduler is None and (workers is None or workers < 2 or len(jobs) < 2):
        workers = None  # nothing to gain from processes
    elif pool is None and workers is not None:
        workers = min(workers, max(len(jobs), 1))
    with use_pool(pool, workers, scheduler) as p:
        return p.map(fn, jobs, desc=desc, progress=progress)
