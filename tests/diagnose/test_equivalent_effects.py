"""Explanations that are the same model on the data (found on a user's own cart: a position-sensor bias b is an
input offset k b) are reported as indistinguishable with no separating probe, not "separated" on round-off; a
c_ parameter that multiplies nothing is no stiffness; a refit of the base parameters that absorbs the gap is said."""

import numpy as np

import reachconf as rc
from reachconf.diagnose.effects import EFFECTS
from reachconf.diagnose.select import paired_test
from reachconf.diagnose.verdict import verdict_text

from test_diagnose import _oscillator_suite


def test_losses_equal_to_the_fits_tolerance_are_no_evidence():
    rng = np.random.default_rng(0)
    a = rng.uniform(1.0, 3.0, 200)
    b = a * (1 + 1e-9 * rng.normal(size=a.size))  # two fits of one model: equal to 9 digits
    t = paired_test(a, b, np.arange(a.size) // 10)
    assert abs(t["z"]) < 0.01  # was |z| of about 1 to 3 on the round-off alone
    real = paired_test(a, a * 1.05, np.arange(a.size) // 10)  # a real 5 % difference keeps its evidence
    assert real["z"] > 10


def test_a_sensor_bias_and_its_equivalent_input_offset_are_indistinguishable_and_no_probe_separates_them():
    m, suite = _oscillator_suite(n=4, seed=3)
    cases = []
    for c in suite:  # p measured 0.05 too high: the same as an input offset k * 0.05 = 0.2 (states start measured)
        Y = np.array(c.Y, dtype=float)
        Y[:, 0] += 0.05
        cases.append(rc.TestCase(c.name, c.group, c.t, c.U, Y, c.input_names, c.output_names))
    rep = rc.diagnose(m, rc.TestSuite(cases), effects=[("input_offset", "u"), ("output_offset", "p")],
                      fit_params=False, progress=False, workers=1)  # fmt: skip
    d = rep.decision
    assert d["status"] == "indistinguishable", rep.verdict
    (alt,) = d["alternatives"]
    assert alt["separating"]["probe"] is None  # was a step "separating them by 11 noise std"
    assert alt["separating"]["separation"] < 1e-3
    assert "no probe maneuver separates them" in rep.verdict


def test_a_c_parameter_that_multiplies_no_signal_is_not_a_stiffness():
    motor = rc.Model(name="motor", states=("i", "w"), inputs=("u",), disturbances=("d",),
                     params={"R": 1.0, "K": 0.1, "L": 0.5, "b": 0.01, "J": 0.01, "c_load": 0.2, "c_m": 1.0},
                     dynamics=lambda s: [(s.u - s.R * s.i - s.K * s.w) / s.L,
                                         (s.c_m * s.K * s.i - s.b * s.w - s.c_load) / s.J + s.d])  # fmt: skip
    assert EFFECTS["tire_saturation"].applicable(motor) == ["c_m"]  # c_load was a target and stopped the diagnosis
    assert EFFECTS["tire_saturation"].applicable(rc.models.bicycle()) == ["c_f", "c_r"]


def test_a_refit_that_absorbs_the_gap_is_said_when_no_effect_is_named():
    record = {"status": "none", "thresholds": {"z_name": 3.0, "min_improvement": 0.3, "consistent_gain": 0.2,
                                                 "max_spread": 0.0, "z_separate": 1.5}}  # fmt: skip
    best = {"label": "input_offset(q)", "prediction_gain": 0.24, "z_vs_base": 2.9, "parts": [["input_offset", "q"]]}
    refit = {"gain": 0.83, "z": 15.0, "moved": {"a1": -0.044, "g": -0.042, "A1": -0.013}, "params": {}}
    text = verdict_text(record, best, False, refit=refit)
    assert "refit of the base parameters itself removes 83 %" in text and "a1 -4.4 %" in text
    weak = dict(refit, z=1.0)
    assert "refit" not in verdict_text(record, best, False, refit=weak)
    # a user's cart with a force gain of 1.2: m, k, c_d all moved by 1/1.2 - 1, 98 % of the loss at z = 1.9 over
    # four cases — the data do not rule it out, and it is most of the gap: said (was silent below z_name)
    cart = {"gain": 0.984, "z": 1.86, "moved": {"m": -0.158, "k": -0.161, "c_d": -0.133}, "params": {}}
    assert "removes 98 %" in verdict_text(record, best, False, refit=cart)
    small = dict(cart, gain=0.2)  # not most of the gap: not said
    assert "refit" not in verdict_text(record, best, False, refit=small)


def test_time_parameters_carry_their_unit_in_the_verdict():
    from reachconf.diagnose.verdict import _fmt_effect

    assert EFFECTS["actuator_lag"].units == ("s",) and EFFECTS["dead_time"].units == ("s",)
    ent = {"effect": "actuator_lag", "target": "u", "params": {"tau": 0.197}, "interval": {"tau": [0.192, 0.202]},
           "units": ["s"]}  # fmt: skip
    assert _fmt_effect(ent) == "actuator_lag on u (tau = 0.197 [0.192, 0.202] s)"
    ent = {"effect": "input_scale", "target": "u", "params": {"k": 0.9}, "interval": {"k": [0.8, 1.0]}, "units": None}
    assert _fmt_effect(ent) == "input_scale on u (k = 0.9 [0.8, 1])"


def test_a_slow_plant_widens_a_library_range_by_registering_the_effect_again():
    import dataclasses

    from reachconf.diagnose.effects import register_effect

    original = EFFECTS["dead_time"]
    try:
        wide = register_effect(dataclasses.replace(original, bounds=lambda x: ((0.0,), (2.0,))))
        assert EFFECTS["dead_time"] is wide and wide.registered
        assert wide.start_values("u", np.zeros(5))[2] == (2.0,)
    finally:
        register_effect(original)
    assert EFFECTS["dead_time"] is original


def test_the_report_does_not_depend_on_the_order_of_the_cases():
    """The held-out cases of the *how far* boxes were the first of fold 0 in the order given: an outside review got
    a 14.56x shrink from its suite in generation order and 10.53x from the same cases read alphabetically."""
    m, suite = _oscillator_suite(lag=0.12, n=4, seed=5)
    cases = list(suite)
    kw = dict(effects=[("actuator_lag", "u"), ("input_offset", "u")], fit_params=False, progress=False, workers=1)
    a = rc.diagnose(m, rc.TestSuite(cases), **kw)
    b = rc.diagnose(m, rc.TestSuite(cases[::-1]), **kw)
    assert a.verdict == b.verdict and a.split == b.split


def test_a_refit_record_is_saved_as_json_also_for_a_parameter_whose_nominal_is_zero(tmp_path):
    import json

    m = rc.Model(name="osc0", states=("p", "v"), inputs=("u",), disturbances=("w",), params={"k": 4.0, "d": 0.8, "b": 0.0},
                 dynamics=lambda s: [s.v, -s.k * s.p - s.d * s.v + s.u + s.b + s.w])  # fmt: skip
    _, suite = _oscillator_suite(n=4, seed=2, offset=0.3)
    rep = rc.diagnose(m, suite, effects=[("input_offset", "u")], progress=False, workers=1)
    refit = rep.base["refit"]
    assert refit["moved"]["b"] is None and set(refit["moved"]) == {"k", "d", "b"}
    rep.save(tmp_path / "r.json")
    assert json.loads((tmp_path / "r.json").read_text())["base"]["refit"]["moved"]["b"] is None


def _unicycle_fits(seed=0):
    """A unicycle whose translational speed is really 0.9 of the command, fitted two ways: an input scale k on v,
    and output scales kx, ky on px and py — the same model whenever kx = ky = k, for any input."""
    import sympy as sp

    from reachconf.diagnose.fit import Candidate, fit_candidate, noise_level, prepare
    from reachconf.diagnose.options import DiagnoseOptions
    from reachconf.model.simulate import simulate

    m = rc.Model(name="unicycle", states=("px", "py", "phi"), inputs=("v", "w"), disturbances=("d",), params={},
                 dynamics=lambda s: [s.v * sp.cos(s.phi), s.v * sp.sin(s.phi), s.w + s.d])  # fmt: skip
    rng = np.random.default_rng(seed)
    cases = []
    for i in range(4):
        t = np.round(np.arange(0, 10.0 + 1e-9, 0.02), 10)
        holds = np.repeat(rng.uniform(-1, 1, size=(t.size // 15 + 1, 2)), 15, axis=0)[: t.size]
        U = np.column_stack([0.6 + 0.4 * holds[:, 0], 0.8 * holds[:, 1]])
        X = simulate(m, [0.0, 0.0, rng.uniform(0, 6)], t, inputs=U * [0.9, 1.0], substeps=4)
        Y = X + rng.normal(scale=[0.005, 0.005, 0.003], size=X.shape)
        cases.append(rc.TestCase(f"c{i}", f"g{i % 2}", t, U, Y, ("v", "w"), ("px", "py", "phi")))
    options = DiagnoseOptions()
    data = [prepare(m, c, options) for c in cases]
    sigma = noise_level(np.vstack([d.Y for d in data]))
    cache = {}
    a = fit_candidate(m, Candidate(((EFFECTS["input_scale"], "v"),)), data, sigma, (), options, cache)
    b = fit_candidate(m, Candidate(((EFFECTS["output_scale"], "px"), (EFFECTS["output_scale"], "py"))), data, sigma,
                      (), options, cache)  # fmt: skip
    return m, data, sigma, options, cache, a, b


def test_a_probe_does_not_separate_two_fits_of_one_model_that_differ_within_their_uncertainty():
    """Found on a user's robot: 'a step on v_tra would separate them (0.5 noise std)' for an input gain and two
    position-sensor gains, one model when the gains are equal — the 0.5 std was the point estimates' difference."""
    from reachconf.diagnose.probes import separating_probe
    from reachconf.diagnose.separable import probe_mimic_losses

    m, data, sigma, options, cache, a, b = _unicycle_fits()
    ((k,),), ((kx,), (ky,)) = a.effect_params.values(), b.effect_params.values()
    assert abs(k - 0.9) < 0.01 and kx != k and ky != k  # three estimates of one gain, not equal
    plain = separating_probe(a, b, data, sigma)  # the point estimates alone
    assert plain["probe"] is not None and plain["separation"] > 0.05  # the old claim
    refit = separating_probe(a, b, data, sigma, refit=lambda probes: probe_mimic_losses(
        m, a, b, data, probes, sigma, (), options, cache), z=options.z_name)  # fmt: skip
    assert refit["probe"] is None, refit
    assert refit["expected_z"] < 0.01 and refit["refit_separation"] < 0.01


def test_a_probe_that_separates_two_different_mechanisms_says_how_many_runs():
    """The same refit does not hide a real difference: a scale on the input against an offset on it."""
    from reachconf.diagnose.fit import Candidate, fit_candidate
    from reachconf.diagnose.probes import MAX_PROBE_RUNS, separating_probe
    from reachconf.diagnose.separable import probe_mimic_losses

    m, data, sigma, options, cache, a, _ = _unicycle_fits()
    b = fit_candidate(m, Candidate(((EFFECTS["input_offset"], "v"),)), data, sigma, (), options, cache)
    sep = separating_probe(a, b, data, sigma, refit=lambda probes: probe_mimic_losses(
        m, a, b, data, probes, sigma, (), options, cache), z=options.z_name)  # fmt: skip
    assert sep["probe"] is not None and 1 <= sep["runs"] <= MAX_PROBE_RUNS
    assert sep["expected_z"] * np.sqrt(sep["runs"]) >= options.z_name


def test_a_model_without_disturbances_gets_one_per_state_equation_to_be_diagnosed():
    """The built-in diff_drive has no disturbances, and diagnose refused it with no way forward (an outside user)."""
    import pytest

    from reachconf.errors import ConformanceError, ModelError
    from reachconf.model.simulate import simulate

    robot = rc.models.diff_drive()
    rng = np.random.default_rng(1)
    cases = []
    for i in range(4):
        t = np.round(np.arange(0, 8.0 + 1e-9, 0.02), 10)
        U = np.column_stack([0.6 + 0.3 * np.sin(0.7 * t + i), 0.5 * np.sin(1.3 * t + 2 * i)])
        X = simulate(robot, [0.0, 0.0, 0.3 * i], t, inputs=U * [0.85, 1.0], substeps=4)  # a 0.85 wheel-speed gain
        cases.append(rc.TestCase(f"c{i}", f"g{i % 2}", t, U, X + rng.normal(scale=0.003, size=X.shape),
                                 robot.input_names, robot.output_names))  # fmt: skip
    suite = rc.TestSuite(cases)
    with pytest.raises(ConformanceError, match=r"rc.with_state_disturbances\(model\)"):
        rc.diagnose(robot, suite, progress=False, workers=1)
    model = rc.with_state_disturbances(robot)
    assert model.disturbance_names == ("w_px", "w_py", "w_phi") and model.state_names == robot.state_names
    x, u = np.array([1.0, 2.0, 0.4]), np.array([0.5, 0.2])
    assert np.allclose(model.f(x, u, [0.1, -0.2, 0.3]), robot.f(x, u) + [0.1, -0.2, 0.3])
    rep = rc.diagnose(model, suite, effects=[("input_scale", "v_tra"), ("input_offset", "v_rot")], progress=False,
                      workers=1)  # fmt: skip
    assert rep.decision["status"] == "named" and rep.decision["named"][0]["effect"] == "input_scale", rep.verdict
    assert abs(rep.decision["named"][0]["params"]["k"] - 0.85) < 0.01
    with pytest.raises(ModelError, match="taken"):
        rc.with_state_disturbances(model)  # w_px exists now
