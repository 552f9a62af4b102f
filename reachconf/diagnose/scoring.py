"""The *which* step's scoring: the base, screened single effects and pairs, cross-fitted on held-out cases.

:func:`score_models` fits the base model on all cases (and, with
``loss_scale = "case"``, weighs each case by the base's misfit on it), screens
every (effect, target) by a fit of its own parameters, cross-fits the best
``screen`` of them jointly with the base parameters, pairs of the best
``pair_top`` that predict better than the base at all (z >= 1), and the
candidates screened again next to the best single effect (``pair_next``).

With a reference run (:mod:`reachconf.diagnose.reference`) every model is
cross-fitted on the reference cases too and scored by what it leaves of the
change (``reference_loss``: the difference of its residuals on the two
recordings, its suite fit made to match its reference fit's residuals; or
its *excess* loss), and the screens are ranked the same way: the candidates
that explain the change are the ones carried forward, not those that absorb
the base model's misfit common to both recordings.
"""

from __future__ import annotations

from dataclasses import replace
from functools import partial
from itertools import combinations

from reachconf.diagnose.fit import Candidate, fit_candidate, prebuild_models, window_losses, window_residuals
from reachconf.diagnose.parallel import FitMap
from reachconf.diagnose.reference import difference_score, excess_scores
from reachconf.diagnose.scales import case_weights, residual_scale
from reachconf.diagnose.select import cross_fit, fold_start, paired_test

__all__ = ["score_models", "refit_record"]


def _start(fits, base_params=None):
    """Per-fold starting values from earlier fold fits (effect parameters; base parameters of the first)."""
    out = []
    for parts in zip(*fits):
        st = dict(base_params or parts[0].base_params)
        for f in parts:
            st.update(f.effect_params)
        out.append(st)
    return out


class _Scorer:
    """Cross-fits and screens on the suite, and with a reference also on it (losses of the change, screens of it)."""

    def __init__(self, model, prepared, ref, folds, sigma, fit_names, options, cache, base_full, base_ref_full,
                 fits):  # fmt: skip
        self.model, self.prepared, self.ref, self.folds = model, prepared, ref, folds
        self.sigma, self.fit_names, self.options, self.cache = sigma, fit_names, options, cache
        self.base_full, self.base_ref_full = base_full, base_ref_full
        self.fits = fits

    def run(self, cands, jobs, done):
        """A stage's jobs (one per candidate of ``cands``) on :attr:`fits`, their models built here first (the
        worker processes inherit them)."""
        prebuild_models(self.model, cands, self.cache)
        return self.fits(jobs, done)

    def cross(self, cand, start):
        if self.ref is None:
            return cross_fit(self.model, cand, self.prepared, self.folds, self.sigma, self.fit_names, self.options,
                             self.cache, start=start)  # fmt: skip
        # the effects start from their own guesses (or start grids) on the reference, not from the suite's values:
        # a fit stuck near the suite's value would understate what the effect can remove there
        on_ref = cross_fit(self.model, cand, self.ref, self.folds, self.sigma, self.fit_names, self.options,
                           self.cache, start=dict(self.base_ref_full.base_params))  # fmt: skip
        if self.options.reference_loss == "difference":
            return self.difference(cand, on_ref, start)
        sc = cross_fit(self.model, cand, self.prepared, self.folds, self.sigma, self.fit_names, self.options,
                       self.cache, start=start)  # fmt: skip
        return excess_scores(sc, on_ref)

    def difference(self, cand, on_ref, start):
        """``cand`` cross-fitted on the suite to explain the change from its reference scoring ``on_ref``, scored
        by what it leaves of it (``reference_loss="difference"``)."""
        return cross_fit(self.model, cand, self.prepared, self.folds, self.sigma, self.fit_names, self.options,
                         self.cache, start=start, targets=self.targets(on_ref),
                         score=difference_score(on_ref, self.prepared, self.ref, self.sigma, self.options))  # fmt: skip

    def targets(self, on_ref):
        """Per fold, the reference fit's residuals on the paired training cases (the suite's fit explains the
        change)."""
        out = []
        for f, fr in enumerate(on_ref.folds):
            train = [r for r, g in zip(self.ref, self.folds) if g != f]
            out.append(window_residuals(fr.model, fr.candidate, fr.effect_params, train, self.sigma,
                                        self.options.substeps))  # fmt: skip
        return out

    def screen(self, cand, start=None, ref_start=None):
        """A screening fit (effect parameters only, the base's fixed) and its ranking key."""
        if self.ref is None:
            f = fit_candidate(self.base_full.model, cand, self.prepared, self.sigma, (), self.options, self.cache,
                              start=start, max_nfev=20)  # fmt: skip
            return f, f.train_cost
        fr = fit_candidate(self.base_ref_full.model, cand, self.ref, self.sigma, (), self.options, self.cache,
                           start=ref_start, max_nfev=20)  # fmt: skip
        if self.options.reference_loss == "difference":  # the suite's fit explains the change: what it leaves
            o = self.options
            rr = window_residuals(fr.model, cand, fr.effect_params, self.ref, self.sigma, o.substeps)
            f = fit_candidate(self.base_full.model, cand, self.prepared, self.sigma, (), o, self.cache, start=start,
                              max_nfev=20, target=rr)  # fmt: skip
            return f, f.train_cost
        f = fit_candidate(self.base_full.model, cand, self.prepared, self.sigma, (), self.options, self.cache,
                          start=start, max_nfev=20)  # fmt: skip
        return f, f.train_cost - fr.train_cost


def score_models(model, prepared, candidates, folds, clusters, sigma, fit_names, options, cache, bar, state,
                 ref=None, fits=None):  # fmt: skip
    """Base, screening, cross-fitted singles and pairs, into ``state`` (kept when interrupted).

    ``state``: ``base_full``, ``base`` (scored), ``models`` (scored singles and
    pairs), ``screen`` (screening fits), ``scale`` (the loss scale per channel:
    ``sigma`` or, with ``loss_scale="residual"``, the base's misfit); with
    ``ref`` (prepared reference cases) also ``base_suite`` and ``base_ref``
    (the base scored on each), and ``base``/``models`` hold losses of the change (``reference_loss``).
    ``fits`` (:class:`~reachconf.diagnose.parallel.FitMap`) runs each stage's independent fits (default: here).
    With ``loss_scale="case"`` the cases of ``prepared`` (and ``ref``, with the
    same weights) are replaced in place by copies carrying their weights.
    """
    base_full = fit_candidate(model, Candidate(()), prepared, sigma, fit_names, options, cache)
    if options.loss_scale == "residual":
        sigma = residual_scale(base_full, prepared, sigma, options)
        base_full = fit_candidate(model, Candidate(()), prepared, sigma, fit_names, options, cache,
                                  start=dict(base_full.base_params))  # fmt: skip
    elif options.loss_scale == "case":
        w = case_weights(base_full, prepared, sigma, options)
        prepared[:] = [replace(d, weight=float(wi)) for d, wi in zip(prepared, w)]
        base_full = fit_candidate(model, Candidate(()), prepared, sigma, fit_names, options, cache,
                                  start=dict(base_full.base_params))  # fmt: skip
    state["scale"] = sigma
    state["base_full"] = base_full
    base_ref_full = None
    if ref is not None:
        ref[:] = [replace(r, weight=d.weight) for r, d in zip(ref, prepared)]
        base_ref_full = fit_candidate(model, Candidate(()), ref, sigma, fit_names, options, cache,
                                      start=dict(base_full.base_params))  # fmt: skip
    fits = fits or FitMap(1)
    sc = _Scorer(model, prepared, ref, folds, sigma, fit_names, options, cache, base_full, base_ref_full, fits)
    base = cross_fit(model, Candidate(()), prepared, folds, sigma, fit_names, options, cache,
                     start=dict(base_full.base_params), fits=fits)  # fmt: skip
    if ref is not None:
        state["base_suite"] = base
        state["base_ref"] = cross_fit(model, Candidate(()), ref, folds, sigma, fit_names, options, cache,
                                      start=dict(base_ref_full.base_params))  # fmt: skip
        if options.reference_loss == "difference":  # the base fitted to explain the change, as every model
            base = sc.difference(Candidate(()), state["base_ref"], dict(base_full.base_params))
        else:
            base = excess_scores(base, state["base_ref"])
    state["base"] = base
    bar.update(1)
    screen, keys = state["screen"], []

    def screened(i, fk):
        screen.append(fk[0])
        keys.append(fk[1])

    bar.set_postfix_str("screen")
    singles = [Candidate(((e, tgt),)) for e, tgt in candidates]
    sc.run(singles, [partial(sc.screen, c) for c in singles], screened)
    order = sorted(range(len(screen)), key=lambda i: keys[i])
    screen[:] = [screen[i] for i in order]
    bar.update(1)
    models = state["models"]

    def scored(i, m):
        models.append(m)
        bar.update(1)

    bar.set_postfix_str("cross-fit the best singles")
    best = screen[: options.screen]
    sc.run([f.candidate for f in best],
           [partial(sc.cross, f.candidate, {**base_full.base_params, **f.effect_params}) for f in best], scored)
    # pairs of the best singles that predict the held-out cases better than the base at all (z >= 1)
    useful = [m for m in models if paired_test(m.losses, state["base"].losses, clusters)["z"] >= 1.0]
    ranked = sorted(useful, key=lambda m: m.total)
    top = ranked[: options.pair_top]
    pairs, jobs = [], []
    for a, b in combinations(top, 2):
        if a.candidate.keys & b.candidate.keys:
            continue
        better = a if a.total <= b.total else b
        st = _start([a.folds, b.folds])
        for s, fb in zip(st, better.folds):
            s.update(fb.base_params)
        pairs.append(Candidate(a.candidate.parts + b.candidate.parts))
        jobs.append(partial(sc.cross, pairs[-1], st))
    bar.set_postfix_str("cross-fit the pairs")
    sc.run(pairs, jobs, scored)
    # a second effect can be masked by a large first one (screened alone, it imitates the first): the effects
    # screened again next to the best single — and next to a single the best does not beat (z < z_separate: the
    # data may hold either, e.g. a lag and a dead time) —, the best ``pair_next`` of the new pairs scored as well
    if ranked and options.pair_next > 0:
        firsts = [ranked[0]] + [m for m in ranked[1:] if len(m.candidate.keys) == 1
                                and paired_test(ranked[0].losses, m.losses, clusters)["z"] < options.z_separate][:1]
        for first in firsts:
            _next_to(first, sc, candidates, bar, models)


def _next_to(first, sc, candidates, bar, models):
    """Screen every candidate next to the single effect ``first``; cross-fit the best ``pair_next`` pairs and
    their second effect alone (into ``models``)."""
    have = {m.candidate.keys for m in models}
    fs = fold_start(first)
    effect_start = {k: v for k, v in fs.items() if isinstance(k, tuple)}
    st0 = {**sc.base_full.base_params, **effect_start}
    cands = []
    for e, tgt in candidates:
        cand = Candidate(first.candidate.parts + ((e, tgt),))
        new_code = cand.structural and cand.structural not in sc.cache
        if (e.name, tgt) in first.candidate.keys or cand.keys in have or new_code:
            continue  # (no new model code is generated for this screen)
        cands.append(cand)
    bar.set_postfix_str(f"screen next to {first.label}")
    nxt = sc.run(cands, [partial(sc.screen, c, start=st0, ref_start=dict(effect_start)) for c in cands], None)
    nxt.sort(key=lambda fk: fk[1])
    todo, jobs = [], []
    for f, _ in nxt[: sc.options.pair_next]:
        todo.append(f.candidate)
        jobs.append(partial(sc.cross, f.candidate, {**fs, **f.effect_params}))
        single = Candidate(f.candidate.parts[-1:])  # the pair must beat this one too (select.decide)
        if single.keys not in have:
            (key1,) = single.keys
            todo.append(single)
            jobs.append(partial(sc.cross, single, {**sc.base_full.base_params, key1: f.effect_params[key1]}))
            have.add(single.keys)
    bar.set_postfix_str(f"cross-fit next to {first.label}")
    sc.run(todo, jobs, lambda i, m: models.append(m))


def refit_record(model, base_full, base_sc, prepared, sigma, clusters, options) -> dict | None:
    """What the refit of the base parameters did: its held-out gain over the model's own values, and how far each
    parameter moved (relative); None when nothing was refitted.

    The model's own values predict every window without a fit, so their window losses are held-out losses
    too; the paired test is the one every effect is judged by (:func:`~reachconf.diagnose.select.paired_test`).
    """
    if not base_full.base_params:
        return None
    own = window_losses(replace(base_full, model=model, base_params={}), prepared, sigma, options)
    t = paired_test(base_sc.losses, own, clusters)
    # (None: a nominal 0 has no relative change)
    moved = {n: (v / float(model.params[n]) - 1.0 if float(model.params[n]) != 0.0 else None)
             for n, v in base_full.base_params.items()}  # fmt: skip
    return {"gain": t["gain"], "z": t["z"], "moved": moved, "params": dict(base_full.base_params)}
