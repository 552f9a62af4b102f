"""Dask backend of :class:`~reachconf.runner.pool.Pool`: one Client per run, lost workers reported, a no-worker timeout.

* One :class:`distributed.Client` per pool (per run), connected with a
  deadline; a Client given by the caller is used as it is and left open.
* The scheduler's ``remove-worker`` events are followed: every lost worker is
  reported (stderr and the pool's log) with the number of the run's jobs that
  were running there; Dask runs those again on the other workers.  A job
  whose workers keep dying (``distributed.scheduler.allowed-failures``)
  raises :class:`~reachconf.runner.pool.WorkersLost`.
* When the cluster has no worker, the run waits up to the pool's
  ``worker_timeout`` for one to join, then raises
  :class:`~reachconf.runner.pool.WorkersLost` with the finished results.
* :meth:`DaskBackend.run_on_workers` installs a worker plugin: setup code
  (e.g. the compiled-model cache, :mod:`reachconf.runner.caches`) runs on
  every worker, also on workers that join later.
"""

from __future__ import annotations

import queue
import threading
import time

from distributed import Client, KilledWorker, WorkerPlugin

from reachconf.errors import OptionsError
from reachconf.runner.address import check_scheduler
from reachconf.runner.tasks import Stopped, WorkersLost

__all__ = ["DaskBackend", "WorkerSetup", "connect"]

#: seconds between two questions to the scheduler about its number of workers
COUNT_INTERVAL = 1.0
#: longest sleep between two looks at the pending tasks while waiting; a finishing task wakes the waiters at once
POLL_NAP_MAX = 0.5


def call_on_one_thread(fn, job):
    """``fn(job)`` with one numba thread in the Dask worker's task thread.

    A Dask worker runs tasks in its own threads; numba's thread count is per
    thread, so the parallel kernels (e.g. point containment) would otherwise
    use every core in every worker and oversubscribe the machine (the local
    process pool sets one thread in its initializer instead).
    """
    try:
        import numba

        numba.set_num_threads(1)
    except Exception:  # noqa: BLE001 - numba absent or its threading layer not ready: run as it is
        pass
    return fn(job)


def connect(address: str, timeout: float | None = None) -> Client:
    """``Client(address)`` with a deadline, errors as :class:`OptionsError` naming the address.

    A server that accepts the connection but never answers as a Dask
    scheduler made ``Client`` wait forever.
    """
    import dask
    from dask.utils import parse_timedelta

    if timeout is None:
        timeout = parse_timedelta(dask.config.get("distributed.comm.timeouts.connect"), default="s")
    box = {}

    def run():
        try:
            box["client"] = Client(address, timeout=timeout)
        except BaseException as exc:  # noqa: BLE001 - reported below
            box["error"] = exc

    thread = threading.Thread(target=run, daemon=True, name="reachconf-dask-connect")
    thread.start()
    thread.join(2 * timeout)
    if thread.is_alive():
        raise OptionsError(f"scheduler {address!r}: cannot connect to the Dask scheduler: no answer within "
                           f"{2 * timeout:g} s (something accepts connections there, but not as a Dask scheduler?)")
    if "error" in box:
        exc = box["error"]
        raise OptionsError(f"scheduler {address!r}: cannot connect to the Dask scheduler: "
                           f"{' '.join(str(exc).split()) or type(exc).__name__}") from None  # fmt: skip
    return box["client"]


class WorkerSetup(WorkerPlugin):
    """A worker plugin running ``fn(payload)`` once in every worker (also in workers that join later)."""

    idempotent = True  # registering the same name again (a second run) does nothing

    def __init__(self, fn, payload):
        self.fn = fn
        self.payload = payload

    def setup(self, worker):
        """Run the setup in the worker process."""
        self.fn(self.payload)


class DaskBackend:
    """Tasks on a Dask cluster, through one Client."""

    def __init__(self, scheduler, pool):
        self._pool = pool
        self._own = not isinstance(scheduler, Client)
        self.client = connect(check_scheduler(scheduler)) if self._own else scheduler
        self.address = self.client.scheduler.address if self.client.scheduler is not None else str(scheduler)
        self._events = queue.SimpleQueue()
        self._keys = {}
        self._lock = threading.Lock()
        self._finished = threading.Condition()
        self._registered = set()
        self._empty_since = None
        self._last_count = 0.0
        self._subscribed = False
        try:
            self.client.subscribe_topic("all", self._on_event)
            self._subscribed = True
        except Exception:  # noqa: BLE001 - an old scheduler: lost workers are then only seen by the count
            pass
        self.size = max(1, sum(self.client.nthreads().values()))

    def describe(self) -> str:
        """``"Dask cluster tcp://host:port"``."""
        return f"Dask cluster {self.address}"

    # ------------------------------------------------------------------ events
    def _on_event(self, event):
        msg = event[1] if isinstance(event, tuple) and len(event) == 2 else event
        if isinstance(msg, dict) and msg.get("action") in ("remove-worker", "add-worker"):
            self._events.put(msg)

    def check(self):
        """Report lost and joining workers; raise :class:`WorkersLost` after the no-worker timeout."""
        with self._lock:
            while True:
                try:
                    msg = self._events.get_nowait()
                except queue.Empty:
                    break
                self._report(msg)
            now = time.monotonic()
            if now - self._last_count < COUNT_INTERVAL:
                return
            self._last_count = now
            count = len(self.client.nthreads())
            if count:
                self.size = max(1, sum(self.client.nthreads().values()))
                if self._empty_since is not None:
                    self._empty_since = None
                    self._pool.note(f"a Dask worker joined {self.address}; the run goes on")
                return
            timeout = self._pool.worker_timeout
            if self._empty_since is None:
                self._empty_since = now
                self._pool.note(f"no Dask worker left on {self.address}; waiting up to {timeout:g} s for one to join "
                                "(worker_timeout or REACHCONF_WORKER_TIMEOUT)")  # fmt: skip
            elif now - self._empty_since > timeout:
                raise WorkersLost(f"no Dask worker on {self.address} for {timeout:g} s; giving up (the finished "
                                  "results are kept; set the wait with worker_timeout or "
                                  "REACHCONF_WORKER_TIMEOUT)")  # fmt: skip

    def _report(self, msg):
        worker = msg.get("worker", "?")
        if msg["action"] == "add-worker":
            self._pool.note(f"Dask worker {worker} joined", warn=False)
            return
        ours = [k for k in msg.get("processing-tasks", ()) if k in self._keys]
        what = "left (retired)" if msg.get("expected") else "lost"
        tail = f"; its {len(ours)} unfinished job(s) of this run are run again" if ours else ""
        self._pool.note(f"Dask worker {worker} {what}{tail}")

    # ------------------------------------------------------------------ tasks
    def submit(self, task):
        """``client.submit(fn, job)``, run on one numba thread (:func:`call_on_one_thread`)."""
        task.inner = self.client.submit(call_on_one_thread, task.fn, task.job, pure=False)
        self._keys[task.inner.key] = task
        task.inner.add_done_callback(self._on_done)

    def _on_done(self, _future):
        with self._finished:
            self._finished.notify_all()

    def wait(self, pending, timeout):
        """The pending tasks that finished within ``timeout``."""
        # not distributed.wait: several threads (the merge's groups, the Pareto orders) wait at once, and
        # distributed.wait from several threads made the client's event loop fail ("deque mutated during
        # iteration"); the futures' done-callbacks wake the waiters instead (a capped sleep guards against a
        # callback that never comes)
        deadline = time.monotonic() + timeout
        while True:
            with self._finished:
                done = [t for t in pending if t.inner.done()]
                left = deadline - time.monotonic()
                if done or left <= 0:
                    break
                self._finished.wait(min(left, POLL_NAP_MAX))
        finished = []
        for task in done:
            fut = task.inner
            self._keys.pop(fut.key, None)
            if fut.status == "cancelled":
                raise Stopped("the task was cancelled")
            if fut.status == "error":
                exc = fut.exception()
                if isinstance(exc, KilledWorker):
                    raise WorkersLost(f"a job of {getattr(task.fn, '__name__', task.fn)} was running on Dask workers "
                                      f"that died, too often ({exc}); giving up - it may crash its worker (memory?)")
                fut.result()  # raises the job's own exception with its traceback
            task.value, task.done = fut.result(), True
            finished.append(task)
        return finished

    def cancel(self, tasks):
        """Cancel the tasks on the cluster."""
        futures = [t.inner for t in tasks if t.inner is not None]
        for t in tasks:
            if t.inner is not None:
                self._keys.pop(t.inner.key, None)
        try:
            self.client.cancel(futures)
        except Exception:  # noqa: BLE001 - the client may be closing (Ctrl-C)
            pass

    def run_on_workers(self, name, fn, payload):
        """A :class:`WorkerSetup` plugin named ``name`` (once per pool; idempotent on the scheduler)."""
        if name in self._registered:
            return
        self.client.register_plugin(WorkerSetup(fn, payload), name=name)
        self._registered.add(name)

    def on_each_worker(self, fn, *args):
        """``client.run(fn, *args)``: ``{worker address: result}``."""
        return self.client.run(fn, *args)

    def close(self):
        """Unsubscribe; close the Client if this pool opened it."""
        if self._subscribed:
            try:
                self.client.unsubscribe_topic("all")
            except Exception:  # noqa: BLE001
                pass
        if self._own:
            self.client.close()
