"""The decision of the gap diagnosis: held-out paired tests, the naming rule, indistinguishable explanations,
robust intervals and the separating probe maneuver."""

import numpy as np
import pytest

import reachconf as rc
from reachconf.diagnose import DiagnoseOptions
from reachconf.diagnose.select import decide, fold_assignment, paired_test, window_clusters
from reachconf.io import TestCase, TestSuite
from reachconf.model.simulate import simulate
from reachconf_kernels.signals import first_order_lag, transport_delay


def test_paired_test_is_the_cluster_robust_z_of_the_loss_differences():
    clusters = np.repeat(np.arange(4), 3)
    b = np.ones(12)
    a = b - np.repeat([0.1, 0.2, 0.3, 0.4], 3) / 3  # per-cluster gains 0.1 .. 0.4
    t = paired_test(a, b, clusters)
    D = np.array([0.1, 0.2, 0.3, 0.4])
    z = D.sum() / np.sqrt(4 / 3 * np.sum((D - D.mean()) ** 2))
    assert t["clusters"] == 4 and abs(t["z"] - z) < 1e-12 and abs(t["gain"] - 1.0 / 12) < 1e-12
    assert paired_test(b, a, clusters)["z"] == pytest.approx(-z)  # antisymmetric
    # a model that is better in half of the clusters and worse in the others is not significantly better
    worse = b + np.repeat([-0.3, 0.3, -0.3, 0.32], 3)
    assert abs(paired_test(worse, b, clusters)["z"]) < 1.0


def test_folds_are_stratified_seeded_and_never_empty():
    groups = ["a"] * 5 + ["b"] * 3 + ["c"]
    f = fold_assignment(groups, 2, seed=3)
    assert set(f) == {0, 1} and np.array_equal(f, fold_assignment(groups, 2, seed=3))
    for g in ("a", "b"):
        sel = f[[i for i, x in enumerate(groups) if x == g]]
        assert abs(np.sum(sel == 0) - np.sum(sel == 1)) <= 1  # each group is spread over the folds
    assert set(fold_assignment(["a", "a"], 2, seed=0)) == {0, 1}


def test_few_cases_are_cut_into_blocks_of_windows():
    ids = window_clusters([10, 10], min_clusters=8)
    assert len(set(ids)) == 8 and np.all(np.diff(ids) >= 0)
    assert len(set(window_clusters([5] * 12, min_clusters=8))) == 12  # enough cases: one cluster each


def test_decide_names_admissible_models_and_reports_inseparable_ones(scored):
    rng = np.random.default_rng(0)
    clusters = np.repeat(np.arange(10), 5)
    base = scored([], 10 + rng.uniform(0, 1, 50))
    lag = scored([("actuator_lag", "u")], base.losses * 0.2)
    delay = scored([("dead_time", "u")], lag.losses * (1 + 0.02 * rng.standard_normal(50)))  # as good as lag
    tiny = scored([("output_scale", "p")], base.losses * 0.97)  # significant but not relevant
    opts = DiagnoseOptions(z_name=3.0, min_improvement=0.3, z_separate=2.0)
    d = decide(base, [lag, delay, tiny], clusters, opts)
    assert d["status"] == "indistinguishable" and "output_scale(p)" not in d["admissible"]
    assert {d["chosen"].label, d["alternatives"][0][0].label} == {"actuator_lag(u)", "dead_time(u)"}
    # a clearly worse dead time is ruled out
    delay_bad = scored([("dead_time", "u")], base.losses * 0.45)
    d = decide(base, [lag, delay_bad, tiny], clusters, opts)
    assert d["status"] == "named" and d["chosen"].label == "actuator_lag(u)" and not d["alternatives"]
    # a pair must beat each of its parts: adding the irrelevant sensor gain to the lag is not named
    pair = scored([("actuator_lag", "u"), ("output_scale", "p")], lag.losses * 0.95)
    d = decide(base, [lag, delay_bad, tiny, pair], clusters, opts)
    assert d["chosen"].label == "actuator_lag(u)"
    # ... a second real effect is
    off = scored([("input_offset", "u")], base.losses * 0.6)
    pair2 = scored([("actuator_lag", "u"), ("input_offset", "u")], lag.losses * 0.3)
    d = decide(base, [lag, delay_bad, off, pair2], clusters, opts)
    assert d["status"] == "named" and d["chosen"].label == "actuator_lag(u) + input_offset(u)"
    # nothing relevant: none
    d = decide(base, [tiny], clusters, opts)
    assert d["status"] == "none" and d["chosen"] is None and d["best"].label == "output_scale(p)"


def _slow_oscillator_suite(delay=None, lag=None, n=6, seed=0, freqs=(0.1, 0.4)):
    m = rc.Model(name="oscillator", states=("p", "v"), inputs=("u",), disturbances=("w",), params={"k": 4.0, "d": 0.8},
                 dynamics=lambda s: [s.v, -s.k * s.p - s.d * s.v + s.u + s.w])  # fmt: skip
    cases = []
    for i in range(n):
        rng = np.random.default_rng(seed + i)
        t = np.round(np.arange(0, 10.0 + 1e-9, 0.01), 10)
        u = sum(np.sin(2 * np.pi * f * t + rng.uniform(0, 6)) for f in rng.uniform(*freqs, size=3))
        ur = transport_delay(t, u, delay) if delay else first_order_lag(t, u, lag) if lag else u.copy()
        X = simulate(m, [0.0, 0.0], t, inputs=ur[:, None], substeps=4)
        Y = X + rng.normal(scale=0.002, size=X.shape).clip(-0.004, 0.004)
        cases.append(TestCase(f"c{i}", f"g{i % 3}", t, u[:, None], Y, ("u",), ("p", "v")))
    return m, TestSuite(cases)


def test_slow_excitation_leaves_lag_and_dead_time_indistinguishable_and_says_which_probe_separates_them():
    m, suite = _slow_oscillator_suite(delay=0.06, freqs=(0.02, 0.06))
    rep = rc.diagnose(m, suite, effects=["actuator_lag", "dead_time", "input_offset"], progress=False,
                      options=DiagnoseOptions(tube_horizon=0.0))  # fmt: skip
    dec = rep.decision
    assert dec["status"] == "indistinguishable", rep.verdict
    labels = {dec["model"]} | {a["label"] for a in dec["alternatives"]}
    assert labels == {"actuator_lag(u)", "dead_time(u)"}
    sep = dec["alternatives"][0]["separating"]
    assert sep["probe"]["kind"] == "sine" and sep["probe"]["input"] == "u" and sep["probe"]["frequency_hz"] >= 0.5
    assert sep["separation"] > 1.0  # noise standard deviations
    bands = dec["alternatives"][0]["data_band_shares"]["u"]
    assert bands["0-0.5 Hz"] > 0.9  # the data hold only slow excitation
    assert "cannot tell" in rep.verdict and "would separate them" in rep.verdict
    # the same effect with excitation up to 3 Hz is named alone
    m, suite = _slow_oscillator_suite(delay=0.06, freqs=(0.5, 3.0))
    rep = rc.diagnose(m, suite, effects=["actuator_lag", "dead_time", "input_offset"], progress=False,
                      options=DiagnoseOptions(tube_horizon=0.0))  # fmt: skip
    assert rep.status == "named" and [(e["effect"], e["target"]) for e in rep.named] == [("dead_time", "u")]
    T = rep.named[0]
    assert T["interval"]["T"][0] <= 0.06 <= T["interval"]["T"][1]
    assert abs(T["params"]["T"] - 0.06) < 0.006


def test_an_effect_at_a_bound_of_its_range_is_not_named():
    from types import SimpleNamespace

    from reachconf.diagnose.effects import EFFECTS
    from reachconf.diagnose.fit import Candidate
    from reachconf.diagnose.select import Scored

    clusters = np.arange(12)
    rng = np.random.default_rng(0)
    base = Scored(Candidate(()), np.full(12, 100.0))
    gain = 50.0 + rng.normal(scale=2.0, size=12)
    lag = (EFFECTS["actuator_lag"], "u")
    scale = (EFFECTS["input_scale"], "a")
    # a scale that removes 60 % of the loss in every case, but at its lower bound (k = 0.2) in a fold fit
    folds = [SimpleNamespace(at_bound=("J_m",)), SimpleNamespace(at_bound=("input_scale.k(a)", "J_m"))]
    at_bound = Scored(Candidate((scale,)), base.losses - gain - 10.0, folds=folds)
    assert at_bound.at_bound == ("input_scale.k(a)",)  # base parameters at a bound do not count
    inner = Scored(Candidate((lag,)), base.losses - gain, folds=[SimpleNamespace(at_bound=("J_m",))] * 2)
    opts = DiagnoseOptions()
    d = decide(base, [at_bound, inner], clusters, opts)
    assert d["chosen"] is inner and d["admissible"] == [inner.label]
    assert d["tests"][at_bound.label] == [{"against": "bounds", "at_bound": ["input_scale.k(a)"]}]
    # without the bound it would have been named (lower loss, same significance)
    free = Scored(Candidate((scale,)), at_bound.losses, folds=[SimpleNamespace(at_bound=())] * 2)
    assert decide(base, [free, inner], clusters, opts)["chosen"] is free
    # stored results carry the flags instead of the fold fits
    assert Scored(Candidate((scale,)), at_bound.losses, bound=("input_scale.k(a)",)).at_bound == ("input_scale.k(a)",)


def test_the_verdict_says_when_the_best_fit_was_not_named_for_its_bound():
    from reachconf.diagnose.verdict import verdict_text

    th = {"z_name": 3.0, "min_improvement": 0.3, "consistent_gain": 0.2, "max_spread": 0.0, "z_separate": 1.5}
    best = {"label": "dead_time(u)", "prediction_gain": 0.8, "z_vs_base": 9.0, "at_bound": ["dead_time.T(u)"],
            "params_by_effect": {"dead_time(u)": {"T": 0.5}}}  # fmt: skip
    text = verdict_text({"status": "none", "thresholds": th}, best, False)
    assert text.startswith("no effect in the library explains the gap")
    assert "dead_time.T(u) = 0.5 ended at the upper bound of its range (0.5)" in text
    assert "larger than the library allows" in text
    # at its no-effect end (T = 0) it is not "larger than the library allows" (an outside review: a clean motor)
    none = dict(best, params_by_effect={"dead_time(u)": {"T": 6.6e-5}})
    text = verdict_text({"status": "none", "thresholds": th}, none, False)
    assert "ended at its no-effect end" in text and "larger" not in text
    free = dict(best, at_bound=[])
    assert "bound" not in verdict_text({"status": "none", "thresholds": th}, free, False)
