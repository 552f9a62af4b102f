"""Trace conformance at the data's own rate: method="auto", windows, where a trace leaves V, pre-flight checks."""

import numpy as np
import pytest

import reachconf as rc
from reachconf.conformance import TraceOptions, minimal_trace_bounds, trace_conformance
from reachconf.conformance.windows import verdict_in_windows, window_plan
from reachconf.io import TestCase, TestSuite
from reachconf.model.simulate import simulate, simulate_ivp
from reachconf.models import bicycle

W_STAR = rc.Interval([-0.2, -0.3, -0.3], [0.2, 0.3, 0.3])
V_RAD = np.array([0.02, 0.02, 0.004, 0.02, 0.02, 0.004])
V_SET = rc.Interval(-V_RAD, V_RAD)


def make_case(model, seed, duration=3.0, rate=100.0, noise=1.0, name=None):
    """Bicycle data at ``rate``: piecewise-constant w in W*, uniform noise of ``noise`` times V's radius."""
    rng = np.random.default_rng(seed)
    t = np.round(np.arange(0.0, duration + 1e-9, 1.0 / rate), 10)
    U = np.column_stack([0.4 * np.sin(0.8 * t + seed), 0.05 * np.sin(1.3 * t + 0.5 * seed)])
    hold = max(1, int(round(0.1 * rate)))
    w = rng.uniform(W_STAR.lo, W_STAR.hi, size=(t.size // hold + 1, model.q)).repeat(hold, axis=0)[: t.size]
    X = simulate(model, [0, 0, 0, 10, 0, 0], t, inputs=U, disturbances=w, substeps=20)
    Y = X + noise * rng.uniform(-V_RAD, V_RAD, size=X.shape)
    return TestCase(name or f"case{seed}", "synthetic", t, U, Y, model.input_names, model.output_names)


@pytest.fixture(scope="module")
def model():
    return bicycle()


def _independent_check(model, case, res, W, V):
    """The certificate re-simulated by solve_ivp: W trace in W, measurement errors in V."""
    X = simulate_ivp(model, res.x0, case.t, inputs=case.U, disturbances=res.W_trace, rtol=1e-10, atol=1e-12)
    Vt = case.Y - X
    assert np.all(res.W_trace >= W.lo - 1e-12) and np.all(res.W_trace <= W.hi + 1e-12)
    assert np.all(Vt >= V.lo - 1e-9) and np.all(Vt <= V.hi + 1e-9)


def test_auto_picks_perstep_where_it_works_and_alg2_where_it_does_not(model):
    """Noise-free data: the per-step trace stays in V (per-step); noisy 100 Hz data: it drifts out (Alg. 2)."""
    clean = make_case(model, 1, noise=0.0, name="clean")
    noisy = make_case(model, 2, noise=1.0, name="noisy")
    W = rc.Interval(W_STAR.lo * 3, W_STAR.hi * 3)
    res = trace_conformance(model, clean, W, V_SET)  # default method: auto
    assert res.conformant and res.method.startswith("perstep"), (res.method, res.reason)
    assert "within W and V" in res.reason
    res = trace_conformance(model, noisy, W, V_SET)
    assert res.conformant and res.method == "optctrl", (res.method, res.reason)
    assert "per-step trace leaves" in res.reason  # says where the per-step trace left W or V
    _independent_check(model, noisy, res, W, V_SET)
    # the explicit methods keep working: per-step alone is not conformant on the noisy case
    assert not trace_conformance(model, noisy, W, V_SET, method="perstep").conformant
    # and minimal_trace_bounds records the choice per case
    box, found = minimal_trace_bounds(model, TestSuite([clean, noisy]), V=V_SET, details=True)
    assert [f.method for f in found] == ["perstep", "optctrl"]
    for case, f in zip((clean, noisy), found):
        assert np.all(box.lo <= f.lo) and np.all(f.hi <= box.hi)
        assert trace_conformance(model, case, box, V_SET).conformant


def test_windows_keep_the_guarantee(model):
    """A case cut into 6 windows with 0.3 s look-ahead: one conformant certificate over all samples.

    With W the true box and noise up to V's bounds, a window's carried start
    state can admit no trace (1 s ahead); that window is solved again joined
    with the one before it, whose start is still free.
    """
    case = make_case(model, 3, duration=6.0)
    opts = TraceOptions(window=100, overlap=30)
    assert len(window_plan(case.t.size, opts.window, opts.overlap)) == 6
    res = trace_conformance(model, case, W_STAR, V_SET, method="optctrl", options=opts)
    assert res.conformant, res.message
    assert 2 <= len(res.windows) <= 6 and res.W_trace.shape == (case.t.size - 1, 3)
    assert [w[0] for w in res.windows[1:]] == [w[1] for w in res.windows[:-1]] and res.windows[-1][1] == 600
    assert len(res.windows) == 6 or "solved again from sample" in res.message
    _independent_check(model, case, res, W_STAR, V_SET)
    # tightness: a tenth of W on every channel cannot explain the data, windowed or not
    tiny = rc.Interval(W_STAR.lo * 0.1, W_STAR.hi * 0.1)
    assert not trace_conformance(model, case, tiny, V_SET, method="optctrl", options=opts).conformant


def test_windowed_verdict_is_the_single_simulation(model):
    """Carrying both integrations' states across windows gives the numbers of one simulation."""
    case = make_case(model, 4, duration=2.0)
    res = trace_conformance(model, case, W_STAR, V_SET, method="optctrl")
    args = (model, case.t, case.U, case.Y, res.x0, res.W_trace, W_STAR.lo, W_STAR.hi, V_SET.lo, V_SET.hi, 10)
    one = verdict_in_windows(*args, window=10**6)
    many = verdict_in_windows(*args, window=37)
    assert one.margin.keys() == many.margin.keys()
    for k in one.margin:
        assert abs(one.margin[k] - many.margin[k]) < 1e-12 and one.margin_time[k] == many.margin_time[k]
    assert np.allclose(one.X, many.X, rtol=0, atol=1e-12) and np.allclose(one.V, many.V, rtol=0, atol=1e-12)


def test_a_trace_that_cannot_stay_in_V_is_located(model):
    """A 0.3 m jump of the measured Y at t = 1.5 s: the result names the output, the time and the excess."""
    case = make_case(model, 5, duration=3.0, noise=0.0)
    Y = case.Y.copy()
    k = int(np.argmin(np.abs(case.t - 1.5)))
    Y[k, 1] += 0.3
    bad = TestCase("jump", "g", case.t, case.U, Y, case.input_names, case.output_names)
    res = trace_conformance(model, bad, W_STAR, V_SET)
    assert not res.conformant
    ch, when, margin = res.worst()
    assert ch == "Y" and abs(when - 1.5) < 0.011 and margin < -0.1
    assert "output Y at t = 1.5 s" in res.message
    with pytest.raises(rc.ConformanceError, match=r"case 'jump'.*output Y at t = 1\.5 s by"):
        minimal_trace_bounds(model, TestSuite([bad]), V=V_SET)


def test_memory_and_time_are_checked_before_the_work(model, monkeypatch):
    case = make_case(model, 6, duration=2.0)
    monkeypatch.setenv("REACHCONF_MEMORY_LIMIT", "1e6")
    with pytest.raises(rc.ResourceError, match=r"trace conformance of case 'case6': 201 samples need about .* available"):
        trace_conformance(model, case, W_STAR, V_SET)
    with pytest.raises(rc.ResourceError, match="reachset conformance of case 'case6'"):
        rc.reachset_conformance(model, case, W_STAR, V_SET)
    monkeypatch.delenv("REACHCONF_MEMORY_LIMIT")
    with pytest.raises(rc.ResourceError, match=r"projected .* exceeds the time limit of 1e-09 s; stopped before the rest"):
        trace_conformance(model, case, W_STAR, V_SET, method="optctrl", options=TraceOptions(window=50),
                          time_limit=1e-9)  # fmt: skip


def test_progress_bar_on_request(model, capsys):
    case = make_case(model, 7, duration=1.0)
    trace_conformance(model, case, W_STAR, V_SET, progress=True)
    assert "DISTURBANCETRACE" in capsys.readouterr().err


@pytest.mark.parametrize("bad", [dict(window=5), dict(overlap=-1), dict(keep_samples=0), dict(window=100.5)])
def test_bad_window_options(bad):
    with pytest.raises(rc.OptionsError):
        TraceOptions(**bad)


def test_bad_method_and_window_plan_covers_every_sample(model):
    case = make_case(model, 8, duration=0.5)
    with pytest.raises(rc.OptionsError, match="method must be one of"):
        trace_conformance(model, case, W_STAR, V_SET, method="per-step")
    with pytest.raises(rc.OptionsError, match="method must be one of"):
        minimal_trace_bounds(model, [case], V=V_SET, method="alg2")
    for K in (2, 3, 101, 1000, 1001, 12345):
        plan = window_plan(K, 100, 20)
        assert plan[0][0] == 0 and plan[-1][1] == K - 1 and plan[-1][2] == K
        assert all(b[0] == a[1] for a, b in zip(plan, plan[1:]))
        assert all(a < c <= b - 1 < K for a, c, b in plan)
