"""Identification of a model's parameters from a test suite (least squares), the one place for it.

Two methods:

* ``"prediction"`` — multi-step prediction (the fits of the gap diagnosis,
  :func:`reachconf.diagnose.fit.fit_candidate` without an effect): windows
  simulated from measured states, residuals in units of the sensor noise,
  parameters kept near nominal by a Gaussian prior;
* ``"equation_error"`` — the model's derivatives at the measured
  (Savitzky–Golay smoothed) states and inputs against the smoothed
  derivatives of the measurements, for the chosen state equations, with a
  weak prior on the logarithms of the nominal values that fixes directions
  the data cannot see (e.g. a scaling of yaw inertia and tyre stiffnesses
  together).  Needs every state measured directly and positive parameters.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import sympy as sp

from reachconf.diagnose.fit import Candidate, fit_candidate, noise_level, prepare
from reachconf.diagnose.options import DiagnoseOptions
from reachconf.errors import ConformanceError, OptionsError
from reachconf.io.results import JsonResult
from reachconf.model.outputs import output_index_of_states

__all__ = ["identify", "Identification"]


@dataclass
class Identification(JsonResult):
    """Result of :func:`identify`.

    Attributes
    ----------
    params : dict name -> float
        The identified parameters.
    start : dict name -> float
        Their nominal values (the start of the fit).
    std : dict name -> float
        Standard deviations from the curvature (NaN where not estimated).
    rms_residual : float
    samples : int
        Number of residuals from data (without the prior).
    method : str
    """

    params: dict
    start: dict
    std: dict = field(default_factory=dict)
    rms_residual: float = float("nan")
    samples: int = 0
    method: str = "prediction"

    def to_dict(self) -> dict:
        """All fields as JSON values."""
        return {"params": self.params, "start": self.start, "std": self.std, "rms_residual": self.rms_residual,
                "samples": self.samples, "method": self.method}  # fmt: skip

    @classmethod
    def from_dict(cls, d: dict) -> "Identification":
        """The result from :meth:`to_dict`."""
        return cls(dict(d["params"]), dict(d["start"]), dict(d.get("std", {})), float(d.get("rms_residual", "nan")),
                   int(d.get("samples", 0)), d.get("method", "prediction"))  # fmt: skip

    def plot(self, ax=None):
        """Each parameter relative to its nominal value, with one standard deviation; returns the axes."""
        import matplotlib.pyplot as plt

        names = list(self.params)
        rel = [self.params[n] / self.start[n] if self.start[n] else np.nan for n in names]
        err = [self.std.get(n, np.nan) / abs(self.start[n]) if self.start[n] else np.nan for n in names]
        if ax is None:
            _, ax = plt.subplots(figsize=(1.0 * len(names) + 3, 3))
        ax.errorbar(range(len(names)), rel, yerr=np.nan_to_num(err), fmt="o", capsize=3)
        ax.axhline(1.0, color="k", lw=0.8)
        ax.set_xticks(range(len(names)), names)
        ax.set_ylabel("identified / nominal")
        ax.set_title(f"identification ({self.method})", fontsize=9)
        return ax


def identify(model, suite, params, method: str = "prediction", *, options: DiagnoseOptions | None = None,
             equations=None, window: float = 0.25, prior: float = 0.01, bounds=None) -> Identification:  # fmt: skip
    """Least-squares identification of ``params`` of ``model`` on the cases of ``suite``.

    Parameters
    ----------
    model : Model
    suite : TestSuite or iterable of TestCase
    params : sequence of str
        Parameters to identify; the others stay at their values.
    method : {"prediction", "equation_error"}
        See the module docstring.
    options : DiagnoseOptions, optional
        ``"prediction"``: window, stride, smoothing, the prior's relative
        standard deviation ``prior`` and the bounds ``param_bounds``.
    equations : sequence of str, optional
        ``"equation_error"``: the states whose equations are fitted (default all).
    window : float, default 0.25
        ``"equation_error"``: Savitzky–Golay window (s, cubic) of the smoothing and the derivatives.
    prior : float, default 0.01
        ``"equation_error"``: weight of the prior on ``log(p / p_nominal)``
        relative to the data (times the square root of the number of samples).
    bounds : dict name -> (lo, hi), optional
        ``"equation_error"``: bounds (default ``p / 100 .. 100 p``).

    Returns
    -------
    Identification

    Raises
    ------
    OptionsError
        On unknown parameters, states or methods.
    ConformanceError
        If the method cannot be applied to the model or data.
    """
    cases = list(suite)
    params = tuple(params)
    unknown = sorted(set(params) - set(model.param_names))
    if unknown:
        raise OptionsError(f"identify: model {model.name!r} has no parameters {unknown}")
    if not cases:
        raise ConformanceError("identify: the suite has no test cases")
    if method == "prediction":
        opts = options or DiagnoseOptions()
        data = [prepare(model, c, opts) for c in cases]
        sigma = noise_level(np.vstack([d.Y for d in data]))
        fit = fit_candidate(model, Candidate(()), data, sigma, params, opts, {})
        return Identification({k: float(v) for k, v in fit.base_params.items()},
                              {k: float(model.params[k]) for k in params}, {k: float("nan") for k in params},
                              float(np.sqrt(fit.train_cost)), sum(d.length * d.starts.size for d in data) * model.p,
                              "prediction")  # fmt: skip
    if method == "equation_error":
        return _equation_error(model, cases, params, equations, window, prior, bounds)
    raise OptionsError(f"identify: method must be 'prediction' or 'equation_error', got {method!r}")


def _stacked(model, cases, direct, window):
    """Smoothed states, inputs and state derivatives of all cases, the filter's edge samples dropped."""
    from scipy.signal import savgol_filter

    rows = []
    for c in cases:
        c = c.select(model.input_names, model.output_names)
        dt = float(np.median(np.diff(c.t)))
        win = max(5, int(round(window / dt)) | 1)
        Ys = savgol_filter(c.Y, win, 3, axis=0)
        dY = savgol_filter(c.Y, win, 3, deriv=1, delta=dt, axis=0)
        U = savgol_filter(c.U, win, 3, axis=0) if model.m else np.zeros((c.t.size, 0))
        keep = slice(win, -win)
        rows.append((Ys[keep][:, direct], U[keep], dY[keep][:, direct]))
    return tuple(np.vstack([r[i] for r in rows]) for i in range(3))


def _equation_error(model, cases, params, equations, window, prior, bounds):
    from scipy.optimize import least_squares

    direct = output_index_of_states(model)
    if direct is None:
        raise ConformanceError(f"identify(method='equation_error'): model {model.name!r} needs every state as an output")
    equations = tuple(model.state_names if equations is None else equations)
    bad = sorted(set(equations) - set(model.state_names))
    if bad:
        raise OptionsError(f"identify: model {model.name!r} has no states {bad}")
    eq = [model.state_names.index(s) for s in equations]
    X, U, dX = _stacked(model, cases, direct, window)
    rhs = sp.lambdify(list(model.z_symbols) + list(model.p_symbols), [model.f_expr[i] for i in eq], "numpy")
    fixed = dict(model.params)
    W0 = np.zeros((X.shape[0], model.q))
    scale = [np.std(dX[:, i]) or 1.0 for i in eq]
    theta0 = np.array([fixed[n] for n in params])
    if np.any(theta0 <= 0):
        raise OptionsError("identify(method='equation_error'): the prior needs positive nominal parameters")
    bounds = dict(bounds or {})
    lo = [bounds.get(n, (v / 100, v * 100))[0] for n, v in zip(params, theta0)]
    hi = [bounds.get(n, (v / 100, v * 100))[1] for n, v in zip(params, theta0)]
    prior_weight = prior * np.sqrt(X.shape[0])

    def resid(theta):
        p = dict(fixed, **dict(zip(params, theta)))
        values = rhs(*X.T, *U.T, *W0.T, *[p[n] for n in model.param_names])
        res = [(np.broadcast_to(v, dX[:, i].shape) - dX[:, i]) / s for v, i, s in zip(values, eq, scale)]
        return np.concatenate(res + [prior_weight * (np.log(theta) - np.log(theta0))])

    sol = least_squares(resid, theta0, bounds=(lo, hi), x_scale="jac")
    J = sol.jac
    dof = max(1, sol.fun.size - theta0.size)
    sigma2 = float(sol.fun @ sol.fun) / dof
    try:
        std = np.sqrt(np.diag(np.linalg.inv(J.T @ J) * sigma2))
    except np.linalg.LinAlgError:
        std = np.full(theta0.size, np.nan)
    return Identification({n: float(v) for n, v in zip(params, sol.x)}, {n: float(v) for n, v in zip(params, theta0)},
                          {n: float(s) for n, s in zip(params, std)}, float(np.sqrt(sigma2)), int(X.shape[0] * len(eq)),
                          "equation_error")  # fmt: skip
