"""One pool of workers per run: serial, local processes or a Dask cluster, shared by every parallel step.

A :class:`Pool` is opened once per run (a command, a script, an example) and
everything the run computes in parallel goes to it as *tasks*: the
synthesis' cases, the α-checks of every group's merge, the Pareto front's
checks.  No step starts a pool or a Dask client of its own, so worker
processes start (and load the compiled models) once.  Results come back in
job order whichever way they ran: serial, local processes and Dask give the
same numbers.

Faults are reported, not hidden: a lost worker (a killed process, a Dask
worker that died) is written to stderr and to :attr:`Pool.log` (the results
of the run carry it), and its jobs run again elsewhere (Dask does this itself;
a broken local pool is restarted).  When no worker is left for
``worker_timeout`` seconds, :class:`WorkersLost` is raised carrying the
results finished so far, as Ctrl-C does with :class:`Interrupted`.

Example
-------
>>> import reachconf as rc
>>> with rc.Pool(workers=2) as pool:                          # doctest: +SKIP
...     synth = rc.synthesize_W(model, suite, V, pool=pool)
...     front = rc.pareto_front(model, suite, V, synth.groups["LC"], pool=pool)
"""

from __future__ import annotations

import os
import sys
import threading
import time
from concurrent.futures import FIRST_EXCEPTION, ThreadPoolExecutor
from concurrent.futures import wait as futures_wait
from contextlib import contextmanager

from tqdm.auto import tqdm

from reachconf.checks import check_workers
from reachconf.errors import OptionsError
from reachconf.runner.local import ExecutorBackend, LocalBackend, SerialBackend
from reachconf.runner.tasks import Interrupted, Stopped, Task, WorkersLost

__all__ = ["Pool", "Task", "Interrupted", "WorkersLost", "use_pool", "progress_bar", "check_workers",
           "worker_timeout_default", "POLL_SECONDS"]  # fmt: skip

#: seconds between checks for lost workers, a stop request or the no-worker timeout while waiting
POLL_SECONDS = 0.5
#: seconds without any worker before :class:`WorkersLost` (``REACHCONF_WORKER_TIMEOUT`` overrides)
DEFAULT_WORKER_TIMEOUT = 60.0


def worker_timeout_default() -> float:
    """Seconds without any worker before giving up: ``$REACHCONF_WORKER_TIMEOUT`` or 60."""
    text = os.environ.get("REACHCONF_WORKER_TIMEOUT")
    if not text:
        return DEFAULT_WORKER_TIMEOUT
    try:
        value = float(text)
    except ValueError:
        raise OptionsError(f"REACHCONF_WORKER_TIMEOUT must be a number of seconds, got {text!r}") from None
    if not value > 0:
        raise OptionsError(f"REACHCONF_WORKER_TIMEOUT must be positive, got {text!r}")
    return value


def progress_shown() -> bool:
    """Draw progress bars by default?  When stderr is a terminal; ``REACHCONF_PROGRESS=1`` also when it is not
    (a log file), ``0`` never."""
    env = os.environ.get("REACHCONF_PROGRESS", "")
    return env == "1" or (env != "0" and sys.stderr is not None and sys.stderr.isatty())


def progress_bar(total, desc, progress=None, unit="case"):
    """A tqdm bar on stderr; ``progress=None``: shown when ``total > 1`` and :func:`progress_shown`."""
    disable = not progress_shown() or (total is not None and total <= 1) if progress is None else not progress
    return tqdm(total=total, desc=desc, unit=unit, disable=disable, leave=False, file=sys.stderr)


class Pool:
    """Workers for a whole run: serial, local processes, or a Dask cluster.

    Parameters
    ----------
    workers : int, optional
        Number of local worker processes (``None`` or 1: run in this process).
    scheduler : str or dask.distributed.Client, optional
        ``"tcp://host:port"`` of a Dask scheduler, or a Client (not closed by
        the pool); needs the ``reachconf[dask]`` extra.  Give either
        ``workers`` or ``scheduler``.
    executor : concurrent.futures.Executor, optional
        Run the tasks on this executor (no fault handling beyond its own).
    worker_timeout : float, optional
        Seconds to wait when no worker is left before raising
        :class:`WorkersLost` (default ``$REACHCONF_WORKER_TIMEOUT`` or 60).
    preload : sequence of str
        Modules the local worker processes import once when their server
        starts (each worker then starts with them loaded).
    stream : file, optional
        Where warnings go (default ``sys.stderr``).

    Attributes
    ----------
    kind : {"serial", "processes", "dask", "executor"}
    size : int
        Number of workers (Dask: threads of the cluster when the pool opened).
    log : list of str
        Events of the pool's life: lost workers, restarts, workers joining.
    """

    def __init__(self, workers=None, scheduler=None, *, executor=None, worker_timeout=None, preload=(), stream=None):
        workers = check_workers(workers)
        if scheduler is not None and workers is not None and workers > 1:
            raise OptionsError(f"give workers or scheduler, not both (workers={workers}, scheduler={scheduler!r})")
        if worker_timeout is None:
            worker_timeout = worker_timeout_default()
        elif isinstance(worker_timeout, bool) or not isinstance(worker_timeout, (int, float)) or not worker_timeout > 0:
            raise OptionsError(f"worker_timeout must be a positive number of seconds, got {worker_timeout!r}")
        self.worker_timeout = float(worker_timeout)
        self.stream = stream
        self.log: list[str] = []
        self._t0 = time.monotonic()
        self._log_lock = threading.Lock()
        self._closed = False
        if scheduler is not None:
            from reachconf.runner.dask import DaskBackend

            self.kind, self._backend = "dask", DaskBackend(scheduler, self)
        elif executor is not None:
            self.kind, self._backend = "executor", ExecutorBackend(executor)
        elif workers is not None and workers > 1:
            self.kind, self._backend = "processes", LocalBackend(workers, tuple(preload), self)
        else:
            self.kind, self._backend = "serial", SerialBackend()

    # ------------------------------------------------------------------ state
    @property
    def size(self) -> int:
        """Number of workers (1 when serial)."""
        return self._backend.size

    @property
    def parallel(self) -> bool:
        """True unless the tasks run one by one in this process."""
        return self.kind != "serial"

    def describe(self) -> str:
        """``"serial"``, ``"2 local processes"``, ``"Dask cluster tcp://... (2 workers)"``."""
        return self._backend.describe()

    def note(self, message: str, warn: bool = True) -> None:
        """Add ``message`` to :attr:`log` (with the time since the pool opened); print it on stderr if ``warn``."""
        line = f"[{time.monotonic() - self._t0:.1f} s] {message}"
        with self._log_lock:
            self.log.append(line)
        if warn:
            tqdm.write(f"reachconf: warning: {message}", file=self.stream or sys.stderr)

    def log_since(self, mark: int) -> list:
        """The log lines added after ``mark`` (an earlier ``len(pool.log)``)."""
        with self._log_lock:
            return list(self.log[mark:])

    # ------------------------------------------------------------------ tasks
    def submit(self, fn, job, index=None) -> Task:
        """Start ``fn(job)`` on a worker (serial: when it is waited for); returns the :class:`Task`."""
        if self._closed:
            raise OptionsError("the pool is closed")
        task = Task(fn, job, index)
        self._backend.submit(task)
        return task

    def iter_done(self, tasks, stop: threading.Event | None = None):
        """Yield the tasks as they finish (serial: in order).

        Raises the job's own exception if one fails, :class:`WorkersLost` when
        no worker is left for :attr:`worker_timeout` seconds, :class:`Stopped`
        when ``stop`` is set.
        """
        pending = []
        for t in tasks:
            if t.done:
                yield t
            else:
                pending.append(t)
        while pending:
            if stop is not None and stop.is_set():
                raise Stopped("stopped")
            finished = self._backend.wait(pending, POLL_SECONDS)
            self._backend.check()
            for t in finished:
                pending.remove(t)
                yield t

    def results(self, tasks, stop=None) -> list:
        """The values of ``tasks`` in their order (waits for all)."""
        for _ in self.iter_done(tasks, stop):
            pass
        return [t.value for t in tasks]

    def cancel(self, tasks) -> None:
        """Cancel the tasks that have not finished (best effort)."""
        left = [t for t in tasks if not t.done and t.inner is not None]
        if left:
            self._backend.cancel(left)

    def map(self, fn, jobs, desc="cases", progress=None, unit="case") -> list:
        """``[fn(job) for job in jobs]`` on the workers, with a progress bar; results in job order.

        Raises
        ------
        Interrupted
            On Ctrl-C, with ``.partial`` (finished results, ``None`` elsewhere).
        WorkersLost
            When no worker is left for :attr:`worker_timeout` seconds (``.partial`` as above).
        """
        jobs = list(jobs)
        results = [None] * len(jobs)
        bar = progress_bar(len(jobs), desc, progress, unit)
        tasks = []
        try:
            tasks = [self.submit(fn, job, i) for i, job in enumerate(jobs)]
            for t in self.iter_done(tasks):
                results[t.index] = t.value
                bar.update()
        except Interrupted:
            self.cancel(tasks)
            raise
        except KeyboardInterrupt:
            self.cancel(tasks)
            raise Interrupted(results) from None
        except WorkersLost as exc:
            self.cancel(tasks)
            exc.partial = results
            raise
        except BaseException:
            self.cancel(tasks)
            raise
        finally:
            bar.close()
        return results

    def first_failures(self, fn, jobs, ok=bool, batch=None, stop=None) -> list:
        """Run ``fn`` on the jobs in batches until a batch has a result that is not ``ok``.

        Returns ``[(index, value), ...]`` of the failing jobs of that batch
        (empty if every job passed).  ``batch`` defaults to :attr:`size`; the
        jobs are taken in the given order (put the likeliest failures first).
        """
        jobs = list(jobs)
        batch = max(1, int(batch or self.size))
        for start in range(0, len(jobs), batch):
            tasks = [self.submit(fn, job, start + i) for i, job in enumerate(jobs[start : start + batch])]
            try:
                values = self.results(tasks, stop)
            except BaseException:
                self.cancel(tasks)
                raise
            bad = [(t.index, v) for t, v in zip(tasks, values) if not ok(v)]
            if bad:
                return bad
        return []

    def each(self, fn, items) -> list:
        """``fn(item, stop)`` for every item; results in item order.

        When the pool is parallel each call runs in a thread of its own, all
        of them submitting their tasks to this pool (e.g. every group's
        α-search at once); else one after the other.  ``stop`` is a
        :class:`threading.Event` to pass on to :meth:`iter_done` /
        :meth:`first_failures`: when one call fails, or on Ctrl-C, it is set
        and the other calls stop at their next wait.
        """
        items = list(items)
        stop = threading.Event()
        if not self.parallel or len(items) < 2:
            return [fn(item, stop) for item in items]
        with ThreadPoolExecutor(len(items), thread_name_prefix="reachconf-each") as threads:
            futures = [threads.submit(fn, item, stop) for item in items]
            try:
                pending = set(futures)
                while pending:
                    done, pending = futures_wait(pending, timeout=POLL_SECONDS, return_when=FIRST_EXCEPTION)
                    errors = [f.exception() for f in done if f.exception() is not None]
                    if errors:  # the first real error, not the Stopped of the others
                        raise next((e for e in errors if not isinstance(e, Stopped)), errors[0])
            except BaseException:
                stop.set()
                raise
        return [f.result() for f in futures]

    def run_on_workers(self, name: str, fn, payload) -> None:
        """Run ``fn(payload)`` once in every worker process, now and in workers that join later (Dask).

        ``name`` identifies the setup (a second call with the same name is a
        no-op on Dask).  Local processes share this machine's files; serial
        pools run nothing.
        """
        self._backend.run_on_workers(name, fn, payload)

    def on_each_worker(self, fn, *args) -> dict:
        """``fn(*args)`` in every worker process now: ``{worker: result}`` (Dask); else ``{"local": fn(*args)}``.

        Local worker processes share this machine's files, so running ``fn``
        here stands for them.
        """
        return self._backend.on_each_worker(fn, *args)

    # ------------------------------------------------------------------ life
    def close(self) -> None:
        """Stop the workers this pool started (a Client given by the caller stays open)."""
        if not self._closed:
            self._closed = True
            self._backend.close()

    def shutdown(self, wait=True, cancel_futures=False) -> None:
        """:meth:`close` (the ``concurrent.futures.Executor`` spelling)."""
        self.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def __repr__(self):
        return f"Pool({self.describe()})"


@contextmanager
def use_pool(pool=None, workers=None, scheduler=None, **kwargs):
    """The pool to run on: ``pool`` if given (left open), else a new :class:`Pool` closed at the end.

    ``pool`` may also be a ``concurrent.futures.Executor`` (wrapped, left
    open).  With ``pool`` given, ``workers`` and ``scheduler`` are ignored.
    """
    if pool is not None:
        yield pool if isinstance(pool, Pool) else Pool(executor=pool, **kwargs)
        return
    own = Pool(workers, scheduler, **kwargs)
    try:
        yield own
    finally:
        own.close()
