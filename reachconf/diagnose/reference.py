"""What changed since a reference run: the diagnosis of the *difference* between two recordings.

``rc.diagnose(model, suite, reference=ref)`` asks which unmodelled effect
explains how ``suite`` differs from a recording of the same cases without
the change (the drive before a software update, a clean recording in a
withheld-effect test) — fault isolation against a fault-free reference.

Every scored model (the base, each single effect, each pair) is also
cross-fitted on the reference cases, with the same folds, loss scale and
case weights.  How the two are compared is
:attr:`~reachconf.diagnose.options.DiagnoseOptions.reference_loss`:

* ``"difference"`` (the default): the model is fitted on the suite so that
  its residuals match the reference fit's on the paired training windows
  (:func:`~reachconf.diagnose.fit.fit_candidate`'s ``target``), and scored
  by the squared difference of the two fits' held-out residuals, window by
  window (:func:`difference_score`).  The model's own misfit, common to
  both recordings (a real car's tyre and lateral-velocity misfit), cancels
  residual by residual; what is left is the change and what the model
  cannot make of it.  The base model's difference loss is the change as
  the base sees it — also when the change *lowers* the misfit (a new sensor
  bias that cancels the car's own, an acceleration scale that moves the
  car's own 0.96 to 1.056) — and the effect that is the change removes it.
* ``"excess"``: the held-out loss on the suite minus the held-out loss on
  the reference, ``e(m) = L(m) - L_ref(m)`` (:func:`excess_scores`).  The
  base's excess must be significant (``z_name``), else the verdict is "no
  change".  Squared losses mix the change with the model's own misfit
  (``(r + d)^2 - r^2 = 2 r d + d^2``): a change that moves an effect the
  recordings share towards zero lowers the misfit and is missed, and
  effects whose difference is small next to that misfit (a dead time
  against a lag) stay indistinguishable.

The naming rule of :func:`reachconf.diagnose.select.decide` is then applied
to these losses unchanged: significance (``z_name``) by the cluster-robust
paired test of the windows, relevance (``min_improvement``) as the share of
the base model's loss (of the change) that an effect removes.  Without a
change the difference of two recordings is their noise, which no effect
predicts: the verdict is "no change" when nothing is named and the base's
excess is not significant — and when the reference holds the suite's own
data (outputs within a thousandth of the noise level, the same inputs),
whatever an effect fits of the two fits' numerical difference.

The windows are paired one to one, so the reference must hold the same
cases: the same number, by the same names (paired by name), with the same sample times.
"""

from __future__ import annotations

import os

import numpy as np

from reachconf.diagnose.fit import prepare, window_counts, window_residuals, window_sums
from reachconf.diagnose.select import Scored, paired_test
from reachconf.errors import OptionsError

__all__ = ["prepare_reference", "excess_scores", "difference_score", "change_test", "same_data"]


def prepare_reference(model, reference, prepared, options) -> list:
    """The reference cases prepared like the suite's, checked to pair with them window by window.

    ``reference``: a :class:`~reachconf.io.TestSuite`, a list of test cases, or the path of a suite folder.

    Raises
    ------
    OptionsError
        When the reference holds another number of cases, other case names, or a case with other sample times.
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
                           "must hold the same cases (same names and sample times) without the change")  # fmt: skip
    by_name = {c.name: c for c in cases}
    missing = [d.name for d in prepared if d.name not in by_name]
    if missing or len(by_name) != len(cases):
        what = f"has no case named {missing[:3]}" if missing else "names two cases alike"
        raise OptionsError(f"reference: it {what}; the reference's cases are paired with the suite's by name "
                           f"(the same cases without the change)")  # fmt: skip
    cases = [by_name[d.name] for d in prepared]  # paired by name, whatever their order
    ref = [prepare(model, c, options) for c in cases]
    for d, r in zip(prepared, ref):
        if d.t.shape != r.t.shape or not np.allclose(d.t, r.t, rtol=0.0, atol=1e-9 * max(1.0, float(np.abs(d.t).max()))):
            raise OptionsError(f"reference: case {r.name!r} does not have the sample times of the suite's case "
                               f"{d.name!r}; the windows are compared one to one")  # fmt: skip
    if not np.array_equal(window_counts(ref), window_counts(prepared)):  # pragma: no cover - same times, same windows
        raise OptionsError("reference: its prediction windows differ from the suite's")
    return ref


def excess_scores(scored: Scored, on_ref: Scored) -> Scored:
    """``scored`` with its held-out losses replaced by the excess over the reference (same fold fits)."""
    return Scored(scored.candidate, np.asarray(scored.losses) - np.asarray(on_ref.losses), scored.folds)


def difference_score(on_ref: Scored, prepared, ref, sigma, options):
    """The ``score`` of :func:`reachconf.diagnose.select.cross_fit` for ``reference_loss="difference"``: per held-out
    window, the squared difference of the suite fit's residuals and those of ``on_ref``'s fit of the same fold
    on the paired reference cases."""
    p = len(np.atleast_1d(sigma))

    def score(f, fit, idx):
        fr = on_ref.folds[f]
        s_cases, r_cases = [prepared[i] for i in idx], [ref[i] for i in idx]
        rr = window_residuals(fr.model, fr.candidate, fr.effect_params, r_cases, sigma, options.substeps)
        rs = window_residuals(fit.model, fit.candidate, fit.effect_params, s_cases, sigma, options.substeps)
        return window_sums((rs - rr) ** 2, s_cases, p)

    return score


def change_test(base: Scored, base_ref: Scored, clusters) -> dict:
    """Is the base model's misfit larger on the suite than on the reference?

    ``{"excess_loss", "share" (of the suite's base loss), "z"}``; ``z > 0``: larger on the suite.
    """
    t = paired_test(base_ref.losses, base.losses, clusters)  # a = reference, b = suite: G = L - L_ref
    total = float(np.sum(base.losses))
    excess = float(np.sum(base.losses) - np.sum(base_ref.losses))
    return {"excess_loss": excess, "share": excess / total if total > 0 else 0.0, "z": t["z"]}


def same_data(prepared, ref_prepared, sigma) -> bool:
    """Whether the reference's recordings equal the suite's: the same inputs, and outputs within a thousandth of
    the noise level in every sample (no change could show through that)."""
    tol = 1e-3 * np.atleast_1d(sigma)
    for d, r in zip(prepared, ref_prepared):
        if d.U.shape != r.U.shape or d.Y.shape != r.Y.shape or not np.allclose(d.U, r.U, rtol=1e-9, atol=1e-12):
            return False
        if np.any(np.abs(d.Y - r.Y) > tol):
            return False
    return True
