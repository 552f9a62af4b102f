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

The windows are paired one to one, so the reference must hold the same
cases: the same number, in the same order, with the same sample times.
"""

from __future__ import annotations

import os

import numpy as np

from reachconf.diagnose.fit import prepare, window_counts
from reachconf.diagnose.select import Scored, paired_test
from reachconf.errors import OptionsError

__all__ = ["prepare_reference", "excess_scores", "change_test"]


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
    """``scored`` with its held-out losses replaced by the excess over the reference (same fold fits)."""
    return Scored(scored.candidate, np.asarray(scored.losses) - np.asarray(on_ref.losses), scored.folds)


def change_test(base: Scored, base_ref: Scored, clusters) -> dict:
    """Is the base model's misfit larger on the suite than on the reference?

    ``{"excess_loss", "share" (of the suite's base loss), "z"}``; ``z > 0``: larger on the suite.
    """
    t = paired_test(base_ref.losses, base.losses, clusters)  # a = reference, b = suite: G = L - L_ref
    total = float(np.sum(base.losses))
    excess = float(np.sum(base.losses) - np.sum(base_ref.losses))
    return {"excess_loss": excess, "share": excess / total if total > 0 else 0.0, "z": t["z"]}
