"""Which effect: held-out likelihood comparisons, the naming rule and indistinguishable alternatives.

Every candidate model (the base, single effects, pairs of effects) is fitted
on the training folds and predicts the held-out cases of each fold
(cross-fitting, :func:`cross_fit`), so that every prediction window has a
held-out loss under every model: the squared multi-step prediction residuals
in units of the sensor noise estimated from the data (the Gaussian negative
log-likelihood up to constants).  Two models are compared by the paired
difference of their held-out losses, summed per cluster (a test case; cases
are cut into blocks when there are few) — the windows of one case share its
maneuver's misfit, the clusters are independent — and its
cluster-robust z statistic (:func:`paired_test`).  The same comparison serves
nested and non-nested models (a Vuong-type test on held-out data).

The decision (:func:`decide`):

* a model with one effect is *admissible* when it beats the base model with
  ``z >= z_name`` and lowers its held-out loss by at least
  ``min_improvement`` (relevance: a tiny, real misfit of the base structure
  does not earn a name);
* ... or, below ``min_improvement``, lowers it by at least
  ``consistent_gain`` with an effect of the same size in every maneuver
  group (relative spread at most ``max_spread``:
  :mod:`reachconf.diagnose.consistency`; a structural misfit absorbed by an
  effect changes with the maneuver);
* a model with two effects is admissible when it beats *each* of its two
  one-effect sub-models in the same way (each effect must earn its place);
* the admissible model with the lowest held-out loss is chosen; every other
  admissible model that is not nested with it and that it does not beat with
  ``z >= z_separate`` is an *indistinguishable* alternative;
* no admissible model: no effect in the library explains the gap.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import partial

import numpy as np

from reachconf.diagnose.fit import Candidate, FitResult, fit_candidate, window_losses

__all__ = ["Scored", "fold_assignment", "window_clusters", "paired_test", "cross_fit", "held_out", "decide",
           "full_fit",
           "fold_start", "maneuver_parts"]


@dataclass
class Scored:
    """A candidate scored on held-out data: per-window held-out losses and the fold fits."""

    candidate: Candidate
    losses: np.ndarray
    folds: list = field(default_factory=list)  # FitResult per fold (trained without that fold)
    bound: tuple | None = None  # effect parameters at a bound, when known without the fold fits (stored results)

    @property
    def label(self) -> str:
        """The candidate's label, e.g. ``actuator_lag(delta) + output_offset(psi)``."""
        return self.candidate.label

    @property
    def total(self) -> float:
        """Total held-out loss over all windows."""
        return float(np.sum(self.losses))

    @property
    def at_bound(self) -> tuple:
        """Effect parameters (``"effect.param(target)"``) that ended at a bound of their range in a fold fit."""
        if self.bound is not None:
            return tuple(self.bound)
        return tuple(sorted({lab for f in self.folds for lab in f.at_bound if "(" in lab}))

    def fold_params(self) -> dict:
        """Mean effect parameters over the fold fits: ``(effect, target) -> tuple``."""
        out = {}
        for key in self.folds[0].effect_params:
            out[key] = tuple(float(v) for v in np.mean([f.effect_params[key] for f in self.folds], axis=0))
        return out


def fold_assignment(groups, k: int, seed: int) -> np.ndarray:
    """Fold of every case: stratified by group (each group's cases spread over the folds), seeded."""
    rng = np.random.default_rng(seed)
    folds = np.zeros(len(groups), dtype=np.int64)
    members = {}
    for i, g in enumerate(groups):
        members.setdefault(g, []).append(i)
    offset = int(rng.integers(k))
    for g in sorted(members):
        idx = rng.permutation(members[g])
        for j, i in enumerate(idx):
            folds[i] = (offset + j) % k
        offset = (offset + len(idx)) % k
    for f in range(k):  # every fold needs a case
        if not np.any(folds == f):
            counts = np.bincount(folds, minlength=k)
            donor = int(np.argmax(counts))
            folds[int(np.flatnonzero(folds == donor)[0])] = f
    return folds


def window_clusters(windows_per_case, min_clusters: int) -> np.ndarray:
    """Cluster id of every prediction window: its case, or a block of its case when there are few cases."""
    counts = np.asarray(windows_per_case, dtype=np.int64)
    blocks = max(1, int(np.ceil(min_clusters / max(len(counts), 1))))
    ids, next_id = [], 0
    for n in counts:
        b = max(1, min(blocks, int(n)))
        ids.append(next_id + (np.arange(n) * b) // max(n, 1))
        next_id += b
    return np.concatenate(ids) if ids else np.zeros(0, dtype=np.int64)


#: Relative resolution of a held-out loss: every fit stops at a relative change of its cost of 1e-6 (``ftol`` of
#: :func:`reachconf.diagnose.fit.fit_candidate`); held-out losses that differ by less than ten times that share are
#: the same model on these data.
LOSS_RESOLUTION = 1e-5


def paired_test(losses_a, losses_b, clusters) -> dict:
    """Does model ``a`` predict the held-out windows better than ``b``?

    Returns ``{"gain": share of b's held-out loss that a removes (0 when b's total is not positive),
    "removed": the loss a removes (loss units), "z": cluster-robust z statistic, "se": its standard error
    (loss units), "clusters": number of clusters}``; ``z > 0`` favours ``a``.
    """
    D = np.bincount(clusters, weights=np.asarray(losses_b) - np.asarray(losses_a))
    C = D.size
    G = float(D.sum())
    with np.errstate(over="ignore"):  # a diverged held-out prediction (loss ~1e170): var = inf, z = 0, as it should
        var = C / (C - 1) * float(np.sum((D - D.mean()) ** 2)) if C > 1 else 0.0
    total_a, total_b = float(np.sum(losses_a)), float(np.sum(losses_b))
    # two fits of the same model on these data differ by the fits' tolerance, not by evidence: the standard error
    # is at least the losses' resolution (else equivalent models "differ" with z ~ G / 0 on round-off)
    se = max(float(np.sqrt(var)), LOSS_RESOLUTION * max(abs(total_a), abs(total_b)))
    z = G / se if se > 0 else (np.inf if G > 0 else (-np.inf if G < 0 else 0.0))
    return {"gain": G / total_b if total_b > 0 else 0.0, "removed": G, "z": float(z), "se": se,
            "clusters": int(C)}  # fmt: skip


def cross_fit(base_model, cand: Candidate, data, folds, sigma, fit_names, options, cache, start=None,
              targets=None, score=None, fits=None) -> Scored:  # fmt: skip
    """Fit ``cand`` on all folds but one, predict the left-out fold; for each fold.

    ``start``: one dict of starting values for every fold, or a list with one per fold.  ``targets``: per fold,
    the residuals the training cases are fitted to (:func:`reachconf.diagnose.fit.fit_candidate`), or None.
    ``score(f, fit, idx)``: the per-window values of the held-out cases ``idx`` under fold ``f``'s fit (default:
    their losses, :func:`reachconf.diagnose.fit.window_losses`).  ``fits``
    (:class:`~reachconf.diagnose.parallel.FitMap`) runs the fold fits (default: one after the other, here).
    """
    k = int(folds.max()) + 1
    jobs = []
    for f in range(k):
        train = [d for d, g in zip(data, folds) if g != f]
        st = start[f] if isinstance(start, list) else start
        tg = targets[f] if targets is not None else None
        jobs.append(partial(fit_candidate, base_model, cand, train, sigma, fit_names, options, cache, start=st,
                            target=tg))  # fmt: skip
    fits = fits(jobs) if fits is not None else [job() for job in jobs]

    def values(f, idx):
        if score is not None:
            return score(f, fits[f], idx)
        return window_losses(fits[f], [data[i] for i in idx], sigma, options)

    return Scored(cand, held_out(values, data, folds), fits)


def held_out(values_of, data, folds) -> np.ndarray:
    """Per-window values of ``data`` (cases in order) from ``values_of(f, idx)``: the values of the cases ``idx``
    (those of fold ``f``, in order, their windows concatenated)."""
    counts = np.array([d.starts.size for d in data])
    first = np.concatenate([[0], np.cumsum(counts)])
    out = np.zeros(int(counts.sum()))
    for f in range(int(folds.max()) + 1):
        idx = np.flatnonzero(folds == f)
        held = values_of(f, idx)
        pos = 0
        for i in idx:
            out[first[i] : first[i + 1]] = held[pos : pos + counts[i]]
            pos += counts[i]
    return out


def _admissible(m: Scored, base: Scored, singles: dict, clusters, options, spread=None, reweigh=None,
                relevance_of=None) -> tuple:  # fmt: skip
    """(admissible, tests): a one-effect model against the base, a two-effect model against each of its parts.

    ``spread(m)``: the relative spread of ``m``'s effects across groups (or None), asked only when a
    significant gain is below ``min_improvement`` but at least ``consistent_gain``.  ``reweigh(r)``: per-window
    factors of the losses when a two-effect model is tested against its part ``r`` (or None: unchanged).
    ``relevance_of``: the loss the relevance shares are taken of (None: the loss of the model tested against)."""
    keys = m.candidate.keys
    if m.at_bound:  # the data push the effect past its plausible range: it stands in for something else
        return False, [{"against": "bounds", "at_bound": list(m.at_bound)}]
    if len(keys) == 1:
        refs = [base]
    else:
        refs = [singles.get(frozenset({(e.name, tgt)})) for e, tgt in m.candidate.parts]  # (in a fixed order)
        if any(r is None for r in refs):
            return False, []
    tests = []
    ok = True
    for r in refs:
        f = reweigh(r) if reweigh is not None and len(keys) > 1 else None
        t = paired_test(m.losses, r.losses, clusters) if f is None else paired_test(m.losses * f, r.losses * f, clusters)
        t["against"] = r.label
        if relevance_of is not None:  # the share of a fixed loss (the base's loss of a reference run's change)
            t["gain"] = t["removed"] / relevance_of  # (also when the part's own excess is <= 0)
        tests.append(t)
        relevant = t["gain"] >= options.min_improvement
        if not relevant and ok and t["z"] >= options.z_name and t["gain"] >= options.consistent_gain:
            s = spread(m) if spread is not None and options.max_spread > 0 else None
            t["spread"] = s
            relevant = s is not None and s <= options.max_spread
        ok &= t["z"] >= options.z_name and relevant
    return bool(ok), tests


def decide(base: Scored, models: list, clusters, options, mimic=None, spread=None, reweigh=None,
           relevance_of=None) -> dict:  # fmt: skip
    """The naming rule (module docstring) on scored models.

    Parameters
    ----------
    base : Scored
    models : list of Scored
    clusters : ndarray
        Cluster id of every window (:func:`window_clusters`).
    options : DiagnoseOptions
    mimic : callable, optional
        ``mimic(chosen, other) -> float or None``: the loss (noise units, all
        windows) that ``other`` refitted to ``chosen``'s predictions cannot
        remove (:func:`reachconf.diagnose.separable.mimic_loss`); None: not
        checked.  Without it, the held-out test alone rules alternatives out.
    spread : callable, optional
        ``spread(model) -> float or None``: the relative spread of the
        model's effects across maneuver groups
        (:func:`reachconf.diagnose.consistency.model_spread`); None: the
        consistency route is closed.
    reweigh : callable, optional
        ``reweigh(single) -> ndarray``: per-window factors of the held-out
        losses when a two-effect model is tested against its one-effect part
        ``single`` (``loss_scale = "case"``: the case weights recomputed from
        that part's own held-out misfit, :func:`reachconf.diagnose.scales.reweigh_factors`);
        None: the losses as scored.
    relevance_of : float, optional
        The loss of which every relevance share is taken (``min_improvement``,
        ``consistent_gain``); None: the loss of the model tested against.  With a
        reference run (:mod:`reachconf.diagnose.reference`) it is the base
        model's loss of the change, so that a second effect must explain a share of the
        change itself, not of what the first effect left of it (near zero).

    Returns
    -------
    dict
        ``status`` ("named", "indistinguishable" or "none"), ``chosen`` (the
        chosen :class:`Scored` or None), ``alternatives`` (list of ``(Scored,
        test)``; ``test["identifiable"]`` is False for those the held-out test
        ruled out but the data cannot separate), ``tests`` (label ->
        admissibility tests), ``admissible`` (labels), ``best`` (the
        lowest-loss model, admissible or not), ``identifiability`` (label ->
        ``{"mimic_loss", "expected_z", "z"}`` of every checked alternative).
    """
    singles = {m.candidate.keys: m for m in models if len(m.candidate.keys) == 1}
    tests, admissible = {}, []
    for m in models:
        ok, t = _admissible(m, base, singles, clusters, options, spread, reweigh, relevance_of)
        tests[m.label] = t
        if ok:
            admissible.append(m)
    ranked = sorted(models, key=lambda m: m.total)
    best = ranked[0] if ranked else None
    if not admissible:
        return {"status": "none", "chosen": None, "alternatives": [], "tests": tests, "admissible": [], "best": best,
                "identifiability": {}}  # fmt: skip
    chosen = min(admissible, key=lambda m: m.total)
    alternatives, checked = [], {}
    for m in sorted(admissible, key=lambda m: m.total):
        if m is chosen:
            continue
        a, b = chosen.candidate.keys, m.candidate.keys
        if a <= b or b <= a:
            continue  # nested: decided by admissibility
        t = paired_test(chosen.losses, m.losses, clusters)
        t["identifiable"] = True
        if t["z"] < options.z_separate:
            alternatives.append((m, t))
            continue
        D = mimic(chosen, m) if mimic is not None else None
        if D is None:
            continue
        expected = float(D / t["se"]) if t["se"] > 0 else (np.inf if D > 0 else 0.0)
        checked[m.label] = {"mimic_loss": float(D), "expected_z": expected, "z": t["z"]}
        if expected < options.z_separate:  # the data cannot show the difference even if the chosen model were right
            t.update(identifiable=False, mimic_loss=float(D), expected_z=expected)
            alternatives.append((m, t))
    return {"status": "indistinguishable" if alternatives else "named", "chosen": chosen,
            "alternatives": alternatives, "tests": tests, "admissible": [m.label for m in admissible],
            "best": best, "identifiability": checked}  # fmt: skip


def fold_start(scored: Scored) -> dict:
    """Starting values from the fold fits of ``scored``: mean base and effect parameters."""
    start = {}
    for f in scored.folds:
        for key, th in f.effect_params.items():
            start.setdefault(key, []).append(th)
        for n, v in f.base_params.items():
            start.setdefault(n, []).append(v)
    return {k: (tuple(np.mean(v, axis=0)) if isinstance(k, tuple) else float(np.mean(v))) for k, v in start.items()}


#: Fewer maneuver groups than this: the parts are the cases; fewer parts: no per-part fits.
MIN_PARTS = 3


def maneuver_parts(data) -> list:
    """The cases split by maneuver group; one case per part when there are fewer than ``MIN_PARTS`` groups."""
    groups = {}
    for d in data:
        groups.setdefault(d.group, []).append(d)
    return list(groups.values()) if len(groups) >= MIN_PARTS else [[d] for d in data]


def full_fit(base_model, scored: Scored, data, sigma, fit_names, options, cache, spread: bool = True,
             fits=None) -> FitResult:  # fmt: skip
    """The chosen candidate fitted on all cases, for its parameters and their intervals.

    With ``spread``, it is also fitted on each group of cases alone (on each
    case when there are fewer than three groups): ``FitResult.spread``.
    ``fits`` (:class:`~reachconf.diagnose.parallel.FitMap`) runs those fits
    (default: one after the other, here).
    """
    start = fold_start(scored)
    fit = fit_candidate(base_model, scored.candidate, data, sigma, fit_names, options, cache, start=start)
    if spread:
        parts = maneuver_parts(data)
        if len(parts) >= MIN_PARTS:
            st = {**fit.base_params, **fit.effect_params}
            jobs = [partial(fit_candidate, base_model, scored.candidate, sub, sigma, fit_names, options, cache, start=st)
                    for sub in parts]  # fmt: skip
            for fg in fits(jobs) if fits is not None else [job() for job in jobs]:
                for key, th in fg.effect_params.items():
                    fit.spread.setdefault(key, []).append(tuple(float(v) for v in th))
    return fit
