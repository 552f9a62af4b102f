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

from reachconf.checks import check_workers
from reachconf.errors import OptionsError, ReachconfError

__all__ = ["run_cases", "process_pool", "Interrupted", "check_scheduler", "DASK_SCHEMES"]

#: address schemes of a Dask scheduler
DASK_SCHEMES = ("tcp", "tls", "inproc", "ucx", "ws", "wss")


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
    workers = check_workers(workers)
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
    client = _connect(Client, check_scheduler(scheduler)) if own else scheduler
    try:
        futures = client.map(fn, jobs, pure=False)
        index = {f.key: i for i, f in enumerate(futures)}
        for fut in dask_completed(futures):
            results[index[fut.key]] = fut.result()
            bar.update()
    finally:
        if own:
            client.close()


def _connect(Client, scheduler):
    """``Client(scheduler)`` with a deadline: a server that accepts but never answers made it wait forever."""
    import threading

    import dask
    from dask.utils import parse_timedelta

    timeout = parse_timedelta(dask.config.get("distributed.comm.timeouts.connect"), default="s")
    box = {}

    def connect():
        try:
            box["client"] = Client(scheduler, timeout=timeout)
        except BaseException as exc:  # noqa: BLE001 - reported below
            box["error"] = exc

    thread = threading.Thread(target=connect, daemon=True, name="reachconf-dask-connect")
    thread.start()
    thread.join(2 * timeout)
    if thread.is_alive():
        raise OptionsError(f"scheduler {scheduler!r}: cannot connect to the Dask scheduler: no answer within "
                           f"{2 * timeout:g} s (something accepts connections there, but not as a Dask scheduler?)")
    if "error" in box:
        exc = box["error"]
        raise OptionsError(f"scheduler {scheduler!r}: cannot connect to the Dask scheduler: "
                           f"{exc or type(exc).__name__}") from None  # fmt: skip
    return box["client"]


def check_scheduler(scheduler, timeout: float = 5.0, probe: bool = True):
    """Check a Dask scheduler address before any work: its form, and (``probe``) that something listens there.

    Parameters
    ----------
    scheduler : str or dask.distributed.Client or None
        ``"tcp://host:port"`` (or another scheme of :data:`DASK_SCHEMES`).
    timeout : float
        Seconds to wait for the TCP connection of the probe.
    probe : bool
        Open (and close) a TCP connection to ``host:port`` (tcp, tls, ws, wss).

    Raises
    ------
    OptionsError
        Naming the address and what happened: malformed, unknown scheme, no
        port, host not found, connection refused, no answer within ``timeout``.
    """
    import socket
    from urllib.parse import urlsplit

    if scheduler is None or not isinstance(scheduler, str):
        if scheduler is not None and type(scheduler).__name__ != "Client":
            raise OptionsError(f"scheduler must be an address 'tcp://host:port' or a dask Client, got {scheduler!r}")
        return scheduler
    where = f"scheduler {scheduler!r}"
    if "://" not in scheduler:
        raise OptionsError(f"{where}: expected an address like 'tcp://host:8786'")
    parts = urlsplit(scheduler)
    if parts.scheme not in DASK_SCHEMES:
        raise OptionsError(f"{where}: unknown scheme {parts.scheme!r}; use one of {', '.join(DASK_SCHEMES)}")
    if parts.scheme in ("inproc", "ucx"):
        return scheduler
    try:
        host, port = parts.hostname, parts.port
    except ValueError as exc:  # port out of range or not a number
        raise OptionsError(f"{where}: bad port ({exc})") from None
    if not host or port is None:
        raise OptionsError(f"{where}: expected host and port, like 'tcp://host:8786'")
    if probe:
        try:
            socket.create_connection((host, port), timeout=timeout).close()
        except socket.gaierror as exc:
            raise OptionsError(f"{where}: host {host!r} not found ({exc.strerror or exc})") from None
        except (TimeoutError, socket.timeout):
            raise OptionsError(f"{where}: no answer from {host}:{port} within {timeout:g} s "
                               "(is the scheduler running, and is the address right?)") from None  # fmt: skip
        except OSError as exc:
            raise OptionsError(f"{where}: cannot connect to {host}:{port}: {exc.strerror or exc} "
                               "(is a Dask scheduler running there?)") from None  # fmt: skip
    return scheduler
