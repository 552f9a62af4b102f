"""Diagnosis against a reference run: the effect that explains the *rise* of the misfit is named.

The plant has a cubic spring the model lacks (a structural misfit no library
effect is) and, in the suite, a velocity-sensor bias too small to earn a name
next to that misfit (it removes less than ``min_improvement`` of the held-out
loss).  Against a reference run of the same inputs without the bias (other
noise), the bias explains the whole excess and is named and sized.
"""

from dataclasses import replace

import numpy as np
import pytest

import reachconf as rc
from reachconf.diagnose.options import DiagnoseOptions
from reachconf.errors import OptionsError
from reachconf.io import TestCase, TestSuite
from reachconf.model.simulate import simulate

PLANT = rc.Model(name="plant", states=("p", "v"), inputs=("u",), disturbances=("w",),
                 params={"k": 4.0, "d": 0.8, "c3": 3.0},
                 dynamics=lambda s: [s.v, -s.k * s.p - s.c3 * s.p**3 - s.d * s.v + s.u + s.w])  # fmt: skip
MODEL = rc.Model(name="oscillator", states=("p", "v"), inputs=("u",), disturbances=("w",), params={"k": 4.0, "d": 0.8},
                 dynamics=lambda s: [s.v, -s.k * s.p - s.d * s.v + s.u + s.w])  # fmt: skip
EFFECTS = ["output_offset", "input_offset", "actuator_lag", "output_scale", "input_scale"]
OPTS = DiagnoseOptions(tube_horizon=0.0)


def _suite(bias=0.0, noise_seed=0, n=6, duration=10.0):
    cases = []
    for i in range(n):
        ru = np.random.default_rng(i)  # the same inputs in every suite
        rng = np.random.default_rng(1000 * noise_seed + i)
        t = np.round(np.arange(0, duration + 1e-9, 0.01), 10)
        u = sum(2.0 * np.sin(2 * np.pi * f * t + ru.uniform(0, 6)) for f in ru.uniform(0.1, 1.5, size=3))
        X = simulate(PLANT, [0.0, 0.0], t, inputs=u[:, None], substeps=4)
        Y = X + rng.normal(scale=0.002, size=X.shape).clip(-0.004, 0.004)
        Y[:, 1] += bias
        cases.append(TestCase(f"c{i}", f"g{i % 3}", t, u[:, None], Y, ("u",), ("p", "v")))
    return TestSuite(cases)


def test_a_small_bias_next_to_a_structural_misfit_is_named_against_a_reference_run():
    suite, ref = _suite(bias=0.05, noise_seed=2), _suite(noise_seed=1)
    alone = rc.diagnose(MODEL, suite, effects=EFFECTS, progress=False, options=OPTS)
    assert alone.status == "none", alone.verdict  # the cubic spring's misfit drowns it
    rep = rc.diagnose(MODEL, suite, effects=EFFECTS, progress=False, options=OPTS, reference=ref)
    assert rep.status == "named", rep.verdict
    assert [(e["effect"], e["target"]) for e in rep.named] == [("output_offset", "v")]
    c = rep.named[0]
    assert abs(c["params"]["c"] - 0.05) < 0.01 and c["interval"]["c"][0] <= 0.05 <= c["interval"]["c"][1]
    ref_rec = rep.decision["reference"]
    assert ref_rec["z"] >= OPTS.z_name and 0.0 < ref_rec["share"] < 0.3
    assert rep.verdict.startswith("against the reference run")
    # the shares are of the excess: the named bias removes (about) all of it
    entry = next(e for e in rep.ranked_effects if e["label"] == "output_offset(v)")
    assert entry["prediction_gain"] > 0.8
    assert rep.base["held_out_loss"] == pytest.approx(alone.base["held_out_loss"], rel=0.05)  # the suite's own loss


def test_no_change_against_the_reference_names_nothing():
    rep = rc.diagnose(MODEL, _suite(noise_seed=2), effects=EFFECTS, progress=False, options=OPTS,
                      reference=_suite(noise_seed=1))  # fmt: skip
    assert rep.status == "none" and rep.named == []
    assert rep.verdict.startswith("no change against the reference run")
    ref = rep.decision["reference"]
    assert ref["z"] < OPTS.z_name and ref["loss"] == "difference"
    # the two recordings differ by their noise, which no effect predicts
    assert all(e["prediction_gain"] < OPTS.min_improvement for e in rep.ranked_effects
               if e["prediction_gain"] is not None)  # fmt: skip


def test_a_change_that_lowers_the_misfit_is_named_against_a_reference_run():
    """The reference has a sensor bias of its own (+0.04); in the suite it moved to -0.01.  The base model's
    misfit *falls* — by the excess of the losses there is no change — but the difference of the residuals
    holds the whole move, and the bias explains it: named, with the suite's value."""
    suite, ref = _suite(bias=-0.01, noise_seed=2), _suite(bias=0.04, noise_seed=1)
    rep = rc.diagnose(MODEL, suite, effects=EFFECTS, progress=False, options=OPTS, reference=ref)
    rec = rep.decision["reference"]
    assert rec["z"] < OPTS.z_name and rec["share"] < 0  # the base's misfit does not rise
    assert rep.status == "named", rep.verdict
    assert [(e["effect"], e["target"]) for e in rep.named] == [("output_offset", "v")]
    assert rep.named[0]["params"]["c"] == pytest.approx(-0.01, abs=0.005)
    entry = next(e for e in rep.ranked_effects if e["label"] == "output_offset(v)")
    assert entry["prediction_gain"] > 0.9 and rec["difference_loss"] > 0
    assert rep.verdict.startswith("against the reference run")
    # scored by the excess of the losses, the same change is missed
    excess = replace(OPTS, reference_loss="excess")
    old = rc.diagnose(MODEL, suite, effects=EFFECTS, progress=False, options=excess, reference=ref)
    assert old.status == "none" and old.verdict.startswith("no change against the reference run")


def test_the_difference_cancels_the_models_own_misfit():
    """The same recording with a bias added (the same noise): the base's difference loss is the bias alone,
    and the bias model leaves nothing of it, although the cubic spring's misfit is large on both."""
    from reachconf.diagnose.fit import prepare
    from reachconf.diagnose.reference import difference_score
    from reachconf.diagnose.select import cross_fit, fold_assignment

    ref_cases = [prepare(MODEL, c, OPTS) for c in _suite(noise_seed=1, n=4, duration=6.0)]
    suite_cases = [prepare(MODEL, c, OPTS) for c in _suite(bias=0.02, noise_seed=1, n=4, duration=6.0)]
    folds = fold_assignment([d.group for d in ref_cases], 2, 0)
    sigma = np.array([0.002, 0.002])
    from reachconf.diagnose.effects import EFFECTS as REGISTRY
    from reachconf.diagnose.fit import Candidate, window_residuals

    out = {}
    for label, cand in (("base", Candidate(())), ("bias", Candidate(((REGISTRY["output_offset"], "v"),)))):
        on_ref = cross_fit(MODEL, cand, ref_cases, folds, sigma, ("k", "d"), OPTS, {})
        targets = [window_residuals(f.model, cand, f.effect_params, [r for r, g in zip(ref_cases, folds) if g != k],
                                    sigma, OPTS.substeps) for k, f in enumerate(on_ref.folds)]  # fmt: skip
        score = difference_score(on_ref, suite_cases, ref_cases, sigma, OPTS)
        out[label] = (on_ref, cross_fit(MODEL, cand, suite_cases, folds, sigma, ("k", "d"), OPTS, {}, targets=targets,
                                        score=score))  # fmt: skip
    own = out["base"][0].total  # the base's own held-out misfit on the reference (the cubic spring)
    base, bias = out["base"][1].total, out["bias"][1].total
    assert own > 1e3 and base > 1e3  # both large: the spring's misfit, and a bias of 10 noise std
    assert bias < 0.01 * base and bias < 0.1 * own  # it leaves (almost) nothing: the spring's misfit cancelled
    fit_v = np.mean([f.effect_params[("output_offset", "v")][0] for f in out["bias"][1].folds])
    ref_v = np.mean([f.effect_params[("output_offset", "v")][0] for f in out["bias"][0].folds])
    assert fit_v - ref_v == pytest.approx(0.02, abs=1e-3)


def test_a_reference_must_hold_the_same_cases():
    suite = _suite(bias=0.05, n=4, duration=6.0)
    with pytest.raises(OptionsError, match="holds 3 test cases, the suite 4"):
        rc.diagnose(MODEL, suite, effects=EFFECTS, progress=False, options=OPTS,
                    reference=TestSuite(list(_suite(n=3, duration=6.0))))  # fmt: skip
    with pytest.raises(OptionsError, match="sample times"):
        rc.diagnose(MODEL, suite, effects=EFFECTS, progress=False, options=OPTS, reference=_suite(n=4, duration=5.0))
    with pytest.raises(OptionsError, match="reference must be a TestSuite"):
        rc.diagnose(MODEL, suite, effects=EFFECTS, progress=False, options=OPTS, reference=3.0)


def test_an_unknown_reference_loss_is_a_named_error(tmp_path, capsys):
    import sys

    from reachconf.cli import main
    from reachconf.io import save_suite

    with pytest.raises(OptionsError, match="reference_loss must be one of"):
        DiagnoseOptions(reference_loss="ratio")
    # in a run file: one line naming the option, status 2
    save_suite(_suite(noise_seed=2, n=2, duration=4.0), tmp_path / "suite")
    save_suite(_suite(noise_seed=1, n=2, duration=4.0), tmp_path / "ref")
    (tmp_path / "osc_bad.py").write_text(
        "import reachconf as rc\n"
        "model = rc.Model(name='oscillator', states=('p', 'v'), inputs=('u',), disturbances=('w',),\n"
        "                 params={'k': 4.0, 'd': 0.8}, dynamics=lambda s: [s.v, -s.k*s.p - s.d*s.v + s.u + s.w])\n"
    )
    run = tmp_path / "run.toml"
    run.write_text('model = "osc_bad:model"\nsuite = "suite"\n[diagnose]\nreference = "ref"\nreference_loss = "ratio"\n')
    sys.path.insert(0, str(tmp_path))
    try:
        capsys.readouterr()
        assert main(["diagnose", str(run)]) == 2
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and "reference_loss" in err, err
    finally:
        sys.path.remove(str(tmp_path))


def test_a_reference_can_be_a_suite_folder(tmp_path):
    from reachconf.io import save_suite

    save_suite(_suite(noise_seed=1, n=4, duration=6.0), tmp_path / "ref")
    rep = rc.diagnose(MODEL, _suite(noise_seed=2, n=4, duration=6.0), effects=["output_offset"], progress=False,
                      options=OPTS, reference=str(tmp_path / "ref"))  # fmt: skip
    assert rep.status == "none" and rep.verdict.startswith("no change against the reference run")


def test_against_a_reference_a_second_effect_must_explain_a_share_of_the_change_itself(scored):
    from reachconf.diagnose.select import decide, window_clusters

    rng = np.random.default_rng(0)
    clusters = window_clusters([10] * 10, min_clusters=8)
    base = scored([], 1.0 + 0.05 * rng.random(100))  # the excess over the reference, per window
    first = scored([("output_offset", "v")], 0.01 + 0.001 * rng.random(100))  # explains 99 % of it
    pair = scored([("output_offset", "v"), ("input_scale", "u")], 0.001 * rng.random(100))  # the last 1 %
    second = scored([("input_scale", "u")], base.losses * 0.999)
    # of what the first effect left, the second removes ~95 % (z large): named as a pair on its own terms ...
    assert decide(base, [first, pair, second], clusters, OPTS)["chosen"].label == pair.label
    # ... but it explains 1 % of the change: against the base's excess it is not relevant
    d = decide(base, [first, pair, second], clusters, OPTS, relevance_of=base.total)
    assert d["status"] == "named" and d["chosen"].label == "output_offset(v)"
    t = next(t for t in d["tests"][pair.label] if t["against"] == "output_offset(v)")
    assert t["z"] >= OPTS.z_name and t["gain"] < 0.02
    # the first effect may leave a negative excess (it removes more than the change added): the second effect's
    # share is still of the base's excess, not zero
    over = scored([("output_offset", "v")], -0.5 + 0.01 * rng.random(100))
    share = OPTS.min_improvement + 0.1  # a share of the base's excess above the naming rule's
    pair2 = scored([("output_offset", "v"), ("input_scale", "u")], over.losses - share - 0.01 * rng.random(100))
    d = decide(base, [over, pair2, second], clusters, OPTS, relevance_of=base.total)
    t = next(t for t in d["tests"][pair2.label] if t["against"] == "output_offset(v)")
    assert t["gain"] == pytest.approx(share, abs=0.02) and d["chosen"].label == pair2.label


def test_cli_diagnose_against_a_reference_suite(tmp_path, capsys):
    import json
    import sys

    from reachconf.cli import main
    from reachconf.io import save_suite

    save_suite(_suite(bias=0.05, noise_seed=2), tmp_path / "suite")
    save_suite(_suite(noise_seed=1), tmp_path / "ref")
    (tmp_path / "osc_ref.py").write_text(
        "import reachconf as rc\n"
        "model = rc.Model(name='oscillator', states=('p', 'v'), inputs=('u',), disturbances=('w',),\n"
        "                 params={'k': 4.0, 'd': 0.8}, dynamics=lambda s: [s.v, -s.k*s.p - s.d*s.v + s.u + s.w])\n"
    )
    run = tmp_path / "run.toml"
    head = 'model = "osc_ref:model"\nsuite = "suite"\n[diagnose]\ntube_horizon = 0.0\n'
    run.write_text(head + 'reference = "ref"\neffects = ' + json.dumps(EFFECTS) + "\n")
    sys.path.insert(0, str(tmp_path))
    try:
        assert main(["diagnose", str(run), "--json", str(tmp_path / "r.json")]) == 0
        d = json.loads((tmp_path / "r.json").read_text())
        assert d["decision"]["reference"]["z"] >= 3 and d["decision"]["named"][0]["effect"] == "output_offset"
        # a --case the suite has but the reference lacks: one line naming the reference folder, status 2
        save_suite(TestSuite([TestCase(f"other{i}", c.group, c.t, c.U, c.Y, c.input_names, c.output_names)
                              for i, c in enumerate(_suite(noise_seed=1))]), tmp_path / "ref2")  # fmt: skip
        run.write_text(head + 'reference = "ref2"\n')
        capsys.readouterr()
        assert main(["diagnose", str(run), "--case", "c0"]) == 2
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and "ref2" in err and "no test case ['c0']" in err, err
        run.write_text(head + 'reference = "nowhere"\n')
        assert main(["diagnose", str(run)]) == 2
        run.write_text(head + "reference = 3\n")
        assert main(["diagnose", str(run)]) == 2
    finally:
        sys.path.remove(str(tmp_path))


def test_output_effect_residuals_are_in_measurement_units():
    """With ``output_scale(v)`` = k the start state comes from ``v / k`` and the residual is ``k v_pred - v``: the
    base model's residual on the data with ``v / k``, times k — an output scale cannot lower the loss by
    shrinking the residuals (``v / k - v_pred`` would; with a reference run, on the difference of two noises)."""
    from reachconf.diagnose.effects import EFFECTS as REGISTRY
    from reachconf.diagnose.fit import Candidate, prepare, window_residuals

    case = next(iter(_suite(noise_seed=1, n=1, duration=6.0)))
    k = 2.0
    shrunk = TestCase(case.name, case.group, case.t, case.U, case.Y * [1.0, 1.0 / k], case.input_names,
                      case.output_names)  # fmt: skip
    sigma = np.array([0.002, 0.002])
    cand = Candidate(((REGISTRY["output_scale"], "v"),))
    r = window_residuals(MODEL, cand, {("output_scale", "v"): (k,)}, [prepare(MODEL, case, OPTS)], sigma, 1)
    r0 = window_residuals(MODEL, Candidate(()), {}, [prepare(MODEL, shrunk, OPTS)], sigma, 1)
    np.testing.assert_allclose(r.reshape(-1, 2), r0.reshape(-1, 2) * [1.0, k], rtol=1e-9, atol=1e-9)
