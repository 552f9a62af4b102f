"""Is an effect the same in every maneuver?  The consistency route of the naming rule.

The relevance part of the naming rule (:func:`reachconf.diagnose.select.decide`)
asks an effect to remove a large share (``min_improvement``) of the held-out
loss of the model it is added to.  That share is relative to a loss which
also holds the base model's own structural misfit, and that misfit can be
large: on a multi-body plant, or a real car, a small but real sensor bias or
a second effect next to a large first one removes a tenth of the loss, no
more than what a small lag removes by absorbing part of the misfit.

What tells the two apart is the maneuver.  A real offset, scale or delay has
one value; an effect that absorbs structural misfit takes the value that best
imitates it, and that changes with the maneuver.  So each effect of a model is
fitted on every maneuver group alone (its effect parameters only; the base
parameters held at the model's cross-fitted values), and its *size* — the
first parameter's distance from the effect's null value
(:attr:`reachconf.diagnose.effects.Effect.null`) — is compared across groups:
the relative spread ``std(size) / |mean(size)|``.  An effect is then relevant
when its significant gain is at least ``consistent_gain`` and the relative
spread of every effect of the model is at most ``max_spread``
(:class:`~reachconf.diagnose.options.DiagnoseOptions`).  Both thresholds are
chosen on the tuning suites of the validation protocol.
"""

from __future__ import annotations

import numpy as np

from reachconf.diagnose.fit import fit_candidate
from reachconf.diagnose.select import MIN_PARTS, fold_start, maneuver_parts

__all__ = ["relative_spread", "group_sizes", "model_spread"]


def relative_spread(estimates, null: float) -> float:
    """``std(x - null) / |mean(x - null)|`` of per-group estimates ``x`` (sample std); inf when undefined."""
    d = np.asarray(estimates, dtype=float) - float(null)
    if d.size < MIN_PARTS or not np.all(np.isfinite(d)):
        return np.inf
    m = abs(float(np.mean(d)))
    return float(np.std(d, ddof=1) / m) if m > 0 else np.inf


def group_sizes(base_model, scored, data, sigma, options, cache) -> dict:
    """First-parameter estimates of every effect of ``scored``'s model, fitted on each group alone.

    Parameters
    ----------
    base_model : reachconf.Model
    scored : reachconf.diagnose.select.Scored
        The cross-fitted model; its fold fits give the starting values and the
        base parameters (held fixed).
    data : list of prepared cases
    sigma : ndarray
        Loss scale per output.
    options : DiagnoseOptions
    cache : dict
        Compiled-model cache of the diagnosis.

    Returns
    -------
    dict
        ``(effect, target) -> list`` of estimates, one per group (per case
        when there are fewer than three groups); empty with too few parts.
    """
    parts = maneuver_parts(data)
    if len(parts) < MIN_PARTS:
        return {}
    start = fold_start(scored)
    model = base_model.with_params(**{n: v for n, v in start.items() if isinstance(n, str)})
    eff_start = {k: v for k, v in start.items() if isinstance(k, tuple)}
    out = {}
    for sub in parts:
        fit = fit_candidate(model, scored.candidate, sub, sigma, (), options, cache, start=eff_start, max_nfev=20)
        for key, th in fit.effect_params.items():
            out.setdefault(key, []).append(float(th[0]))
    return out


def model_spread(candidate, sizes: dict) -> float | None:
    """The largest relative spread over the effects of ``candidate`` (None: an effect has no null value)."""
    worst = 0.0
    for e, tgt in candidate.parts:
        if e.null is None or (e.name, tgt) not in sizes:
            return None
        worst = max(worst, relative_spread(sizes[(e.name, tgt)], e.null[0]))
    return worst
