"""The diagnosis pipeline: where the gap lies, which unmodelled effect causes it, how far W shrinks.

:func:`diagnose` (``reachconf.diagnose(model, suite)``):

1. the base model's declared parameters are identified by multi-step
   prediction least squares (:mod:`.fit`), so that a wrong nominal parameter is
   not mistaken for an unmodelled effect; they are refitted jointly with every
   candidate effect below;
2. *where* (:func:`.locate.locate_gap`): channel shares of the normalised
   disturbance box, time segments outside the quiet envelope per case and
   group, rank correlations with operating conditions; and, if the suite holds
   requested (``<input>_req``) next to measured actuator signals, whether the
   gap sits on the actuator or the process side (the two set-ups of Figure 1);
3. *which* effect (:mod:`.select`): every (effect, target) of the library
   (:mod:`.effects`) is screened by a fit of its own parameters on the base
   model; the best ``screen`` are fitted jointly with the base parameters by
   cross-fitting (the cases are split into folds, stratified by group; each
   fold is predicted by a model fitted on the others), and so are pairs of the
   best ``pair_top`` of those that predict better than the base at all (z >= 1).  Models are compared by their held-out prediction loss
   with cluster-robust paired tests; an effect is named only when it is both
   significant and relevant; explanations the data cannot separate are
   reported together, with the probe maneuver that would separate them
   (:mod:`.probes`).  The named model is refitted on all cases; its parameter
   intervals come from the cluster-robust (sandwich) covariance;
4. a model-free check (:mod:`.sparse`): sparse regression of the base model's
   disturbance traces on lagged/differentiated inputs and state products;
5. *how far* (:mod:`.howfar`): the minimal trace-conformant ``W`` (and ``V``
   with ``W = 0``) of base and named model on held-out cases (the first fold).
"""

from __future__ import annotations

import os
import time
from functools import partial

import numpy as np
from tqdm.auto import tqdm

from reachconf.blas_threads import with_one_blas_thread
from reachconf.conformance.trace import trace_disturbances
from reachconf.diagnose.consistency import group_sizes, model_spread
from reachconf.diagnose.effects import EFFECTS, Effect
from reachconf.diagnose.fit import (
    noise_level,
    prepare,
    window_counts,
)
from reachconf.diagnose.howfar import (
    actuator_vs_process,
    box_shrink,
    box_size,
    decimated_cases,
    measurement_box,
    minimal_box,
    reach_tubes,
    reachset_W,
)
from reachconf.diagnose.locate import locate_gap
from reachconf.diagnose.options import DiagnoseOptions
from reachconf.diagnose.parallel import FitMap, picklable
from reachconf.diagnose.probes import band_shares, separating_probe
from reachconf.diagnose.reference import change_test, prepare_reference, same_data
from reachconf.diagnose.report import GapReport
from reachconf.diagnose.scales import case_layout, reweigh_factors
from reachconf.diagnose.scoring import refit_record, score_models
from reachconf.diagnose.select import (
    decide,
    fold_assignment,
    fold_start,
    full_fit,
    window_clusters,
)
from reachconf.diagnose.separable import mimic_loss, probe_mimic_losses
from reachconf.diagnose.sparse import feature_dictionary, sparse_features
from reachconf.diagnose.verdict import (
    decision_record,
    effect_entries,
    model_entry,
    verdict_text,
)
from reachconf.checks import check_options
from reachconf.errors import ConformanceError, OptionsError
from reachconf.io.cases import TestSuite, suite_cases
from reachconf.model.core import require_model
from reachconf.model.outputs import state_estimate
from reachconf.sets.core import Interval

__all__ = ["diagnose", "resolve_effects"]


def resolve_effects(model, effects):
    """The candidate (effect, target) pairs of ``effects`` ("all", names, or (name, target) pairs) on ``model``.

    Raises
    ------
    OptionsError
        An unknown effect, or a target the effect cannot act on in this model.
    """
    if isinstance(effects, str) and effects == "all":
        chosen = list(EFFECTS.values())
    else:
        if effects is None or not (isinstance(effects, (str, Effect, tuple)) or hasattr(effects, "__iter__")):
            raise OptionsError(f"effects must be 'all', an effect name, (name, target) pairs or Effect objects, "
                               f"got {effects!r}"[:200])  # fmt: skip
        items = [effects] if isinstance(effects, (str, Effect, tuple)) else list(effects)
        chosen, pairs = [], []
        for it in items:
            if isinstance(it, Effect):
                chosen.append(it)
            elif isinstance(it, tuple) and len(it) == 2:
                name, tgt = it
                if name not in EFFECTS:
                    raise OptionsError(f"effects: unknown effect {name!r}; known: {sorted(EFFECTS)}")
                pairs.append((EFFECTS[name], tgt))
            elif isinstance(it, str) and it in EFFECTS:
                chosen.append(EFFECTS[it])
            else:
                raise OptionsError(f"effects: unknown effect {it!r}; known: {sorted(EFFECTS)}")
        out = [(e, t) for e in chosen for t in e.applicable(model)]
        for e, t in pairs:
            if t not in e.applicable(model):
                raise OptionsError(f"effects: {e.name} cannot act on {t!r} of model {model.name!r}; "
                                   f"targets: {e.applicable(model)}")  # fmt: skip
            out.append((e, t))
        return list({(e.name, t): (e, t) for e, t in out}.values())  # an effect named twice is one candidate
    return [(e, t) for e in chosen for t in e.applicable(model)]



def _cpu_time() -> float:
    """CPU seconds of this process and of its finished children (the forked fit workers)."""
    t = os.times()
    return time.process_time() + t.children_user + t.children_system


def _boxes(model, segments, V, reach: bool) -> tuple:
    """*How far* of one model on ``segments``: its minimal trace-conformant W box, its minimal V box with W = 0
    (each None when not found) and, with ``reach``, its reachset-conformant W (:func:`.howfar.reachset_W`)."""
    return minimal_box(model, segments, V), measurement_box(model, segments), reachset_W(model, segments, V) if reach else None


def _fit_names(model, fit_params):
    if fit_params is True:
        return tuple(model.param_names)
    if fit_params is False or fit_params is None:
        return ()
    if isinstance(fit_params, str):  # one name (a string is not split into letters)
        fit_params = (fit_params,)
    if not hasattr(fit_params, "__iter__") or not all(isinstance(n, str) for n in fit_params):
        raise OptionsError(f"fit_params must be True, False, None or parameter names, got {fit_params!r}"[:200])
    names = tuple(fit_params)
    unknown = sorted(set(names) - set(model.param_names))
    if unknown:
        raise OptionsError(f"fit_params: model {model.name!r} has no parameters {unknown}")
    return names


@with_one_blas_thread
def diagnose(model, suite, effects="all", holdout: float = 0.5, fit_params=True, seed: int = 0, V=None,
             options: DiagnoseOptions | None = None, progress: bool = True, reach: bool = False,
             reference=None, workers=None) -> GapReport:  # fmt: skip
    """Diagnose the sim-to-real gap of ``model`` on ``suite`` (see the module docstring).

    Parameters
    ----------
    model : reachconf.Model
        The base model (with disturbances ``w``; its inputs are driven by the suite's signals).
    suite : TestSuite or iterable of TestCase
        At least two cases; taken in the order of their names (when unique),
        so that the report does not depend on how they were listed.
    effects : "all", str, Effect, (name, target) or a list of these
        Candidate effects (default: the whole library on every applicable target).
    holdout : float, default 0.5
        Share of the cases held out in each fold of the cross-fitting
        (``round(1 / holdout)`` folds, at least 2).
    fit_params : bool or sequence of str
        Base parameters re-identified jointly (True: all declared parameters).
    seed : int
        Seed of the fold assignment.
    V : Interval, optional
        Measurement-error set; default 3 noise standard deviations per output,
        estimated from third differences of the data.
    options : DiagnoseOptions
    reach : bool
        Also synthesise the reachset-conformant W (steps 1-3 of section 4.3.2,
        the α-search of eq. 68) of the held-out segments for the base and the
        named model (``before_after["W_reachset"]``); slower.
    reference : TestSuite, iterable of TestCase or path of a suite folder, optional
        The same cases (same names and sample times) recorded without the
        change: the effect named is then the one that explains how the suite
        differs from it (:mod:`reachconf.diagnose.reference`; by default the
        difference of the two recordings' residuals,
        ``options.reference_loss``; ``decision["reference"]`` holds the base
        model's excess misfit over the reference, its z and the difference
        loss).  Every scored model is also fitted on the reference, which
        doubles the time of the *which* step.
    workers : int, optional
        Processes that run the independent jobs of each stage — the *which*
        step's fits, the named model's per-group fits, the base's
        disturbance trace of every case (once, for *where*, *how far* and the
        model-free check) and each model's *how far* boxes
        (:mod:`reachconf.diagnose.parallel`; forked from this one).  Default:
        one per core (at most 8), or 1 inside a worker process of a pool
        and where processes cannot be forked.  The report is the same for
        any number.

    Returns
    -------
    GapReport
    """
    t_start, c_start = time.perf_counter(), _cpu_time()
    require_model(model, "diagnose")
    options = check_options(options, DiagnoseOptions, "diagnose")
    if not (isinstance(holdout, (int, float)) and not isinstance(holdout, bool) and 0 < holdout < 1):
        raise OptionsError(f"holdout must be in (0, 1), got {holdout!r}")
    if not isinstance(seed, (int, np.integer)) or isinstance(seed, bool) or seed < 0:
        raise OptionsError(f"diagnose: seed must be a non-negative integer, got {seed!r}")
    cases = suite_cases(suite, "diagnose")
    if len({c.name for c in cases}) == len(cases):  # the report does not depend on the cases' order (folds, how far)
        cases = sorted(cases, key=lambda c: c.name)
    if len(cases) < 2:
        raise ConformanceError(f"diagnose needs at least two test cases (training and held-out), got {len(cases)}")
    if model.q == 0:
        raise ConformanceError(f"model {model.name!r} has no disturbances: there is no gap box to diagnose "
                               "(rc.with_state_disturbances(model) adds one to every state equation)")  # fmt: skip
    try:
        state_estimate(model, cases[0])
    except ConformanceError:
        raise ConformanceError(
            f"diagnose: model {model.name!r} has outputs {model.output_names} for states {model.state_names}: every "
            f"prediction window starts from the measured state, so each state must be an output or computable from "
            f"the outputs (measure the missing state, or write the model without it)") from None
    fit_names = _fit_names(model, fit_params)
    candidates = resolve_effects(model, effects)
    if not candidates:
        raise OptionsError("effects: no candidate effect applies to this model")
    fits = FitMap(workers)  # (checks ``workers`` whatever the effects)
    if fits.workers > 1 and not picklable({e for e, _ in candidates}):
        fits = FitMap(1)  # an effect that cannot travel between processes keeps the fits here

    prepared = [prepare(model, c, options) for c in cases]
    ref_prepared = prepare_reference(model, reference, prepared, options) if reference is not None else None
    sigma = noise_level(np.vstack([d.Y for d in prepared]))
    if V is None:
        V = Interval(-3 * sigma, 3 * sigma)
    elif not isinstance(V, Interval) or V.dim != model.p:
        raise OptionsError(f"V must be an Interval of dimension {model.p} (the model's outputs)")
    k_folds = int(min(max(2, round(1.0 / holdout)), len(prepared)))
    folds = fold_assignment([d.group for d in prepared], k_folds, seed)
    clusters = window_clusters(window_counts(prepared), options.min_clusters)
    dt = float(np.median(np.diff(prepared[0].t)))
    k = 1 if options.box_rate is None else max(int(round(1.0 / (options.box_rate * dt))), 1)
    short = [c.name for c in cases if c.t.size <= k]  # a decimated case keeps (size - 1) // k + 1 samples
    if short:
        raise OptionsError(f"DiagnoseOptions.box_rate {options.box_rate:g} Hz keeps one sample of case(s) {short[:3]} "
                           f"(every {k}th of samples {dt:g} s apart): raise it, or None for the data's own rate")  # fmt: skip
    cache = {}
    n_pairs = options.pair_top * (options.pair_top - 1) // 2
    bar = tqdm(total=3 + min(options.screen, len(candidates)) + n_pairs, desc="diagnose", disable=not progress,
               leave=False)  # fmt: skip

    timings = {"prepare": _cpu_time() - c_start}
    interrupted = False
    state = {"screen": [], "models": []}
    try:
        score_models(model, prepared, candidates, folds, clusters, sigma, fit_names, options, cache, bar, state,
                     ref=ref_prepared, fits=fits)  # fmt: skip
    except KeyboardInterrupt:  # pragma: no cover - interactive: decide on what was scored so far
        if "base" not in state:
            raise
        interrupted = True
    base_full, base_sc, models, screen = state["base_full"], state["base"], state["models"], state["screen"]
    # the suite's own held-out loss of the base (with a reference, base_sc holds its loss of the change)
    base_total = state["base_suite"].total if ref_prepared is not None else base_sc.total
    scale = state["scale"]  # the loss scale of every fit (sigma: the sensor noise, for V and the probes)
    timings["which"] = _cpu_time() - c_start - sum(timings.values())
    fulls, mimics = {}, {}

    def full(m):
        if m.label not in fulls:
            fulls[m.label] = full_fit(model, m, prepared, scale, fit_names, options, cache, fits=fits)
        return fulls[m.label]

    def mimic(a, b):  # can the data separate b from the chosen a? (select.decide, separable.mimic_loss)
        res = mimic_loss(model, full(a), b.candidate, prepared, scale, fit_names, options, cache, start=fold_start(b))
        mimics[b.label] = res
        return res["mimic_loss"]

    def probe_refit(a, b):  # what would a probe maneuver add? (probes.separating_probe)
        return lambda probes: probe_mimic_losses(model, a, b, prepared, probes, scale, fit_names, options, cache)

    spreads = {}

    def spread(m):  # is every effect of m the same in every maneuver group? (select.decide, consistency)
        if m.label not in spreads:
            sizes = group_sizes(model, m, prepared, scale, options, cache)
            spreads[m.label] = {"spread": model_spread(m.candidate, sizes), "sizes": sizes}
        return spreads[m.label]["spread"]

    layout = case_layout(prepared, len(np.atleast_1d(scale))) if options.loss_scale == "case" else None

    def reweigh(single):  # a pair against its part: the case weights from that part's misfit (select.decide)
        return reweigh_factors(single.losses, layout) if layout is not None else None

    # with a reference run the excess over it decides (reference.py): is there a change at all?
    change = change_test(state["base_suite"], state["base_ref"], clusters) if ref_prepared is not None else None
    # (with reference_loss="difference" every model is scored by what it leaves of the change: decide on it; the
    # mimic check guards against effects that absorb the base's own misfit differently, which cancels there)
    difference = change is not None and options.reference_loss == "difference"
    changed = change is None or change["z"] >= options.z_name or difference
    decision = decide(base_sc, models if changed else [], clusters, options, mimic=None if difference else mimic,
                      spread=spread if change is None else None, reweigh=reweigh if change is None else None,
                      relevance_of=base_sc.total if change is not None else None)  # fmt: skip
    chosen = decision["chosen"]
    if change is not None and chosen is not None and same_data(prepared, ref_prepared, sigma):
        # the reference holds the suite's own data: what an effect removed is the two fits' numerical difference,
        # not a change (reference.py)
        change["same_data"] = True
        change["null_effect"] = chosen.label
        decision.update(status="none", chosen=None, alternatives=[])
        changed = False
    if change is not None:
        change["loss"] = options.reference_loss
        change["difference_loss"] = base_sc.total if options.reference_loss == "difference" else None
    if not changed:
        decision["best"] = min(models, key=lambda m: m.total) if models else None
    decision["consistency"] = {label: {"spread": v["spread"], "sizes": {f"{e}({t})": x for (e, t), x in v["sizes"].items()}}
                               for label, v in spreads.items()}  # fmt: skip
    for label, res in mimics.items():
        decision["identifiability"].setdefault(label, {}).update(effect_loss=res["effect_loss"],
                                                                 mimic_params=res["params"])  # fmt: skip
    chosen = decision["chosen"]
    named, alternatives, chosen_full = [], [], None
    if chosen is not None:
        chosen_full = full(chosen)
        named = effect_entries(chosen_full, options.interval, options.interval_method)
        for alt, test in decision["alternatives"]:
            alt_full = full(alt)
            differ = sorted(chosen.candidate.keys ^ alt.candidate.keys)
            inputs = sorted({t for e, t in differ if EFFECTS.get(e) is not None and EFFECTS[e].kind == "input"})
            alternatives.append({"label": alt.label, "parts": [[e.name, t] for e, t in alt.candidate.parts],
                                 "z": test["z"], "gain": test["gain"], "differs": [list(x) for x in differ],
                                 "identifiable": test["identifiable"], "expected_z": test.get("expected_z"),
                                 "effects": effect_entries(alt_full, options.interval, options.interval_method),
                                 "separating": separating_probe(chosen_full, alt_full, prepared, sigma,
                                                                refit=probe_refit(chosen_full, alt_full),
                                                                z=options.z_name),
                                 "data_band_shares": {u: band_shares(prepared, u, model) for u in inputs}})  # fmt: skip
    bar.update(1)
    timings["named"] = _cpu_time() - c_start - sum(timings.values())

    # held-out cases of the first fold for where / how far (models fitted on the other folds)
    test = [d for d, f in zip(prepared, folds) if f == 0]
    train = [d for d, f in zip(prepared, folds) if f != 0]
    base0 = base_sc.folds[0]
    after0 = chosen.folds[0] if chosen is not None else base0
    box_test = test[: options.box_cases]
    test_base = decimated_cases(model, base0, test, k, substeps=options.substeps)
    train_base = decimated_cases(model, base0, train, k, substeps=options.substeps)
    # the base's disturbance traces of every case, once, for where, how far (eps) and the model-free check
    traces = fits([partial(trace_disturbances, base0.model, c, V=V) for c in train_base + test_base])
    train_traces, test_traces = traces[: len(train_base)], traces[len(train_base) :]
    where = {"location": locate_gap(base0.model, TestSuite(train_base + test_base), V=V, traces=traces).to_dict()}
    avp = actuator_vs_process(model, base0, box_test, V, k, options.box_segment)
    if avp is not None:
        where["actuator_vs_process"] = avp
    channels = list(model.disturbance_names)
    timings["where"] = _cpu_time() - c_start - sum(timings.values())
    eps = 1e-9 + 0.05 * np.ptp(np.vstack([r.W_trace for r in test_traces]), axis=0)
    segs_base = decimated_cases(model, base0, box_test, k, options.box_segment, options.substeps)
    segs_after = segs_base
    if chosen is not None:
        segs_after = decimated_cases(model, after0, box_test, k, options.box_segment, options.substeps)
    # the boxes of the base and of the named model: independent, one job each
    pairs = [(base0, segs_base), (after0, segs_after)] if chosen is not None else [(base0, segs_base)]
    boxes = fits([partial(_boxes, f.model, segs, V, reach) for f, segs in pairs])
    (base_box, vb, reach_b), (after_box, va, reach_a) = boxes[0], boxes[-1]
    if base_box is None:
        raise ConformanceError("diagnose: no minimal disturbance box found for the refitted base model")
    before_after, shrink = {}, None
    if after_box is not None:
        shrink, per = box_shrink(base_box, after_box, eps, channels)
        before_after["W"] = {ch: {"before": [float(base_box[0][i]), float(base_box[1][i])],
                                  "after": [float(after_box[0][i]), float(after_box[1][i])], "shrink": per[ch]}
                             for i, ch in enumerate(channels)}  # fmt: skip
        before_after["W_volume_shrink"] = shrink
    if vb is not None and va is not None:
        before_after["V"] = {ch: {"before": [float(vb[0][i]), float(vb[1][i])], "after": [float(va[0][i]), float(va[1][i])],
                                  "shrink": float((box_size(vb)[i] + 1e-12) / (box_size(va)[i] + 1e-12))}
                             for i, ch in enumerate(model.output_names)}  # fmt: skip
    if reach:
        (rb, okb), (ra, oka) = reach_b, reach_a
        if rb is not None and ra is not None:
            before_after["W_reachset"] = {
                ch: {"before": [float(rb[0][i]), float(rb[1][i])], "after": [float(ra[0][i]), float(ra[1][i])],
                     "shrink": float((box_size(rb)[i] + eps[i]) / (box_size(ra)[i] + eps[i]))}
                for i, ch in enumerate(channels)}  # fmt: skip
            before_after["W_reachset_conformant"] = {"before": okb, "after": oka}
        else:
            before_after["W_reachset_error"] = okb if rb is None else oka
    tubes = []
    if after_box is not None and options.tube_horizon > 0 and test:
        first = test[0]
        tubes = reach_tubes(model, [("base", base0, base_box), ("with effect", after0, after_box)],
                            lambda f: decimated_cases(model, f, [first], k, substeps=options.substeps)[0], options.tube_horizon, V)  # fmt: skip

    timings["how_far"] = _cpu_time() - c_start - sum(timings.values())
    # model-free check on the training cases of the first fold
    blocks, w_traces, names = [], [], None
    for c, tr in zip(train_base, train_traces):
        F, names = feature_dictionary(c.t, np.asarray(c.U, float), np.asarray(c.Y, float), model.input_names,
                                      model.output_names)  # fmt: skip
        blocks.append(F)
        w_traces.append(tr.W_trace)
    features = sparse_features(w_traces, blocks, names, channels) if names else []
    bar.close()
    timings["model_free"] = _cpu_time() - c_start - sum(timings.values())

    ranked = sorted(models, key=lambda m: m.total)
    ranked_entries = [model_entry(m, base_sc, clusters, decision) for m in ranked]
    scored_keys = {m.candidate.keys for m in models}
    for f in screen:
        if f.candidate.keys not in scored_keys:
            (e, tgt), = f.candidate.parts
            ranked_entries.append({"label": f.candidate.label, "parts": [[e.name, tgt]], "effect": e.name,
                                   "target": tgt, "params": dict(zip(e.params, map(float, f.effect_params[(e.name, tgt)]))),
                                   "held_out_loss": None, "prediction_gain": None, "z_vs_base": None,
                                   "admissible": False, "screen_cost": f.train_cost})  # fmt: skip
    record = decision_record(decision, named, alternatives, options)
    record["input_hold"] = options.input_hold  # the timing effects' estimates assume it (report.timing_hold_note)
    record["sample_interval"] = float(np.median([d.dt for d in prepared]))
    if change is not None:
        record["reference"] = change
    best_entry = ranked_entries[0] if ranked_entries else None
    refit = refit_record(model, base_full, base_sc, prepared, scale, clusters, options) if change is None else None
    verdict = verdict_text(record, best_entry, interrupted, shrink if chosen is not None else None, refit=refit)
    base_info = {"params": {k2: float(v) for k2, v in base_full.base_params.items()},
                 "nominal": {k2: float(model.params[k2]) for k2 in fit_names}, "held_out_loss": base_total,
                 "box": {ch: [float(a), float(b)] for ch, a, b in zip(channels, base_box[0], base_box[1])},
                 "V": [[float(a), float(b)] for a, b in zip(V.lo, V.hi)], "noise_sigma": sigma.tolist(),
                 "loss_scale": {"method": options.loss_scale, "per_output": np.asarray(scale).tolist(),
                                "per_case": {d.name: float(d.weight) for d in prepared}},
                 "folds": k_folds, "clusters": int(clusters.max()) + 1 if clusters.size else 0,
                 "cpu_seconds_by_step": timings, "workers": fits.workers, "refit": refit}  # fmt: skip
    split = {"train": [d.name for d in train], "test": [d.name for d in test],
             "folds": {d.name: int(f) for d, f in zip(prepared, folds)}}  # fmt: skip
    report = GapReport(where, ranked_entries, verdict, base_info, None, features, before_after, split,
                       time.perf_counter() - t_start, decision=record)  # fmt: skip
    report.cpu_seconds = _cpu_time() - c_start
    report.tubes = tubes
    report.scores = {"clusters": clusters, "base": base_sc.losses,
                     "models": [{"label": m.label, "parts": [[e.name, t] for e, t in m.candidate.parts],
                                 "at_bound": list(m.at_bound),
                                 "losses": m.losses} for m in models], "layout": layout}  # fmt: skip
    return report
