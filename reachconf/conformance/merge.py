"""The merge of section 4.3.2: ``W_RC,Mnvr`` per group, every group's α-search on the run's one pool.

Per group (maneuver) the hull of its cases' ``W_RC`` is scaled by the
α-search of eq. 68 until it is reachset conformant for every case of the
group.  The reach checks are tasks of the run's :class:`~reachconf.runner.Pool`:
with a parallel pool every group searches in a thread of its own and all of
them feed the same workers; a check stops at the first failing member (the
likeliest failure is checked first), in batches sized so that the workers
stay busy.  The boxes do not depend on how the checks ran.
"""

from __future__ import annotations

import math
import threading
import time

import numpy as np

from reachconf.conformance.alpha import alpha_search, reachset_check
from reachconf.runner.pool import progress_bar
from reachconf.sets.core import Interval
from reachconf.verdict import Verdict

__all__ = ["merge_groups", "merge_group", "check_job"]


def check_job(job) -> Verdict:
    """Task of a merge check: ``(model, case, W, V, options)`` -> the verdict (the check stops at the first violation)."""
    model, case, W, V, options = job
    return reachset_check(model, case, W, V, options).verdict


def _conformant(verdict) -> bool:
    return Verdict(verdict) is Verdict.CONFORMANT


def _hull(syntheses) -> Interval:
    """The interval hull of the cases' ``W_RC``."""
    return Interval(np.min([cs.W_RC.lo for cs in syntheses], axis=0), np.max([cs.W_RC.hi for cs in syntheses], axis=0))


def merge_group(model, members, Vbox, options, pool, batch=1, stop=None, step=None):
    """``W_RC,Mnvr`` of one group: the α-search on the hull of its cases' ``W_RC`` over all of them.

    When that fails and some but not all cases are conformant alone (and
    ``options.alpha_below_failed_reach``), the search is repeated on the hull
    of those cases' ``W_RC``; the box must still pass every case.

    Parameters
    ----------
    members : list of (TestCase, CaseSynthesis)
    batch : int or callable
        Members checked at once (a callable is asked before every batch).
    stop : threading.Event, optional
        Set when the run stops (see :meth:`Pool.each <reachconf.runner.pool.Pool.each>`).
    step : callable, optional
        Called after every α trial (progress).

    Returns
    -------
    (Interval, float, bool, float, Verdict)
        The box, α, conformant, seconds and the verdict: not conformant if a
        member's measurement left its set at the largest α, undecided if only
        reaches failed there.
    """
    t0 = time.perf_counter()
    hull = _hull([cs for _, cs in members])
    # the member most likely to fail is checked first and a check stops at the first failure
    order = sorted(range(len(members)), key=lambda j: (members[j][1].conformant, -members[j][1].alpha))

    failed = []  # verdicts of the members that failed the last check

    def check(W):
        failed.clear()
        jobs = [(model, members[j][0], W, Vbox, options) for j in order]
        size = batch() if callable(batch) else batch
        bad = pool.first_failures(check_job, jobs, ok=_conformant, batch=size, stop=stop)
        if step is not None:
            step()
        if bad:
            failed.extend(Verdict(v) for _, v in bad)
            first = [order[i] for i, _ in bad]
            order[:] = first + [j for j in order if j not in first]
            # a member whose reach failed fails again in a larger box: alpha_search stops doubling
            return Verdict.UNDECIDED if Verdict.UNDECIDED in failed else Verdict.NOT_CONFORMANT
        return Verdict.CONFORMANT

    iterations = options.merge_iterations or options.alpha_iterations
    below = options.alpha_below_failed_reach
    alpha, W, ok, _ = alpha_search(check, hull, iterations, options.alpha_max, below)
    alone = [cs for _, cs in members if cs.conformant]
    if not ok and below and 0 < len(alone) < len(members):
        # a case that is not conformant alone has no W_RC (its box is the trace box of a failed search) and can
        # widen the hull beyond any reach: the hull of the cases conformant alone, still checked on every case
        alpha, W, ok, _ = alpha_search(check, _hull(alone), iterations, options.alpha_max, below)
    verdict = Verdict.CONFORMANT if ok else (Verdict.NOT_CONFORMANT if Verdict.NOT_CONFORMANT in failed
                                             else Verdict.UNDECIDED)  # fmt: skip
    return W, alpha, ok, time.perf_counter() - t0, verdict


def merge_groups(model, cases, per_case, Vbox, options, pool, progress=None):
    """The merge of every group on ``pool`` (all groups' α-searches at once when it is parallel).

    Returns ``(groups, group_alpha, group_conformant, group_seconds, group_verdict)``,
    dicts keyed by group in the order the groups first appear.
    """
    by_group: dict = {}
    for case, cs in zip(cases, per_case):
        by_group.setdefault(case.group, []).append((case, cs))
    iterations = options.merge_iterations or options.alpha_iterations
    bar = progress_bar(len(by_group) * (iterations + 1), "merge", progress, unit="check")
    lock = threading.Lock()
    active = [len(by_group)]

    def step():
        with lock:
            if bar.total is not None and bar.n >= bar.total:  # α was doubled: more checks than estimated
                bar.total += 1
            bar.update()

    def batch():  # keep the workers busy: fewer groups left -> more members of each checked at once
        with lock:
            return max(1, math.ceil(pool.size / max(active[0], 1)))

    def one(item, stop):
        g, members = item
        try:
            return merge_group(model, members, Vbox, options, pool, batch, stop, step)
        finally:
            with lock:
                active[0] -= 1

    try:
        done = pool.each(one, list(by_group.items()))
    finally:
        bar.close()
    out = ({}, {}, {}, {}, {})
    for g, values in zip(by_group, done):
        for d, v in zip(out, values):
            d[g] = v
    return out
