"""Scales of the prediction loss (:attr:`~reachconf.diagnose.options.DiagnoseOptions.loss_scale`).

Every fit minimises, and every held-out comparison sums, squared multi-step
prediction residuals divided by a scale.  "sensor" divides by the sensor
noise only; the two functions here give the second step of a feasible
weighted least squares from the refitted base model's misfit: per output
channel (:func:`residual_scale`) or per case (:func:`case_weights`).
"""

from __future__ import annotations

import numpy as np

from reachconf.diagnose.fit import FitResult, window_counts, window_residuals
from reachconf.diagnose.options import DiagnoseOptions

__all__ = ["case_layout", "case_weights", "residual_scale", "reweigh_factors"]


def case_weights(fit: FitResult, data, sigma, options: DiagnoseOptions) -> np.ndarray:
    """Per-case weights of the prediction loss from a fitted model's misfit (``loss_scale = "case"``).

    ``1 / max(1, s_c)`` with ``s_c`` the root-mean-square normalised
    multi-step prediction residual of ``fit`` on case ``c`` (all channels,
    in units of ``sigma``).  Used as weights of the residuals, they are the
    second step of a feasible weighted least squares whose error variance
    differs from run to run: a run the base model cannot follow at all (e.g.
    a maneuver that takes the plant far into tyre saturation) counts like
    any other run instead of dominating every fit and every held-out
    comparison by its squared errors.  The weights are fixed before any
    effect is fitted, so an effect's fit stays consistent; runs that follow
    the base model to the noise level keep weight 1.

    Parameters
    ----------
    fit : FitResult
        The fitted (base) model.
    data : list of PreparedCase
        With weight 1.
    sigma : ndarray, shape (p,)
    options : DiagnoseOptions

    Returns
    -------
    ndarray, shape (len(data),)
    """
    r = window_residuals(fit.model, fit.candidate, fit.effect_params, data, sigma, options.substeps)
    sizes = np.array([d.starts.size * d.per_window * len(sigma) for d in data])
    ends = np.cumsum(sizes)
    rms = np.array([np.sqrt(np.mean(r[e - n : e] ** 2)) if n else 1.0 for n, e in zip(sizes, ends)])
    rms = np.where(np.isfinite(rms), rms, np.inf)
    return 1.0 / np.maximum(rms, 1.0)


def residual_scale(fit: FitResult, data, sigma, options: DiagnoseOptions) -> np.ndarray:
    """Per-channel scale of the prediction loss from a fitted model's misfit (``loss_scale = "residual"``).

    The root-mean-square multi-step prediction residual of ``fit`` on
    ``data`` per output channel, in the outputs' units, at least ``sigma``
    (the sensor noise).  Used as the standard deviations of the Gaussian
    likelihood, it is the variance estimate of a two-step (feasible)
    weighted least squares: a channel counts by its own misfit level.

    Parameters
    ----------
    fit : FitResult
        The fitted (base) model.
    data : list of PreparedCase
    sigma : ndarray, shape (p,)
        The sensor noise per output (the floor and the unit of the residuals).
    options : DiagnoseOptions

    Returns
    -------
    ndarray, shape (p,)
    """
    sigma = np.asarray(sigma, dtype=float)
    r = window_residuals(fit.model, fit.candidate, fit.effect_params, data, sigma, options.substeps)
    rms = np.sqrt(np.mean(r.reshape(-1, sigma.size) ** 2, axis=0)) * sigma
    return np.maximum(np.where(np.isfinite(rms), rms, sigma), sigma)


def case_layout(data, p: int) -> dict:
    """Where each prediction window belongs, for :func:`reweigh_factors`: ``case`` (the case of every window),
    ``weights`` (each case's weight) and ``elements`` (residual elements per window of each case)."""
    counts = window_counts(data)
    return {"case": np.repeat(np.arange(len(data)), counts), "weights": np.array([d.weight for d in data], float),
            "elements": np.array([d.per_window * p for d in data], dtype=float)}  # fmt: skip


def reweigh_factors(losses, layout: dict) -> np.ndarray:
    """Per-window factors that re-weigh held-out losses by a model's own misfit (``loss_scale = "case"``).

    The case weights of :func:`case_weights` come from the base model's
    misfit.  When a two-effect model is tested against one of its one-effect
    parts, the error variance of each run is that part's misfit: the same
    second step of a feasible weighted least squares, one model further
    (iterated).  A run that the first effect follows to the noise level
    counts with weight 1 again, a run it still cannot follow counts less.

    Parameters
    ----------
    losses : ndarray
        Held-out window losses of the one-effect model (weighted by the case weights), cases in order.
    layout : dict
        :func:`case_layout` of the cases.

    Returns
    -------
    ndarray, shape like ``losses``
        ``(w'_c / w_c) ** 2`` for every window of case ``c``, with ``w'_c = 1 / max(1, s_c)`` and ``s_c`` the
        root-mean-square normalised residual of the model on case ``c`` (its weight removed).
    """
    case, w, elements = layout["case"], layout["weights"], layout["elements"]
    n = w.size
    counts = np.bincount(case, minlength=n)
    sums = np.bincount(case, weights=np.asarray(losses, dtype=float), minlength=n)
    with np.errstate(divide="ignore", invalid="ignore"):
        ms = sums / (w**2 * np.maximum(counts, 1) * elements)
    ms = np.where(np.isfinite(ms), ms, np.inf)
    w_new = 1.0 / np.maximum(np.sqrt(ms), 1.0)
    return ((w_new / w) ** 2)[case]
