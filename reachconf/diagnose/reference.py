"""What changed since a reference run: the diagnosis of the *rise* of the misfit.

``rc.diagnose(model, suite, reference=ref)`` asks which unmodelled effect
explains how ``suite`` differs from a recording of the same cases without
the change (the drive before a software update, a clean recording in a
withheld-effect test) — fault isolation against a fault-free reference.

Every scored model (the base, each single effect, each pair) is also
cross-fitted on the reference cases, with the same folds, loss scale and
case weights, and its held-out loss per prediction window there is
subtracted from its loss on the suite: the *excess loss* ``e(m) = L(m) -
L_ref(m)``.  The base model's excess is the misfit the change added; an
effect that is the change removes it on the suite and finds nothing to fit
on the reference (``e -> 0``), while an effect that only absorbs the base
model's structural misfit (a real car's lateral-velocity misfit, a small
lag of the plant's own) removes about as much on both recordings (``e``
unchanged).  The naming rule of :func:`reachconf.diagnose.select.decide` is
then applied to the excess losses unchanged: significance (``z_name``) by
the cluster-robust paired test of the windows, relevance
(``min_improvement``) as the share of the *excess* an effect removes.

When the base model's excess is not significant, the change may still be
there: an effect the recordings share can *move* so that the base model's
misfit does not grow — a sensor bias of the car's own (+0.02 rad/s) and a
new one of the opposite sign cancel, an acceleration scale of 0.96 becomes
1.056.  The base model sees no change, but each effect's *reference fit*
does: fitted on the reference, it predicts the suite worse than the
reference.  :func:`shift_decision` then applies the naming rule to the one-effect
models with, in place of the base, the *frozen excess* of each effect
(:func:`frozen_excess`: ``f(m) = L(m; theta_ref) - L_ref(m; theta_ref)``, the
reference's fold fits predicting the same held-out windows of both
recordings): an effect is named when its reference fit sees a change
(``z_name``) and refitting it on the suite removes at least
``min_improvement`` of that frozen excess with ``z >= z_name`` — its
parameter moved, by what the report gives as the named value against the
reference's.  Two recordings without a change give ``f = 0`` for every
effect.

The windows are paired one to one, so the reference must hold the same
cases: the same number, in the same order, with the same sample times.
"""

from __future__ import annotations

import os

import numpy as np

from reachconf.diagnose.fit import prepare, window_counts
from reachconf.diagnose.select import Scored, decide, held_out_losses, paired_test
from reachconf.errors import OptionsError

__all__ = ["prepare_reference", "excess_scores", "change_test", "frozen_excess", "parameter_change", "shift_decision"]


def prepare_reference(model, reference, prepared, options) -> list:
    """The reference cases prepared like the suite's, checked to pair with them window by window.

    ``reference``: a :class:`~reachconf.io.TestSuite`, a list of test cases, or the path of a suite folder.

    Raises
    ------
    OptionsError
        When the reference holds another number of cases, or a case with other sample times.
    """
    if isinstance(reference, (str, os.PathLike)):  # a suite folder
        from reachconf.io import load_suite

        reference = load_suite(reference, model=model)
    if not hasattr(reference, "__iter__"):
        raise OptionsError(f"reference must be a TestSuite, a list of TestCase or a suite folder, "
                           f"got {type(reference).__name__}")  # fmt: skip
    cases = list(reference)
    if len(cases) != len(prepared):
        raise OptionsError(f"reference: it holds {len(cases)} test cases, the suite {len(prepared)}; the reference "
                           "must hold the same cases (same order and sample times) without the change")  # fmt: skip
    ref = [prepare(model, c, options) for c in cases]
    for d, r in zip(prepared, ref):
        if d.t.shape != r.t.shape or not np.allclose(d.t, r.t, rtol=0.0, atol=1e-9 * max(1.0, float(np.abs(d.t).max()))):
            raise OptionsError(f"reference: case {r.name!r} does not have the sample times of the suite's case "
                               f"{d.name!r}; the windows are compared one to one")  # fmt: skip
    if not np.array_equal(window_counts(ref), window_counts(prepared)):  # pragma: no cover - same times, same windows
        raise OptionsError("reference: its prediction windows differ from the suite's")
    return ref


def excess_scores(scored: Scored, on_ref: Scored) -> Scored:
    """``scored`` with its held-out losses replaced by the excess over the reference (same fold fits).

    The reference's scoring is kept as ``.ref`` (for :func:`frozen_excess`)."""
    return Scored(scored.candidate, np.asarray(scored.losses) - np.asarray(on_ref.losses), scored.folds, ref=on_ref)


def change_test(base: Scored, base_ref: Scored, clusters) -> dict:
    """Is the base model's misfit larger on the suite than on the reference?

    ``{"excess_loss", "share" (of the suite's base loss), "z"}``; ``z > 0``: larger on the suite.
    """
    t = paired_test(base_ref.losses, base.losses, clusters)  # a = reference, b = suite: G = L - L_ref
    total = float(np.sum(base.losses))
    excess = float(np.sum(base.losses) - np.sum(base_ref.losses))
    return {"excess_loss": excess, "share": excess / total if total > 0 else 0.0, "z": t["z"]}


def frozen_excess(scored: Scored, prepared, folds, sigma, options) -> Scored:
    """``f(m)`` per window: the reference's fold fits of ``scored`` predicting the suite's held-out windows,
    minus their held-out loss on the reference (the same windows; module docstring)."""
    on_ref = scored.ref
    on_suite = held_out_losses(on_ref.folds, prepared, folds, sigma, options)
    return Scored(scored.candidate, on_suite - np.asarray(on_ref.losses), on_ref.folds)


def parameter_change(scored: Scored) -> float:
    """The z of the change of ``scored``'s effect parameters between the reference and the suite.

    Per fold, the suite's fit minus the reference's (both trained on the same, paired cases) against the
    cluster-robust standard error of that *difference*: from the paired per-case influences of the two fits
    (:func:`reachconf.diagnose.fit._robust_cov`), so that what the two recordings share (the model's misfit
    in each case, the same inputs) cancels and what differs (the noise, the change) remains; without
    anything shared it is the root sum of squares of the two fits' standard deviations.  Fold means of the differences and of the errors; the largest ``|z|`` over the
    effect's parameters.  0 when a fit has no influences.
    """
    (key,) = scored.candidate.keys
    deltas, ses = [], []
    for fs, fr in zip(scored.folds, scored.ref.folds):
        idx = [i for i, lab in enumerate(fs.labels) if lab.startswith(f"{key[0]}.") and lab.endswith(f"({key[1]})")]
        if fs.influence is None or fr.influence is None or fs.influence.shape != fr.influence.shape or not idx:
            return 0.0
        D = fs.influence[:, idx] - fr.influence[:, idx]
        C = D.shape[0]
        ses.append(np.sqrt(C / (C - 1) * np.sum(D**2, axis=0)) if C > 1 else np.full(len(idx), np.nan))
        deltas.append(np.asarray(fs.effect_params[key]) - np.asarray(fr.effect_params[key]))
    delta, se = np.abs(np.mean(deltas, axis=0)), np.mean(ses, axis=0)
    z = np.where(se > 0, delta / np.where(se > 0, se, 1.0), np.where(delta > 0, np.inf, 0.0))
    return float(np.nanmax(z)) if np.any(np.isfinite(z)) else 0.0


def shift_decision(base: Scored, models, prepared, folds, clusters, sigma, options, mimic=None):
    """The naming rule for a moved effect, when the base model sees no change (module docstring).

    ``models``: the scored models (excess losses, with ``.ref``); the one-effect ones whose reference fit
    predicts the suite worse than the reference (``f(m) > 0`` in total) are considered.  Significance: the z
    of the parameter's change (:func:`parameter_change`); relevance: the share of ``f(m)`` that refitting the
    effect on the suite removes.  Returns ``(decision, shifts)``: :func:`reachconf.diagnose.select.decide`'s
    result and, per one-effect label, ``{"frozen_excess": f's total, "z": f's paired z, "reference_params":
    the reference's fit (fold mean), "z_change", "test"}``.
    """
    against, shifts, seen = {}, {}, []
    for m in models:
        if len(m.candidate.keys) != 1 or m.ref is None:
            continue
        f = frozen_excess(m, prepared, folds, sigma, options)
        t = paired_test(np.zeros_like(f.losses), f.losses, clusters)  # z > 0: f > 0, the suite predicted worse
        (e, _), = m.candidate.parts
        (th,) = m.ref.fold_params().values()
        zc = parameter_change(m)
        shifts[m.label] = {"frozen_excess": f.total, "z": t["z"], "z_change": zc,
                           "reference_params": dict(zip(e.params, map(float, th))), "test": None}  # fmt: skip
        if f.total > 0:  # the effect's reference fit predicts the suite worse than the reference
            against[m.label] = (f, zc)
            seen.append(m)
    d = decide(base, seen, clusters, options, mimic=mimic, against=against)
    for label, tests in d["tests"].items():
        for t in tests:
            if t.get("against") == label:
                t["against"] = f"{label} as fitted on the reference"
        shifts[label]["test"] = tests[0] if tests else None
    return d, shifts
