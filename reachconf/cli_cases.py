"""Per-case work of ``reachconf conform`` and ``reachconf reach``, in this process or on the run's one pool.

With ``--workers N`` (or the run file's ``workers``) or ``--scheduler ADDR``
the cases are tasks of one :class:`reachconf.runner.Pool`: the model is built
here once and its compiled code reaches the workers
(:func:`reachconf.model.shipping.prepare_model`).  The results are identical
to a serial run and come back in case order.  ``--worker-timeout SECONDS``
sets how long a run waits when no worker is left (``REACHCONF_WORKER_TIMEOUT``
otherwise, default 60 s); the finished cases are then saved, as on Ctrl-C.

The task functions (:func:`conform_case`, :func:`reach_case`) are module
level, so that worker processes and Dask can unpickle them.
"""

from __future__ import annotations

import argparse
import math
import os
import time

from reachconf.errors import OptionsError

__all__ = ["add_pool_options", "apply_worker_timeout", "conform_case", "map_cases", "positive_seconds", "reach_case",
           "pool_settings"]  # fmt: skip

#: modules the local worker processes import once, before the workers fork
PRELOAD = ("reachconf.cli_cases",)


def positive_seconds(text):
    """An option's value as a finite number of seconds > 0 (``argparse`` type; a one-line usage error otherwise)."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be a number of seconds, got {text!r}") from None
    if not math.isfinite(value) or value <= 0:
        raise argparse.ArgumentTypeError(f"must be a positive, finite number of seconds, got {text!r}")
    return value


def add_pool_options(sp, positive_int):
    """``--workers N``, ``--scheduler ADDR`` and ``--worker-timeout SECONDS`` on the subparser ``sp``."""
    sp.add_argument("--workers", type=positive_int, default=None, help="local worker processes (>= 1)")
    sp.add_argument("--scheduler", default=None, help="Dask scheduler address tcp://host:port")
    sp.add_argument("--worker-timeout", type=positive_seconds, default=None, dest="worker_timeout",
                    help="seconds to wait when no worker is left before giving up (default: "
                         "$REACHCONF_WORKER_TIMEOUT or 60); the finished cases are kept")  # fmt: skip


def apply_worker_timeout(args) -> None:
    """Make ``--worker-timeout`` the wait of every pool this command starts (through ``REACHCONF_WORKER_TIMEOUT``)."""
    if getattr(args, "worker_timeout", None) is not None:
        os.environ["REACHCONF_WORKER_TIMEOUT"] = repr(float(args.worker_timeout))


def pool_settings(args, spec):
    """``(workers, scheduler)`` of a command: the flags, else the run file's ``workers``; the address checked."""
    from reachconf.runner import check_scheduler

    check_scheduler(args.scheduler)
    if args.scheduler is not None and args.workers is not None:
        raise OptionsError("give --workers or --scheduler, not both")
    workers = args.workers or (None if args.scheduler else getattr(spec, "workers", None))
    return workers, args.scheduler


def map_cases(args, spec, fn, names, make_jobs, on_result, desc="cases"):
    """Run ``fn`` on one job per case and hand each result to ``on_result(name, result)`` in case order.

    Serially (no workers), every result is handed on as soon as it is
    there, so a Ctrl-C keeps the cases finished before it.  On a pool the
    results are handed on at the end; an interruption or the loss of every
    worker hands on the finished ones first and re-raises.

    Parameters
    ----------
    args : argparse.Namespace
        The command's arguments (``workers``, ``scheduler``).
    spec : reachconf.runfile.RunSpec
        The run file (its model and ``workers``).
    fn : callable
        A module-level task function, ``fn(job) -> result``.
    names : sequence of str
        The cases' names, in order.
    make_jobs : callable
        ``make_jobs(parallel) -> list`` of jobs in the order of ``names``
        (``parallel``: the jobs run on workers, so they must not draw
        progress bars of their own).
    on_result : callable
        ``on_result(name, result)``.
    desc : str
        Label of the pool's progress bar.
    """
    from reachconf.model.shipping import prepare_model
    from reachconf.runner import Interrupted, Pool, WorkersLost

    workers, scheduler = pool_settings(args, spec)
    if scheduler is None and (workers is None or workers <= 1):
        for name, job in zip(names, make_jobs(False)):
            on_result(name, fn(job))
        return
    jobs = make_jobs(True)
    with Pool(min(workers, len(jobs)) if scheduler is None else None, scheduler, preload=PRELOAD) as pool:
        print(f"workers: {pool.describe()}", flush=True)
        prepare_model(pool, spec.model, (spec.reach_options,))
        try:
            results = pool.map(fn, jobs, desc=desc)
        except (Interrupted, WorkersLost) as exc:
            for name, result in zip(names, exc.partial or []):
                if result is not None:
                    on_result(name, result)
            exc.partial = None  # the command's own partial results (by case name) are saved instead
            raise
    for name, result in zip(names, results):
        on_result(name, result)


def conform_case(job) -> dict:
    """One case's trace and/or reachset conformance (a task of ``reachconf conform``).

    ``job`` is ``(model, case, W, V, X0, kinds, trace_method, trace_options,
    reach_options, progress, time_limit)``; the result maps each kind to its
    summary (the fields ``conformance.json`` holds).
    """
    from reachconf.conformance.reachset import reachset_conformance
    from reachconf.conformance.trace import trace_conformance

    model, case, W, V, X0, kinds, method, trace_options, reach_options, progress, time_limit = job
    entry = {}
    if "trace" in kinds:
        res = trace_conformance(model, case, W, V, method=method, options=trace_options, progress=progress,
                                time_limit=time_limit)  # fmt: skip
        # the summary fields only (to_dict would list the traces: a long case's would not fit in memory)
        entry["trace"] = {"verdict": res.verdict, "conformant": res.verdict.json_conformant, "method": res.method,
                          "reason": res.reason, "margins": res.margins, "margin_times": res.margin_times,
                          "seconds": res.seconds, "message": res.message}  # fmt: skip
    if "reachset" in kinds:
        res = reachset_conformance(model, case, W, V, X0=X0, options=reach_options, keep_tube=False,
                                   progress=progress, time_limit=time_limit)  # fmt: skip
        entry["reachset"] = {"verdict": res.verdict, "conformant": res.verdict.json_conformant,
                             "first_violation_time": res.first_violation_time, "max_violation": res.max_violation,
                             "seconds": res.seconds, "message": res.message}  # fmt: skip
    return entry


def reach_case(job) -> dict:
    """One case's reach tube (a task of ``reachconf reach``).

    ``job`` is ``(model, case, X0, W, options, streamed, time_limit)``;
    the result holds ``"tube"`` and ``"seconds"``, or ``"error"`` (the
    :class:`~reachconf.errors.ReachError`'s message) and ``"seconds"``.
    """
    from reachconf.errors import ReachError
    from reachconf.reach import reach
    from reachconf.reach_stream import reach_streamed

    model, case, X0, W, options, streamed, time_limit = job
    t0 = time.perf_counter()
    reach_fn = reach_streamed if streamed else reach
    kw = {"time_limit": time_limit} if streamed else {}
    try:
        tube = reach_fn(model, X0, case.t - case.t[0], inputs=case.U if model.m else None, W=W, options=options,
                        **kw)  # fmt: skip
    except ReachError as exc:
        return {"error": str(exc), "seconds": time.perf_counter() - t0}
    return {"tube": tube, "seconds": time.perf_counter() - t0}
