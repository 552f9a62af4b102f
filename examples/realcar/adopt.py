"""The engineer's two-stage workflow on the real car: adopt what the clean run's diagnosis found, then diagnose anew.

Stage 1 diagnoses the clean run (:func:`diagnosis.run_diagnosis`).  Its named
effects — or, when none is named, its best held-out model if that is
significant (on this car ``input_scale(ax) + tire_fiala(axles)``: 24 % below
the refitted base, z 6.4, below the naming rule's 30 %) — are *adopted* by
:func:`adopt`: fitted jointly
with the base parameters :data:`diagnosis.FIT` on the whole clean run, together
with the car's own steering timing.  The model-kind effects (the tyre) are built
into the model with their fitted parameters; the input and output effects (the
``ax`` scale) and the timing correct every recording's columns
(:meth:`Adopted.apply`) before it is cut into cases, as the diagnosis would
apply them.  Stage 2 diagnoses a recording with the adopted model, its
parameters fixed at the clean fit, and the signal candidates
(``withheld.py --stage2``).

The steering timing: the library's ``dead_time`` is causal (``T >= 0``), but
the car's own timing, fitted with the adopted tyre, is a lead of 0.027 s (the
steering record lags the vehicle's response); at the bound, the clean run's
dead time cannot serve as the reference an injected delay is sized against.
:func:`adopt` fits ``dead_time(delta)`` jointly with the adopted effects on the
steering record advanced by :data:`TIMING_MARGIN` and subtracts the margin: a
signed timing, which :meth:`Adopted.apply` removes by shifting the record.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

import reachconf as rc
from reachconf.diagnose import EFFECTS
from reachconf.diagnose.fit import Candidate, fit_candidate, noise_level, prepare

#: the steering record is advanced by this much [s] before the (causal) dead time is fitted: the signed
#: timing of the car is the fitted dead time minus it (measured: -0.027 s with the adopted tyre)
TIMING_MARGIN = 0.1


@dataclass
class Adopted:
    """The clean run's findings, fitted on the whole clean run: the model and the corrections of the recordings.

    Attributes
    ----------
    model : reachconf.Model
        The base model with the adopted model-kind effects and all parameters at the clean fit.
    parts : list of (str, str)
        The adopted (effect, target) pairs.
    params : dict
        The fitted base parameters.
    effect_params : dict
        ``"effect(target)"`` -> {parameter: value} of every adopted effect.
    signal : list of (str, str, tuple)
        The adopted input/output effects ``(effect, target, theta)``, applied to the recordings.
    timing : float
        The car's own steering timing [s] (negative: a lead), removed from the recordings' ``delta``.
    cost : float
        Mean squared normalised prediction residual of the adopted model on the clean run.
    """

    model: object
    parts: list
    params: dict
    effect_params: dict
    signal: list = field(default_factory=list)
    timing: float = 0.0
    cost: float = float("nan")

    def apply(self, cols) -> dict:
        """The recording's columns as the adopted model sees them (timing shift, then the input/output effects).

        Parameters
        ----------
        cols : dict
            Columns of :func:`data.read_run` (possibly with an injected effect).

        Returns
        -------
        dict
            A copy; ``delta`` glitch-repaired (as :func:`data.make_suite` does) before it is shifted.
        """
        from data import repair_glitches

        out = {k: np.array(v, float) for k, v in cols.items()}
        t = out["t"]
        out["delta"], _ = repair_glitches(out["delta"])
        if self.timing:
            out["delta"] = np.interp(t - self.timing, t, out["delta"])
        for name, target, theta in sorted(self.signal, key=lambda s: EFFECTS[s[0]].order):
            eff = EFFECTS[name]
            if eff.kind == "input":
                out[target] = eff.apply_signal(t, out[target], theta)
            else:  # the output the model should produce: the sensor's effect removed
                out[target] = eff.inverse(out[target], theta)
        return out

    def to_dict(self) -> dict:
        """The adoption as JSON values (recorded in ``withheld.json``)."""
        return {"parts": [f"{e}({t})" for e, t in self.parts], "params": self.params,
                "effect_params": self.effect_params, "timing": self.timing, "cost": self.cost}  # fmt: skip


def found_parts(report) -> list:
    """What the clean run's diagnosis found: its named effects, else the parts of its best held-out model
    when that beats the base significantly (paired z at least the naming rule's ``z_name``; relevance aside)."""
    if report.named:
        return [(e["effect"], e["target"]) for e in report.named]
    best = next((e for e in report.ranked_effects if e.get("held_out_loss") is not None), None)
    z_name = getattr(report, "decision", {}).get("thresholds", {}).get("z_name", 3.0)
    if best is None or not best.get("z_vs_base", 0.0) >= z_name:
        return []
    return [tuple(p) for p in best["parts"]]


def _loss_scale(model, prep, sigma, fit_params, options, cache, start):
    """The loss scale of the diagnosis (``options.loss_scale``) from the refitted base model, as the pipeline does:
    ``(sigma, weigh)`` with ``weigh(prepared cases)`` giving them the per-case weights ("case"; else unchanged)."""
    if options.loss_scale == "sensor":
        return sigma, lambda p: p
    from reachconf.diagnose import scales

    base = fit_candidate(model, Candidate(()), prep, sigma, fit_params, options, cache,
                         start={k: v for k, v in start.items() if isinstance(k, str)})  # fmt: skip
    if options.loss_scale == "residual":
        return scales.residual_scale(base, prep, sigma, options), lambda p: p
    w = [float(x) for x in scales.case_weights(base, prep, sigma, options)]
    return sigma, lambda p: [replace(d, weight=wi) for d, wi in zip(p, w)]


def adopt(model, cols, report, fit_params, options=None, timing=True) -> Adopted:
    """Adopt what ``report`` (the clean run's diagnosis) found: one joint fit on the whole clean run.

    Parameters
    ----------
    model : reachconf.Model
        The base model of the diagnosis (``single_track()``).
    cols : dict
        The clean run's columns (:func:`data.read_run`).
    report : reachconf.diagnose.GapReport
        The clean run's diagnosis (starting values: its refitted base and fold-mean effect parameters).
    fit_params : sequence of str
        Base parameters fitted jointly with the adopted effects.
    options : reachconf.DiagnoseOptions, optional
        Its ``loss_scale`` weighs the fit as the diagnosis weighs its fits (per channel or per case, from
        the refitted base model's misfit on the clean run; the advanced-steering fit keeps those weights).
    timing : bool, default True
        Fit and adopt the car's own (signed) steering timing too (see the module docstring).

    Returns
    -------
    Adopted
    """
    from data import make_suite

    options = options or rc.DiagnoseOptions()
    parts = found_parts(report)
    effects = tuple((EFFECTS[e], t) for e, t in parts)
    start = {k: v for k, v in report.base.get("params", {}).items() if k in fit_params}
    best = next((e for e in report.ranked_effects if e.get("held_out_loss") is not None), {})
    for e, t in parts:
        p = best.get("params_by_effect", {}).get(f"{e}({t})")
        if p:
            start[(e, t)] = tuple(p[k] for k in EFFECTS[e].params)
    prep = [prepare(model, c, options) for c in make_suite(cols)]
    sigma = noise_level(np.vstack([d.Y for d in prep]))
    cache = {}
    sigma, weigh = _loss_scale(model, prep, sigma, tuple(fit_params), options, cache, start)
    prep = weigh(prep)
    fit = fit_candidate(model, Candidate(effects), prep, sigma, tuple(fit_params), options, cache, start=start)
    own = 0.0
    if timing and ("dead_time", "delta") not in parts:
        from data import repair_glitches

        adv = dict(cols)
        t = np.asarray(cols["t"], float)
        adv["delta"] = np.interp(t + TIMING_MARGIN, t, repair_glitches(cols["delta"])[0])
        prep_adv = weigh([prepare(model, c, options) for c in make_suite(adv)])
        st = {**fit.base_params, **fit.effect_params, ("dead_time", "delta"): (TIMING_MARGIN,)}
        fit = fit_candidate(model, Candidate(((EFFECTS["dead_time"], "delta"),) + effects), prep_adv, sigma,
                            tuple(fit_params), options, cache, start=st)  # fmt: skip
        own = float(fit.effect_params[("dead_time", "delta")][0]) - TIMING_MARGIN
    adopted_model = model.with_params(**{k: float(v) for k, v in fit.base_params.items()})
    signal = []
    for e, t in effects:
        theta = tuple(float(v) for v in fit.effect_params[(e.name, t)])
        if e.kind in ("input", "output"):
            signal.append((e.name, t, theta))
        else:
            adopted_model = e.apply_model(adopted_model, t, theta)
    return Adopted(adopted_model, parts, {k: float(v) for k, v in fit.base_params.items()},
                   {f"{e.name}({t})": dict(zip(e.params, map(float, fit.effect_params[(e.name, t)])))
                    for e, t in effects}, signal, own, float(fit.train_cost))  # fmt: skip
