"""Smallest disturbance / measurement-error boxes from trace conformance.

* :func:`minimize_box` — synthesis step 2 (section 4.3.2): minimise the volume
  of the disturbance box of one test case subject to trace conformance under
  ``V`` (sequential convex programming, :func:`reachconf.conformance.optctrl.box_scp`),
  then check the result with Alg. 1.
* :func:`minimal_trace_bounds` — the smallest per-channel box ``W`` (given
  ``V``), or ``V`` (for ``W = {0}``), that makes every trace of a suite
  conformant: the analogue of Tables 3 and 4.
"""

from __future__ import annotations

import time

import numpy as np

from types import SimpleNamespace

from reachconf.conformance.optctrl import box_scp, optctrl_trace
from reachconf.conformance.trace import (
    TraceOptions,
    TraceResult,
    simulate_verdict,
    trace_conformance,
    trace_disturbances,
)
from reachconf.errors import ConformanceError, OptionsError
from reachconf.io.cases import case_arrays
from reachconf.runner import run_cases
from reachconf.sets.convert import as_box
from reachconf.sets.core import Interval

__all__ = ["minimize_box", "minimal_trace_bounds", "case_box"]


def _inflate(lo, hi, rel, floor):
    pad = rel * (hi - lo) + floor
    return lo - pad, hi + pad


def minimize_box(model, case, V, W_start: Interval, start: TraceResult, options: TraceOptions | None = None):
    """Synthesis step 2: a small box W (sum of widths normalised by ``W_start``) keeping the case trace conformant.

    Parameters
    ----------
    W_start : Interval
        Step 1's box (eqs. 62–66); returned unchanged if no better box is found.
    start : TraceResult
        The trace step 1 came from (its ``x0`` and ``W_trace`` seed the SCP).

    Returns
    -------
    (Interval, TraceResult)
        The box and the Alg. 1 result that proves it (``conformant`` is True
        unless even ``W_start`` is not trace conformant under V).
    """
    options = options or TraceOptions()
    t, U, Y = case_arrays(model, case)
    Vb = as_box(V, model.p, "V")
    V_lo, V_hi = Vb.lo, Vb.hi
    vc, vr = 0.5 * (V_lo + V_hi), 0.5 * (V_hi - V_lo)
    # The volume itself is a degenerate objective (one zero-width channel makes it 0 whatever the others
    # are), so the SCP minimises the sum of the channel widths normalised by step 1's box: the
    # analogue of the report's volume minimisation that shrinks every channel it can.
    scale = np.where(W_start.hi - W_start.lo > 0, W_start.hi - W_start.lo, 1.0)
    name = getattr(case, "name", "case")
    floor = 1e-9 * (1 + np.abs(W_start.hi - W_start.lo))
    # the SCP works on the linearised dynamics: leave 2 % of V for linearisation and integration errors,
    # and if its trace still leaves V when simulated, solve again with 10 % and 25 % left
    for keep in (0.98, 0.9, 0.75):
        lo, hi, x0, W = box_scp(model, t, U, Y, vc - keep * vr, vc + keep * vr, start.x0.copy(),
                                start.W_trace.copy(), options, objective="sum", scale=scale)  # fmt: skip
        for attempt in range(4):
            blo, bhi = _inflate(lo, hi, 0.01 * attempt, floor)
            res = simulate_verdict(model, name, t, U, Y, x0, W, blo, bhi, V_lo, V_hi, options.substeps, "scp",
                                   time.perf_counter())  # fmt: skip
            if res.conformant:
                return Interval(blo, bhi), res
    res = trace_conformance(model, case, W_start, V, method="perstep", options=options)
    return W_start, res


def minimal_trace_bounds(model, suite, V=None, method: str = "perstep", solve_for: str = "W",
                         options: TraceOptions | None = None, workers=None, scheduler=None,
                         executor=None) -> Interval:  # fmt: skip
    """Smallest per-channel box making every trace of the suite conformant (Tables 3/4 analogue).

    Parameters
    ----------
    suite : TestSuite or iterable of TestCase
    V : Interval, optional
        Measurement-error set (required for ``solve_for="W"``; ignored for "V").
    method : {"perstep", "optctrl"}
        "perstep": the box is the hull of the per-step disturbance traces
        (section 3.2.1); "optctrl": per case the box of smallest normalised
        widths by SCP (Alg. 2's constraints with the box as variable), then
        the hull over cases.
    solve_for : {"W", "V"}
        "V": the smallest measurement-error box for ``W = {0}``.
    workers, scheduler, executor : see :func:`reachconf.runner.run_cases`
        ``executor`` reuses a running pool (e.g. one per script instead of one per call).

    Returns
    -------
    Interval
        Verified: ``trace_conformance`` with this box says conformant for every case.

    Raises
    ------
    ConformanceError
        If no verified box is found (e.g. the per-step trace drifts outside V).
    """
    options = options or TraceOptions()
    cases = list(suite)
    if not cases:
        raise ConformanceError("the suite has no test cases")
    if solve_for not in ("W", "V"):
        raise OptionsError(f"solve_for must be 'W' or 'V', got {solve_for!r}")
    if solve_for == "W" and V is None:
        raise OptionsError("minimal_trace_bounds(solve_for='W') needs the measurement-error set V")
    if method not in ("perstep", "optctrl"):
        raise OptionsError(f"method must be 'perstep' or 'optctrl', got {method!r}")
    jobs = [(model, case, V, method, solve_for, options) for case in cases]
    boxes = run_cases(_case_box_job, jobs, workers=workers, scheduler=scheduler, desc="minimal bounds", executor=executor)
    lo = np.min([b[0] for b in boxes], axis=0)
    hi = np.max([b[1] for b in boxes], axis=0)
    if solve_for == "W" and method == "optctrl":
        # Alg. 1's certificate: each case's own SCP trace (x0, W trace) re-simulated must satisfy
        # eqs. 22-24 with the hull box; no need to search for a trace again
        for attempt in range(6):
            box = Interval(lo, hi)
            bad = [c.name for c, b in zip(cases, boxes) if not _certify(model, c, b, box, V, options)]
            if not bad:
                return box
            lo, hi = _inflate(lo, hi, 0.004 * 2**attempt, 1e-9 * np.ones(model.q))
        raise ConformanceError(f"no verified W box found with method 'optctrl': the traces of cases {bad} "
                               "do not re-simulate within V (integration or linearisation error too large)")  # fmt: skip
    verify_method = "optctrl" if (solve_for == "V" or method == "optctrl") else "perstep"
    dim = model.p if solve_for == "V" else model.q
    for attempt in range(6):
        box = Interval(lo, hi)
        W, Vb = (Interval(np.zeros(model.q), np.zeros(model.q)), box) if solve_for == "V" else (box, V)
        jobs = [(model, case, W, Vb, verify_method, options) for case in cases]
        verdicts = run_cases(_verify, jobs, workers=workers, scheduler=scheduler, desc="verify bounds", executor=executor)
        failed = [c.name for c, ok in zip(cases, verdicts) if not ok]
        if not failed:
            return box
        if verify_method == "perstep":
            break  # the per-step traces do not depend on the box: enlarging cannot help
        # Alg. 2 keeps 0.1 % of the box as margin: grow in small steps so the box stays near-minimal
        lo, hi = _inflate(lo, hi, 0.004 * 2**attempt, 1e-9 * np.ones(dim))
    raise ConformanceError(
        f"no verified {solve_for} box found with method {method!r}: cases {failed} are not trace conformant "
        f"with the hull of the per-case boxes"
        + ("; the per-step traces drift outside V — try method='optctrl'" if verify_method == "perstep" else "")
    )


def _case_box_job(job):
    return case_box(*job)


def case_box(model, case, V=None, method: str = "perstep", solve_for: str = "W", options: TraceOptions | None = None):
    """The smallest box of one test case (the per-case part of :func:`minimal_trace_bounds`).

    Parameters
    ----------
    model : Model
    case : TestCase
    V : Interval, optional
        Measurement-error set (for ``solve_for="W"``).
    method : {"perstep", "optctrl"}
        "perstep": the hull of the per-step disturbance trace; "optctrl": the
        box of smallest normalised widths by SCP (from the per-step trace).
    solve_for : {"W", "V"}
        "V": the smallest measurement-error box for ``W = {0}`` (SCP).
    options : TraceOptions

    Returns
    -------
    tuple
        ``(lo, hi)``; for ``method="optctrl"`` and ``solve_for="W"``
        ``(lo, hi, x0, W_trace)`` with the SCP's trace (Alg. 1's certificate).
    """
    options = options or TraceOptions()
    t, U, Y = case_arrays(model, case)
    if solve_for == "V":
        start = trace_disturbances(model, case, method="perstep", options=options) if model.q else None
        x0 = start.x0 if start is not None else case_arrays(model, case)[2][0][: model.n]
        W0 = np.zeros((t.size - 1, model.q))
        zero = (np.zeros(model.q), np.zeros(model.q))
        lo, hi, _, _ = box_scp(model, t, U, Y, None, None, x0, W0, options, objective="sum", W_fixed=zero,
                               V_free=True)  # fmt: skip
        return lo, hi
    if method == "perstep":
        res = trace_disturbances(model, case, method="perstep", options=options)
        return res.W_trace.min(axis=0), res.W_trace.max(axis=0)
    start = trace_disturbances(model, case, method="perstep", options=options)
    Vb = as_box(V, model.p, "V")
    V_lo, V_hi = Vb.lo, Vb.hi
    vc, vr = 0.5 * (V_lo + V_hi), 0.5 * (V_hi - V_lo)
    scale = np.ptp(start.W_trace, axis=0)
    scale = np.where(scale > 0, scale, 1.0)
    lo, hi, x0, W = box_scp(model, t, U, Y, vc - 0.98 * vr, vc + 0.98 * vr, start.x0, start.W_trace, options,
                            objective="sum", scale=scale)  # fmt: skip
    return lo, hi, x0, W


def _certify(model, case, found, box, V, options) -> bool:
    """Re-simulate a case's SCP trace (eqs. 22-24 with ``box`` and ``V``): the Alg. 1 verdict for that trace."""
    _, _, x0, W = found
    t, U, Y = case_arrays(model, case)
    Vb = as_box(V, model.p, "V")
    V_lo, V_hi = Vb.lo, Vb.hi
    res = simulate_verdict(model, case.name, t, U, Y, x0, W, box.lo, box.hi, V_lo, V_hi, options.substeps, "scp",
                           time.perf_counter())  # fmt: skip
    if res.conformant:
        return True
    # the SCP trace is consistent with the linearised dynamics only: let Alg. 2 correct it, starting from it
    x1, W1, _ = optctrl_trace(model, t, U, Y, box.lo, box.hi, V_lo, V_hi, options, case,
                              start=SimpleNamespace(x0=x0, W_trace=W))  # fmt: skip
    return simulate_verdict(model, case.name, t, U, Y, x1, W1, box.lo, box.hi, V_lo, V_hi, options.substeps,
                            "optctrl", time.perf_counter()).conformant  # fmt: skip


def _verify(job):
    model, case, W, V, method, options = job
    return trace_conformance(model, case, W, V, method=method, options=options).conformant
