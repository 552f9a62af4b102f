"""Joint least-squares fits of base-model parameters and candidate effects by multi-step prediction.

One-step residuals cannot see a sensor offset or a short delay at 100 Hz (the
sensor noise dominates them), so every candidate is fitted and scored by
*multi-step prediction*: windows of ``window`` seconds started from the
measured (Savitzky–Golay smoothed) states every ``stride`` seconds are
simulated without disturbances (compiled RK4, :func:`reachconf_kernels.integrate.rk4_windows`,
all windows in one call) and compared with the measurements, each residual
divided by the output's noise level (estimated from third differences) or, with
``DiagnoseOptions.loss_scale = "residual"``, by the base model's own misfit
level per channel, or with ``"case"`` also weighted per case by it
(:mod:`reachconf.diagnose.scales`).  The
base model's parameters are fitted jointly with the effect's, kept near their
nominal values by a Gaussian prior (relative standard deviation ``prior``) and
hard bounds, so that they cannot soak up the effect.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from reachconf.diagnose.effects import effect_param_name
from reachconf.diagnose.options import PAST_SPAN_MAX, DiagnoseOptions
from reachconf.diagnose.residuals import case_starts, received_inputs, window_residuals
from reachconf.errors import ConformanceError, OptionsError
from reachconf.io.cases import TestCase, case_arrays

__all__ = ["noise_level", "PreparedCase", "prepare", "Candidate", "FitResult",
           "case_starts", "fit_candidate", "prebuild_models", "transformed_case", "transformed_signals", "window_residuals", "window_losses",
           "window_counts", "prediction_cost"]


def noise_level(Y: np.ndarray) -> np.ndarray:
    """Noise standard deviation per column: robust (MAD) spread of third differences / sqrt(20)."""
    d3 = np.diff(Y, n=3, axis=0)
    mad = np.median(np.abs(d3 - np.median(d3, axis=0)), axis=0)
    sigma = 1.4826 * mad / np.sqrt(20.0)
    floor = 1e-6 * np.maximum(np.ptp(Y, axis=0), 1e-12)
    return np.maximum(sigma, floor)


def past_estimate(Y: np.ndarray, M: int) -> np.ndarray:
    """Estimate of every sample from the ``M`` samples before it (quadratic least squares, extrapolated).

    In closed loop the recorded commands react to the sensor noise; a window
    started from a state smoothed over *later* samples would share that noise
    with the commands and bias the fitted lags and delays.  Rows before ``M``
    are left at 0.
    """
    j = np.arange(1, M + 1, dtype=float)
    c = np.linalg.pinv(np.vander(-j, 3, increasing=True))[0]  # weights of y[k-1], ..., y[k-M]
    out = np.zeros_like(Y, dtype=float)
    for i, cj in enumerate(c):
        out[M:] += cj * Y[M - 1 - i : Y.shape[0] - 1 - i]
    return out


@dataclass
class PreparedCase:
    """A test case's arrays, smoothed outputs and prediction windows."""

    name: str
    group: str
    t: np.ndarray
    U: np.ndarray
    Y: np.ndarray
    Ys: np.ndarray
    starts: np.ndarray
    length: int
    case: object
    offsets: np.ndarray | None = None  # compared steps within a window (1 ... length)
    idx: np.ndarray | None = None  # sample index of every compared prediction, window after window
    weight: float = 1.0  # multiplies the case's normalised residuals (``loss_scale = "case"``)
    prefix_Y: np.ndarray | None = None  # compared samples before the first window, when ``Y`` holds only the windows'
    dt: float | None = None  # median sampling interval (s)
    hold: str = "zero"  # how the inputs move between samples (``DiagnoseOptions.input_hold``)

    @property
    def per_window(self) -> int:
        """Compared predictions per window."""
        return int(self.offsets.size)


def smoothing_window(options: DiagnoseOptions, dt: float) -> int:
    """Samples of the Savitzky–Golay window at the sampling interval ``dt``: ``options.smooth``, or fewer (odd, at
    least 3) where that would span more than ``options.smooth_span`` seconds."""
    if options.smooth_span is None:
        return int(options.smooth)
    n = int(np.floor(options.smooth_span / dt + 1e-9)) + 1
    n -= 1 - n % 2  # odd
    return int(max(3, min(options.smooth, n)))


def prepare(model, case, options: DiagnoseOptions) -> PreparedCase:
    """A :class:`PreparedCase`: the case's arrays, smoothed outputs and prediction windows."""
    from scipy.signal import savgol_filter

    t, U, Y = case_arrays(model, case)
    dt = float(np.median(np.diff(t)))  # (a gap in the sampling is not its rate)
    if options.window < dt:
        raise OptionsError(f"DiagnoseOptions.window {options.window:g} s is shorter than the data's sampling interval "
                           f"({dt:g} s of case {case.name!r}): a prediction window needs at least two samples")  # fmt: skip
    length = max(int(round(options.window / dt)), 2)
    stride = max(int(round(options.stride / dt)), 1)
    if t.size < length + 2:
        raise ConformanceError(f"test case {case.name!r} is shorter than one prediction window ({options.window} s)")
    smooth = smoothing_window(options, dt)
    win = min(smooth, t.size - (1 - t.size % 2))
    Ys = savgol_filter(Y, win, 2, axis=0) if win >= 3 else Y.copy()
    first, lead = 0, 0
    mode = options.start_state
    M = 2 * smooth - 1
    if mode == "auto":  # the "past" extrapolation only over the span where it was validated (DiagnoseOptions)
        mode = "past" if M * dt <= PAST_SPAN_MAX + 1e-9 else "prefix"
    if mode in ("past", "prefix"):
        if t.size > M + length + 2:
            if mode == "past":
                Ys[M:] = past_estimate(Y, M)[M:]
            else:  # from the centred estimate whose last sample is the one before the window (simulated, not scored)
                lead = (win - 1) // 2 + 1
            first = M  # (the same scored samples either way)
    starts = np.arange(first, t.size - length - 1, stride, dtype=np.int64)
    every = max(int(round(options.compare_step / dt)), 1)
    offsets = np.arange(length, 0, -every, dtype=np.int64)[::-1]  # always includes the window's last step
    idx = (starts[:, None] + offsets[None, :]).reshape(-1)
    starts, offsets = starts - lead, offsets + lead  # each window simulated from `lead` samples before its start
    return PreparedCase(case.name, getattr(case, "group", "default"), t, U, Y, Ys, starts, length + lead, case,
                        offsets, idx, dt=dt, hold=options.input_hold)  # fmt: skip


@dataclass(frozen=True)
class Candidate:
    """One or more (effect, target) pairs fitted jointly with the base parameters."""

    parts: tuple  # ((Effect, target), ...)

    @property
    def label(self) -> str:
        """``effect(target) + ...``, or ``base`` for no effect."""
        return " + ".join(f"{e.name}({t})" for e, t in self.parts) if self.parts else "base"

    @property
    def keys(self) -> frozenset:
        """The (effect name, target) pairs: candidates are nested when one's keys contain the other's."""
        return frozenset((e.name, t) for e, t in self.parts)

    @property
    def inputs(self) -> list:
        """Its input effects ``(Effect, target)`` in their composition order (offsets before scales)."""
        return [(e, t) for e, t in sorted(self.parts, key=lambda p: p[0].order) if e.kind == "input"]

    @property
    def structural(self) -> tuple:
        """The (effect name, target) pairs of its model-kind effects: the key of its compiled model (empty: none)."""
        return tuple((e.name, t) for e, t in self.parts if e.kind in ("param", "state"))


def _model_for(base, cand: Candidate, cache: dict):
    """The base model with the candidate's model-kind effects applied (compiled once, cached)."""
    model = base
    key = cand.structural
    if not key:
        return base, ()
    if key not in cache:
        names = []
        for e, t in cand.parts:
            if e.kind in ("param", "state"):
                model = e.apply_model(model, t)
                names += [n for n in model.param_names if n not in base.param_names and n not in names]
        model.compiled()
        cache[key] = (model, tuple(names))
    model, names = cache[key]
    # the cached model may have been built from a base with other parameter values
    return model.with_params(**{n: base.params[n] for n in base.param_names}), names


def prebuild_models(base, cands, cache: dict) -> None:
    """Build and compile the models of the candidates' model-kind effects into ``cache`` (before worker
    processes fork, so that they inherit them: :mod:`reachconf.diagnose.parallel`)."""
    for cand in cands:
        if cand.structural:
            _model_for(base, cand, cache)[0].compiled()


def transformed_signals(model, cand: Candidate, theta_eff: dict, t, U, Y, starts=None):
    """Inputs the system really received and outputs the model should produce (input/output effects applied).

    ``starts``: the start offsets of input effects with memory (:func:`case_starts`).
    """
    U = received_inputs(model, cand.inputs, t, U, theta_eff, starts).copy()
    Y = Y.copy()
    for e, tgt in cand.parts:
        if e.kind == "output":
            i = model.output_names.index(tgt)
            Y[:, i] = e.inverse(Y[:, i], theta_eff[(e.name, tgt)])
    return U, Y


def transformed_case(model, case, cand: Candidate, theta_eff: dict, starts=None):
    """A copy of ``case`` as seen by the model with the candidate's input/output effects (``starts``: as
    :func:`transformed_signals`)."""
    t, U, Y = case_arrays(model, case)
    U2, Y2 = transformed_signals(model, cand, theta_eff, t, U, Y, starts)
    # extra signals (e.g. a measured lateral acceleration) travel along: the gap location correlates with them
    extras = {k: v for k, v in dict(getattr(case, "extras", {})).items() if np.shape(v) == np.shape(t)}
    return TestCase(case.name, getattr(case, "group", "default"), t, U2, Y2, model.input_names, model.output_names,
                    extras)  # fmt: skip


def window_counts(data) -> np.ndarray:
    """Number of prediction windows of each prepared case."""
    return np.array([d.starts.size for d in data], dtype=np.int64)


@dataclass
class FitResult:
    """A fitted candidate: the model with its parameters, the effect parameters and their uncertainty.

    Attributes
    ----------
    candidate : Candidate
    model : Model
        The base (or transformed) model with the fitted parameters.
    base_params : dict
    effect_params : dict (effect, target) -> tuple
    effect_std : dict (effect, target) -> tuple
        Cluster-robust (sandwich) standard deviations, cases as clusters.
    train_cost : float
    success : bool
    message : str
    x : ndarray
        All fitted parameters; ``labels`` names them.
    cov : dict
        ``"case"``/``"group"`` -> (sandwich covariance of ``x``, number of clusters).
    at_bound : tuple
        Labels of the parameters that ended at a bound.
    spread : dict
        (effect, target) -> the estimates fitted on each group of cases alone.
    bounds : dict
        (effect, target) -> ``(lo, hi)`` tuples: the parameters' admissible
        range in this fit (:attr:`Effect.bounds`); intervals are clipped to it.
    """

    candidate: Candidate
    model: object  # base (or transformed) model with the fitted parameters
    base_params: dict
    effect_params: dict  # (effect, target) -> tuple
    effect_std: dict  # (effect, target) -> tuple: robust std, case clusters (group clusters if so chosen)
    train_cost: float
    success: bool
    message: str = ""
    x: np.ndarray | None = None
    labels: tuple = ()  # parameter labels of x: base names, then "effect.param(target)"
    cov: dict = field(default_factory=dict)  # clustering -> (covariance of x, number of clusters)
    at_bound: tuple = ()  # labels of parameters ending at a bound
    spread: dict = field(default_factory=dict)  # (effect, target) -> per-group estimates (list of tuples)
    bounds: dict = field(default_factory=dict)  # (effect, target) -> (lo tuple, hi tuple) of the fit

    def std(self, key, method: str = "case") -> tuple:
        """Standard deviations of the effect parameters of ``key``: robust (``"case"``, ``"group"``) or of the
        per-group estimates (``"spread"``, times ``sqrt(1 + 1/G)``: the spread of a new maneuver's estimate)."""
        th = self.effect_params[key]
        if method == "spread":
            est = np.asarray(self.spread.get(key, []), dtype=float)
            if est.ndim != 2 or est.shape[0] < 2:
                return tuple(float("nan") for _ in th)
            G = est.shape[0]
            return tuple(float(v) for v in np.std(est, axis=0, ddof=1) * np.sqrt(1 + 1 / G))
        cov, _ = self.cov.get(method, (None, 0))
        if cov is None:
            return tuple(float("nan") for _ in th)
        e_name, tgt = key
        return tuple(float(np.sqrt(max(cov[i, i], 0.0))) for i, lab in enumerate(self.labels)
                     if lab.startswith(f"{e_name}.") and lab.endswith(f"({tgt})"))  # fmt: skip

    def interval(self, key, level: float = 0.95, method: str = "spread") -> list:
        """``[(lo, hi), ...]`` intervals of the effect parameters of ``key = (effect, target)``.

        Estimate +- Student t quantile (number of clusters or groups - 1 degrees of freedom) x :meth:`std`,
        clipped to the parameter's admissible range (:attr:`bounds`): a dead time is never negative.
        """
        from scipy.stats import t as student_t

        th = self.effect_params[key]
        n = len(self.spread.get(key, [])) if method == "spread" else self.cov.get(method, (None, 0))[1]
        if n < 2:
            return [(float("nan"), float("nan")) for _ in th]
        q = float(student_t.ppf(0.5 + level / 2, n - 1))
        lo, hi = self.bounds.get(key, ((-np.inf,) * len(th), (np.inf,) * len(th)))
        return [(float(max(v - q * sd, a)), float(min(v + q * sd, b)))
                for v, sd, a, b in zip(th, self.std(key, method), lo, hi)]  # fmt: skip


def _robust_cov(J, r, n_data, blocks_by):
    """Sandwich covariances ``B^-1 M B^-1`` (``B = J^T J`` incl. prior rows, ``M`` from cluster scores).

    ``blocks_by``: clustering name -> array of cluster ids per data residual (contiguous clusters).
    A fit that ended where the residuals are huge (a candidate whose simulation diverges) overflows here:
    its covariances are then inf/NaN, without numpy's warnings.
    """
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
        B = J.T @ J
        Binv = np.linalg.pinv(B)
        Jd = J[:n_data] * r[:n_data, None]
        out = {}
        for name, ids in blocks_by.items():
            _, first = np.unique(ids, return_index=True)
            first = np.sort(first)
            C = first.size
            if C < 2:
                continue
            S = np.add.reduceat(Jd, first, axis=0)  # scores per cluster
            M = S.T @ S * C / (C - 1)
            out[name] = (Binv @ M @ Binv, int(C))
        return out


def fit_candidate(base, cand: Candidate, train, sigma, fit_names, options: DiagnoseOptions, cache: dict,
                  start: dict | None = None, max_nfev: int = 60, target=None) -> FitResult:  # fmt: skip
    """Least-squares fit of the candidate's parameters jointly with the base parameters ``fit_names``.

    ``start`` (optional) holds starting values: base parameter names and
    ``(effect, target)`` keys.  The prior keeps the base parameters near the
    values of ``base``.  The covariance of the result is the cluster-robust
    sandwich (clusters: cases and groups of ``train``), which holds also when
    the windows' errors are correlated and the model is misspecified.
    ``target`` (optional, laid out as :func:`window_residuals` of ``train``):
    fit the residuals to it instead of to zero — with a reference run, the
    reference fit's residuals on the paired cases, so that the fit explains
    the change between the recordings (``reference_loss="difference"``).
    A lag's state at the start of each case is a nuisance, chosen per case
    in every evaluation on the samples before the case's first window
    (:func:`case_starts`).
    """
    from scipy.optimize import least_squares

    start = start or {}
    model, new_names = _model_for(base, cand, cache)
    model.compiled()  # compile (or load) once: the with_params copies below share it instead of re-hashing sympy
    nominal = np.array([base.params[n] for n in fit_names], dtype=float)
    scale = np.where(nominal != 0, np.abs(nominal), 1.0)
    lo_b = nominal - options.param_bounds * scale
    hi_b = nominal + options.param_bounds * scale
    # effect parameters: signal effects in order of parts, then model-effect parameters
    slots, x0, lo, hi = [], [start.get(n, v) for n, v in zip(fit_names, nominal)], list(lo_b), list(hi_b)
    labels = list(fit_names)
    for e, tgt in cand.parts:
        sig = _target_signal(base, e, tgt, train)
        first = None
        if e.kind in ("input", "output") and train and not e.registered:  # the library's effects are known finite
            j = (base.input_names if e.kind == "input" else base.output_names).index(tgt)
            first = (train[0].t, (train[0].U if e.kind == "input" else train[0].Y)[:, j])
        g, blo, bhi = e.start_values(tgt, sig, *(first or (None, None)))
        g = start.get((e.name, tgt), g)
        slots.append((e, tgt, len(x0), len(e.params)))
        x0 += list(g)
        lo += list(blo)
        hi += list(bhi)
        labels += [f"{e.name}.{p}({tgt})" for p in e.params]
    lo, hi = np.array(lo, float), np.array(hi, float)
    x0 = np.clip(np.array(x0, float), lo + 1e-9 * (hi - lo), hi - 1e-9 * (hi - lo))
    nb = len(fit_names)

    def unpack(x):
        params = dict(zip(fit_names, x[:nb]))
        eff = {}
        for e, tgt, i, k in slots:
            th = tuple(x[i : i + k])
            eff[(e.name, tgt)] = th
            if e.kind in ("param", "state"):
                params.update({effect_param_name(e.name, p, tgt): v for p, v in zip(e.params, th)})
        return model.with_params(**params), eff

    n_data = [None]
    def fun(x):
        m, eff = unpack(x)
        r = window_residuals(m, cand, eff, train, sigma, options.substeps)
        if target is not None:
            r = r - target
        n_data[0] = r.size
        prior = (x[:nb] - nominal) / (options.prior * scale) * np.sqrt(r.size)
        return np.concatenate([r, prior])

    for e, tgt, i, _ in slots:  # effects whose loss has several minima: start from the best of their grid
        if e.start_grid and (e.name, tgt) not in start:
            tries = [v for v in e.start_grid if lo[i] < v < hi[i]]
            if tries:
                costs = []
                for v in [x0[i], *tries]:
                    x = x0.copy()
                    x[i] = v
                    r = fun(x)
                    costs.append(float(r @ r) if np.all(np.isfinite(r)) else np.inf)
                x0[i] = [x0[i], *tries][int(np.argmin(costs))]
    span = hi - lo
    try:
        # a candidate whose simulation diverges at some trial point gives huge residuals there: the solver's
        # products overflow and it steps back; numpy's warnings about that are not the user's business
        with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
            sol = least_squares(fun, x0, bounds=(lo, hi), x_scale=np.where(np.isfinite(span), span / 10, 1.0),
                                xtol=1e-5, ftol=1e-6, max_nfev=max_nfev)  # fmt: skip
    except (ValueError, FloatingPointError, ZeroDivisionError) as exc:  # pragma: no cover - numerical failure
        m, eff = unpack(x0)
        return FitResult(cand, m, dict(zip(fit_names, x0[:nb])), eff, {}, np.inf, False, str(exc), x0, tuple(labels))
    m, eff = unpack(sol.x)
    N = n_data[0]
    r = sol.fun[:N]
    # clusters of the residuals: cases and groups (the windows of a case share its maneuver's misfit)
    per_case = np.array([d.starts.size * d.per_window * len(sigma) for d in train])
    case_ids = np.repeat(np.arange(len(train)), per_case)
    group_index = {g: i for i, g in enumerate(dict.fromkeys(d.group for d in train))}
    order = np.argsort([group_index[d.group] for d in train], kind="stable")
    cov = {}
    try:
        cov = _robust_cov(sol.jac, sol.fun, N, {"case": case_ids})
        if len(group_index) >= 2:
            # groups must be contiguous for the cluster sums: permute the residual rows case-wise
            rows = np.concatenate([np.arange(per_case[:i].sum(), per_case[: i + 1].sum()) for i in order])
            gids = np.repeat([group_index[train[i].group] for i in order], per_case[order])
            Jp = np.vstack([sol.jac[rows], sol.jac[N:]])
            fp = np.concatenate([sol.fun[rows], sol.fun[N:]])
            cov.update(_robust_cov(Jp, fp, N, {"group": gids}))
    except np.linalg.LinAlgError:  # pragma: no cover
        pass
    std = {}
    chosen = cov.get(options.interval_method, cov.get("case"))
    if chosen is not None:
        sd = np.sqrt(np.clip(np.diag(chosen[0]), 0, None))
        for e, tgt, i, k in slots:
            std[(e.name, tgt)] = tuple(float(v) for v in sd[i : i + k])
    tol = 1e-6 * np.where(np.isfinite(span), span, 1.0)
    at_bound = tuple(lab for lab, v, a, b, eps in zip(labels, sol.x, lo, hi, tol) if v - a <= eps or b - v <= eps)
    bounds = {(e.name, tgt): (tuple(map(float, lo[i : i + k])), tuple(map(float, hi[i : i + k])))
              for e, tgt, i, k in slots}  # fmt: skip
    return FitResult(cand, m, dict(zip(fit_names, sol.x[:nb])), eff, std, float(np.mean(r**2)), bool(sol.success),
                     sol.message, np.array(sol.x), tuple(labels), cov, at_bound, bounds=bounds)  # fmt: skip


def _target_signal(model, e, tgt, data):
    if e.kind == "input":
        j = model.input_names.index(tgt)
        return np.concatenate([d.U[:, j] for d in data])
    if e.kind == "output":
        i = model.output_names.index(tgt)
        return np.concatenate([d.Y[:, i] for d in data])
    return None


def window_losses(fit: FitResult, data, sigma, options: DiagnoseOptions) -> np.ndarray:
    """Sum of squared normalised residuals of every prediction window of ``data`` (cases in order)."""
    r = window_residuals(fit.model, fit.candidate, fit.effect_params, data, sigma, options.substeps)
    return window_sums(r**2, data, len(sigma))


def window_sums(values, data, p: int) -> np.ndarray:
    """Sums of per-residual ``values`` (laid out as :func:`window_residuals`) over every window of ``data``."""
    sizes = np.concatenate([np.full(d.starts.size, d.per_window * p) for d in data])
    if sizes.size and np.all(sizes == sizes[0]):
        return np.sum(values.reshape(-1, int(sizes[0])), axis=1)
    return np.add.reduceat(values, np.concatenate([[0], np.cumsum(sizes)[:-1]]))


def prediction_cost(fit: FitResult, data, sigma, options: DiagnoseOptions) -> float:
    """Mean squared normalised multi-step prediction residual on ``data`` (held-out cases)."""
    r = window_residuals(fit.model, fit.candidate, fit.effect_params, data, sigma, options.substeps)
    return float(np.mean(r**2))
