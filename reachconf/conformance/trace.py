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
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace

import numpy as np

from reachconf.checks import check_field_types, check_options
from reachconf.conformance.optctrl import NO_TRACE, optctrl_trace
from reachconf.errors import ConformanceError, OptionsError
from reachconf.io.cases import case_arrays
from reachconf.io.results import JsonResult
from reachconf.model.core import require_model
from reachconf.model.outputs import affine_output, evaluate_outputs, output_index_of_states, state_estimate
from reachconf.model.simulate import simulate
from reachconf.sets.convert import as_box
from reachconf.sets.core import Interval
from reachconf.verdict import Verdict
from reachconf_kernels.tracefit import perstep_fit

__all__ = [
    "TraceOptions",
    "TraceResult",
    "trace_conformance",
    "trace_disturbances",
    "simulate_verdict",
    "state_estimate",
    "case_arrays",
]


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
        cvxpy solver (None: Clarabel, then OSQP).
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

    def __post_init__(self):
        check_field_types(self)
        if self.objective not in ("absolute", "relative"):
            raise OptionsError(f"TraceOptions.objective must be 'absolute' or 'relative', got {self.objective!r}")
        if self.anchor not in ("auto", "measured", "simulated"):
            raise OptionsError(f"TraceOptions.anchor must be 'auto', 'measured' or 'simulated', got {self.anchor!r}")
        for name in ("substeps", "gauss_newton_iterations", "max_iterations", "subdivision"):
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
    X : ndarray (K, n)
        Simulated states (the IVP solution, Alg. 1 line 3).
    W_trace : ndarray (K-1, q)
        Disturbance on each sample interval (``(K-1) r`` rows with subdivision r).
    V_trace : ndarray (K, p)
        Measurement errors ``Y - h(X, U)`` (Alg. 1 line 4).
    margins : dict
        Channel (disturbance or output name) -> smallest distance to the
        bound over the trace (negative where the bound is violated; output
        margins already reduced by the integration-error estimate).
    method : str
    seconds : float
    message : str
    integration_error : ndarray (p,)
        Estimated integration error of the simulated outputs.
    disturbance_names, output_names : tuple of str
        The model's channel names (labels of :meth:`plot`).
    verdict : Verdict
        ``CONFORMANT`` (the simulated trace keeps every bound), ``NOT_CONFORMANT``
        (the disturbance trace Alg. 1 found leaves W or V once simulated: the
        report's verdict, though another trace might exist), or ``UNDECIDED``
        (no trace to judge: the simulation diverged or Alg. 2's QP found no
        trace; ``message`` says why).
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

    def __post_init__(self):
        self.verdict = Verdict.of(self.conformant) if self.verdict is None else Verdict(self.verdict)

    def disturbance_box(self) -> Interval:
        """Interval hull of the disturbance trace (eqs. 62–66)."""
        return Interval(self.W_trace.min(axis=0), self.W_trace.max(axis=0))

    def error_box(self) -> Interval:
        """Interval hull of the measurement-error trace."""
        return Interval(self.V_trace.min(axis=0), self.V_trace.max(axis=0))

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
            "seconds": float(self.seconds),
            "message": self.message,
            "x0": self.x0.tolist(),
            "margins": {k: float(v) for k, v in self.margins.items()},
            "W_box": [[float(a), float(b)] for a, b in zip(*_box_lists(self.W_trace))],
            "V_box": [[float(a), float(b)] for a, b in zip(*_box_lists(self.V_trace))],
            "disturbance_names": list(self.disturbance_names),
            "output_names": list(self.output_names),
            "t": self.t.tolist(),
            "X": self.X.tolist(),
            "W_trace": self.W_trace.tolist(),
            "V_trace": self.V_trace.tolist(),
            "integration_error": None if self.integration_error is None else self.integration_error.tolist(),
        }

    @classmethod
    def from_dict(cls, d: dict) -> "TraceResult":
        """The result from :meth:`to_dict`."""
        t = np.asarray(d["t"], dtype=float)
        X = np.asarray(d["X"], dtype=float).reshape(t.size, -1)
        q, p = len(d["disturbance_names"]), len(d["output_names"])
        ie = d.get("integration_error")
        return cls(d["case"], t, bool(d["conformant"]), np.asarray(d["x0"], dtype=float), X,
                   np.asarray(d["W_trace"], dtype=float).reshape(-1, q), np.asarray(d["V_trace"], dtype=float).reshape(-1, p),
                   {k: np.nan if v is None else float(v) for k, v in d["margins"].items()}, d["method"], float(d["seconds"]), d["message"],
                   None if ie is None else np.asarray(ie, dtype=float), tuple(d["disturbance_names"]),
                   tuple(d["output_names"]), Verdict(d.get("verdict", Verdict.of(bool(d["conformant"])))))  # fmt: skip

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
            axes[1].plot(self.t, self.V_trace[:, i], label=names_v[i], lw=0.8)
        axes[0].set_ylabel("disturbance w")
        axes[1].set_ylabel("measurement error v")
        axes[1].set_xlabel("t [s]")
        for a in axes:
            a.legend(fontsize=7, ncol=3)
        axes[0].set_title(f"{self.case}: {self.verdict.label} ({self.method})")
        return axes


def _box_lists(A):
    if A.size == 0:
        return [], []
    return A.min(axis=0), A.max(axis=0)


# ---------------------------------------------------------------------------
# data plumbing
# ---------------------------------------------------------------------------
def _weights(model, Yx, V_lo, V_hi, objective):
    """Weights of the per-step residual components (per step, per state)."""
    K, n = Yx.shape
    if objective == "relative":
        if np.any(Yx[1:] == 0):
            raise ConformanceError("objective='relative' (eq. 27) needs measurements that are never zero")
        return 1.0 / Yx[1:] ** 2
    direct = output_index_of_states(model)
    scale = np.ptp(Yx, axis=0)
    if direct is not None:
        vrad = 0.5 * (V_hi - V_lo)[direct]
        scale = np.where(vrad > 0, vrad, scale)
    scale = np.where(scale > 0, scale, 1.0)
    return np.tile(1.0 / scale**2, (K - 1, 1))


# ---------------------------------------------------------------------------
# IVP and verdict (Alg. 1, lines 3-5)
# ---------------------------------------------------------------------------
def simulate_verdict(model, case_name, t, U, Y, x0, Wt, W_lo, W_hi, V_lo, V_hi, substeps, method, t0,
                     message="", search_failed=False) -> TraceResult:  # fmt: skip
    """Alg. 1, lines 3-5: simulate a candidate trace and judge it against the bounds (eqs. 22-24).

    The model is simulated from ``x0`` with the disturbance trace ``Wt`` (RK4 at
    ``substeps`` and twice that; the difference is the integration-error
    estimate), the measurement errors ``Y - h(X, U)`` are computed from the
    simulated states, and every disturbance and output margin must be
    non-negative, the outputs' after subtracting the integration error.  The
    verdict rests on this simulation only, so it is never wrongly "conformant".

    Parameters
    ----------
    model : Model
    case_name : str
    t, U, Y : ndarray
        The case's arrays (``TestCase.case_arrays``).
    x0 : ndarray (n,)
    Wt : ndarray (K-1, q)
        Candidate disturbance trace.
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

    Returns
    -------
    TraceResult
    """
    X, xerr = simulate(model, x0, t, U, Wt, substeps, error_estimate=True, check=False)
    Vt = Y - evaluate_outputs(model, X, U)
    # integration error mapped to the outputs (first order, through |dh/dx|)
    aff = affine_output(model)
    if aff is not None:
        yerr = xerr @ np.abs(aff[0]).T
    else:
        yerr = np.max(xerr, axis=1, keepdims=True) * np.ones((1, model.p)) * 10.0
    margins = {}
    ok = True
    for i, name in enumerate(model.disturbance_names):
        m = float(np.min(np.minimum(Wt[:, i] - W_lo[i], W_hi[i] - Wt[:, i]))) if Wt.size else 0.0
        margins[name] = m
        ok &= m >= 0
    for i, name in enumerate(model.output_names):
        key = name if name not in margins else f"v:{name}"
        m = float(np.min(np.minimum(Vt[:, i] - yerr[:, i] - V_lo[i], V_hi[i] - Vt[:, i] - yerr[:, i])))
        margins[key] = m
        ok &= m >= 0
    finite = bool(np.all(np.isfinite(X)))
    ok = ok and finite
    if not finite:
        message = (message + "; " if message else "") + "the simulated trace diverged (NaN/inf)"
    verdict = Verdict.of(ok, undecided=not ok and (not finite or search_failed))
    return TraceResult(case_name, t, bool(ok), x0, X, Wt, Vt, margins, method, time.perf_counter() - t0,
                       message, yerr.max(axis=0), model.disturbance_names, model.output_names, verdict)  # fmt: skip


# ---------------------------------------------------------------------------
# DISTURBANCETRACE, section 3.2.1
# ---------------------------------------------------------------------------
def _perstep(model, t, U, Y, V_lo, V_hi, options, case):
    Yx = state_estimate(model, case)
    anchor = options.anchor
    if anchor == "auto":
        anchor = "measured" if model.q >= model.n else "simulated"
    if model.q == 0:
        return Yx[0].copy(), np.zeros((t.size - 1, 0)), anchor
    weights = np.ascontiguousarray(_weights(model, Yx, V_lo, V_hi, options.objective))
    W0 = np.zeros((t.size - 1, model.q))
    comp = model.compiled()
    Wt, _ = perstep_fit(comp.f, Yx, Yx, np.ascontiguousarray(U[:-1]), np.diff(t), model.param_vector, weights, W0,
                        int(options.substeps), int(options.gauss_newton_iterations), anchor == "simulated")  # fmt: skip
    return Yx[0].copy(), Wt, anchor


def trace_disturbances(model, case, method: str = "perstep", V=None, options: TraceOptions | None = None):
    """DISTURBANCETRACE without bounds: the disturbance trace and its simulated trace.

    The verdict fields refer to unbounded ``W`` and the given ``V`` (default
    ``{0}``).  Synthesis step 1 (eqs. 62–66) takes ``result.disturbance_box()``.
    """
    return trace_conformance(model, case, None, V, method=method, options=options, _unbounded=True)


def trace_conformance(model, case, W, V, method: str = "perstep", options: TraceOptions | None = None,
                      _unbounded: bool = False) -> TraceResult:  # fmt: skip
    """Alg. 1: is the model with disturbance set ``W`` and measurement-error set ``V`` trace conformant?

    Parameters
    ----------
    model : Model
    case : TestCase
    W, V : Interval or Zonotope (their interval hulls are used), or None for ``{0}``
    method : {"perstep", "optctrl"}
        DISTURBANCETRACE by the per-step fit (section 3.2.1, eqs. 25–27) or by
        the optimal-control QP (Alg. 2, eqs. 29–41).
    options : TraceOptions

    Returns
    -------
    TraceResult
    """
    t0 = time.perf_counter()
    where = "trace_disturbances" if _unbounded else "trace_conformance"
    require_model(model, where)
    options = check_options(options, TraceOptions, where)
    if not isinstance(method, str) or method not in ("perstep", "optctrl"):
        raise OptionsError(f"{where}: method must be 'perstep' or 'optctrl', got {method!r}")
    t, U, Y = case_arrays(model, case)
    if _unbounded:
        W_lo, W_hi = np.full(model.q, -np.inf), np.full(model.q, np.inf)
    else:
        Wb = as_box(W, model.q, "W")
        W_lo, W_hi = Wb.lo, Wb.hi
    Vb = as_box(V, model.p, "V")
    V_lo, V_hi = Vb.lo, Vb.hi
    name = getattr(case, "name", "case")
    if method == "perstep":
        x0, Wt, anchor = _perstep(model, t, U, Y, V_lo, V_hi, options, case)
        return simulate_verdict(model, name, t, U, Y, x0, Wt, W_lo, W_hi, V_lo, V_hi, options.substeps,
                                f"perstep ({anchor})", t0)  # fmt: skip
    x0, Wt, message = optctrl_trace(model, t, U, Y, W_lo, W_hi, V_lo, V_hi, options, case)
    return simulate_verdict(model, name, t, U, Y, x0, Wt, W_lo, W_hi, V_lo, V_hi, options.substeps, "optctrl", t0,
                            message, search_failed=NO_TRACE in message)  # fmt: skip
