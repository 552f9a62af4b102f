"""Round trip of the conformance engine on a suite with a known disturbance box W* and noise in V."""

import numpy as np
import pytest

import reachconf as rc
from reachconf.conformance import (
    SynthesisOptions,
    pareto_front,
    reachset_conformance,
    synthesize_W,
    trace_conformance,
)
from reachconf.io import TestCase, TestSuite
from reachconf.model.simulate import simulate

W_STAR = rc.Interval([-1.0, -0.5], [1.0, 0.5])
V_RAD = np.array([0.01, 0.01])
V_SET = rc.Interval(-V_RAD, V_RAD)


def plant():
    return rc.Model(
        name="coupled_decay",
        states=("x1", "x2"),
        disturbances=("w1", "w2"),
        dynamics=lambda s: [-s.x1 + 0.3 * s.x2 + s.w1, -2.0 * s.x2 + 0.5 * s.x1 + s.w2],
    )


def make_suite(model, n=3, duration=6.0, dt=0.05):
    cases = []
    for seed in range(n):
        rng = np.random.default_rng(seed)
        t = np.round(np.arange(0.0, duration + 1e-9, dt), 10)
        hold = 20  # disturbance held for 1 s: the states approach the extremes W* allows
        levels = rng.uniform(W_STAR.lo, W_STAR.hi, size=(t.size // hold + 1, model.q))
        levels[0] = W_STAR.hi  # make sure both channels are excited to their bounds
        levels[1] = W_STAR.lo
        w = levels.repeat(hold, axis=0)[: t.size]
        X = simulate(model, [0.0, 0.0], t, disturbances=w, substeps=20)
        Y = X + rng.uniform(-V_RAD, V_RAD, size=X.shape)
        cases.append(TestCase(f"case{seed}", "steps", t, np.zeros((t.size, 0)), Y, (), model.output_names))
    return TestSuite(cases, name="round trip")


@pytest.fixture(scope="module")
def model():
    return plant()


@pytest.fixture(scope="module")
def suite(model):
    return make_suite(model)


@pytest.fixture(scope="module")
def synthesis(model, suite):
    return synthesize_W(model, suite, V_SET, SynthesisOptions(alpha_iterations=8))


def test_true_sets_are_trace_and_reachset_conformant(model, suite):
    for case in suite:
        assert trace_conformance(model, case, W_STAR, V_SET, method="optctrl").conformant
        res = reachset_conformance(model, case, W_STAR, V_SET)
        assert res.conformant and res.max_violation == 0.0


@pytest.mark.parametrize("channel", [0, 1])
def test_half_box_on_an_excited_channel_is_not_conformant(model, suite, channel):
    lo, hi = W_STAR.lo.copy(), W_STAR.hi.copy()
    lo[channel] *= 0.5
    hi[channel] *= 0.5
    half = rc.Interval(lo, hi)
    assert not any(trace_conformance(model, c, half, V_SET, method="optctrl").conformant for c in suite)
    results = [reachset_conformance(model, c, half, V_SET) for c in suite]
    assert not all(r.conformant for r in results)
    bad = [r for r in results if not r.conformant]
    assert all(r.first_violation_time is not None and r.max_violation > 0 for r in bad)


def test_minimal_trace_bounds_inside_true_box(model, suite):
    box = rc.minimal_trace_bounds(model, suite, V=V_SET, method="optctrl")
    tol = 0.02 * (W_STAR.hi - W_STAR.lo)  # solver tolerance of the SCP
    assert np.all(box.lo >= W_STAR.lo - tol) and np.all(box.hi <= W_STAR.hi + tol)
    assert all(trace_conformance(model, c, box, V_SET, method="optctrl").conformant for c in suite)


def test_synthesis_shrinks_and_stays_conformant(model, suite, synthesis):
    res = synthesis
    assert set(res.cases) == {c.name for c in suite}
    for case in suite:
        cs = res.cases[case.name]
        assert cs.conformant
        assert np.all(cs.W_RC.lo >= cs.W_TC.lo - 1e-12) and np.all(cs.W_RC.hi <= cs.W_TC.hi + 1e-12)
        assert cs.W_RC.volume() < cs.W_TC.volume()
        assert 0 < cs.alpha <= 1
        assert reachset_conformance(model, case, cs.W_RC, V_SET).conformant
        assert set(cs.step_seconds) == {"step1", "step2", "step3"}
    W = res.groups["steps"]
    assert res.group_conformant["steps"]
    assert all(reachset_conformance(model, c, W, V_SET).conformant for c in suite)
    d = res.to_dict()
    assert d["groups"]["steps"] == W.to_list()
    assert "| steps |" in res.table()


def test_alpha_search_is_tight(model, suite, synthesis):
    """Just below the found alpha the case is not reachset conformant (up to the bisection step)."""
    cs = synthesis.cases["case0"]
    c, g = cs.W_opt.center, cs.W_opt.radius
    below = max(cs.alpha - 2.0 ** -8, 0.0)
    smaller = rc.Interval(c - below * g, c + below * g)
    assert not reachset_conformance(model, suite[0], smaller, V_SET).conformant


def test_failed_reach_is_never_conformant():
    m = rc.Model(name="blowup", states=("x",), disturbances=("w",), dynamics=lambda s: [s.x**2 + s.w])
    t = np.linspace(0, 3, 31)
    case = TestCase("c", "g", t, np.zeros((t.size, 0)), np.ones((t.size, 1)), (), ("x",))
    res = reachset_conformance(m, case, rc.Interval([-0.1], [0.1]), rc.Interval([-0.01], [0.01]),
                               X0=rc.Interval([0.9], [1.1]))  # fmt: skip
    assert not res.conformant
    assert res.message and res.max_violation == float("inf")


def test_pareto_front_boxes_are_conformant_and_non_dominated(model, suite, synthesis):
    start = synthesis.groups["steps"]
    front = pareto_front(model, suite.select(names=["case0"]), V_SET, start, iterations=4)
    assert 1 <= len(front.boxes) <= model.q
    W = front.widths
    for i in range(len(W)):
        for j in range(len(W)):
            if i != j:
                assert not (np.all(W[j] <= W[i]) and np.any(W[j] < W[i]))
    for box in front.boxes:
        assert reachset_conformance(model, suite[0], box, V_SET).conformant
        assert np.all(box.hi - box.lo <= start.hi - start.lo + 1e-12)


def test_serial_processes_and_dask_agree(model, suite):
    opts = SynthesisOptions(alpha_iterations=4, optimize=False, merge=False)
    small = suite.select(names=["case0", "case1"])
    serial = synthesize_W(model, small, V_SET, opts)
    procs = synthesize_W(model, small, V_SET, opts, workers=2)
    distributed = pytest.importorskip("dask.distributed")
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=False, dashboard_address=None) as cluster:
        with distributed.Client(cluster) as client:
            dask = synthesize_W(model, small, V_SET, opts, scheduler=client)
    for other in (procs, dask):
        for name, cs in serial.cases.items():
            o = other.cases[name]
            assert o.alpha == cs.alpha
            np.testing.assert_array_equal(o.W_RC.lo, cs.W_RC.lo)
            np.testing.assert_array_equal(o.W_RC.hi, cs.W_RC.hi)


def test_bad_options_and_sets_raise_reachconf_errors():
    import numpy as np
    import pytest

    import reachconf as rc
    from reachconf.conformance import SynthesisOptions
    from reachconf.errors import OptionsError, ReachconfError
    from reachconf.runner import run_cases

    with pytest.raises(OptionsError):
        SynthesisOptions(alpha_iterations=0)
    with pytest.raises(OptionsError):
        run_cases(abs, [1, 2], workers=0)
    m = rc.models.get_model("vanderpol") if hasattr(rc.models, "get_model") else None
    assert m is not None
    suite = rc.TestSuite([rc.TestCase("c", "g", np.array([0.0, 0.1, 0.2]), np.zeros((3, m.m)),
                                      np.zeros((3, m.p)), m.input_names, m.output_names)])  # fmt: skip
    with pytest.raises(ReachconfError):  # V of the wrong dimension
        rc.reachset_conformance(m, suite, W=rc.Interval(-np.ones(m.q), np.ones(m.q)),
                                V=rc.Interval(-np.ones(m.p + 1), np.ones(m.p + 1)))  # fmt: skip
    with pytest.raises(OptionsError):
        rc.pareto_front(m, suite, rc.Interval(-np.ones(m.p), np.ones(m.p)), rc.Interval(-np.ones(m.q), np.ones(m.q)),
                        check="x")  # fmt: skip


@pytest.mark.parametrize("needed, alpha_max, expect_ok", [(0.3, 1.0, True), (0.3, 4.0, True), (2.5, 4.0, True),
                                                          (2.5, 1.0, False), (5.0, 4.0, False)])  # fmt: skip
def test_alpha_search_brackets_the_smallest_conformant_alpha(needed, alpha_max, expect_ok):
    from reachconf.conformance.synthesis import alpha_search

    W = rc.Interval(np.array([-1.0, 0.0]), np.array([1.0, 2.0]))  # centre (0, 1), radius (1, 1)
    alpha, box, ok, trials = alpha_search(lambda B: B.radius[0] >= needed - 1e-12, W, 12, alpha_max)
    assert ok is expect_ok
    if expect_ok:
        assert needed - 1e-12 <= alpha <= needed + max(1.0, needed) * 2.0**-11
        np.testing.assert_allclose(box.center, W.center)
        np.testing.assert_allclose(box.radius, alpha * W.radius)
        assert all(ok_ == (a >= needed - 1e-12) for a, ok_ in trials)
    else:
        assert alpha == alpha_max


@pytest.mark.parametrize("bad", [{"alpha_max": 0.5}, {"alpha_max": float("inf")}, {"alpha_max": float("nan")},
                                 {"merge_iterations": 0}, {"merge_iterations": 2.5}, {"reach": "fast"},
                                 {"reach_fallback": {"tensor_order": 3}}, {"alpha_below_failed_reach": "yes"}])  # fmt: skip
def test_bad_synthesis_options_raise(bad):
    with pytest.raises(rc.OptionsError, match=next(iter(bad))):
        SynthesisOptions(**bad)


def test_reach_fallback_only_when_the_reach_itself_fails():
    """A set explosion under ``reach`` is retried with ``reach_fallback``; a missed measurement is not."""
    from reachconf.conformance import synthesis as syn

    m = rc.Model(name="blowup", states=("x",), disturbances=("w",), dynamics=lambda s: [s.x**2 + s.w])
    t = np.linspace(0, 1.5, 16)
    x = 1.0 / (1.0 / 0.5 - t)  # x' = x^2 from x(0) = 0.5, w = 0
    V = rc.Interval([-0.01], [0.01])
    case = TestCase("c", "g", t, np.zeros((t.size, 0)), x[:, None], (), ("x",))
    W = rc.Interval([-0.01], [0.01])
    coarse = rc.ReachOptions(algorithm="lin", time_step=0.1, max_splits=0, zonotope_order=1, tensor_order=2,
                             max_error=1e-4)  # fmt: skip
    fine = rc.ReachOptions(time_step=0.01, tensor_order=3)
    alone = syn.reachset_check(m, case, W, V, SynthesisOptions(reach=coarse))
    assert not alone.conformant and alone.message  # the coarse reach fails
    both = syn.reachset_check(m, case, W, V, SynthesisOptions(reach=coarse, reach_fallback=fine))
    assert both.conformant and not both.message
    # a box that misses the measurements is not retried: same verdict, and the fine options never help it
    shifted = rc.Interval([0.3], [0.32])
    assert not syn.reachset_check(m, case, shifted, V, SynthesisOptions(reach=fine, reach_fallback=coarse)).conformant
