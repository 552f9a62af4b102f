"""Identifiability of two explanations from the data at hand: drag vs an acceleration offset.

At nearly constant speed a drag ``c_d v |v|`` is nearly a constant deceleration, the same as a braking
offset on the acceleration command; a speed sweep separates them.
"""

import numpy as np
import pytest

import reachconf as rc
from reachconf.diagnose import EFFECTS, DiagnoseOptions
from reachconf.diagnose.fit import Candidate
from reachconf.diagnose.select import decide, paired_test
from reachconf.io import TestCase, TestSuite


def test_an_alternative_the_held_out_test_rules_out_is_kept_when_the_data_cannot_separate_it(scored):
    rng = np.random.default_rng(1)
    clusters = np.repeat(np.arange(12), 4)
    base = scored([], 20 + rng.uniform(0, 1, 48))
    drag = scored([("drag", "vx")], base.losses * 0.3)
    offset = scored([("input_offset", "ax")], drag.losses * (1.08 + 0.01 * rng.standard_normal(48)))
    opts = DiagnoseOptions(z_name=3.0, min_improvement=0.3, z_separate=1.5)
    t = paired_test(drag.losses, offset.losses, clusters)
    assert t["z"] > 5 and t["se"] > 0  # the held-out test alone prefers the drag clearly
    assert decide(base, [drag, offset], clusters, opts)["status"] == "named"
    # the offset reproduces the drag's predictions up to a loss far below the held-out test's resolution
    small = 0.5 * t["se"]
    d = decide(base, [drag, offset], clusters, opts, mimic=lambda a, b: small)
    assert d["status"] == "indistinguishable" and d["chosen"].label == "drag(vx)"
    (alt, test), = d["alternatives"]
    assert alt.label == "input_offset(ax)" and test["identifiable"] is False
    assert test["expected_z"] == pytest.approx(0.5) and d["identifiability"]["input_offset(ax)"]["mimic_loss"] == small
    # ... and ruled out when what it cannot reproduce is large enough to show
    d = decide(base, [drag, offset], clusters, opts, mimic=lambda a, b: 3 * t["se"])
    assert d["status"] == "named" and not d["alternatives"]
    assert d["identifiability"]["input_offset(ax)"]["expected_z"] == pytest.approx(3.0)
    # an unchecked pair (None) is decided by the held-out test alone
    assert decide(base, [drag, offset], clusters, opts, mimic=lambda a, b: None)["status"] == "named"


def _longitudinal():
    return rc.Model(name="longitudinal", states=("x", "vx"), inputs=("ax",), disturbances=("w",), params={},
                    dynamics=lambda s: [s.vx, s.ax + s.w])  # fmt: skip


def _suite(offset, sweep, n=6, seed=0):
    """A speed controller tracks a reference; the vehicle's acceleration is the command plus ``offset``."""
    dt, T = 0.01, 20.0
    t = np.round(np.arange(0, T + 1e-9, dt), 10)
    cases = []
    for i in range(n):
        rng = np.random.default_rng(seed + i)
        if sweep:  # accelerate from 5 to 20 m/s and brake back (0.75 m/s² peak)
            v_ref = 12.5 - 7.5 * np.cos(2 * np.pi * t / T) + 0.3 * np.sin(2 * np.pi * rng.uniform(0.2, 0.5) * t)
        else:  # hold 10 m/s with small corrections
            v_ref = 10.0 + 0.15 * np.sin(2 * np.pi * rng.uniform(0.2, 0.5) * t + rng.uniform(0, 6))
        a_ref = np.gradient(v_ref, dt)
        x, v = 0.0, float(v_ref[0])
        X, U = np.zeros((t.size, 2)), np.zeros((t.size, 1))
        for k in range(t.size):
            X[k] = x, v
            vm = v + rng.normal(scale=0.02)
            U[k, 0] = a_ref[k] + 1.5 * (v_ref[k] - vm)  # the recorded command
            a = U[k, 0] + offset
            x, v = x + v * dt + 0.5 * a * dt**2, v + a * dt
        Y = X + rng.normal(scale=[0.01, 0.02], size=X.shape)
        cases.append(TestCase(f"c{i}", f"g{i % 3}", t, U, Y, ("ax",), ("x", "vx")))
    return TestSuite(cases)


@pytest.mark.parametrize("sweep", [False, True], ids=["constant_speed", "speed_sweep"])
def test_drag_and_a_braking_offset_are_indistinguishable_at_constant_speed_and_separated_by_a_speed_sweep(sweep):
    suite = _suite(offset=-0.3, sweep=sweep)
    rep = rc.diagnose(_longitudinal(), suite, effects=["drag", "input_offset"], fit_params=False, progress=False,
                      options=DiagnoseOptions(tube_horizon=0.0))  # fmt: skip
    dec = rep.decision
    if not sweep:
        assert dec["status"] == "indistinguishable", rep.verdict
        labels = {dec["model"]} | {a["label"] for a in dec["alternatives"]}
        assert labels == {"drag(vx)", "input_offset(ax)"}
        sep = dec["alternatives"][0]["separating"]
        # what separates them: another speed, or accelerating and braking
        assert sep["probe"]["kind"] in ("operating_point", "doublet") and sep["separation"] > 3.0, sep
        assert "cannot tell" in rep.verdict and "would separate them" in rep.verdict
    else:
        assert dec["status"] == "named" and dec["model"] == "input_offset(ax)", rep.verdict
        (named,) = rep.named
        lo, hi = named["interval"]["c"]
        assert abs(named["params"]["c"] + 0.3) < 0.02 and lo <= -0.3 <= hi
        assert dec["identifiability"] == {} or all(v["expected_z"] >= 1.5 for v in dec["identifiability"].values())


def test_mimic_loss_is_what_one_effect_cannot_reproduce_of_the_other_on_the_data_present():
    from reachconf.diagnose.fit import fit_candidate, noise_level, prepare
    from reachconf.diagnose.separable import mimic_loss

    model, opts = _longitudinal(), DiagnoseOptions()
    drag, offset = Candidate(((EFFECTS["drag"], "vx"),)), Candidate(((EFFECTS["input_offset"], "ax"),))
    share = {}
    for sweep in (False, True):
        data = [prepare(model, c, opts) for c in _suite(offset=-0.3, sweep=sweep, n=3)]
        sigma = noise_level(np.vstack([d.Y for d in data]))
        fit = fit_candidate(model, offset, data, sigma, (), opts, {})
        res = mimic_loss(model, fit, drag, data, sigma, (), opts, {})
        assert res["effect_loss"] > 1e4  # the offset itself is large in noise units
        share[sweep] = res["mimic_loss"] / res["effect_loss"]
        # the drag that reproduces a -0.3 m/s² offset best: c_d v|v| = 0.3 at the data's speeds
        assert res["params"]["drag(vx)"][0] > 0
    # at 10 m/s the drag reproduces the offset up to a tiny share; over 5-20 m/s it cannot
    assert share[False] < 1e-3 and share[True] > 0.1, share


def test_a_drag_only_decelerates_so_it_cannot_stand_in_for_an_accelerating_offset():
    # at constant speed a braking offset and a drag are indistinguishable (above); a drag cannot push forward
    assert EFFECTS["drag"].bounds(None)[0] == (0.0,)
    suite = _suite(offset=+0.3, sweep=False)
    rep = rc.diagnose(_longitudinal(), suite, effects=["drag", "input_offset"], fit_params=False, progress=False,
                      options=DiagnoseOptions(tube_horizon=0.0))  # fmt: skip
    assert rep.decision["status"] == "named" and rep.decision["model"] == "input_offset(ax)", rep.verdict
    assert abs(rep.named[0]["params"]["c"] - 0.3) < 0.02
    drag = next(e for e in rep.ranked_effects if e["label"] == "drag(vx)")
    assert drag["params_by_effect"]["drag(vx)"]["c_d"] == pytest.approx(0.0, abs=1e-6)
