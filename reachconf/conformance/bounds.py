"""Smallest disturbance / measurement-error boxes from trace conformance.

* :func:`minimize_box` — synthesis step 2 (section 4.3.2): minimise the
  disturbance box of one test case subject to trace conformance under ``V``
  (sequential convex programming on the sparse QP of
  :mod:`reachconf.conformance.optctrl`), then check the result with Alg. 1.
* :func:`case_box` — one case's smallest box with its certificate and
  the method that found it.
* :func:`minimal_trace_bounds` — the smallest per-channel box ``W`` (given
  ``V``), or ``V`` (for ``W = {0}``), that makes every trace of a suite
  conformant: the analogue of Tables 3 and 4.

Every box returned is verified: the trace that proves it (``x0`` and the
disturbance trace) is simulated again (Alg. 1, lines 3–5) with the box and V.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from reachconf.conformance.optctrl import TraceQP, disturbance_scale
from reachconf.conformance.trace import (
    TraceOptions,
    TraceResult,
    simulate_verdict,
    trace_conformance,
    trace_disturbances,
)
from reachconf.conformance.windows import describe_violation
from reachconf.checks import check_options
from reachconf.errors import ConformanceError, OptionsError
from reachconf.io.cases import case_arrays
from reachconf.model.core import require_model
from reachconf.model.outputs import state_estimate
from reachconf.runner import run_cases
from reachconf.sets.convert import as_box
from reachconf.sets.core import Interval

__all__ = ["minimize_box", "minimal_trace_bounds", "case_box", "CaseBox", "certify_trace", "box_scp", "step1_trace"]

_METHODS = ("auto", "perstep", "optctrl")
#: ``box_scp`` stops when the widths changed by less than this share of the start spread in two iterations in a row
STALL_CHANGE = 2e-3


def _inflate(lo, hi, rel, floor):
    pad = rel * (hi - lo) + floor
    return lo - pad, hi + pad


def certify_trace(model, case, x0, W, box: Interval, V, options: TraceOptions, method="scp") -> TraceResult:
    """Alg. 1's verdict for one given trace ``(x0, W)`` with the box ``W ∈ box`` and ``V`` (no search)."""
    t, U, Y = case_arrays(model, case)
    Vb = as_box(V, model.p, "V", exact=True)
    return simulate_verdict(model, getattr(case, "name", "case"), t, U, Y, np.array(x0, float), W, box.lo, box.hi,
                            Vb.lo, Vb.hi, options.substeps, method, time.perf_counter(),
                            keep_samples=options.keep_samples)  # fmt: skip


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
    Vb = as_box(V, model.p, "V", exact=True)
    V_lo, V_hi = Vb.lo, Vb.hi
    # The volume itself is a degenerate objective (one zero-width channel makes it 0 whatever the others
    # are), so the SCP minimises the sum of the channel widths normalised by step 1's box: the
    # analogue of the report's volume minimisation that shrinks every channel it can.
    scale = np.where(W_start.hi - W_start.lo > 0, W_start.hi - W_start.lo, 1.0)
    found = _scp_box(model, case, t, U, Y, V, V_lo, V_hi, start.x0, start.W_trace, scale, options)
    if found is not None:
        return found[0], found[1]
    res = certify_trace(model, case, start.x0, start.W_trace, W_start, V, options, method=start.method)
    return W_start, res


def _scp_box(model, case, t, U, Y, V, V_lo, V_hi, x0, W0, scale, options):
    """Box SCP from the trace ``(x0, W0)``; ``(box, certificate)`` or None if no box was certified."""
    vc, vr = 0.5 * (V_lo + V_hi), 0.5 * (V_hi - V_lo)
    floor = 1e-9 * (1 + np.abs(scale))
    # the SCP works on the linearised dynamics: leave 2 % of V for linearisation and integration errors,
    # and if its trace still leaves V when simulated, solve again with 10 % and 25 % left
    for keep in (0.98, 0.9, 0.75):
        lo, hi, x0s, W = box_scp(model, t, U, Y, vc - keep * vr, vc + keep * vr, np.array(x0, float),
                                        np.array(W0, float), options, objective="sum", scale=scale)  # fmt: skip
        if not np.all(np.isfinite(lo)) or not np.all(np.isfinite(hi)):
            continue
        blo, bhi = _inflate(lo, hi, 0.0, floor)
        res = certify_trace(model, case, x0s, W, Interval(blo, bhi), V, options)
        if res.conformant:
            return Interval(blo, bhi), res
    return None


@dataclass
class CaseBox:
    """One case's smallest trace-conformant box with its certificate.

    Attributes
    ----------
    lo, hi : ndarray
        The box (W, or V with ``solve_for="V"``).
    x0, W : ndarray
        The certificate: the trace that, simulated, satisfies eqs. 22–24 with the box.
    method : str
        "perstep", "optctrl" (Alg. 2 then the box SCP), or "optctrl (Alg. 2 trace)"
        when the SCP found no smaller certified box.
    reason : str
        Why that method.
    seconds : dict
        Time of the steps ("perstep", "alg2", "scp").
    """

    lo: np.ndarray
    hi: np.ndarray
    x0: np.ndarray
    W: np.ndarray
    method: str
    reason: str
    seconds: dict


def case_box(model, case, V=None, method: str = "auto", solve_for: str = "W",
             options: TraceOptions | None = None, certify: bool = True) -> CaseBox:  # fmt: skip
    """The smallest box of one case (the per-case part of :func:`minimal_trace_bounds`), with its certificate.

    Parameters
    ----------
    model, case
    V : Interval, optional
        Measurement-error set (for ``solve_for="W"``).
    method : {"auto", "perstep", "optctrl"}
        See :func:`minimal_trace_bounds`.
    solve_for : {"W", "V"}
        "V": the smallest measurement-error box for ``W = {0}`` (SCP).
    options : TraceOptions
    certify : bool, default True
        False: ``method="optctrl"`` returns the SCP's box from the per-step
        trace as it is, without Alg. 1's certificate or fallbacks (a
        best-effort size of the disturbances, e.g. for a model that cannot be
        trace conformant at all; the gap diagnosis compares such sizes).

    Raises
    ------
    ConformanceError
        If no trace within V is found: the message says where the best trace
        leaves V (case, output, time, by how much).
    """
    require_model(model, "case_box")
    options = check_options(options, TraceOptions, "case_box")
    if solve_for not in ("W", "V"):
        raise OptionsError(f"case_box: solve_for must be 'W' or 'V', got {solve_for!r}")
    if method not in _METHODS:
        raise OptionsError(f"case_box: method must be one of {_METHODS}, got {method!r}")
    if solve_for == "W" and V is None:
        raise OptionsError("case_box(solve_for='W') needs the measurement-error set V")
    name = getattr(case, "name", "case")
    t, U, Y = case_arrays(model, case)
    secs = {}
    if solve_for == "V":
        t0 = time.perf_counter()
        start = trace_disturbances(model, case, method="perstep", options=options) if model.q else None
        x0 = start.x0 if start is not None else Y[0][: model.n]
        W0 = np.zeros((t.size - 1, model.q))
        zero = (np.zeros(model.q), np.zeros(model.q))
        lo, hi, x0, W = box_scp(model, t, U, Y, None, None, x0, W0, options, objective="sum", W_fixed=zero,
                                       V_free=True)  # fmt: skip
        secs["scp"] = time.perf_counter() - t0
        return CaseBox(lo, hi, x0, W, "optctrl", "V box by SCP with W = {0}", secs)
    Vb = as_box(V, model.p, "V", exact=True)
    V_lo, V_hi = Vb.lo, Vb.hi
    t0 = time.perf_counter()
    ps = trace_disturbances(model, case, method="perstep", V=V, options=options)
    secs["perstep"] = time.perf_counter() - t0
    if method == "perstep" or (method == "auto" and ps.conformant):
        why = "per-step trace within V" if ps.conformant else "method='perstep' was asked for"
        return CaseBox(ps.W_trace.min(axis=0), ps.W_trace.max(axis=0), ps.x0, ps.W_trace, "perstep", why, secs)
    if method == "auto":
        ch, when, margin = ps.worst()
        reason = "per-step trace " + describe_violation(model, ch, margin, when, np.full(model.q, -np.inf),
                                                         np.full(model.q, np.inf), V_lo, V_hi)  # fmt: skip
    else:
        reason = "method='optctrl' was asked for"
    if method == "optctrl" and not certify:
        scale = np.ptp(ps.W_trace, axis=0)
        vc, vr = 0.5 * (V_lo + V_hi), 0.5 * (V_hi - V_lo)
        t0 = time.perf_counter()
        lo, hi, x0, W = box_scp(model, t, U, Y, vc - 0.98 * vr, vc + 0.98 * vr, ps.x0, ps.W_trace, options,
                                objective="sum", scale=np.where(scale > 0, scale, 1.0))  # fmt: skip
        secs["scp"] = time.perf_counter() - t0
        return CaseBox(lo, hi, x0, W, "optctrl (not certified)", reason, secs)
    if method == "optctrl":
        # the box SCP directly from the per-step trace, normalised by its spread
        scale = np.ptp(ps.W_trace, axis=0)
        t0 = time.perf_counter()
        found = _scp_box(model, case, t, U, Y, V, V_lo, V_hi, ps.x0, ps.W_trace, np.where(scale > 0, scale, 1.0),
                         options)  # fmt: skip
        secs["scp"] = time.perf_counter() - t0
        if found is not None:
            return CaseBox(found[0].lo, found[0].hi, found[1].x0, found[1].W_trace, "optctrl", reason, secs)
        reason += "; the SCP from the per-step trace found no certified box, so from Alg. 2's"
    t0 = time.perf_counter()
    a2 = trace_disturbances(model, case, method="optctrl", V=V, options=options)
    secs["alg2"] = time.perf_counter() - t0
    if not a2.conformant:
        raise ConformanceError(f"case {name!r}: no disturbance trace within V found ({reason}; Alg. 2: "
                               f"{a2.message})")  # fmt: skip
    scale = np.ptp(a2.W_trace, axis=0)
    t0 = time.perf_counter()
    found = _scp_box(model, case, t, U, Y, V, V_lo, V_hi, a2.x0, a2.W_trace, np.where(scale > 0, scale, 1.0),
                     options)  # fmt: skip
    secs["scp"] = secs.get("scp", 0.0) + time.perf_counter() - t0
    if found is not None:
        return CaseBox(found[0].lo, found[0].hi, found[1].x0, found[1].W_trace, "optctrl", reason, secs)
    # the SCP found no smaller certified box: Alg. 2's trace is itself a certificate (of a larger box)
    W0 = a2.W_trace
    return CaseBox(W0.min(axis=0), W0.max(axis=0), a2.x0, W0, "optctrl (Alg. 2 trace)", reason, secs)


def minimal_trace_bounds(model, suite, V=None, method: str = "auto", solve_for: str = "W",
                         options: TraceOptions | None = None, workers=None, scheduler=None,
                         executor=None, details: bool = False):  # fmt: skip
    """Smallest per-channel box making every trace of the suite conformant (Tables 3/4 analogue).

    Parameters
    ----------
    suite : TestSuite or iterable of TestCase
    V : Interval, optional
        Measurement-error set (required for ``solve_for="W"``; ignored for "V").
    method : {"auto", "perstep", "optctrl"}, default "auto"
        Per case: "perstep" — the hull of the per-step disturbance trace
        (section 3.2.1); "optctrl" — the box of smallest normalised widths by
        SCP (Alg. 2's constraints with the box as variable) from the per-step
        trace; "auto" — the per-step box where the per-step trace stays within
        V, else Alg. 2's trace (eq. 36) and the box SCP from it.  Then the hull
        over cases.
    solve_for : {"W", "V"}
        "V": the smallest measurement-error box for ``W = {0}``.
    workers, scheduler, executor : see :func:`reachconf.runner.run_cases`
        ``executor`` reuses a running pool (e.g. one per script instead of one per call).
    details : bool
        Also return the per-case :class:`CaseBox` list (method used and why).

    Returns
    -------
    Interval (and, with ``details``, the list of CaseBox)
        Verified: each case's own trace, simulated, is conformant with this
        box and V (Alg. 1's certificate).

    Raises
    ------
    ConformanceError
        If a case has no trace within V: the message names the case, the
        output, the time and by how much V is exceeded.
    """
    require_model(model, "minimal_trace_bounds")
    options = check_options(options, TraceOptions, "minimal_trace_bounds")
    cases = list(suite)
    if not cases:
        raise ConformanceError("the suite has no test cases")
    if solve_for not in ("W", "V"):
        raise OptionsError(f"solve_for must be 'W' or 'V', got {solve_for!r}")
    if solve_for == "W" and V is None:
        raise OptionsError("minimal_trace_bounds(solve_for='W') needs the measurement-error set V")
    if method not in _METHODS:
        raise OptionsError(f"method must be one of {_METHODS}, got {method!r}")
    jobs = [(model, case, V, method, solve_for, options) for case in cases]
    boxes = run_cases(_case_box_job, jobs, workers=workers, scheduler=scheduler, desc="minimal bounds",
                      executor=executor)  # fmt: skip
    lo = np.min([b.lo for b in boxes], axis=0)
    hi = np.max([b.hi for b in boxes], axis=0)
    dim = model.p if solve_for == "V" else model.q
    floor = 1e-9 * np.ones(dim)
    failed = []
    for attempt in range(6):
        if solve_for == "W":
            box = Interval(*_inflate(lo, hi, 0.0, floor))
            failed = []
            for case, b in zip(cases, boxes):
                res = certify_trace(model, case, b.x0, b.W, box, V, options, method=b.method)
                if not res.conformant:
                    failed.append((case.name, res.message))
            if not failed:
                return (box, boxes) if details else box
            break  # the certificates' V margins do not depend on the W box
        # V: the SCP's box is the hull of its own residuals, exactly tight; Alg. 2 keeps 0.1 % of V in
        # reserve, so grow in small steps until Alg. 2 finds a trace for every case (its own certificate)
        box = Interval(*_inflate(lo, hi, 0.004 * 2**attempt if attempt else 0.002, floor))
        zero = Interval(np.zeros(model.q), np.zeros(model.q))
        failed = []
        for case in cases:
            res = trace_conformance(model, case, zero, box, method="optctrl", options=options)
            if not res.conformant:
                failed.append((case.name, res.message))
        if not failed:
            return (box, boxes) if details else box
    raise ConformanceError(f"no verified {solve_for} box found with method {method!r}: "
                           + "; ".join(f"case {n!r}: {m}" for n, m in failed))  # fmt: skip


def _case_box_job(job) -> CaseBox:
    return case_box(*job)


def box_scp(model, t, U, Y, V_lo, V_hi, x0, W, options, objective="sum", W_fixed=None, V_free=False,
                   iterations=None, scale=None):  # fmt: skip
    """Sequential convex programming for the smallest box (W, or V with ``V_free``).

    Parameters
    ----------
    x0, W : start trace (W on the grid of ``options.subdivision``, or on the sample grid)
    objective : {"sum", "volume"}
        Minimise the sum of the widths normalised by ``scale`` (default: the
        start trace's spread), or the volume (tangent majorisation of the
        log-volume: degenerate, a zero width makes it zero).
    W_fixed : (lo, hi) or None
        Keep the disturbances inside this fixed box (e.g. ``{0}`` when
        solving for V) instead of a variable one.
    V_free : bool
        Make the measurement-error box the variable (``V_lo, V_hi`` are ignored).

    Returns
    -------
    (lo, hi, x0, W)
        The box is the hull of the final (re-simulated) trace's disturbances
        (or measurement errors with ``V_free``), not the QP's variables.
    """
    r = int(options.subdivision)
    q, p = model.q, model.p
    if V_free:
        big = np.full(p, np.inf)
        prob = TraceQP(model, t, U, Y, -big, big, r=r, substeps=options.substeps)
    else:
        prob = TraceQP(model, t, U, Y, V_lo, V_hi, r=r, substeps=options.substeps)
    if r > 1 and W.shape[0] == t.size - 1:
        W = np.repeat(W, r, axis=0)
    W = np.array(W, dtype=float)
    prob.trust = prob.trust * options.trust_region
    X = prob.simulate(x0, W)
    if V_free:
        res = Y - prob.outputs(X)
        lo_prev, hi_prev = res.min(axis=0), res.max(axis=0)
        spread = np.where(hi_prev - lo_prev > 0, hi_prev - lo_prev, 1.0)
        prob.set_scales(0.5 * spread)
        prob.trust = prob.trust * options.trust_region
        prob.sw = np.ones(q)
        dim = p
    else:
        lo_prev, hi_prev = (W.min(axis=0), W.max(axis=0)) if W.size else (np.zeros(q), np.zeros(q))
        prob.sw = disturbance_scale(np.full(q, -np.inf), np.full(q, np.inf), W, q)
        dim = q
    width0 = np.maximum(hi_prev - lo_prev, 1e-12)
    norm = np.asarray(scale, float) if scale is not None else width0
    unit = prob.sv if V_free else prob.sw
    wlo, whi = W_fixed if W_fixed is not None else (np.full(q, -np.inf), np.full(q, np.inf))
    stalled = 0
    for it in range(iterations or options.max_iterations):
        if objective == "volume":
            weights = unit / (np.maximum(hi_prev - lo_prev, 0) + 1e-3 * width0)
        else:
            weights = unit / norm
        if V_free:
            status, DX, DW, extra = prob.solve(X, W, "vbox", W_lo=wlo, W_hi=whi, weights=weights)
        else:
            status, DX, DW, extra = prob.solve(X, W, "box", V_lo=V_lo, V_hi=V_hi, weights=weights)
        if status != "optimal":
            break
        X_tilde = X + DX
        if q:
            W = W + DW
        x0 = X_tilde[0]
        X = prob.simulate(x0, W)
        if not np.all(np.isfinite(X)):
            break
        new_lo, new_hi = extra[:dim], extra[dim:]
        change = float(np.max(np.abs(new_hi - new_lo - (hi_prev - lo_prev)) / width0)) if dim else 0.0
        lo_prev, hi_prev = new_lo, new_hi
        e = prob.linearisation_error(X, X_tilde) if not V_free else 0.0
        if e <= max(options.epsilon, 1e-9) and change < 1e-3:
            break
        if it >= 2 and e <= 1e-2 and change < 2e-2:  # settled to 2 %: the box is verified by Alg. 1 anyway
            break
        # the box no longer moves (widths within STALL_CHANGE of the start spread twice in a row) while the
        # linearisation error stays: more iterations only re-solve the same QP (measured on the vehicle's 100 Hz
        # slalom: 13 more iterations moved no width by more than 0.3 %); the box is verified by Alg. 1 anyway
        stalled = stalled + 1 if it >= 1 and change < STALL_CHANGE else 0
        if stalled >= 2:
            break
    if V_free:
        res = Y - prob.outputs(X)
        return res.min(axis=0), res.max(axis=0), x0, W
    if q:
        return W.min(axis=0), W.max(axis=0), x0, W
    return np.zeros(0), np.zeros(0), x0, W


def states_readable(model, case) -> bool:
    """Can the states be read from the case's outputs (what the per-step fit needs)?"""
    try:
        state_estimate(model, case)
    except ConformanceError:
        return False
    return True


def step1_trace(model, case, V, method, options):
    """Step 1's disturbance trace by ``method`` ("auto": per-step where it stays within V, else Alg. 2).

    Returns ``(TraceResult, reason)``.
    """
    if method == "optctrl":
        return trace_disturbances(model, case, method="optctrl", V=V, options=options), "step1_method='optctrl'"
    if method == "auto" and not states_readable(model, case):
        res = trace_disturbances(model, case, method="optctrl", V=V, options=options)
        return res, "the states cannot be read from the outputs: Alg. 2"
    res = trace_disturbances(model, case, method="perstep", V=V, options=options)
    if method == "perstep":
        return res, "step1_method='perstep'"
    if res.conformant:
        return res, "per-step trace within V"
    Vb = as_box(V, model.p, "V", exact=True)
    ch, when, margin = res.worst()
    inf = np.full(model.q, np.inf)
    reason = "per-step trace " + describe_violation(model, ch, margin, when, -inf, inf, Vb.lo, Vb.hi)
    a2 = trace_disturbances(model, case, method="optctrl", V=V, options=options)
    if not a2.conformant:  # keep the per-step trace; step 2 starts from it
        return res, reason + f"; Alg. 2 found no trace within V either ({a2.message}), per-step trace kept"
    return a2, reason
