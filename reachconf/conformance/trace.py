"""Trace conformance (source report section 3.2, Alg. 1 and Alg. 2).

A model ``<f, h, V, W>`` is trace conformant to a test case ``<U, Y, T>`` if
some initial state, disturbance trace in ``W`` and measurement-error trace in
``V`` reproduce the measurements (eqs. 22–24).  Alg. 1 finds a candidate
disturbance trace (DISTURBANCETRACE: the per-step fit of section 3.2.1, or the
optimal-control QP of Alg. 2), then *simulates* the model with it (the IVP of
line 3) and computes the measurement errors from the simulated states (line
4).  The verdict uses only the simulated trace, so it is never wrongly
"conformant" — the search may fail to find a trace (a false "not
conformant"), never the reverse.  The IVP is integrated with RK4 at two step
sizes; the difference (an estimate of the integration error) is subtracted
from the measurement-error margins.

``method="auto"`` (the default): the per-step fit where its simulated trace
stays within W and V, Alg. 2 where it does not.  Cases are processed in
windows (:mod:`reachconf.conformance.windows`): any length runs in bounded
memory and linear time; the result records the method used, per window, and
why.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from reachconf.budget import TimeBudget, check_memory, check_time_limit
from reachconf.checks import check_field_types, check_options
from reachconf.conformance.windows import (
    PERSTEP_NO_PROOF,
    describe_violation,
    disturbance_trace_in_windows,
    keep_step,
    summarize_windows,
    verdict_in_windows,
)
from reachconf.errors import ConformanceError, OptionsError
from reachconf.io.cases import case_arrays
from reachconf.io.results import JsonResult
from reachconf.model.core import require_model
from reachconf.model.outputs import state_estimate
from reachconf.sets.convert import as_box
from reachconf.sets.core import Interval
from reachconf.verdict import Verdict

__all__ = [
    "TraceOptions",
    "TraceResult",
    "trace_conformance",
    "trace_disturbances",
    "simulate_verdict",
    "state_estimate",
    "case_arrays",
    "trace_bytes_per_sample",
    "METHODS",
]

#: DISTURBANCETRACE methods of :func:`trace_conformance`
METHODS = ("auto", "perstep", "optctrl")


@dataclass(frozen=True)
class TraceOptions:
    """Options of trace conformance.

    Parameters
    ----------
    objective : {"absolute", "relative"}, default "absolute"
        Per-step fit: weighted squared residual (weights ``1 / scale^2``, the
        scale being V's radius or, if V is zero there, the signal's spread) or
        the relative residual of eq. 27 (``/ y_{k+1}``; needs non-zero data).
    anchor : {"auto", "measured", "simulated"}, default "auto"
        Per-step fit: start every step from the measured state (eq. 25, steps
        independent) or from the simulated state of the previous step (the
        IVP trace, no drift).  "auto": measured if there are at least as many
        disturbances as states, else simulated.
    substeps : int, default 10
        RK4 steps per sample interval of the IVP and the per-step fit.
    gauss_newton_iterations : int, default 8
        Iterations of the per-step fit.
    max_iterations : int, default 15
        Outer iterations of Alg. 2 (QP + IVP).
    epsilon : float, default 1e-6
        Alg. 2 stops when ``||X - X_tilde||_inf <= epsilon`` (line 8).
    subdivision : int, default 1
        ``r`` of Alg. 2: disturbances per sample interval (r-step subdivision).
    trust_region : float, default 1.0
        Bound on the state change per QP iteration, in units of the state scale.
    solver : str or None, default None
        Ignored; kept so that run files setting it still load.  The QPs are
        solved by the Riccati kernel and Clarabel (no modelling layer).
    window : int, default 2000
        Samples per window: DISTURBANCETRACE and the verdict run window by
        window, carrying the state, so that memory stays bounded and time
        linear in the length of a case (a case of up to ``window + overlap``
        samples is one window: 20 s at 100 Hz).
    overlap : int, default 200
        Samples of look-ahead of an Alg. 2 window beyond the part it keeps.
    keep_samples : int, default 100000
        At most this many samples of the state and measurement-error traces
        are kept in the result (every ``trace_step``-th sample); the
        disturbance trace (the certificate) and margins are always complete.
    """

    objective: str = "absolute"
    anchor: str = "auto"
    substeps: int = 10
    gauss_newton_iterations: int = 8
    max_iterations: int = 15
    epsilon: float = 1e-6
    subdivision: int = 1
    trust_region: float = 1.0
    solver: str | None = None
    window: int = 2000
    overlap: int = 200
    keep_samples: int = 100_000

    def __post_init__(self):
        check_field_types(self)
        if self.objective not in ("absolute", "relative"):
            raise OptionsError(f"TraceOptions.objective must be 'absolute' or 'relative', got {self.objective!r}")
        if self.anchor not in ("auto", "measured", "simulated"):
            raise OptionsError(f"TraceOptions.anchor must be 'auto', 'measured' or 'simulated', got {self.anchor!r}")
        if not (isinstance(self.overlap, (int, np.integer)) and self.overlap >= 0):
            raise OptionsError(f"TraceOptions.overlap must be a non-negative integer, got {self.overlap!r}")
        if not (isinstance(self.window, (int, np.integer)) and self.window >= 10):
            raise OptionsError(f"TraceOptions.window must be an integer >= 10, got {self.window!r}")
        for name in ("substeps", "gauss_newton_iterations", "max_iterations", "subdivision", "keep_samples"):
            v = getattr(self, name)
            if not (isinstance(v, (int, np.integer)) and v >= 1):
                raise OptionsError(f"TraceOptions.{name} must be a positive integer, got {v!r}")
        if not self.epsilon > 0 or not self.trust_region > 0:
            raise OptionsError("TraceOptions.epsilon and trust_region must be positive")


@dataclass
class TraceResult(JsonResult):
    """Outcome of Alg. 1 for one test case.

    Attributes
    ----------
    case : str
    t : ndarray (K,)
    conformant : bool
        True only if the simulated trace satisfies eqs. 22–24 with margin.
    x0 : ndarray (n,)
    X : ndarray (K', n)
        Simulated states (the IVP solution, Alg. 1 line 3) at every
        ``trace_step``-th sample (all of them unless the case is longer than
        ``TraceOptions.keep_samples``).
    W_trace : ndarray (K-1, q)
        Disturbance on each sample interval (``(K-1) r`` rows with subdivision r).
    V_trace : ndarray (K', p)
        Measurement errors ``Y - h(X, U)`` (Alg. 1 line 4), at the samples of ``X``.
    margins : dict
        Channel (disturbance or output name) -> smallest distance to the
        bound over the trace (negative where the bound is violated; output
        margins already reduced by the integration-error estimate).  NaN
        (``null`` in JSON) for the disturbances when Alg. 2 found no trace
        (``UNDECIDED``): its last guess is no certificate.
    method : str
        DISTURBANCETRACE used: ``"perstep (measured|simulated)"``,
        ``"optctrl"`` (Alg. 2), or for ``method="auto"`` on a long case the
        count of windows of each.
    seconds : float
    message : str
        Alg. 2's convergence and, when not conformant, where the simulated
        trace leaves W or V (channel, time, by how much).
    integration_error : ndarray (p,)
        Estimated integration error of the simulated outputs.
    disturbance_names, output_names : tuple of str
        The model's channel names (labels of :meth:`plot`).
    verdict : Verdict
        ``CONFORMANT`` (the simulated trace keeps every bound), ``NOT_CONFORMANT`` (the trace Alg. 1
        found leaves W or V once simulated: the report's verdict, though another trace might exist;
        ``UNDECIDED`` with ``method="perstep"``, no search within V), or ``UNDECIDED`` (no trace to
        judge: the simulation diverged or Alg. 2's QP found no trace; ``message`` says why).
    reason : str
        Why that method (``method="auto"``: the per-step trace stayed within
        W and V, or where it left them).
    margin_times : dict
        Channel -> time of its smallest margin.
    trace_step : int
        ``X`` and ``V_trace`` hold every ``trace_step``-th sample.
    error_bounds : (ndarray, ndarray) or None
        Interval hull of the measurement errors over every sample.
    windows : list of (first sample, last sample, method)
    """

    case: str
    t: np.ndarray
    conformant: bool
    x0: np.ndarray
    X: np.ndarray
    W_trace: np.ndarray
    V_trace: np.ndarray
    margins: dict = field(default_factory=dict)
    method: str = "perstep"
    seconds: float = 0.0
    message: str = ""
    integration_error: np.ndarray | None = None
    disturbance_names: tuple = ()
    output_names: tuple = ()
    verdict: Verdict | None = None
    reason: str = ""
    margin_times: dict = field(default_factory=dict)
    trace_step: int = 1
    error_bounds: tuple | None = None
    windows: list = field(default_factory=list)

    def __post_init__(self):
        self.verdict = Verdict.of(self.conformant) if self.verdict is None else Verdict(self.verdict)

    def disturbance_box(self) -> Interval:
        """Interval hull of the disturbance trace (eqs. 62–66).

        Raises
        ------
        ConformanceError
            The trace is not finite (no disturbance trace was found: the message says why).
        """
        if not np.all(np.isfinite(self.W_trace)):
            why = self.message or self.reason or "the trace is not finite"
            raise ConformanceError(f"case {self.case!r}: no disturbance trace to take the box of ({why})")
        return Interval(self.W_trace.min(axis=0), self.W_trace.max(axis=0))

    def error_box(self) -> Interval:
        """Interval hull of the measurement-error trace (over every sample)."""
        if self.error_bounds is not None:
            return Interval(*self.error_bounds)
        return Interval(self.V_trace.min(axis=0), self.V_trace.max(axis=0))

    @property
    def t_kept(self) -> np.ndarray:
        """Sample times of ``X`` and ``V_trace``."""
        return self.t[:: self.trace_step]

    def worst(self):
        """``(channel, time, margin)`` of the smallest margin (negative: where the trace leaves W or V)."""
        known = {k: v for k, v in self.margins.items() if not np.isnan(v)}  # NaN: no margin (see ``margins``)
        if not known:
            return None
        ch = min(known, key=known.get)
        return ch, self.margin_times.get(ch), float(known[ch])

    def to_dict(self) -> dict:
        """The verdict, margins and boxes, and the traces themselves (``t``, ``X``, ``W_trace``, ``V_trace``).

        Numbers that are not finite (margins against an unbounded W, a
        diverged trace) become ``None`` in the JSON file (see ``verdict``).
        """
        return {
            "case": self.case,
            "verdict": self.verdict,
            "conformant": self.verdict.json_conformant,
            "method": self.method,
            "reason": self.reason,
            "seconds": float(self.seconds),
            "message": self.message,
            "x0": self.x0.tolist(),
            "margins": {k: float(v) for k, v in self.margins.items()},
            "margin_times": {k: float(v) for k, v in self.margin_times.items()},
            "W_box": [[float(a), float(b)] for a, b in zip(*_box_lists(self.W_trace))],
            "V_box": [[float(a), float(b)] for a, b in zip(*(self.error_bounds or _box_lists(self.V_trace)))],
            "disturbance_names": list(self.disturbance_names),
            "output_names": list(self.output_names),
            "t": self.t.tolist(),
            "trace_step": int(self.trace_step),
            "X": self.X.tolist(),
            "W_trace": self.W_trace.tolist(),
            "V_trace": self.V_trace.tolist(),
            "integration_error": None if self.integration_error is None else self.integration_error.tolist(),
            "windows": [list(w) for w in self.windows],
        }

    @classmethod
    def from_dict(cls, d: dict) -> "TraceResult":
        """The result from :meth:`to_dict`."""
        t = np.asarray(d["t"], dtype=float)
        x0 = np.asarray(d["x0"], dtype=float)
        X = np.asarray(d["X"], dtype=float).reshape(-1, x0.size)
        q, p = len(d["disturbance_names"]), len(d["output_names"])
        ie = d.get("integration_error")
        vb = d.get("V_box")
        return cls(d["case"], t, bool(d["conformant"]), x0, X,
                   np.asarray(d["W_trace"], dtype=float).reshape(-1, q), np.asarray(d["V_trace"], dtype=float).reshape(-1, p),
                   {k: np.nan if v is None else float(v) for k, v in d["margins"].items()}, d["method"], float(d["seconds"]), d["message"],
                   None if ie is None else np.asarray(ie, dtype=float), tuple(d["disturbance_names"]),
                   tuple(d["output_names"]), Verdict(d.get("verdict", Verdict.of(bool(d["conformant"])))),
                   d.get("reason", ""), dict(d.get("margin_times", {})),
                   int(d.get("trace_step", 1)),
                   None if not vb else (np.array([a for a, _ in vb]), np.array([b for _, b in vb])),
                   [tuple(w) for w in d.get("windows", [])])  # fmt: skip

    def plot(self, ax=None, model=None):
        """Disturbance and measurement-error traces over time (two axes); returns them.

        Parameters
        ----------
        ax : pair of matplotlib Axes, optional
            New figure if None.
        model : Model, optional
            Labels (default: the names stored in the result, else ``w1..``, ``v1..``).
        """
        import matplotlib.pyplot as plt

        q, p = self.W_trace.shape[1], self.V_trace.shape[1]
        axes = ax
        if axes is None:
            _, axes = plt.subplots(2, 1, figsize=(9, 6), sharex=True)
        tw = self.t[:-1] if self.W_trace.shape[0] == self.t.size - 1 else np.linspace(
            self.t[0], self.t[-1], self.W_trace.shape[0], endpoint=False)  # fmt: skip
        names_w = model.disturbance_names if model is not None else (self.disturbance_names or
                                                                       [f"w{i + 1}" for i in range(q)])  # fmt: skip
        names_v = model.output_names if model is not None else (self.output_names or [f"v{i + 1}" for i in range(p)])
        for i in range(q):
            axes[0].step(tw, self.W_trace[:, i], where="post", label=names_w[i], lw=0.8)
        for i in range(p):
            axes[1].plot(self.t_kept, self.V_trace[:, i], label=names_v[i], lw=0.8)
        axes[0].set_ylabel("disturbance w")
        axes[1].set_ylabel("measurement error v")
        axes[1].set_xlabel("t [s]")
        # matplotlib's "best" placement searches every vertex: on a long trace it takes seconds (and warns)
        loc = "best" if self.W_trace.shape[0] * max(q, p) <= 20_000 else "upper right"
        for a in axes:
            a.legend(fontsize=7, ncol=3, loc=loc)
        axes[0].set_title(f"{self.case}: {self.verdict.label} ({self.method})")
        return axes


def _box_lists(A):
    if A.size == 0:
        return [], []
    return A.min(axis=0), A.max(axis=0)


def simulate_verdict(model, case_name, t, U, Y, x0, Wt, W_lo, W_hi, V_lo, V_hi, substeps, method, t0,
                     message="", search_failed=False, keep_samples: int = 100_000) -> TraceResult:  # fmt: skip
    """Alg. 1, lines 3-5: simulate a candidate trace and judge it against the bounds (eqs. 22-24).

    The model is simulated from ``x0`` with the disturbance trace ``Wt`` (RK4 at
    ``substeps`` and twice that; the difference is the integration-error
    estimate; window by window, carrying both states), the measurement errors
    ``Y - h(X, U)`` are computed from the simulated states, and every
    disturbance and output margin must be non-negative, the outputs' after
    subtracting the integration error.  The verdict rests on this simulation
    only, so it is never wrongly "conformant".

    Parameters
    ----------
    model : Model
    case_name : str
    t, U, Y : ndarray
        The case's arrays (``TestCase.case_arrays``).
    x0 : ndarray (n,)
    Wt : ndarray ((K-1) r, q)
        Candidate disturbance trace (``r`` per sample interval).
    W_lo, W_hi, V_lo, V_hi : ndarray
        The boxes (``-inf``/``inf`` for unbounded).
    substeps : int
    method : str
        Recorded in the result.
    t0 : float
        ``time.perf_counter()`` at the start (for ``seconds``).
    message : str
    search_failed : bool
        DISTURBANCETRACE found no trace (Alg. 2's QP failed): a trace that
        then misses the bounds gives ``UNDECIDED``, not ``NOT_CONFORMANT``.
    keep_samples : int
        At most this many samples of the state and error traces are kept.

    Returns
    -------
    TraceResult
        When not conformant, ``message`` says where the trace leaves W or V.
    """
    K = t.size
    r = max(1, Wt.shape[0] // max(1, K - 1))
    step = keep_step(K, keep_samples)
    v = verdict_in_windows(model, t, U, Y, x0, Wt, W_lo, W_hi, V_lo, V_hi, substeps, r, keep_every=step,
                           progress=False)  # fmt: skip
    ok = v.finite and all(m >= 0 for m in v.margin.values())
    if not v.finite:
        message = (message + "; " if message else "") + "the simulated trace diverged (NaN/inf)"
    elif not ok:
        worst = min(v.margin, key=v.margin.get)
        where = describe_violation(model, worst, v.margin[worst], v.margin_time[worst], W_lo, W_hi, V_lo, V_hi)
        message = (message + "; " if message else "") + f"the simulated trace {where}"
    verdict = Verdict.of(ok, undecided=not ok and (not v.finite or search_failed))
    margins, margin_times = dict(v.margin), dict(v.margin_time)
    if search_failed and not ok:  # the disturbance trace is the search's last guess, not one it found: no W margins
        for name in model.disturbance_names:
            if name in margins:
                margins[name] = np.nan
                margin_times.pop(name, None)
    return TraceResult(case_name, t, bool(ok), np.array(x0, dtype=float), v.X, Wt, v.V, margins, method,
                       time.perf_counter() - t0, message, v.yerr, model.disturbance_names, model.output_names,
                       verdict, margin_times=margin_times, trace_step=step, error_bounds=(v.v_lo, v.v_hi))  # fmt: skip


def trace_bytes_per_sample(model, options, method) -> tuple[float, float]:
    """Memory estimate of trace conformance: ``(bytes per sample, fixed bytes)``.

    Per sample: the case copies (t, U, Y), the state estimate and the
    disturbance trace.  Fixed: the kept traces and the working arrays of one
    window (Alg. 2's QP dominates: about 6 KB per window sample for the
    vehicle models with Clarabel).
    """
    n, m, q, p = model.n, model.m, model.q, model.p
    r = int(options.subdivision) if method != "perstep" else 1
    per = 8.0 * (2 * (1 + m + p) + 2 * n + 2 * q * r + 2)
    window = int(options.window) + int(options.overlap)
    qp = 0.0 if method == "perstep" else window * r * 700.0 * (n + q)
    work = window * r * 8.0 * (12 * n + 4 * p + 4 * q + n * (n + q) * 3)
    kept = 2 * 8.0 * options.keep_samples * (n + p + 1)
    return per, qp + work + kept + 64e6


def trace_disturbances(model, case, method: str = "perstep", V=None, options: TraceOptions | None = None):
    """DISTURBANCETRACE without bounds: the disturbance trace and its simulated trace.

    The verdict fields refer to unbounded ``W`` and the given ``V`` (default
    ``{0}``).  Synthesis step 1 (eqs. 62–66) takes ``result.disturbance_box()``.
    """
    return trace_conformance(model, case, None, V, method=method, options=options, _unbounded=True)


def trace_conformance(model, case, W, V, method: str = "auto", options: TraceOptions | None = None,
                      _unbounded: bool = False, progress: bool | None = None,
                      time_limit: float | None = None) -> TraceResult:  # fmt: skip
    """Alg. 1: is the model with disturbance set ``W`` and measurement-error set ``V`` trace conformant?

    Parameters
    ----------
    model : Model
    case : TestCase
    W, V : Interval, Zonotope that is a box (else SetArgumentError: a hull is no W), or None for ``{0}``
    method : {"auto", "perstep", "optctrl"}, default "auto"
        DISTURBANCETRACE by the per-step fit (section 3.2.1, eqs. 25–27), by
        the optimal-control QP (Alg. 2, eqs. 29–41), or "auto": the per-step
        fit where its simulated trace stays within W and V, Alg. 2 where not
        (``result.method`` and ``result.reason`` say which and why).
    options : TraceOptions
        ``window``/``overlap``: long cases run window by window in bounded
        memory and linear time (:mod:`reachconf.conformance.windows`).
    progress : bool or None
        Progress bar (default: for cases of 50,000 samples or more).
    time_limit : float or None
        Seconds; the run stops with :class:`~reachconf.errors.ResourceError`
        after the first window if its projected duration is longer.

    Returns
    -------
    TraceResult

    Raises
    ------
    ResourceError
        Before any work, if the case needs more memory than is available.
    """
    t_start = time.perf_counter()
    where = "trace_disturbances" if _unbounded else "trace_conformance"
    require_model(model, where)
    options = check_options(options, TraceOptions, where)
    check_time_limit(time_limit)
    if progress is not None and not isinstance(progress, bool):
        raise OptionsError(f"{where}: progress must be True, False or None, got {progress!r}")
    if not isinstance(method, str) or method not in METHODS:
        raise OptionsError(f"{where}: method must be one of {METHODS}, got {method!r}")
    t, U, Y = case_arrays(model, case)
    name = getattr(case, "name", "case")
    if _unbounded:
        W_lo, W_hi = np.full(model.q, -np.inf), np.full(model.q, np.inf)
    else:
        Wb = as_box(W, model.q, "W", exact=True)
        W_lo, W_hi = Wb.lo, Wb.hi
    Vb = as_box(V, model.p, "V", exact=True)
    V_lo, V_hi = Vb.lo, Vb.hi
    per, fixed = trace_bytes_per_sample(model, options, method)
    check_memory(f"trace conformance of case {name!r}", t.size, per, fixed,
                 hint="Split the recording (TestCase.segment) or lower TraceOptions.window")  # fmt: skip
    try:
        Yx = state_estimate(model, case)
    except Exception:  # the states cannot be read from the outputs: Alg. 2 only
        if method == "perstep":
            raise
        Yx = None
    budget = TimeBudget(f"trace conformance of case {name!r}", time_limit)
    x0, Wt, info = disturbance_trace_in_windows(model, t, U, Y, Yx, W_lo, W_hi, V_lo, V_hi, options, method,
                                                progress=progress, budget=budget)  # fmt: skip
    label, reason, message, search_failed = summarize_windows(info, method)
    res = simulate_verdict(model, name, t, U, Y, x0, Wt, W_lo, W_hi, V_lo, V_hi, options.substeps, label, t_start,
                           message, search_failed=search_failed, keep_samples=options.keep_samples)  # fmt: skip
    res.reason, res.windows = reason, [tuple(w[:3]) for w in info["windows"]]
    if method == "perstep" and res.verdict is Verdict.NOT_CONFORMANT:  # no proof: see PERSTEP_NO_PROOF
        res.verdict, res.message = Verdict.UNDECIDED, res.message + PERSTEP_NO_PROOF
    return res

