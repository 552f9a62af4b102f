"""The diagnosis pipeline: where the gap lies, which unmodelled effect causes it, how far W shrinks.

:func:`diagnose` (``reachconf.diagnose(model, suite)``) runs, on disjoint
training and held-out test cases:

1. the base model's declared parameters are re-identified by multi-step
   prediction least squares on the training cases (:mod:`.fit`), so that a
   wrong nominal parameter is not mistaken for an unmodelled effect;
2. *where* (:func:`.locate.locate_gap`): channel shares of the normalised
   disturbance box, time segments outside the quiet envelope per case and
   group, rank correlations with operating conditions; and, if the suite holds
   requested (``<input>_req``) next to measured actuator signals, whether the
   gap sits on the actuator or the process side (the two set-ups of Figure 1);
3. *which* effect: every (effect, target) of the library (:mod:`.effects`) is
   fitted jointly with the base parameters (kept near nominal by a prior) and
   scored and ranked on the held-out cases by the multi-step prediction cost
   (candidates within ``tie`` of the best cost are ordered by the box
   shrink); the best ``top`` are also scored by the minimal trace-conformant
   disturbance box (the SCP of synthesis step 2 under ``V``) against the
   refitted base: the shrink of the smallest zero-centred box containing it
   (volume and per channel); the best is combined with each runner-up;
4. a model-free check (:mod:`.sparse`): sparse regression of the base model's
   disturbance traces on lagged/differentiated inputs and state products;
5. *how far*: the minimal trace-conformant ``W`` (and ``V`` with ``W = 0``)
   of base and best model on the held-out cases.

The verdict names an effect only if it shrinks the box by ``min_shrink`` and
the held-out prediction cost by ``min_improvement``; otherwise it says "no
effect in the library explains the gap".
"""

from __future__ import annotations

import time

import numpy as np
from tqdm.auto import tqdm

from reachconf.conformance.bounds import case_box
from reachconf.conformance.synthesis import SynthesisOptions, synthesize_W
from reachconf.conformance.trace import TraceOptions, trace_disturbances
from reachconf.diagnose.effects import EFFECTS, Effect
from reachconf.diagnose.fit import (
    Candidate,
    DiagnoseOptions,
    fit_candidate,
    noise_level,
    prediction_cost,
    prepare,
    transformed_case,
)
from reachconf.diagnose.locate import locate_gap
from reachconf.diagnose.report import GapReport
from reachconf.diagnose.sparse import feature_dictionary, sparse_features
from reachconf.errors import ConformanceError, OptionsError, ReachconfError
from reachconf.io.cases import TestCase, TestSuite
from reachconf.model.outputs import output_index_of_states
from reachconf.reach import reach
from reachconf.reach_options import ReachOptions
from reachconf.sets.core import Interval

__all__ = ["diagnose"]


def _resolve_effects(model, effects):
    if isinstance(effects, str) and effects == "all":
        chosen = list(EFFECTS.values())
    else:
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
        return out
    return [(e, t) for e in chosen for t in e.applicable(model)]


def _split(prepared, holdout, seed):
    """Disjoint training/held-out cases, stratified by group (at least one of each overall)."""
    rng = np.random.default_rng(seed)
    groups = {}
    for d in prepared:
        groups.setdefault(d.group, []).append(d)
    train, test = [], []
    for g in sorted(groups):
        members = groups[g]
        order = rng.permutation(len(members))
        n_test = int(round(holdout * len(members)))
        if len(members) >= 2:
            n_test = min(max(n_test, 1), len(members) - 1)
        test += [members[i] for i in order[:n_test]]
        train += [members[i] for i in order[n_test:]]
    if not test:
        test.append(train.pop(int(rng.integers(len(train)))))
    if not train:
        train.append(test.pop(int(rng.integers(len(test)))))
    return train, test


def _box(model, cases, V, opts):
    """Hull of the per-case minimal W boxes (SCP of synthesis step 2, best effort: the base model may admit no
    trace at all), or None if the SCP fails."""
    los, his = [], []
    try:
        for c in cases:
            r = case_box(model, c, V, "optctrl", "W", TraceOptions(), certify=False)
            los.append(r.lo)
            his.append(r.hi)
    except (ReachconfError, np.linalg.LinAlgError, ValueError):
        return None
    return np.min(los, axis=0), np.max(his, axis=0)


def _vbox(model, cases):
    try:
        rs = [case_box(model, c, None, "perstep", "V", TraceOptions()) for c in cases]
    except (ReachconfError, np.linalg.LinAlgError, ValueError):
        return None
    return np.min([r.lo for r in rs], axis=0), np.max([r.hi for r in rs], axis=0)


def _decimated(model, fit, cases, k, segment=None):
    """Held-out cases as the candidate model sees them, decimated; cut into ``segment``-second pieces if given.

    The minimal box of a whole open-loop trace is dominated by the drift that
    small errors build up over many seconds; boxes of short segments (each
    free to start anywhere in the measurement's V) measure what the effect
    changes.
    """
    out = []
    for d in cases:
        c = transformed_case(model, d.case, fit.candidate, fit.effect_params)
        out += _pieces(c.decimate(k) if k > 1 else c, segment)
    return out


def _pieces(c, segment):
    if segment is None:
        return [c]
    out = []
    t0, t_end = float(c.t[0]), float(c.t[-1])
    while t0 + 0.5 * segment <= t_end:
        t1 = min(t0 + segment, t_end)
        out.append(c.segment(t0, t1))
        t0 = t1
    return out


def _size(box):
    """Widths of the smallest box centred at ``w = 0`` that contains ``box``.

    The disturbance a model needs is measured from its nominal ``w = 0``: an
    unmodelled constant (an offset) moves the minimal box away from 0 without
    widening it, so raw widths would not see it.
    """
    return 2.0 * np.maximum(np.abs(box[0]), np.abs(box[1]))


def _shrink(base_box, box, eps, channels):
    per = (_size(base_box) + eps) / (_size(box) + eps)
    return float(np.prod(per)), dict(zip(channels, map(float, per)))


def _entry(fit, cost, base_cost):
    (e, tgt), = fit.candidate.parts
    th = fit.effect_params[(e.name, tgt)]
    sd = fit.effect_std.get((e.name, tgt), (float("nan"),) * len(th))
    return {"effect": e.name, "target": tgt, "params": dict(zip(e.params, map(float, th))),
            "params_std": dict(zip(e.params, map(float, sd))), "prediction_cost": float(cost),
            "prediction_gain": float(1 - cost / base_cost) if base_cost > 0 else 0.0, "shrink_volume": None,
            "shrink_per_channel": None, "base_params": {k: float(v) for k, v in fit.base_params.items()}}  # fmt: skip


def _actuator_vs_process(model, fit, cases, V, k, min_shrink, segment):
    """Figure 1: the base model driven by measured actuator outputs vs by (affinely mapped) requests."""
    req = {u: f"{u}_req" for u in model.input_names}
    have = [u for u in model.input_names if all(req[u] in d.case.signals for d in cases)]
    if not have:
        return None
    measured = _decimated(model, fit, cases, k, segment)
    requested = []
    maps = {}
    for u in have:
        j = model.input_names.index(u)
        A = np.concatenate([d.case.signal(req[u]) for d in cases])
        B = np.concatenate([d.U[:, j] for d in cases])
        coef = np.polyfit(A, B, 1)
        maps[u] = [float(coef[0]), float(coef[1])]
    for d in cases:
        c = d.case.with_requests(maps, inputs=have)
        requested += _pieces(c.decimate(k) if k > 1 else c, segment)
    bm = _box(fit.model, measured, V, None)
    br = _box(fit.model, requested, V, None)
    if bm is None or br is None:
        return None
    eps = 1e-9 + 0.05 * np.maximum(_size(bm), _size(br))
    ratio, per = _shrink(br, bm, eps, model.disturbance_names)
    side = "actuators" if ratio >= min_shrink else "process model"
    verdict = (f"with the requested instead of the measured actuator signals ({', '.join(have)}) the minimal W "
               f"volume is {ratio:.2f}x larger: the gap sits mostly in the {side}")  # fmt: skip
    return {"inputs": have, "request_map": maps, "volume_ratio": ratio, "per_channel_ratio": per,
            "box_measured": [list(map(float, bm[0])), list(map(float, bm[1]))],
            "box_requested": [list(map(float, br[0])), list(map(float, br[1]))], "verdict": verdict}  # fmt: skip


def _tubes(model, fits_boxes, case_of, horizon, V):
    """X-Y (first two states) reach tubes of one held-out case, base and best model on the same axes."""
    tubes = []
    for label, fit, box in fits_boxes:
        c = case_of(fit)
        keep = c.t <= c.t[0] + horizon + 1e-9
        t, U, Y = c.t[keep], np.asarray(c.U, float)[keep], np.asarray(c.Y, float)[keep]
        direct = output_index_of_states(fit.model)
        if direct is None:
            return []
        vr = 0.5 * (V.hi - V.lo)[direct]
        X0 = Interval(Y[0, direct] - vr, Y[0, direct] + vr)
        try:
            tube = reach(fit.model, X0, t, inputs=U, W=Interval(box[0], box[1]), options=ReachOptions(progress=False))
        except ReachconfError as exc:
            tubes.append({"label": label, "error": str(exc)})
            continue
        tubes.append({"label": label, "tube": tube, "measured": Y[:, direct[:2]]})
    return tubes


def _reachset_W(model, segments, V):
    """Reachset-conformant W of the held-out segments (synthesis steps 1-3 and the merge, one group)."""
    cases = [TestCase(c.name, "held-out", np.array(c.t), np.array(c.U), np.array(c.Y), c.input_names, c.output_names)
             for c in segments]  # fmt: skip
    try:
        res = synthesize_W(model, TestSuite(cases), V, SynthesisOptions(), progress=False)
    except ReachconfError as exc:
        return None, str(exc)
    box = res.groups["held-out"]
    return (np.asarray(box.lo, float), np.asarray(box.hi, float)), bool(res.group_conformant["held-out"])


def diagnose(model, suite, effects="all", holdout: float = 0.3, fit_params=True, seed: int = 0, V=None,
             options: DiagnoseOptions | None = None, progress: bool = True, reach: bool = False) -> GapReport:  # fmt: skip
    """Diagnose the sim-to-real gap of ``model`` on ``suite`` (see the module docstring).

    Parameters
    ----------
    model : reachconf.Model
        The base model (with disturbances ``w``; its inputs are driven by the suite's signals).
    suite : TestSuite or iterable of TestCase
        At least two cases (training and held-out cases are disjoint).
    effects : "all", str, Effect, (name, target) or a list of these
        Candidate effects (default: the whole library on every applicable target).
    holdout : float
        Share of the cases of each group held out for scoring.
    fit_params : bool or sequence of str
        Base parameters re-identified jointly (True: all declared parameters).
    seed : int
        Seed of the training/held-out split.
    V : Interval, optional
        Measurement-error set; default 3 noise standard deviations per output,
        estimated from third differences of the data.
    options : DiagnoseOptions
    reach : bool
        Also synthesise the reachset-conformant W (steps 1-3 of section 4.3.2,
        the α-search of eq. 68) of the held-out segments for the base and the
        best model (``before_after["W_reachset"]``); slower.

    Returns
    -------
    GapReport
    """
    t_start = time.perf_counter()
    options = options or DiagnoseOptions()
    if not isinstance(options, DiagnoseOptions):
        raise OptionsError(f"options must be a DiagnoseOptions, got {type(options).__name__}")
    if not 0 < holdout < 1:
        raise OptionsError(f"holdout must be in (0, 1), got {holdout!r}")
    cases = list(suite)
    if len(cases) < 2:
        raise ConformanceError(f"diagnose needs at least two test cases (training and held-out), got {len(cases)}")
    if model.q == 0:
        raise ConformanceError(f"model {model.name!r} has no disturbances: there is no gap box to diagnose")
    if fit_params is True:
        fit_names = tuple(model.param_names)
    elif fit_params is False or fit_params is None:
        fit_names = ()
    else:
        fit_names = tuple(fit_params)
        unknown = sorted(set(fit_names) - set(model.param_names))
        if unknown:
            raise OptionsError(f"fit_params: model {model.name!r} has no parameters {unknown}")
    candidates = _resolve_effects(model, effects)
    if not candidates:
        raise OptionsError("effects: no candidate effect applies to this model")

    prepared = [prepare(model, c, options) for c in cases]
    sigma = noise_level(np.vstack([d.Y for d in prepared]))
    if V is None:
        V = Interval(-3 * sigma, 3 * sigma)
    elif not isinstance(V, Interval) or V.dim != model.p:
        raise OptionsError(f"V must be an Interval of dimension {model.p} (the model's outputs)")
    train, test = _split(prepared, holdout, seed)
    dt = float(np.median(np.diff(prepared[0].t)))
    k = max(int(round(1.0 / (options.box_rate * dt))), 1)
    cache = {}
    bar = tqdm(total=len(candidates) + 3, desc="diagnose", disable=not progress, leave=False)

    base = fit_candidate(model, Candidate(()), train, sigma, fit_names, options, cache)
    base_cost = prediction_cost(base, test, sigma, options)
    bar.update(1)
    test_base = _decimated(model, base, test, k)
    train_base = _decimated(model, base, train, k)
    where = {"location": locate_gap(base.model, TestSuite(train_base + test_base), V=V).to_dict()}
    avp = _actuator_vs_process(model, base, test, V, k, options.min_shrink, options.box_segment)
    if avp is not None:
        where["actuator_vs_process"] = avp
    bar.update(1)

    # natural scale of each disturbance channel: spread of the base model's per-step traces (held-out)
    per_step = [trace_disturbances(base.model, c, V=V).W_trace for c in test_base]
    eps = 1e-9 + 0.05 * np.ptp(np.vstack(per_step), axis=0)
    test_segments = _decimated(model, base, test, k, options.box_segment)
    base_box = _box(base.model, test_segments, V, None)
    if base_box is None:
        raise ConformanceError("diagnose: no minimal disturbance box found for the refitted base model")
    channels = list(model.disturbance_names)

    fits = []
    interrupted = False
    try:
        for e, tgt in candidates:
            bar.set_postfix_str(f"{e.name}({tgt})")
            f = fit_candidate(model, Candidate(((e, tgt),)), train, sigma, fit_names, options, cache)
            fits.append((f, prediction_cost(f, test, sigma, options)))
            bar.update(1)
    except KeyboardInterrupt:
        interrupted = True  # report what was fitted so far
    fits.sort(key=lambda fc: fc[1])
    entries = []
    for i, (f, cost) in enumerate(fits):
        ent = _entry(f, cost, base_cost)
        if i < options.top and not interrupted:
            box = _box(f.model, _decimated(model, f, test, k, options.box_segment), V, None)
            if box is not None:
                ent["shrink_volume"], ent["shrink_per_channel"] = _shrink(base_box, box, eps, channels)
                ent["box"] = {ch: [float(a), float(b)] for ch, a, b in zip(channels, box[0], box[1])}
        entries.append((ent, f))
    # best held-out multi-step prediction first; candidates within ``tie`` of the best prediction cost are
    # ordered by the shrink of the minimal box (lag and dead time predict alike at low frequencies)
    ranked = list(entries)
    if ranked and ranked[0][0]["shrink_volume"] is not None:
        best_cost = ranked[0][0]["prediction_cost"]
        tied = [ef for ef in ranked if ef[0]["shrink_volume"] is not None
                and ef[0]["prediction_cost"] <= (1 + options.tie) * best_cost]  # fmt: skip
        tied.sort(key=lambda ef: -ef[0]["shrink_volume"])
        ranked = tied + [ef for ef in ranked if not any(ef is t for t in tied)]
    bar.update(1)

    best = ranked[0][0] if ranked else None
    named = bool(best and best["prediction_gain"] >= options.min_improvement
                 and (best["shrink_volume"] is None or best["shrink_volume"] >= options.min_shrink))  # fmt: skip
    combination = None
    best_fit = ranked[0][1] if named else base
    if named and options.combine:
        for ent, f in ranked[1 : 1 + min(2, options.top)]:
            if ent["shrink_volume"] is None:
                continue
            parts = ranked[0][1].candidate.parts + f.candidate.parts
            cf = fit_candidate(model, Candidate(parts), train, sigma, fit_names, options, cache)
            box = _box(cf.model, _decimated(model, cf, test, k, options.box_segment), V, None)
            if box is None:
                continue
            sv, per = _shrink(base_box, box, eps, channels)
            if sv >= 1.2 * best["shrink_volume"] and (combination is None or sv > combination["shrink_volume"]):
                params = {f"{e.name}.{p}({t})": float(v) for (e, t) in parts
                          for p, v in zip(e.params, cf.effect_params[(e.name, t)])}  # fmt: skip
                combination = {"label": cf.candidate.label, "parts": [[e.name, t] for e, t in parts],
                               "params": params, "shrink_volume": sv, "shrink_per_channel": per,
                               "prediction_cost": prediction_cost(cf, test, sigma, options)}  # fmt: skip
                best_fit = cf

    # model-free check on the training cases
    blocks, traces = [], []
    names = None
    for c in train_base:
        tr = trace_disturbances(base.model, c, V=V)
        F, names = feature_dictionary(c.t, np.asarray(c.U, float), np.asarray(c.Y, float), model.input_names,
                                      model.output_names)  # fmt: skip
        blocks.append(F)
        traces.append(tr.W_trace)
    features = sparse_features(traces, blocks, names, channels) if names else []

    # how far it shrinks: W and V (W = 0) before/after on the held-out cases
    before_after = {}
    after_box = _box(best_fit.model, _decimated(model, best_fit, test, k, options.box_segment), V, None) if best_fit is not base else base_box
    if after_box is not None:
        before_after["W"] = {ch: {"before": [float(base_box[0][i]), float(base_box[1][i])],
                                  "after": [float(after_box[0][i]), float(after_box[1][i])],
                                  "shrink": float((_size(base_box)[i] + eps[i]) / (_size(after_box)[i] + eps[i]))}
                             for i, ch in enumerate(channels)}  # fmt: skip
    vb = _vbox(base.model, test_segments)
    va = _vbox(best_fit.model, _decimated(model, best_fit, test, k, options.box_segment)) if best_fit is not base else vb
    if vb is not None and va is not None:
        before_after["V"] = {ch: {"before": [float(vb[0][i]), float(vb[1][i])], "after": [float(va[0][i]), float(va[1][i])],
                                  "shrink": float((_size(vb)[i] + 1e-12) / (_size(va)[i] + 1e-12))}
                             for i, ch in enumerate(model.output_names)}  # fmt: skip
    if reach:
        segs_after = _decimated(model, best_fit, test, k, options.box_segment) if best_fit is not base else None
        rb, okb = _reachset_W(base.model, test_segments, V)
        ra, oka = _reachset_W(best_fit.model, segs_after, V) if segs_after is not None else (rb, okb)
        if rb is not None and ra is not None:
            before_after["W_reachset"] = {
                ch: {"before": [float(rb[0][i]), float(rb[1][i])], "after": [float(ra[0][i]), float(ra[1][i])],
                     "shrink": float((_size(rb)[i] + eps[i]) / (_size(ra)[i] + eps[i]))}
                for i, ch in enumerate(channels)}  # fmt: skip
            before_after["W_reachset_conformant"] = {"before": okb, "after": oka}
        else:
            before_after["W_reachset_error"] = okb if rb is None else oka
    tubes = []
    if after_box is not None and options.tube_horizon > 0:
        first = test[0]
        tubes = _tubes(model, [("base", base, base_box), ("with effect", best_fit, after_box)],
                       lambda f: _decimated(model, f, [first], k)[0], options.tube_horizon, V)  # fmt: skip
    bar.close()

    ranked_entries = [e for e, _ in ranked]
    verdict = _verdict(ranked_entries, named, combination, interrupted)
    base_info = {"params": {k2: float(v) for k2, v in base.base_params.items()},
                 "nominal": {k2: float(model.params[k2]) for k2 in fit_names}, "prediction_cost": base_cost,
                 "box": {ch: [float(a), float(b)] for ch, a, b in zip(channels, base_box[0], base_box[1])},
                 "V": [[float(a), float(b)] for a, b in zip(V.lo, V.hi)], "noise_sigma": sigma.tolist()}  # fmt: skip
    split = {"train": [d.name for d in train], "test": [d.name for d in test]}
    report = GapReport(where, ranked_entries, verdict, base_info, combination, features, before_after, split,
                       time.perf_counter() - t_start)  # fmt: skip
    report.tubes = tubes
    return report


def _verdict(ranked, named, combination, interrupted) -> str:
    pre = "INTERRUPTED, partial result: " if interrupted else ""
    if not ranked:
        return pre + "no effect was fitted"
    best = ranked[0]
    runner = ranked[1] if len(ranked) > 1 else None
    if not named:
        sv = best["shrink_volume"]
        return pre + ("no effect in the library explains the gap (best: "
                      f"{best['effect']} on {best['target']}, W volume shrink "
                      f"{'n/a' if sv is None else f'{sv:.2f}x'}, held-out prediction cost "
                      f"{-100 * best['prediction_gain']:+.0f} %)")  # fmt: skip
    params = ", ".join(f"{k} = {v:.4g}" for k, v in best["params"].items())
    text = (f"{best['effect']} on {best['target']} ({params}) explains the gap: the minimal W volume shrinks "
            f"{best['shrink_volume']:.2f}x and the held-out prediction cost by {100 * best['prediction_gain']:.0f} %")
    if runner is not None:
        text += (f"; margin over the runner-up {runner['effect']} on {runner['target']}: held-out prediction cost "
                 f"{runner['prediction_cost'] / best['prediction_cost']:.2f}x lower")
        if runner["shrink_volume"]:
            text += f", W volume {best['shrink_volume'] / runner['shrink_volume']:.2f}x smaller"
    if combination:
        text += f"; together with a second effect ({combination['label']}) {combination['shrink_volume']:.2f}x"
    return pre + text
