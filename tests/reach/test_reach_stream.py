"""Reachability in bounded memory: the streamed reach and the streamed reachset-conformance check."""

import numpy as np
import pytest

import reachconf as rc
from reachconf.conformance.reachset import initial_set, reachset_conformance
from reachconf.demo import V_TRUE, W_TRUE, make_long_case
from reachconf.models import get_model
from reachconf.reach_stream import reach_streamed

#: the fixed-step streamed layout (steps of 0.02 s); the adaptive one is in test_reach_adaptive_stream.py
OPTS = rc.ReachOptions(algorithm="lin", time_step=0.02)


@pytest.fixture(scope="module")
def setting():
    model = get_model("bicycle_closed_loop")
    case = make_long_case(1500, maneuver="weaving", seed=3)
    return model, case, initial_set(model, case, V_TRUE)


def test_streamed_reach_keeps_every_bound_and_some_sets(setting):
    model, case, X0 = setting
    full = rc.reach(model, X0, case.t, inputs=case.U, W=W_TRUE, options=OPTS)
    st = reach_streamed(model, X0, case.t, inputs=case.U, W=W_TRUE, options=OPTS, max_sets=100)
    assert st.keep_every == 15 and len(st.time_interval_sets) == 100
    assert np.allclose(st.bounds(), full.bounds(), rtol=0, atol=1e-9)
    k = 7 * st.keep_every
    assert np.allclose(st.time_interval_sets[7].center, full.time_interval_sets[k].center, atol=1e-12)
    # sampled trajectories stay in the kept sets (soundness of what is kept)
    rng = np.random.default_rng(0)
    for _ in range(5):
        x0 = rng.uniform(X0.lo, X0.hi)
        w = rng.uniform(W_TRUE.lo, W_TRUE.hi, size=(case.t.size, model.q))
        X = rc.simulate(model, x0, case.t, inputs=case.U, disturbances=w, substeps=4)
        for t_k, S in zip(st.times, st.time_point_sets):
            j = int(round(t_k * 100))
            assert S.contains(X[j], tol=1e-7)
    with pytest.raises(rc.ReachError, match="keeps the sets of every 15th step"):
        st.at(case.t[3] + 0.001)


@pytest.mark.parametrize("algorithm", ["lin", "adaptive"])
def test_streamed_reachset_check_equals_the_kept_tube(setting, algorithm, monkeypatch):
    """Same verdict per sample with and without keeping the tube (eq. 43), also for a non-conformant W.

    "adaptive" streams in chunks of 300 samples (five), restarting its step control at each boundary: measured,
    the same verdicts and max violations 2e-11 apart (relative).
    """
    import reachconf.reach_adaptive_stream as ras

    monkeypatch.setattr(ras, "CHUNK_SAMPLES", 300)
    model, case, X0 = setting
    opts = OPTS if algorithm == "lin" else rc.ReachOptions(algorithm="adaptive")
    for W in (W_TRUE, rc.Interval(W_TRUE.lo * 0.2, W_TRUE.hi * 0.2)):
        kept = reachset_conformance(model, case, W, V_TRUE, options=opts, keep_tube=True)
        streamed = reachset_conformance(model, case, W, V_TRUE, options=opts, keep_tube=False)
        assert np.array_equal(kept.inside, streamed.inside)
        assert kept.conformant == streamed.conformant == (W is W_TRUE)
        assert kept.first_violation_time == streamed.first_violation_time
        if not kept.conformant:
            assert np.isclose(kept.max_violation, streamed.max_violation, rtol=1e-6)


def test_streamed_check_of_a_split_reach_is_a_union():
    """After splits, a measurement counts as inside if any piece contains it (the kept tube's union)."""
    from reachconf.models import vanderpol

    m = vanderpol()
    t = np.round(np.arange(0, 3.0 + 1e-9, 0.02), 10)
    Y = rc.simulate(m, [1.4, 2.4], t)
    X0 = rc.Interval([1.25, 2.35], [1.55, 2.45])
    V = rc.Interval([-0.01, -0.01], [0.01, 0.01])
    opts = rc.ReachOptions(algorithm="lin", tensor_order=3, time_step=0.01, max_error=0.03, max_splits=64)
    for shift in (0.0, 0.4):  # inside; partly outside (from some time on)
        case = rc.TestCase("vdp", "g", t, np.zeros((t.size, 0)), Y + shift * (t > 1.5)[:, None], (), m.output_names)
        kept = reachset_conformance(m, case, None, V, X0=X0, options=opts, keep_tube=True)
        streamed = reachset_conformance(m, case, None, V, X0=X0, options=opts, keep_tube=False)
        assert kept.tube.splits > 0
        assert np.array_equal(kept.inside, streamed.inside)
        assert streamed.conformant == (shift == 0.0)


def test_bad_input_of_the_streamed_reach(setting):
    model, case, X0 = setting
    with pytest.raises(rc.SetError):
        reach_streamed(model, rc.Interval([0.0], [1.0]), case.t, inputs=case.U, W=W_TRUE, options=OPTS)
    with pytest.raises(rc.ReachError, match="strictly increasing"):
        reach_streamed(model, X0, case.t[::-1], inputs=case.U, W=W_TRUE, options=OPTS)
    with pytest.raises(rc.OptionsError):
        make_long_case(10, maneuver="circle")


def test_reach_checks_memory_before_the_work(setting, monkeypatch):
    """rc.reach (the API, not only the CLI) refuses a tube that cannot fit, before any work."""
    model, case, X0 = setting
    # a tiny time step: about 2e9 steps (the count itself allocates nothing)
    tiny = rc.ReachOptions(time_step=1e-8)
    with pytest.raises(rc.ResourceError, match=r"reach of model 'bicycle_closed_loop': .* need about .*reach_streamed"):
        rc.reach(model, X0, case.t - case.t[0], inputs=case.U, W=W_TRUE, options=tiny)
    # steps so small that their count overflows (it wrapped to one step per sample and ran; found by the run-file fuzz)
    for step in (1e-300, 5e-324):
        with pytest.raises(rc.ResourceError, match="need about"):
            rc.reach(model, X0, case.t - case.t[0], inputs=case.U, W=W_TRUE, options=rc.ReachOptions(time_step=step))
    monkeypatch.setenv("REACHCONF_MEMORY_LIMIT", "1e6")
    with pytest.raises(rc.ResourceError, match="nothing was computed"):
        rc.reach(model, X0, case.t[:50] - case.t[0], inputs=case.U[:50], W=W_TRUE, options=OPTS)
    monkeypatch.delenv("REACHCONF_MEMORY_LIMIT")
    tube = rc.reach(model, X0, case.t[:50] - case.t[0], inputs=case.U[:50], W=W_TRUE, options=OPTS)
    assert tube.bounds().shape[0] > 0
