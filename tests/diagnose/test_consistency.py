"""The consistency route of the naming rule: a small significant gain names an effect only when the effect has the
same size in every maneuver group; and the screening of second effects next to the best single one."""

import numpy as np
import pytest

import reachconf as rc
from reachconf.diagnose import EFFECTS, DiagnoseOptions
from reachconf.diagnose.consistency import model_spread, relative_spread
from reachconf.diagnose.effects import Effect
from reachconf.diagnose.fit import Candidate
from reachconf.diagnose.select import decide
from reachconf.io import TestCase, TestSuite
from reachconf.model.simulate import simulate


def test_relative_spread_is_the_spread_of_the_size_over_its_mean():
    assert relative_spread([1.1, 1.2, 1.3], null=1.0) == pytest.approx(0.1 / 0.2)
    assert relative_spread([0.02, 0.02, 0.02], null=0.0) == 0.0
    assert relative_spread([0.1, -0.1, 0.0], null=0.0) == np.inf  # no size on average
    assert relative_spread([0.1, 0.1], null=0.0) == np.inf  # too few groups to say
    sizes = {("input_offset", "u"): [0.1, 0.11, 0.09], ("actuator_lag", "u"): [0.01, 0.03, 0.02]}
    both = Candidate(((EFFECTS["input_offset"], "u"), (EFFECTS["actuator_lag"], "u")))
    assert model_spread(both, sizes) == pytest.approx(0.5)  # the worse of the two
    tyre = Candidate(((EFFECTS["tire_saturation"], "c_f"),))
    assert model_spread(tyre, {("tire_saturation", "c_f"): [1.0, 1.0, 1.0]}) is None  # no null value: no route


def test_effect_null_values_are_checked():
    with pytest.raises(rc.OptionsError, match="null"):
        Effect("bad", "input", ("c",), lambda x: (0.0,), lambda x: ((-1.0,), (1.0,)), signal=lambda t, u, th: u,
               null=(0.0, 1.0))  # fmt: skip
    with pytest.raises(rc.OptionsError, match="max_spread"):
        DiagnoseOptions(max_spread=-0.1)
    with pytest.raises(rc.OptionsError, match="consistent_gain"):
        DiagnoseOptions(consistent_gain=float("nan"))
    with pytest.raises(rc.OptionsError, match="pair_next"):
        DiagnoseOptions(pair_next=-1)


def test_a_small_significant_gain_is_named_only_when_the_effect_is_the_same_in_every_group(scored):
    rng = np.random.default_rng(1)
    clusters = np.repeat(np.arange(12), 4)
    base = scored([], 10 + rng.uniform(0, 1, 48))
    bias = scored([("output_offset", "p")], base.losses * (0.85 + 0.01 * rng.standard_normal(48)))  # 15 %, z >> 3
    opts = DiagnoseOptions(z_name=3.0, min_improvement=0.4, consistent_gain=0.1, max_spread=0.1)
    asked = []

    def spread(value):
        def f(m):
            asked.append(m.label)
            return value

        return f

    assert decide(base, [bias], clusters, opts)["status"] == "none"  # no spread measured: relevance alone
    d = decide(base, [bias], clusters, opts, spread=spread(0.03))
    assert d["status"] == "named" and d["chosen"] is bias and asked == ["output_offset(p)"]
    assert d["tests"]["output_offset(p)"][0]["spread"] == 0.03
    assert decide(base, [bias], clusters, opts, spread=spread(0.3))["status"] == "none"  # changes with the maneuver
    assert decide(base, [bias], clusters, opts, spread=spread(None))["status"] == "none"
    closed = DiagnoseOptions(z_name=3.0, min_improvement=0.4, consistent_gain=0.1, max_spread=0.0)
    asked.clear()
    assert decide(base, [bias], clusters, closed, spread=spread(0.0))["status"] == "none" and not asked
    tiny = scored([("output_offset", "p")], base.losses * 0.95)  # 5 %: below consistent_gain, spread not asked
    assert decide(base, [tiny], clusters, opts, spread=spread(0.0))["status"] == "none" and not asked
    big = scored([("output_offset", "p")], base.losses * 0.3)  # relevant anyway: spread not asked
    assert decide(base, [big], clusters, opts, spread=spread(0.9))["status"] == "named" and not asked


def _offset_and_gain_suite(n=6, seed=0):
    """x' = -x + u1 + u2: a large offset on u1 and a gain error on u2 (0.7); three groups."""
    model = rc.Model(name="two_inputs", states=("x",), inputs=("u1", "u2"), disturbances=("w",), params={},
                     dynamics=lambda s: [-s.x + s.u1 + s.u2 + s.w])  # fmt: skip
    rng = np.random.default_rng(seed)
    t = np.round(np.arange(0, 8.0 + 1e-9, 0.02), 10)
    cases = []
    for i in range(n):
        f = (0.3, 0.6, 1.0)[i % 3]
        U = np.column_stack([0.5 * np.sin(2 * np.pi * 0.2 * t + rng.uniform(0, 6)),
                             np.sin(2 * np.pi * f * t + rng.uniform(0, 6))])  # fmt: skip
        X = simulate(model, [0.0], t, inputs=np.column_stack([U[:, 0] + 0.5, 0.7 * U[:, 1]]), substeps=4)
        Y = X + 0.01 * rng.standard_normal(X.shape)
        cases.append(TestCase(f"c{i}", f"g{i % 3}", t, U, Y, ("u1", "u2"), ("x",)))
    return model, TestSuite(cases)


def test_a_second_effect_left_out_of_the_screen_is_screened_next_to_the_best_single_one():
    model, suite = _offset_and_gain_suite()
    effects = [("input_offset", "u1"), ("input_scale", "u2"), ("actuator_lag", "u2"), ("actuator_lag", "u1")]
    pair = "input_offset(u1) + input_scale(u2)"

    def run(pair_next):
        opts = DiagnoseOptions(screen=1, pair_top=0, pair_next=pair_next, tube_horizon=0.0)  # one single scored
        return rc.diagnose(model, suite, effects=effects, fit_params=False, progress=False, options=opts)

    report = run(1)
    labels = [m["label"] for m in report.scores["models"]]
    assert labels[:2] == ["input_offset(u1)", pair] and "input_scale(u2)" in labels, labels  # its single part too
    assert report.decision["model"] == pair, report.verdict
    named = {(e["effect"], e["target"]): e["params"] for e in report.decision["named"]}
    assert named[("input_offset", "u1")]["c"] == pytest.approx(0.5, abs=0.02)
    assert named[("input_scale", "u2")]["k"] == pytest.approx(0.7, abs=0.02)
    assert pair not in [m["label"] for m in run(0).scores["models"]]


def test_the_diagnosis_measures_each_effect_on_every_group_for_the_consistency_route():
    model, suite = _offset_and_gain_suite()
    effects = [("input_offset", "u1"), ("actuator_lag", "u1")]
    opts = DiagnoseOptions(min_improvement=0.999, consistent_gain=0.05, max_spread=0.2, pair_top=0, pair_next=0,
                           tube_horizon=0.0)  # fmt: skip
    report = rc.diagnose(model, suite, effects=effects, fit_params=False, progress=False, options=opts)
    measured = report.decision["consistency"]["input_offset(u1)"]
    sizes = measured["sizes"]["input_offset(u1)"]
    assert len(sizes) == 3 and np.allclose(sizes, 0.5, atol=0.05), sizes  # one fit per group
    assert measured["spread"] == pytest.approx(relative_spread(sizes, 0.0)) and measured["spread"] < 0.05
    assert report.decision["model"] == "input_offset(u1)" and "same in every maneuver" in report.verdict
