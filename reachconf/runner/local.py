"""Backends of :class:`~reachconf.runner.pool.Pool` on this machine: serial, local processes, a given executor.

Local worker processes come from a *forkserver* (``spawn`` on Windows) that
imports the heavy modules once (:data:`HEAVY_MODULES` plus the pool's
``preload``), so each worker starts with them loaded.  The workers do not
run the user's script: a script that calls ``synthesize_W(..., workers=2)``
without an ``if __name__ == "__main__":`` guard works (only when the job
function itself is defined in the script is the script imported by the
workers, which then needs the guard, as ``multiprocessing`` always does).

A worker process that dies (killed, out of memory) breaks a
``ProcessPoolExecutor``; here the loss is reported (:meth:`Pool.note
<reachconf.runner.pool.Pool.note>`), the pool is restarted and the unfinished
jobs run again, up to :data:`MAX_RESTARTS` times.
"""

from __future__ import annotations

import multiprocessing as mp
import os
import signal
import sys
import threading
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor
from concurrent.futures import wait as futures_wait
from concurrent.futures.process import BrokenProcessPool
from contextlib import contextmanager

from reachconf.runner.tasks import Stopped, WorkersLost

__all__ = ["SerialBackend", "LocalBackend", "ExecutorBackend", "HEAVY_MODULES", "MAX_RESTARTS", "script_hidden"]

#: modules the local workers' server imports once (each worker then starts with them loaded)
HEAVY_MODULES = ("numpy", "scipy.linalg", "scipy.optimize", "scipy.sparse", "sympy", "numba", "cvxpy", "tqdm.auto")
#: restarts of a broken local pool (a worker process died) before :class:`WorkersLost`
MAX_RESTARTS = 3

_MAIN_LOCK = threading.Lock()


class SerialBackend:
    """Tasks run one by one in this process, when they are waited for."""

    size = 1

    def describe(self) -> str:
        """``"serial"``."""
        return "serial"

    def submit(self, task):
        """Nothing to start: the task runs in :meth:`wait`."""

    def wait(self, pending, timeout):
        """Run the first pending task; return it."""
        task = pending[0]
        task.value = task.fn(task.job)
        task.done = True
        return [task]

    def check(self):
        """Nothing can be lost."""

    def cancel(self, tasks):
        """Nothing runs in the background."""

    def run_on_workers(self, name, fn, payload):
        """This process is the worker and has its own files."""

    def on_each_worker(self, fn, *args):
        """This machine's files serve the local workers: ``fn`` runs here."""
        return {"local": fn(*args)}

    def close(self):
        """Nothing to stop."""


def one_thread():
    """Worker initializer: one numba thread (the BLAS variables are set before the worker starts)."""
    import numba

    numba.set_num_threads(1)


def worker_pid() -> int:
    """The worker's process id (the task that starts each worker)."""
    return os.getpid()


@contextmanager
def script_hidden(hide: bool = True):
    """Hide the ``__main__`` script while worker processes start, so that they do not run it.

    ``multiprocessing`` re-runs the script (as ``__mp_main__``) in every
    worker it starts with ``spawn`` or ``forkserver``; a script without an
    ``if __name__ == "__main__":`` guard then starts workers from its workers
    and fails.  Workers that only run reachconf's own functions do not need
    the script.
    """
    if not hide:
        yield
        return
    with _MAIN_LOCK:
        main = sys.modules.get("__main__")
        saved = {}
        if main is not None:
            for key in ("__file__", "__spec__"):
                if key in vars(main):
                    saved[key] = vars(main)[key]
            vars(main).pop("__file__", None)
            if "__spec__" in saved:
                main.__spec__ = None
        try:
            yield
        finally:
            if main is not None:
                vars(main).update(saved)


def _exit_text(code) -> str:
    if code is None:
        return "still running"
    if code < 0:
        try:
            name = signal.Signals(-code).name
        except ValueError:
            name = f"signal {-code}"
        hint = " - out of memory, or killed by hand?" if -code == signal.SIGKILL else ""
        return f"killed by {name}{hint}"
    if code == 255:  # multiprocessing's forkserver reports 255 when it could not read the status (e.g. a SIGKILL)
        return "exit status 255: unknown, or killed"
    return f"exit status {code}"


class LocalBackend:
    """A process pool on this machine, restarted when one of its processes dies."""

    def __init__(self, workers, preload, pool):
        self.size = int(workers)
        self._pool = pool
        self._preload = tuple(dict.fromkeys(HEAVY_MODULES + tuple(preload)))
        self._lock = threading.Lock()
        self._executor = None
        self._processes = []
        self._generation = 0
        self._restarts = 0
        self._with_script = False
        self._outstanding = 0

    def describe(self) -> str:
        """``"2 local processes"``."""
        return f"{self.size} local processes"

    def _start(self):
        # one thread per worker: BLAS/OpenMP thread pools in every process oversubscribe the cores (OpenBLAS
        # threads busy-wait), which made 2 workers slower than 1 on a 2-core machine; numba's own variable
        # must not be set here (numba re-reads NUMBA_* in this process), the initializer sets its threads
        for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
            os.environ.setdefault(var, "1")
        method = "spawn" if os.name == "nt" else "forkserver"
        ctx = mp.get_context(method)
        if method == "forkserver":
            ctx.set_forkserver_preload(list(self._preload))
        executor = ProcessPoolExecutor(max_workers=self.size, mp_context=ctx, initializer=one_thread)
        before = set(mp.active_children())
        with script_hidden(not self._with_script):
            for _ in range(self.size):  # start every process now, while the script is hidden
                executor.submit(worker_pid)
        self._processes = [p for p in mp.active_children() if p not in before]
        self._executor = executor

    def submit(self, task):
        """Send the task to a worker process (starting the processes on the first task)."""
        with self._lock:
            if self._executor is None:
                self._with_script = getattr(task.fn, "__module__", None) == "__main__"
                self._start()
            executor, generation = self._executor, self._generation
        try:
            inner = executor.submit(task.fn, task.job)
        except BrokenProcessPool:
            self._restart(generation)
            return self.submit(task)
        with self._lock:
            self._outstanding += 1
        task.inner, task.generation = inner, generation

    def wait(self, pending, timeout):
        """The pending tasks that finished within ``timeout``; lost ones are started again."""
        inners = {t.inner: t for t in pending}
        done, _ = futures_wait(list(inners), timeout=timeout, return_when=FIRST_COMPLETED)
        finished = []
        for fut in done:
            task = inners[fut]
            with self._lock:
                self._outstanding -= 1
            if fut.cancelled():
                raise Stopped("the task was cancelled")
            exc = fut.exception()
            if isinstance(exc, BrokenProcessPool):
                self._restart(task.generation)
                self.submit(task)
                continue
            if exc is not None:
                raise exc
            task.value, task.done = fut.result(), True
            finished.append(task)
        return finished

    def _restart(self, generation):
        with self._lock:
            if generation != self._generation:  # another thread restarted the pool already
                return
            dead = [p for p in self._processes if p.exitcode is not None]
            culprits = [p for p in dead if p.exitcode != -signal.SIGTERM] or dead
            what = ", ".join(f"process {p.pid} ({_exit_text(p.exitcode)})" for p in culprits) or "a process"
            self._restarts += 1
            if self._restarts > MAX_RESTARTS:
                raise WorkersLost(f"local worker processes died {self._restarts} times (last: {what}); giving up - "
                                  "a job may be crashing its worker (memory?)")  # fmt: skip
            self._pool.note(f"lost local worker {what}; restarting the {self.size} worker processes, the unfinished "
                            f"jobs run again (restart {self._restarts} of at most {MAX_RESTARTS})")  # fmt: skip
            self._shutdown(terminate=True)
            self._outstanding = 0
            self._start()
            self._generation += 1

    def check(self):
        """Local processes are restarted, never missing: nothing to check."""

    def cancel(self, tasks):
        """Cancel tasks that have not started."""
        for t in tasks:
            if t.inner is not None and t.inner.cancel():
                with self._lock:
                    self._outstanding -= 1

    def run_on_workers(self, name, fn, payload):
        """Local workers share this machine's files: nothing to install."""

    def on_each_worker(self, fn, *args):
        """This machine's files serve the local workers: ``fn`` runs here."""
        return {"local": fn(*args)}

    def _shutdown(self, terminate):
        executor, self._executor = self._executor, None
        if executor is None:
            return
        if not terminate:
            executor.shutdown(wait=True, cancel_futures=True)
            return
        executor.shutdown(wait=False, cancel_futures=True)
        for p in self._processes:
            if p.exitcode is None:
                p.terminate()
        for p in self._processes:
            p.join(timeout=5)

    def close(self):
        """Stop the processes (at once if jobs are still running: Ctrl-C or an error)."""
        with self._lock:
            self._shutdown(terminate=self._outstanding > 0)


class ExecutorBackend:
    """A ``concurrent.futures`` executor given by the caller (left open)."""

    def __init__(self, executor):
        self._executor = executor
        self.size = int(getattr(executor, "_max_workers", None) or os.cpu_count() or 1)

    def describe(self) -> str:
        """``"executor ProcessPoolExecutor"``."""
        return f"executor {type(self._executor).__name__}"

    def submit(self, task):
        """Submit ``fn(job)`` to the executor."""
        task.inner = self._executor.submit(task.fn, task.job)

    def wait(self, pending, timeout):
        """The pending tasks that finished within ``timeout``."""
        inners = {t.inner: t for t in pending}
        done, _ = futures_wait(list(inners), timeout=timeout, return_when=FIRST_COMPLETED)
        for fut in done:
            exc = fut.exception()
            if isinstance(exc, BrokenProcessPool):
                raise WorkersLost(f"a worker process of the executor died ({exc})")
            if exc is not None:
                raise exc
            inners[fut].value, inners[fut].done = fut.result(), True
        return [inners[f] for f in done]

    def check(self):
        """Nothing to check."""

    def cancel(self, tasks):
        """Cancel tasks that have not started."""
        for t in tasks:
            t.inner.cancel()

    def run_on_workers(self, name, fn, payload):
        """The executor's workers are on this machine."""

    def on_each_worker(self, fn, *args):
        """This machine's files serve the local workers: ``fn`` runs here."""
        return {"local": fn(*args)}

    def close(self):
        """The executor belongs to the caller: left open."""
