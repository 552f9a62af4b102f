"""Run independent jobs (one per test case) serially, in local processes or on a Dask cluster.

Results come back in job order whichever way they run, so they are
identical.  A tqdm bar shows progress; Ctrl-C stops cleanly and raises
:class:`Interrupted` carrying the results finished so far (``None`` for the
others), so callers can save partial results.
"""

from __future__ import annotations

import os
from concurrent.futures import ProcessPoolExecutor, as_completed

from tqdm.auto import tqdm

from reachconf.errors import OptionsError, ReachconfError

__all__ = ["run_cases", "process_pool", "Interrupted"]


class Interrupted(ReachconfError, KeyboardInterrupt):
    """Raised on Ctrl-C; ``.partial`` holds the results finished so far (``None`` for the rest)."""

    def __init__(self, partial):
        super().__init__(f"interrupted: {sum(r is not None for r in partial)} of {len(partial)} jobs finished")
        self.partial = partial


def _progress(total, desc, disable):
    if disable is None:
        disable = os.environ.get("REACHCONF_PROGRESS", "1") == "0" or total <= 1
    return tqdm(total=total, desc=desc, unit="case", disable=disable, leave=False)


def process_pool(workers: int):
    """A process pool to pass to several :func:`run_cases` calls (saves the worker start-up each time)."""
    import multiprocessing as mp

    # one thread per worker: BLAS/OpenMP/numba thread pools in every process oversubscribe the cores
    # (OpenBLAS threads busy-wait), which made 2 workers slower than 1 on this 2-core machine
    # (the BLAS variables are read when a worker loads numpy; numba's own variable must not be set here:
    # numba re-reads NUMBA_* in this process and refuses a change once its threads run)
    for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ.setdefault(var, "1")
    ctx = mp.get_context("spawn" if os.name == "nt" else "forkserver")
    return ProcessPoolExecutor(max_workers=int(workers), mp_context=ctx, initializer=_one_thread)


def _one_thread():
    import numba

    numba.set_num_threads(1)


def run_cases(fn, jobs, workers=None, scheduler=None, desc="cases", progress=None, executor=None):
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
    executor : concurrent.futures.Executor, optional
        Run on this pool (see :func:`process_pool`) instead of starting one.
    progress : bool, optional
        Show a progress bar (default: when there is more than one job and
        ``REACHCONF_PROGRESS`` is not ``0``).
    """
    jobs = list(jobs)
    if workers is not None and (int(workers) != workers or workers < 1):
        raise OptionsError(f"workers must be a positive integer, got {workers!r}")
    results = [None] * len(jobs)
    bar = _progress(len(jobs), desc, None if progress is None else not progress)
    try:
        if scheduler is not None:
            _run_dask(fn, jobs, scheduler, results, bar)
        elif executor is not None and len(jobs) > 1:
            _run_on(executor, fn, jobs, results, bar)
        elif workers and workers > 1 and len(jobs) > 1:
            with process_pool(min(int(workers), len(jobs))) as pool:
                _run_on(pool, fn, jobs, results, bar)
        else:
            for i, job in enumerate(jobs):
                results[i] = fn(job)
                bar.update()
    except KeyboardInterrupt:
        raise Interrupted(results) from None
    finally:
        bar.close()
    return results


def _run_on(pool, fn, jobs, results, bar):
    futures = {pool.submit(fn, job): i for i, job in enumerate(jobs)}
    try:
        for fut in as_completed(futures):
            results[futures[fut]] = fut.result()
            bar.update()
    except BaseException:
        for fut in futures:
            fut.cancel()
        raise


def _run_dask(fn, jobs, scheduler, results, bar):
    try:
        from dask.distributed import Client, as_completed as dask_completed
    except ImportError:
        raise OptionsError("scheduler= needs Dask: pip install 'reachconf[dask]'") from None
    own = not isinstance(scheduler, Client)
    client = Client(scheduler) if own else scheduler
    try:
        futures = client.map(fn, jobs, pure=False)
        index = {f.key: i for i, f in enumerate(futures)}
        for fut in dask_completed(futures):
            results[index[fut.key]] = fut.result()
            bar.update()
    finally:
        if own:
            client.close()
