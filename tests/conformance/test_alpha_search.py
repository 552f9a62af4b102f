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


def _three_valued(lo, hi):
    """A check: not conformant below α = lo (box too small), conformant in [lo, hi), undecided from hi on."""

    def check(box):
        a = box.radius[0] / W.radius[0]
        if a >= hi - 1e-12:
            return Verdict.UNDECIDED
        return Verdict.CONFORMANT if a >= lo - 1e-12 else Verdict.NOT_CONFORMANT

    return check


def test_below_a_failed_reach_the_window_is_found_and_narrowed():
    alpha, box, ok, trials = alpha_search(_three_valued(0.12, 0.2), W, iterations=10, alpha_max=4.0,
                                          below_failed_reach=True)  # fmt: skip
    assert ok and 0.12 <= alpha <= 0.12 + 2.0**-10
    assert trials[0] == (1.0, False) and [a for a, _ in trials[1:4]] == [0.5, 0.25, 0.125]
    np.testing.assert_allclose(box.radius, alpha * W.radius)
    # every trial marked conformant lies in the window, every other outside it
    assert all(ok_ == (0.12 - 1e-12 <= a < 0.2 - 1e-12) for a, ok_ in trials)
    # off by default (the function's default; SynthesisOptions turns it on): the search stops at α = 1
    assert alpha_search(_three_valued(0.12, 0.2), W, iterations=10, alpha_max=4.0)[2:] == (False, [(1.0, False)])


def test_no_window_below_a_failed_reach_reports_the_failed_alpha():
    alpha, box, ok, trials = alpha_search(_three_valued(0.3, 0.3), W, iterations=6, alpha_max=4.0,
                                          below_failed_reach=True)  # fmt: skip
    assert not ok and alpha == 1.0 and box == W
    assert len(trials) == 1 + 6 and not any(ok_ for _, ok_ in trials)


def test_a_window_between_a_too_small_and_an_exploding_alpha_above_one():
    alpha, _, ok, trials = alpha_search(_three_valued(1.4, 1.8), W, iterations=8, alpha_max=4.0,
                                        below_failed_reach=True)  # fmt: skip
    assert ok and 1.4 <= alpha <= 1.4 + 2.0**-8
    assert [a for a, _ in trials[:3]] == [1.0, 2.0, 1.5]


def test_the_window_on_a_real_reach_is_verified_and_alpha_one_is_not():
    """x' = x² + w explodes for a large W: α = 1 is undecided, the found α's reach holds every measurement."""
    from reachconf.conformance.alpha import reachset_check
    from reachconf.conformance.synthesis import SynthesisOptions
    from reachconf.io import TestCase

    m = rc.Model(name="blowup", states=("x",), disturbances=("w",), dynamics=lambda s: [s.x**2 + s.w])
    t = np.linspace(0, 1.5, 16)
    x = 1.0 / (1.0 / 0.5 - t)  # w = 0
    case = TestCase("c", "g", t, np.zeros((t.size, 0)), x[:, None], (), ("x",))
    V = rc.Interval([-0.01], [0.01])
    opts = SynthesisOptions(reach=rc.ReachOptions(algorithm="lin", time_step=0.05, tensor_order=2))
    big = rc.Interval([-3.0], [3.0])
    verdicts = []

    def check(box):
        verdicts.append(reachset_check(m, case, box, V, opts).verdict)
        return verdicts[-1]

    alpha, box, ok, trials = alpha_search(check, big, iterations=6, alpha_max=4.0, below_failed_reach=True)
    assert verdicts[0] is Verdict.UNDECIDED and ok and alpha < 1.0
    again = rc.reachset_conformance(m, case, box, V, options=opts.reach)
    assert again.verdict is Verdict.CONFORMANT and again.inside.all()


def test_the_merge_falls_back_to_the_hull_of_the_cases_conformant_alone(monkeypatch):
    """A case with no W_RC of its own (a huge trace box) must not make the hull unreachable; every case is still checked."""
    from types import SimpleNamespace

    from reachconf.conformance import merge
    from reachconf.conformance.synthesis import CaseSynthesis, SynthesisOptions
    from reachconf.runner.pool import Pool

    checked = []

    def fake_check(model, case, box, V, options):  # the reach explodes beyond radius 1; must cover [-0.15, 0.25]
        checked.append((case.name, float(box.lo[0]), float(box.hi[0])))
        if box.radius[0] > 1.0:
            return SimpleNamespace(verdict=Verdict.UNDECIDED)
        ok = box.lo[0] <= -0.15 and box.hi[0] >= 0.25
        return SimpleNamespace(verdict=Verdict.CONFORMANT if ok else Verdict.NOT_CONFORMANT)

    monkeypatch.setattr(merge, "reachset_check", fake_check)

    def member(name, lo, hi, ok):
        box = rc.Interval([lo], [hi])
        verdict = Verdict.CONFORMANT if ok else Verdict.UNDECIDED
        return SimpleNamespace(name=name), CaseSynthesis(name, "g", box, box, box, 1.0, ok, 0.0, {}, ok, "", [], "",
                                                         "", verdict)  # fmt: skip

    members = [member("a", -0.2, 0.2, True), member("b", -0.1, 0.3, True), member("c", 10.0, 110.0, False)]
    V = rc.Interval([-0.01], [0.01])
    with Pool() as pool:
        box, alpha, ok, _, verdict = merge.merge_group(None, members, V, SynthesisOptions(merge_iterations=8), pool)
    assert ok and verdict is Verdict.CONFORMANT
    assert box.lo[0] <= -0.15 and box.hi[0] >= 0.25 and box.radius[0] <= 1.0
    np.testing.assert_allclose(box.center, [0.05])  # the hull of a and b, not of c
    final = {name for name, lo, hi in checked if np.isclose(lo, box.lo[0]) and np.isclose(hi, box.hi[0])}
    assert final == {"a", "b", "c"}
    with Pool() as pool:  # without the option: the hull of all three, which no α makes conformant
        off = SynthesisOptions(merge_iterations=8, alpha_below_failed_reach=False)
        assert not merge.merge_group(None, members, V, off, pool)[2]
