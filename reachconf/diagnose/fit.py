"""Joint least-squares fits of base-model parameters and candidate effects by multi-step prediction.

One-step residuals cannot see a sensor offset or a short delay at 100 Hz (the
sensor noise dominates them), so every candidate is fitted and scored by
*multi-step prediction*: windows of ``window`` seconds started from the
measured (Savitzky–Golay smoothed) states every ``stride`` seconds are
simulated without disturbances (compiled RK4, :func:`reachconf_kernels.integrate.rk4_windows`,
all windows in one call) and compared with the measurements, each residual
divided by the output's noise level (estimated from third differences).  The
base model's parameters are fitted jointly with the effect's, kept near their
nominal values by a Gaussian prior (relative standard deviation ``prior``) and
hard bounds, so that they cannot soak up the effect.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from reachconf.checks import check_field_types
from reachconf.diagnose.effects import effect_param_name
from reachconf.errors import ConformanceError, OptionsError
from reachconf.io.cases import TestCase, case_arrays
from reachconf.model.outputs import evaluate_outputs, output_index_of_states, state_estimate, state_index_of_outputs
from reachconf_kernels.integrate import rk4_windows

__all__ = ["DiagnoseOptions", "noise_level", "PreparedCase", "prepare", "Candidate", "fit_candidate", "transformed_case"]


@dataclass(frozen=True)
class DiagnoseOptions:
    """Options of :func:`reachconf.diagnose`.

    Parameters
    ----------
    window : float, default 1.0
        Length of the multi-step prediction windows (s).
    stride : float, default 1.0
        Time between window starts (s).
    substeps : int, default 1
        RK4 steps per sample interval in the predictions.
    smooth : int, default 11
        Savitzky–Golay window (samples, quadratic) of the window start states.
    prior : float, default 0.1
        Relative standard deviation of the prior on the base parameters.
    param_bounds : float, default 0.5
        Base parameters stay within ``nominal (1 +- param_bounds)``.
    top : int, default 6
        Number of candidates (best by held-out prediction) scored by the minimal box.
    box_rate : float, default 20.0
        Sample rate (Hz) the held-out cases are decimated to for the minimal-box scores.
    box_segment : float, default 2.0
        The held-out cases are cut into segments of this length (s) for the
        minimal-box scores (the box is the hull of the segments' boxes).
    min_shrink : float, default 1.0
        Smallest volume shrink of the minimal box for naming an effect (1:
        any shrink; the held-out prediction gain ``min_improvement`` decides).
    min_improvement : float, default 0.3
        ... and smallest relative reduction of the held-out prediction cost.
    tie : float, default 0.1
        Candidates whose held-out prediction cost is within this fraction of
        the best are ranked by the shrink of the minimal box instead.
    combine : bool, default True
        Also try the best effect together with each runner-up (e.g. a scale and an offset).
    tube_horizon : float, default 2.0
        Horizon (s) of the before/after reach tubes of one held-out case (0: none).
    """

    window: float = 1.0
    stride: float = 1.0
    substeps: int = 1
    smooth: int = 11
    prior: float = 0.1
    param_bounds: float = 0.5
    top: int = 6
    box_rate: float = 20.0
    box_segment: float = 2.0
    min_shrink: float = 1.0
    min_improvement: float = 0.3
    tie: float = 0.1
    combine: bool = True
    tube_horizon: float = 2.0

    def __post_init__(self):
        check_field_types(self)
        for name in ("window", "stride", "prior", "param_bounds", "box_rate", "box_segment"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and np.isfinite(v) and v > 0):
                raise OptionsError(f"DiagnoseOptions.{name} must be a positive number, got {v!r}")
        for name in ("substeps", "smooth", "top"):
            v = getattr(self, name)
            if not (isinstance(v, (int, np.integer)) and v >= 1):
                raise OptionsError(f"DiagnoseOptions.{name} must be a positive integer, got {v!r}")
        if self.smooth < 3 or self.smooth % 2 == 0:
            raise OptionsError(f"DiagnoseOptions.smooth must be an odd number >= 3, got {self.smooth}")
        if not (isinstance(self.tie, (int, float)) and 0 <= self.tie < 1):
            raise OptionsError(f"DiagnoseOptions.tie must be in [0, 1), got {self.tie!r}")
        if not self.min_shrink >= 1.0 or not 0 <= self.min_improvement < 1:
            raise OptionsError("DiagnoseOptions.min_shrink must be >= 1 and min_improvement in [0, 1)")


def noise_level(Y: np.ndarray) -> np.ndarray:
    """Noise standard deviation per column: robust (MAD) spread of third differences / sqrt(20)."""
    d3 = np.diff(Y, n=3, axis=0)
    mad = np.median(np.abs(d3 - np.median(d3, axis=0)), axis=0)
    sigma = 1.4826 * mad / np.sqrt(20.0)
    floor = 1e-6 * np.maximum(np.ptp(Y, axis=0), 1e-12)
    return np.maximum(sigma, floor)


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


def prepare(model, case, options: DiagnoseOptions) -> PreparedCase:
    """A :class:`PreparedCase`: the case's arrays, smoothed outputs and prediction windows."""
    from scipy.signal import savgol_filter

    t, U, Y = case_arrays(model, case)
    dt = float(np.median(np.diff(t)))
    length = max(int(round(options.window / dt)), 2)
    stride = max(int(round(options.stride / dt)), 1)
    if t.size < length + 2:
        raise ConformanceError(f"test case {case.name!r} is shorter than one prediction window ({options.window} s)")
    win = min(options.smooth, t.size - (1 - t.size % 2))
    Ys = savgol_filter(Y, win, 2, axis=0) if win >= 3 else Y.copy()
    starts = np.arange(0, t.size - length - 1, stride, dtype=np.int64)
    return PreparedCase(case.name, getattr(case, "group", "default"), t, U, Y, Ys, starts, length, case)


@dataclass
class Candidate:
    """One or more (effect, target) pairs fitted jointly with the base parameters."""

    parts: tuple  # ((Effect, target), ...)

    @property
    def label(self) -> str:
        """``effect(target) + ...``, or ``base`` for no effect."""
        return " + ".join(f"{e.name}({t})" for e, t in self.parts) if self.parts else "base"


def _model_for(base, cand: Candidate, cache: dict):
    """The base model with the candidate's model-kind effects applied (compiled once, cached)."""
    model = base
    key = tuple((e.name, t) for e, t in cand.parts if e.kind in ("param", "state"))
    if not key:
        return base, ()
    if key not in cache:
        names = []
        for e, t in cand.parts:
            if e.kind in ("param", "state"):
                model = e.apply_model(model, t)
                names += [n for n in model.param_names if n not in base.param_names and n not in names]
        cache[key] = (model, tuple(names))
    return cache[key]


def transformed_signals(model, cand: Candidate, theta_eff: dict, t, U, Y):
    """Inputs the system really received and outputs the model should produce (input/output effects applied)."""
    U = U.copy()
    Y = Y.copy()
    for e, tgt in sorted(cand.parts, key=lambda p: p[0].order):
        th = theta_eff[(e.name, tgt)]
        if e.kind == "input":
            j = model.input_names.index(tgt)
            U[:, j] = e.apply_signal(t, U[:, j], th)
        elif e.kind == "output":
            i = model.output_names.index(tgt)
            Y[:, i] = e.inverse(Y[:, i], th)
    return U, Y


def transformed_case(model, case, cand: Candidate, theta_eff: dict):
    """A copy of ``case`` as seen by the model with the candidate's input/output effects."""
    t, U, Y = case_arrays(model, case)
    U2, Y2 = transformed_signals(model, cand, theta_eff, t, U, Y)
    return TestCase(case.name, getattr(case, "group", "default"), t, U2, Y2, model.input_names, model.output_names)


def _states(model, Ys, U, direct):
    if direct is not None:
        return np.ascontiguousarray(Ys[:, direct])
    t = np.arange(Ys.shape[0], dtype=float)
    return state_estimate(model, TestCase("windows", "default", t, U, Ys, model.input_names, model.output_names))


def window_residuals(model, cand: Candidate, theta_eff: dict, data, sigma, substeps):
    """Normalised multi-step prediction residuals of all windows of all cases (one flat array)."""
    comp = model.compiled()
    pv = model.param_vector
    direct = output_index_of_states(model)
    plain = state_index_of_outputs(model)
    out = []
    for d in data:
        U, Ym = transformed_signals(model, cand, theta_eff, d.t, d.U, d.Y)
        _, Ysm = transformed_signals(model, cand, theta_eff, d.t, d.U, d.Ys)
        X0 = _states(model, Ysm[d.starts], U[d.starts], direct)
        P = rk4_windows(comp.f, np.ascontiguousarray(X0), d.starts, U, d.t, pv, model.q, d.length, int(substeps))
        idx = (d.starts[:, None] + 1 + np.arange(d.length)[None, :]).reshape(-1)
        Xp = P.reshape(-1, model.n)
        Yp = Xp[:, plain] if plain is not None else evaluate_outputs(model, Xp, U[idx])
        if not np.all(np.isfinite(Yp)):
            Yp = np.where(np.isfinite(Yp), Yp, 1e6)
        out.append(((Yp - Ym[idx]) / sigma).reshape(-1))
    return np.concatenate(out)


@dataclass
class FitResult:
    """A fitted candidate: the model with its parameters, the effect's parameters and their spread.

    Attributes
    ----------
    candidate : Candidate
    model : Model
        The base (or transformed) model with the fitted parameters.
    base_params : dict
    effect_params : dict (effect, target) -> tuple
    effect_std : dict (effect, target) -> tuple
    train_cost : float
    success : bool
    message : str
    """

    candidate: Candidate
    model: object  # base (or transformed) model with the fitted parameters
    base_params: dict
    effect_params: dict  # (effect, target) -> tuple
    effect_std: dict
    train_cost: float
    success: bool
    message: str = ""


def fit_candidate(base, cand: Candidate, train, sigma, fit_names, options: DiagnoseOptions, cache: dict) -> FitResult:
    """Least-squares fit of the candidate's parameters jointly with the base parameters ``fit_names``."""
    from scipy.optimize import least_squares

    model, new_names = _model_for(base, cand, cache)
    nominal = np.array([base.params[n] for n in fit_names], dtype=float)
    scale = np.where(nominal != 0, np.abs(nominal), 1.0)
    lo_b = nominal - options.param_bounds * scale
    hi_b = nominal + options.param_bounds * scale
    # effect parameters: signal effects in order of parts, then model-effect parameters
    slots, x0, lo, hi = [], list(nominal), list(lo_b), list(hi_b)
    for e, tgt in cand.parts:
        sig = _target_signal(base, e, tgt, train)
        g = e.guess(sig)
        blo, bhi = e.bounds(sig)
        slots.append((e, tgt, len(x0), len(e.params)))
        x0 += list(g)
        lo += list(blo)
        hi += list(bhi)
    x0 = np.clip(np.array(x0, float), np.array(lo) + 1e-12, np.array(hi) - 1e-12)
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
        n_data[0] = r.size
        prior = (x[:nb] - nominal) / (options.prior * scale) * np.sqrt(r.size)
        return np.concatenate([r, prior])

    span = np.array(hi) - np.array(lo)
    try:
        sol = least_squares(fun, x0, bounds=(lo, hi), x_scale=np.where(np.isfinite(span), span / 10, 1.0),
                            xtol=1e-6, ftol=1e-6, max_nfev=60)  # fmt: skip
    except (ValueError, FloatingPointError, ZeroDivisionError) as exc:  # pragma: no cover - numerical failure
        m, eff = unpack(x0)
        return FitResult(cand, m, dict(zip(fit_names, x0[:nb])), eff, {}, np.inf, False, str(exc))
    m, eff = unpack(sol.x)
    N = n_data[0]
    r = sol.fun[:N]
    # parameter uncertainty from the curvature; the residuals of one window are strongly correlated
    # (about one independent error per window), so the variance is inflated by the window length
    std = {}
    try:
        J = sol.jac
        cov = np.linalg.pinv(J.T @ J) * float(np.mean(r**2)) * max(d.length for d in train)
        sd = np.sqrt(np.clip(np.diag(cov), 0, None))
        for e, tgt, i, k in slots:
            std[(e.name, tgt)] = tuple(sd[i : i + k])
    except np.linalg.LinAlgError:  # pragma: no cover
        pass
    return FitResult(cand, m, dict(zip(fit_names, sol.x[:nb])), eff, std, float(np.mean(r**2)), bool(sol.success),
                     sol.message)  # fmt: skip


def _target_signal(model, e, tgt, data):
    if e.kind == "input":
        j = model.input_names.index(tgt)
        return np.concatenate([d.U[:, j] for d in data])
    if e.kind == "output":
        i = model.output_names.index(tgt)
        return np.concatenate([d.Y[:, i] for d in data])
    return None


def prediction_cost(fit: FitResult, data, sigma, options: DiagnoseOptions) -> float:
    """Mean squared normalised multi-step prediction residual on ``data`` (held-out cases)."""
    r = window_residuals(fit.model, fit.candidate, fit.effect_params, data, sigma, options.substeps)
    return float(np.mean(r**2))
