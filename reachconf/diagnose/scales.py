"""Scales of the prediction loss (:attr:`~reachconf.diagnose.options.DiagnoseOptions.loss_scale`).

Every fit minimises, and every held-out comparison sums, squared multi-step
prediction residuals divided by a scale.  "sensor" divides by the sensor
noise only; the two functions here give the second step of a feasible
weighted least squares from the refitted base model's misfit: per output
channel (:func:`residual_scale`) or per case (:func:`case_weights`).
"""

from __future__ import annotations

import numpy as np

from reachconf.diagnose.fit import FitResult, window_residuals
from reachconf.diagnose.options import DiagnoseOptions

__all__ = ["case_weights", "residual_scale"]


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
