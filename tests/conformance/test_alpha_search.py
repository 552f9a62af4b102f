"""The α-search of eq. 68: doubling stops after an undecided check (found by a new-user audit: after the
reach failed at α = 1 it still tried 2 and 4, and the table printed the unverified box with α = 4)."""

import numpy as np

import reachconf as rc
from reachconf.conformance.alpha import alpha_search
from reachconf.verdict import Verdict

W = rc.Interval([-1.0, 2.0], [1.0, 4.0])


def test_a_failed_reach_is_not_retried_with_a_larger_box():
    tried = []

    def check(box):
        tried.append(box)
        return Verdict.UNDECIDED

    alpha, box, ok, trials = alpha_search(check, W, iterations=5, alpha_max=4.0)
    assert not ok and alpha == 1.0 and trials == [(1.0, False)] and len(tried) == 1 and box == W


def test_a_box_that_is_too_small_is_doubled_and_bisected():
    need = 2.6  # conformant from this α on

    def check(box):
        a = box.radius[0] / W.radius[0]
        return Verdict.CONFORMANT if a >= need - 1e-12 else Verdict.NOT_CONFORMANT

    alpha, box, ok, trials = alpha_search(check, W, iterations=12, alpha_max=4.0)
    assert ok and need <= alpha <= need + 2.0 / 2**12
    assert [a for a, _ in trials[:3]] == [1.0, 2.0, 4.0]
    np.testing.assert_allclose(box.center, W.center)


def test_plain_bool_checks_still_work():
    alpha, _, ok, trials = alpha_search(lambda box: box.radius[0] >= 0.5, W, iterations=3)
    assert ok and trials[0] == (1.0, True) and 0.5 <= alpha <= 0.625
