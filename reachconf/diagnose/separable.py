"""Can the data at hand separate two explanations?  The mimic loss of one fitted candidate by another.

Two candidate effects may act almost alike over the operating range a suite
covers: a drag ``c_d v |v|`` and an acceleration offset ``c`` are the same
term when the speed barely changes (``v |v|`` is nearly a constant over the
data); an acceleration scale and an offset are the same when the
acceleration barely changes sign.  A held-out test may still prefer one of
them "significantly" — because the two absorb a misfit of the base structure
differently, not because of their mechanisms.

:func:`mimic_loss` measures what the data could show if the chosen model
``A`` were exactly right: the other candidate ``B`` is refitted (its effect
and the base parameters, as in its own fit) to ``A``'s noise-free
predictions on the suite's own prediction windows (the same inputs and start
states); its remaining loss ``D`` (squared differences in units of the
sensor noise, summed over all windows, the units of the held-out losses) is
the part of ``A``'s effect that ``B`` cannot reproduce on these maneuvers —
a collinearity statistic of the two effects computed from the data actually
present (for effects linear in their parameters it is ``1 - R^2`` of one
regressor on the other, times the effect's size in noise units).  The
decision (:func:`reachconf.diagnose.select.decide`) compares ``D`` with the
standard error of the observed held-out loss difference.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from reachconf.diagnose.fit import fit_candidate, window_losses
from reachconf.diagnose.residuals import residuals_and_prefix

__all__ = ["mimic_loss", "pseudo_measurements"]


def pseudo_measurements(fit, data, sigma, options) -> list:
    """Copies of the prepared cases ``data`` whose compared measurements are ``fit``'s noise-free predictions.

    The copies keep the inputs, times and (measured) start states of every
    window; their ``Y`` holds only the compared samples (``idx`` becomes
    ``0 .. n-1``), set to the predicted measurement (output effects applied);
    the samples before the first window, which choose a lag's start, are
    ``fit``'s predictions from ``t_0`` (``prefix_Y``).
    """
    r, before = residuals_and_prefix(fit.model, fit.candidate, fit.effect_params, data, sigma, options.substeps)
    out, pos = [], 0
    for d, pre in zip(data, before):
        n = d.idx.size * len(sigma)
        Ym = np.asarray(d.Y, dtype=float)[d.idx]
        pred = Ym + r[pos : pos + n].reshape(Ym.shape) * sigma / d.weight  # (residuals in measurement units)
        out.append(replace(d, Y=pred, idx=np.arange(d.idx.size, dtype=np.int64), prefix_Y=pre))
        pos += n
    return out


def mimic_loss(base_model, fit_a, cand_b, data, sigma, fit_names, options, cache, start=None) -> dict:
    """How well candidate ``cand_b`` reproduces the fitted candidate ``fit_a`` on the windows of ``data``.

    Parameters
    ----------
    base_model : Model
        The base model the diagnosis started from (the prior's centre).
    fit_a : FitResult
        The chosen candidate fitted on all cases.
    cand_b : Candidate
        The other explanation.
    data : list of PreparedCase
    sigma : ndarray
        Noise level of every output.
    fit_names : tuple of str
        Base parameters refitted with ``cand_b`` (as in its own fit).
    options : DiagnoseOptions
    cache : dict
        Compiled-model cache of the diagnosis.
    start : dict, optional
        Starting values (e.g. ``cand_b``'s own fit).

    Returns
    -------
    dict
        ``mimic_loss`` (``D``: summed squared differences between ``B``'s best
        reproduction and ``A``'s predictions, noise units), ``effect_loss``
        (the same for the base model with ``A``'s base parameters and no
        effect: the size of ``A``'s effect) and ``params`` (``B``'s effect
        parameters of the reproduction).
    """
    pseudo = pseudo_measurements(fit_a, data, sigma, options)
    fb = fit_candidate(base_model, cand_b, pseudo, sigma, fit_names, options, cache, start=start)
    D = float(np.sum(window_losses(fb, pseudo, sigma, options)))
    bare = replace(fit_a, candidate=replace(fit_a.candidate, parts=()), effect_params={})
    bare_model = base_model.with_params(**{n: float(v) for n, v in fit_a.base_params.items()})
    size = float(np.sum(window_losses(replace(bare, model=bare_model), pseudo, sigma, options)))
    return {"mimic_loss": D, "effect_loss": size,
            "params": {f"{k[0]}({k[1]})": [float(v) for v in th] for k, th in fb.effect_params.items()}}  # fmt: skip
