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

from reachconf.diagnose.fit import fit_candidate, prepare, window_losses
from reachconf.diagnose.residuals import residuals_and_prefix

__all__ = ["mimic_loss", "probe_mimic_losses", "pseudo_measurements"]


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


def probe_mimic_losses(base_model, fit_a, fit_b, data, probes, sigma, fit_names, options, cache) -> list:
    """What a probe maneuver would add to the data: :func:`mimic_loss` on the suite and one probe together.

    For each probe ``(t, U, Y)`` (``Y``: ``fit_a``'s predicted measurements on the probe, from its start) the
    candidate of ``fit_b`` is refitted (effect and base parameters ``fit_names``, from ``fit_b``'s values) to
    ``fit_a``'s predictions on the suite's windows *and* on the probe's; what it then cannot reproduce on the
    probe is what one run of it would show if ``fit_a`` were right.  An operating point that a constant term
    mimics alone (an offset for a drag at another speed) separates only together with the data.

    Returns
    -------
    list of (float, int)
        Per probe: the squared differences on the probe's windows (noise units) and the number of compared
        samples they sum.
    """
    from reachconf.io.cases import TestCase

    pseudo = pseudo_measurements(fit_a, data, sigma, options)
    start = {**fit_b.base_params, **fit_b.effect_params}
    out = []
    for t, U, Y in probes:
        case = TestCase("probe", "probe", t, U, Y, tuple(base_model.input_names), tuple(base_model.output_names))
        probe = pseudo_measurements(fit_a, [prepare(base_model, case, options)], sigma, options)
        fb = fit_candidate(base_model, fit_b.candidate, pseudo + probe, sigma, fit_names, options, cache, start=start)
        D = float(np.sum(window_losses(fb, probe, sigma, options)))
        out.append((D if np.isfinite(D) else np.inf, int(probe[0].idx.size * np.size(sigma))))
    return out
