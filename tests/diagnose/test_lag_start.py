"""Where a lag starts: cases cut from a longer run begin with the actuator in motion.

The diagnosis fits a lag's state at the start of each case
(``reachconf.diagnose.fit.case_starts``) on the samples before the case's
first prediction window; before, the lag started at the request's first
sample, which biased a fitted time constant low on the real car's injected
lags (0.25 s came out 0.15 s).
"""

import numpy as np
import pytest

import reachconf as rc
from reachconf.diagnose import EFFECTS, DiagnoseOptions
from reachconf.diagnose.fit import Candidate, case_starts, prepare, window_residuals
from reachconf.io import TestCase, TestSuite
from reachconf.model.simulate import simulate
from reachconf_kernels.signals import first_order_lag, first_order_lag_from


def _oscillator():
    return rc.Model(name="oscillator", states=("p", "v"), inputs=("u",), disturbances=("w",),
                    params={"k": 4.0, "d": 0.8},
                    dynamics=lambda s: [s.v, -s.k * s.p - s.d * s.v + s.u + s.w])  # fmt: skip


def _lag_request(t, y, tau):
    """The zero-order-hold request whose lag (:func:`first_order_lag`) is ``y``: its exact inverse."""
    u = np.empty_like(y)
    state = u[0] = y[0]
    for k in range(1, y.size):
        r = (t[k] - t[k - 1]) / tau
        g = -np.expm1(-r) / r
        u[k - 1] = (y[k - 1] - g * state) / (1.0 - g) if k > 1 else y[0]
        state = u[k - 1] + (state - u[k - 1]) * np.exp(-r)
    u[-1] = u[-2]
    return u


def _cut_run(tau, seconds=48.0, case_seconds=6.0, dt=0.01, seed=3, noise=0.002, angle_noise=0.02):
    """Cases cut from one run whose recorded input became the request of a lag (as ``examples/realcar/withheld.py``
    injects one): the actuator is in motion at each cut, and the inverse lag amplifies the record's noise."""
    rng = np.random.default_rng(seed)
    t = np.round(np.arange(0.0, seconds + 1e-9, dt), 10)
    f = rng.uniform(0.2, 1.2, size=5)
    y = sum(np.sin(2 * np.pi * fi * t + rng.uniform(0, 6)) / (1 + fi) for fi in f)
    y = y + rng.normal(scale=angle_noise, size=t.size)  # the recorded input, with its noise
    u = _lag_request(t, y, tau)
    m = _oscillator()
    X = simulate(m, [0.0, 0.0], t, inputs=y[:, None], substeps=4)
    Y = X + rng.normal(scale=noise, size=X.shape).clip(-2 * noise, 2 * noise)
    n = int(round(case_seconds / dt))
    cases, truth = [], []
    for i, k in enumerate(range(0, t.size - n, n)):
        seg = slice(k, k + n)
        cases.append(TestCase(f"c{i}", f"g{i % 2}", t[seg] - t[k], u[seg, None], Y[seg], ("u",), ("p", "v")))
        truth.append(y[k] - u[k])  # where the lag really starts, from the request's first sample
    return m, TestSuite(cases), np.array(truth)


def test_the_lag_starts_where_the_signal_says():
    t = np.round(np.arange(0.0, 2.0 + 1e-9, 0.01), 10)
    u = np.sin(3 * t) + 0.5
    lag = EFFECTS["actuator_lag"]
    np.testing.assert_allclose(first_order_lag(t, u, 0.2), first_order_lag_from(t, u, 0.2, u[0]))
    np.testing.assert_allclose(lag.apply_signal(t, u, (0.2,)), first_order_lag(t, u, 0.2))
    moved = lag.apply_signal(t, u, (0.2,), start=0.3)
    np.testing.assert_allclose(moved, first_order_lag_from(t, u, 0.2, u[0] + 0.3))
    # the difference is the start's decay: 0.3 exp(-t / tau) (interval means)
    decay = first_order_lag_from(t, np.zeros_like(u), 0.2, 1.0)
    np.testing.assert_allclose(moved - lag.apply_signal(t, u, (0.2,)), 0.3 * decay, atol=1e-12)
    assert abs(decay[-1] - np.exp(-2.0 / 0.2)) < 1e-12
    # effects without memory ignore a start
    off = EFFECTS["input_offset"]
    np.testing.assert_allclose(off.apply_signal(t, u, (0.1,), start=0.3), u + 0.1)


@pytest.mark.parametrize("tau", [0.3, 0.05])
def test_case_starts_recover_where_a_cut_lag_really_starts(tau):
    m, suite, truth = _cut_run(tau)
    t = np.array(suite.cases[0].t)
    np.testing.assert_allclose(first_order_lag(t, _lag_request(t, np.sin(t), tau), tau)[:-1], np.sin(t)[:-1],
                               atol=1e-9)  # fmt: skip
    cand = Candidate(((EFFECTS["actuator_lag"], "u"),))
    opts = DiagnoseOptions()
    sigma = np.array([0.002, 0.002])
    found = []
    theta = {("actuator_lag", "u"): (tau,)}
    for case in suite.cases:
        d = prepare(m, case, opts)
        starts, r = case_starts(m, cand, theta, d, sigma, opts.substeps)
        found.append(starts.get(("actuator_lag", "u"), 0.0))
        # the residuals are the model's with the lag started there (up to the windows after the start has decayed
        # to 1e-5, which are not simulated again); given starts are used as they are
        r_given = window_residuals(m, cand, theta, [d], sigma, opts.substeps, [starts])
        np.testing.assert_allclose(r_given, r, rtol=0, atol=1e-3 * max(np.max(np.abs(r)), 1e-12))
    found = np.array(found)
    assert np.sqrt(np.mean(truth**2)) > 0.1  # the request's first sample is far from where the lag is
    # within a fifth of the start's spread; fitted on the scored windows instead, the start of the 0.05-s lag (seen
    # there only through exp(-0.21 / 0.05)) was 7 times the spread off
    assert np.sqrt(np.mean((found - truth) ** 2)) < 0.2 * np.sqrt(np.mean(truth**2))


def test_a_start_is_chosen_before_the_scored_windows():
    """Prequential: the samples before a case's first prediction window choose the lag's start, so a held-out score
    never fits a nuisance to the windows it scores (measurements after them changed: the same start)."""
    import dataclasses

    tau = 0.2
    m, suite, _ = _cut_run(tau, seconds=14.0)
    cand = Candidate(((EFFECTS["actuator_lag"], "u"),))
    opts = DiagnoseOptions()
    sigma = np.array([0.002, 0.002])
    theta = {("actuator_lag", "u"): (tau,)}
    d = prepare(m, suite.cases[0], opts)
    first = int(d.starts[0])
    assert first > 0
    Y = np.array(d.Y, dtype=float)
    Y[first + 1 :] += 0.05 * np.sin(np.arange(Y.shape[0] - first - 1))[:, None]  # the scored samples moved
    moved = dataclasses.replace(d, Y=Y)
    s0 = case_starts(m, cand, theta, d, sigma, opts.substeps)[0]
    s1 = case_starts(m, cand, theta, moved, sigma, opts.substeps)[0]
    assert s0 and s0 == s1
    # a case without samples before its first window ("centered" start states) keeps the lag at rest
    centred = prepare(m, suite.cases[0], DiagnoseOptions(start_state="centered"))
    assert int(centred.starts[0]) == 0
    assert case_starts(m, cand, theta, centred, sigma, opts.substeps)[0] == {}


def test_diagnose_sizes_a_lag_on_cases_cut_from_one_run():
    # with the lag started at the request's first sample: a dead time of 0.2 s, indistinguishable from a lag
    tau = 0.3
    m, suite, _ = _cut_run(tau)
    rep = rc.diagnose(m, suite, effects=["actuator_lag", "dead_time", "input_offset"], progress=False)
    assert rep.status == "named"
    (named,) = rep.named
    assert (named["effect"], named["target"]) == ("actuator_lag", "u")
    assert abs(named["params"]["tau"] - tau) < 0.1 * tau


def test_bad_starts_are_named_errors():
    import dataclasses

    from reachconf.errors import OptionsError

    m, suite, _ = _cut_run(0.3, seconds=14.0)
    cand = Candidate(((EFFECTS["actuator_lag"], "u"),))
    opts = DiagnoseOptions()
    data = [prepare(m, c, opts) for c in suite.cases]
    sigma = np.array([0.002, 0.002])
    theta = {("actuator_lag", "u"): (0.3,)}
    with pytest.raises(OptionsError, match="starts: one dict per case"):
        window_residuals(m, cand, theta, data, sigma, opts.substeps, starts=[{}])
    # a start belongs to an input effect and must be callable
    with pytest.raises(OptionsError, match="start must be a callable of an input effect"):
        dataclasses.replace(EFFECTS["output_offset"], start=lambda t, x, th, s: x)
    with pytest.raises(OptionsError, match="start must be a callable"):
        dataclasses.replace(EFFECTS["actuator_lag"], start=0.1)


def test_a_lag_mimics_itself_on_its_own_predictions():
    """The identifiability check refits a candidate to another's noise-free predictions; those copies keep only the
    windows' compared samples, so the samples before the first window (which choose a lag's start) must be the
    predictions too — a lag fitted to its own predictions then reproduces them (its start included)."""
    from reachconf.diagnose.fit import fit_candidate
    from reachconf.diagnose.separable import mimic_loss, pseudo_measurements

    tau = 0.2
    m, suite, _ = _cut_run(tau, seconds=24.0)
    cand = Candidate(((EFFECTS["actuator_lag"], "u"),))
    opts = DiagnoseOptions()
    sigma = np.array([0.002, 0.002])
    data = [prepare(m, c, opts) for c in suite.cases]
    fit = fit_candidate(m, cand, data, sigma, (), opts, {})
    assert abs(fit.effect_params[("actuator_lag", "u")][0] - tau) < 0.1 * tau
    pseudo = pseudo_measurements(fit, data, sigma, opts)
    assert all(p.prefix_Y is not None and p.prefix_Y.shape[1] == 2 and np.all(np.isfinite(p.prefix_Y)) for p in pseudo)
    res = mimic_loss(m, fit, cand, data, sigma, (), opts, {}, start={("actuator_lag", "u"): (tau,)})
    assert res["effect_loss"] > 100.0
    assert res["mimic_loss"] < 1e-4 * res["effect_loss"]
