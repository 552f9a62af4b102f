"""Window start states at a low sample rate: the "past" quadratic extrapolation is biased where the state's slope
jumps with the input, and the bias reads a lag as a dead time; "prefix" windows start from the centred estimate a
few samples earlier and simulate those samples (found on a user's two-tank plant at 50 Hz)."""

import numpy as np
import pytest

import reachconf as rc
from reachconf.diagnose import EFFECTS, DiagnoseOptions
from reachconf.diagnose.fit import prepare
from reachconf.model.simulate import simulate
from reachconf_kernels.signals import transport_delay


def _tank():
    return rc.Model(name="tank", states=("h",), inputs=("q",), disturbances=("w",), params={"A": 15.0, "a": 0.5},
                    dynamics=lambda s: [(s.q - s.a * s.h) / s.A + s.w])  # fmt: skip


def _suite(kind, seed=0, n=8, fs=50.0, noise=0.01):
    base = _tank()
    rng = np.random.default_rng(seed)
    cases = []
    for i in range(n):
        t = np.round(np.arange(0, 20.0 + 1e-9, 1 / fs), 10)
        holds = rng.uniform(0.1, 0.5, size=200).cumsum()
        q = 40 + 20 * rng.uniform(-1, 1, size=holds.size)[np.searchsorted(holds, t)]  # random holds of 0.1-0.5 s
        if kind == "lag":
            plant = EFFECTS["actuator_lag"].apply_model(base, "q", (0.05,))
            X = simulate(plant, [80.0, q[0]], t, inputs=q[:, None], substeps=20)[:, :1]
        else:
            X = simulate(base, [80.0], t, inputs=transport_delay(t, q, 0.05)[:, None], substeps=20)
        Y = X + rng.normal(scale=noise, size=X.shape)
        cases.append(rc.TestCase(f"c{i}", f"g{i % 4}", t, q[:, None], Y, ("q",), ("h",)))
    return base, rc.TestSuite(cases)


def test_prefix_windows_score_the_same_samples_from_earlier_starts():
    base, suite = _suite("lag", n=1)
    past = prepare(base, suite[0], DiagnoseOptions(start_state="past"))
    pre = prepare(base, suite[0], DiagnoseOptions(start_state="prefix"))
    assert np.array_equal(past.idx, pre.idx)  # the same compared samples
    lead = (DiagnoseOptions().smooth - 1) // 2 + 1
    assert np.array_equal(pre.starts, past.starts - lead) and pre.length == past.length + lead
    assert np.array_equal(pre.starts[:, None] + pre.offsets[None, :], pre.idx.reshape(pre.starts.size, -1))


@pytest.mark.parametrize("kind, effect, param", [("lag", "actuator_lag", "tau"), ("dead", "dead_time", "T")])
def test_prefix_starts_tell_a_small_lag_from_a_dead_time_at_50_hz(kind, effect, param):
    base, suite = _suite(kind)
    effects = [("actuator_lag", "q"), ("dead_time", "q")]
    rep = rc.diagnose(base, suite, effects=effects, fit_params=False, progress=False, workers=1,
                      options=DiagnoseOptions(start_state="prefix"))  # fmt: skip
    named = rep.decision["named"]
    assert rep.decision["status"] == "named" and [e["effect"] for e in named] == [effect], rep.verdict
    assert abs(named[0]["params"][param] - 0.05) < 0.005, rep.verdict


def test_auto_keeps_the_past_estimate_where_its_span_is_short_and_prefix_is_the_default():
    from reachconf.diagnose.options import PAST_SPAN_MAX

    assert DiagnoseOptions().start_state == "prefix"
    for fs, expected in ((100.0, "past"), (50.0, "prefix")):
        base, suite = _suite("lag", n=1, fs=fs)
        auto = prepare(base, suite[0], DiagnoseOptions(start_state="auto"))
        chosen = prepare(base, suite[0], DiagnoseOptions(start_state=expected))
        assert np.array_equal(auto.starts, chosen.starts) and np.array_equal(auto.Ys, chosen.Ys), fs
        assert ((2 * DiagnoseOptions().smooth - 1) / fs <= PAST_SPAN_MAX) == (expected == "past")


def test_a_models_names_are_also_under_the_constructors_words():
    m = _tank()
    assert m.states == m.state_names == ("h",) and m.inputs == m.input_names == ("q",)
    assert m.disturbances == m.disturbance_names == ("w",)
    assert m.with_params(A=10.0).inputs == ("q",)


def _pendulum_suite(seed=0, fs=100.0, tau=0.03, n=6, duration=10.0):
    """A nonlinear pendulum whose torque passes a small lag the model lacks (an outside check's plant, 100 Hz)."""
    import sympy as sp

    base = rc.Model(name="pendulum", states=("th", "om"), inputs=("tq",), disturbances=("w1", "w2"),
                    params={"g_l": 9.81, "c": 0.5},
                    dynamics=lambda s: [s.om + s.w1, -s.g_l * sp.sin(s.th) - s.c * s.om + s.tq + s.w2])  # fmt: skip
    plant = EFFECTS["actuator_lag"].apply_model(base, "tq", (tau,))
    rng = np.random.default_rng(seed)
    cases = []
    for i in range(n):
        t = np.round(np.arange(0, duration + 1e-9, 1 / fs), 10)
        holds = rng.uniform(0.1, 0.5, size=100).cumsum()
        u = 6.0 * rng.uniform(-1, 1, size=holds.size)[np.searchsorted(holds, t)]  # random holds of 0.1-0.5 s
        X = simulate(plant, [0.0, 0.0, u[0]], t, inputs=u[:, None], substeps=20)[:, :2]
        Y = X + rng.normal(size=X.shape) * np.array([0.005, 0.03])
        cases.append(rc.TestCase(f"c{i}", f"g{i % 3}", t, u[:, None], Y, ("tq",), ("th", "om")))
    return base, rc.TestSuite(cases)


def test_the_default_start_state_names_a_small_lag_at_100_hz_where_past_names_a_dead_time():
    # "past" spans 0.21 s here, "auto" would use it: an outside check found 0.03-s lags named dead times at 100-120 Hz
    base, suite = _pendulum_suite()
    diag = lambda **kw: rc.diagnose(base, suite, effects=["actuator_lag", "dead_time"], progress=False, workers=1,  # noqa: E731
                                    options=DiagnoseOptions(tube_horizon=0.0, **kw))  # fmt: skip
    rep = diag()
    named = rep.decision["named"]
    assert rep.status == "named" and [e["effect"] for e in named] == ["actuator_lag"], rep.verdict
    assert abs(named[0]["params"]["tau"] - 0.03) < 0.003, rep.verdict
    past = diag(start_state="past")  # the bias the default avoids (so this test can tell them apart)
    assert [e["effect"] for e in past.decision["named"]] == ["dead_time"], past.verdict
