"""Low sample rates: input effects evaluated on every RK4 substep (``DiagnoseOptions.substeps``) — a lag's output
moves within a sample interval, and held over the whole interval as its mean, a lag shorter than a sample at 20 Hz
came out several percent short with an interval that excluded the truth (an outside check's DC motor) — and a
smoothing window at most ``smooth_span`` seconds long (docs/notes/diagnosis.md, "Low sample rates")."""

import numpy as np
import pytest

import reachconf as rc
from reachconf.diagnose import EFFECTS, DiagnoseOptions
from reachconf.diagnose.fit import smoothing_window
from reachconf.conformance.optctrl import fine_grid
from reachconf.diagnose.report import timing_hold_note
from reachconf.diagnose.residuals import ramp_grid, steps_per_sample
from reachconf.model.simulate import simulate
from reachconf_kernels.integrate import rk4_windows
from reachconf_kernels.signals import first_order_lag


def _motor():
    return rc.Model(name="motor", states=("om",), inputs=("V",), disturbances=("w",), params={"Km": 2.0, "Tm": 0.15},
                    dynamics=lambda s: [(s.Km * s.V - s.om) / s.Tm + s.w])  # fmt: skip


def _held(t, n, rng):
    holds = rng.uniform(0.1, 0.5, size=200).cumsum()
    return 3 + 3 * rng.uniform(-1, 1, size=holds.size)[np.searchsorted(holds, t)]


def test_substep_inputs_equal_the_per_sample_kernel_for_held_inputs_and_follow_a_lag_on_every_substep():
    model = _motor()
    comp, pv = model.compiled(), model.param_vector
    rng = np.random.default_rng(3)
    t = np.round(np.arange(0, 4.0 + 1e-9, 0.05), 10)
    u = _held(t, t.size, rng)
    X0 = rng.uniform(0, 8, size=(5, 1))
    starts = np.array([0, 7, 20, 41, 60], dtype=np.int64)
    for m in (1, 3, 5):
        t_sub, U_sub, _ = fine_grid(t, u[:, None], m)
        assert t_sub.size == (t.size - 1) * m + 1 and t_sub[-1] == t[-1] and np.all(np.diff(t_sub) > 0)
        a = rk4_windows(comp.f, X0, starts, np.ascontiguousarray(u[:, None]), t, pv, model.q, 15, m, False)
        b = rk4_windows(comp.f, X0, starts, np.ascontiguousarray(U_sub), t, pv, model.q, 15, m, True)
        np.testing.assert_allclose(b, a, rtol=1e-12, atol=1e-12)  # held inputs: the same arithmetic
    # a 0.03-s lag's output per substep: the windows converge to the plant with the lag as a state
    plant = EFFECTS["actuator_lag"].apply_model(model, "V", (0.03,))
    errs = []
    for m in (1, 2, 8):
        t_sub, U_sub, _ = fine_grid(t, u[:, None], m)
        lagged = first_order_lag(t_sub, np.ascontiguousarray(U_sub[:, 0]), 0.03)[:, None]
        P = rk4_windows(comp.f, X0[:1], np.zeros(1, dtype=np.int64), np.ascontiguousarray(lagged), t, pv, model.q,
                        t.size - 1, m, True)  # fmt: skip
        X = simulate(plant, [X0[0, 0], u[0]], t, inputs=u[:, None], substeps=200)[1:, :1]
        errs.append(float(np.max(np.abs(P[0] - X))))
    assert errs[2] < errs[1] < errs[0] and errs[2] < 0.1 * errs[0], errs


def test_steps_per_sample_is_the_option_or_enough_for_steps_of_at_most_10_ms():
    class D:
        def __init__(self, fs):
            self.t = np.arange(0, 2.0, 1 / fs)

    assert steps_per_sample(3, D(20.0)) == 3
    assert [steps_per_sample(None, D(fs)) for fs in (200.0, 100.0, 50.0, 20.0, 8.0)] == [1, 1, 2, 5, 13]
    assert DiagnoseOptions().substeps is None and DiagnoseOptions(substeps=1).substeps == 1
    for bad in (0, -2, 2.5, "5", True):
        with pytest.raises(rc.OptionsError, match="substeps"):
            DiagnoseOptions(substeps=bad)


def test_the_smoothing_window_is_at_most_smooth_span_seconds_long():
    o = DiagnoseOptions()
    assert [smoothing_window(o, 1 / fs) for fs in (10.0, 20.0, 25.0, 40.0, 50.0, 100.0, 1000.0)] == [3, 7, 7, 11, 11,
                                                                                                   11, 11]  # fmt: skip
    assert smoothing_window(DiagnoseOptions(smooth_span=None), 0.05) == 11
    assert smoothing_window(DiagnoseOptions(smooth=5, smooth_span=10.0), 0.05) == 5
    for bad in (0.0, -1.0, float("nan")):
        with pytest.raises(rc.OptionsError, match="smooth_span"):
            DiagnoseOptions(smooth_span=bad)


def _suite(seed, fs=20.0, tau=0.03, n=6, noise=0.0005):
    base = _motor()
    rng = np.random.default_rng(seed)
    plant = EFFECTS["actuator_lag"].apply_model(base, "V", (tau,))
    cases = []
    for i in range(n):
        t = np.round(np.arange(0, 20.0 + 1e-9, 1 / fs), 10)
        u = _held(t, t.size, rng)
        X = simulate(plant, [6.0, u[0]], t, inputs=u[:, None], substeps=50)[:, :1]
        cases.append(rc.TestCase(f"c{i}", f"g{i % 3}", t, u[:, None], X + rng.normal(size=X.shape) * noise, ("V",),
                                 ("om",)))  # fmt: skip
    return base, rc.TestSuite(cases)


def test_a_sub_sample_lag_at_20_hz_is_recovered_with_inputs_per_substep():
    base, suite = _suite(0)
    taus = {}
    for sub in (1, 10):
        rep = rc.diagnose(base, suite, effects=["actuator_lag", "dead_time"], progress=False, workers=1,
                          options=DiagnoseOptions(tube_horizon=0.0, substeps=sub, smooth=3))  # fmt: skip
        named = rep.decision["named"]
        assert [e["effect"] for e in named] == ["actuator_lag"], rep.verdict
        taus[sub] = named[0]["params"]["tau"]
    assert abs(taus[10] / 0.03 - 1) < 0.01, taus  # per substep: the truth
    assert taus[1] < 0.03 * 0.98, taus  # held per sample: short by more than 2 %


def test_ramp_grid_holds_the_linear_inputs_mean_over_every_step():
    t = np.array([0.0, 0.05, 0.1, 0.2])
    U = np.column_stack([1 + 2 * t, 3 - t**2])
    for r in (1, 2, 5):
        tf, Uf = ramp_grid(t, U, r)
        t_ref, _, _ = fine_grid(t, U, r)
        np.testing.assert_allclose(tf, t_ref)
        assert Uf.shape == ((t.size - 1) * r + 1, 2) and np.array_equal(Uf[-1], U[-1])
        mid = (tf[:-1] + tf[1:]) / 2
        np.testing.assert_allclose(Uf[:-1, 0], 1 + 2 * mid, rtol=1e-12)  # a ramp: its value at the step's midpoint
        for k in range(t.size - 1):  # within an interval the second input moves linearly from sample to sample
            rows = Uf[k * r : (k + 1) * r, 1]
            np.testing.assert_allclose(rows, U[k, 1] + (np.arange(r) + 0.5) / r * (U[k + 1, 1] - U[k, 1]))
    assert DiagnoseOptions().input_hold == "zero" and DiagnoseOptions(input_hold="linear").input_hold == "linear"
    for bad in ("first", "", None):
        with pytest.raises(rc.OptionsError, match="input_hold"):
            DiagnoseOptions(input_hold=bad)


def _decimated_suite(seed, tau=0.05, fs=20.0, n=6, noise=0.0005):
    """Commands of a 1-kHz controller (holds at random instants, not at the samples) through a 0.05-s lag, the
    states and the commands recorded at 20 Hz: every 50th sample of each."""
    base = _motor()
    rng = np.random.default_rng(seed)
    plant = EFFECTS["actuator_lag"].apply_model(base, "V", (tau,))
    tf = np.round(np.arange(0, 20.0 + 1e-9, 1e-3), 10)
    every = int(round(1000 / fs))
    cases = []
    for i in range(n):
        uf = _held(tf, tf.size, rng)
        X = simulate(plant, [6.0, uf[0]], tf, inputs=uf[:, None], substeps=2)[::every, :1]
        cases.append(rc.TestCase(f"c{i}", f"g{i % 3}", tf[::every], uf[::every, None],
                                 X + rng.normal(size=X.shape) * noise, ("V",), ("om",)))  # fmt: skip
    return base, rc.TestSuite(cases)


def test_a_log_decimated_from_a_faster_controller_needs_the_linear_hold():
    base, suite = _decimated_suite(0)
    taus = {}
    for hold in ("zero", "linear"):
        rep = rc.diagnose(base, suite, effects=["actuator_lag", "dead_time"], progress=False, workers=1,
                          options=DiagnoseOptions(tube_horizon=0.0, input_hold=hold))  # fmt: skip
        named = rep.decision["named"]
        assert [e["effect"] for e in named] == ["actuator_lag"], rep.verdict
        taus[hold] = named[0]["params"]["tau"]
        note = timing_hold_note(rep.decision)
        assert f'input_hold="{hold}"' in note and "0.025 s" in note and note in rep.summary()
    assert taus["zero"] < 0.04, taus  # the commands taken half a sample late: the lag about half a sample short
    assert abs(taus["linear"] / 0.05 - 1) < 0.08, taus
