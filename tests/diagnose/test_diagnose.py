"""Gap location: a disturbance pulse injected in one channel and time window is found there."""

import numpy as np
import pytest

import reachconf as rc
from reachconf.io import TestCase, TestSuite
from reachconf.model.simulate import simulate


def test_locate_gap_finds_channel_segment_and_condition():
    m = rc.Model(name="two_decay", states=("x1", "x2"), inputs=("u",), disturbances=("w1", "w2"),
                 dynamics=lambda s: [-s.x1 + s.u + s.w1, -2.0 * s.x2 + 0.5 * s.x1 + s.w2])  # fmt: skip
    cases = []
    for seed in range(4):
        rng = np.random.default_rng(seed)
        t = np.round(np.arange(0, 5.0 + 1e-9, 0.02), 10)
        u = np.sin(t + seed)
        w = rng.normal(scale=0.02, size=(t.size, 2))
        w[(t >= 2.0) & (t < 3.0), 1] += 1.5  # the unmodelled effect: a push on x2 between 2 and 3 s
        X = simulate(m, [0.0, 0.0], t, inputs=u[:, None], disturbances=w, substeps=10)
        cases.append(TestCase(f"c{seed}", "maneuver", t, u[:, None], X, ("u",), ("x1", "x2")))
    rep = rc.locate_gap(m, TestSuite(cases))
    assert max(rep.shares, key=rep.shares.get) == "w2"
    segs = [s for s in rep.group_segments["maneuver"] if s["channel"] == "w2"]
    assert segs and abs(segs[0]["t0"] - 2.0) < 0.15 and abs(segs[0]["t1"] - 3.0) < 0.15
    assert not [s for s in rep.group_segments["maneuver"] if s["channel"] == "w1" and s["t1"] - s["t0"] > 0.5]
    assert "w2" in rep.conditions and rep.conditions["w2"]
    assert "w2, 2.0-3.0 s" in rep.summary() or "w2, 1.9" in rep.summary() or "w2, 2.1" in rep.summary()
    assert '"shares"' in rep.to_json()
    # the traces a caller has already computed give the same location; traces of other cases are refused
    from reachconf.conformance.trace import trace_disturbances

    traces = [trace_disturbances(m, c) for c in cases]
    assert rc.locate_gap(m, TestSuite(cases), traces=traces).to_json() == rep.to_json()
    with pytest.raises(rc.OptionsError, match="locate_gap: traces must hold one TraceResult per case"):
        rc.locate_gap(m, TestSuite(cases), traces=traces[::-1])
    with pytest.raises(rc.OptionsError, match="locate_gap: traces must hold one TraceResult per case"):
        rc.locate_gap(m, TestSuite(cases), traces=[r.W_trace for r in traces])


# ---------------------------------------------------------------------------------------------------------------
# which effect: the library, the joint fits and the report
import json  # noqa: E402

from reachconf.diagnose import EFFECTS, DiagnoseOptions  # noqa: E402
from reachconf.errors import ConformanceError, OptionsError  # noqa: E402
from reachconf_kernels.signals import first_order_lag, transport_delay  # noqa: E402


def _oscillator(k=4.0):
    return rc.Model(name="oscillator", states=("p", "v"), inputs=("u",), disturbances=("w",),
                    params={"k": k, "d": 0.8},
                    dynamics=lambda s: [s.v, -s.k * s.p - s.d * s.v + s.u + s.w])  # fmt: skip


def _oscillator_suite(lag=None, offset=0.0, n=6, noise=0.002, seed=0, k=4.0):
    """Cases of the oscillator driven by a multisine; the real input passes a lag/offset the model lacks."""
    m = _oscillator(k)
    cases = []
    for i in range(n):
        rng = np.random.default_rng(seed + i)
        t = np.round(np.arange(0, 8.0 + 1e-9, 0.01), 10)
        f = rng.uniform(0.3, 2.5, size=4)
        u = sum(np.sin(2 * np.pi * fi * t + rng.uniform(0, 6)) for fi in f)
        u_real = first_order_lag(t, u, lag) if lag else u.copy()
        u_real = u_real + offset
        X = simulate(m, [0.0, 0.0], t, inputs=u_real[:, None], substeps=4)
        Y = X + rng.normal(scale=noise, size=X.shape).clip(-2 * noise, 2 * noise)
        cases.append(TestCase(f"c{i}", f"g{i % 2}", t, u[:, None], Y, ("u",), ("p", "v")))
    return m, TestSuite(cases)


def test_signal_kernels_match_the_model_transformations():
    t = np.round(np.arange(0, 3.0 + 1e-9, 0.01), 10)
    u = np.sin(2 * t) + (t > 1.0)
    # zero delay is the identity, an integer number of samples a shift
    assert np.allclose(transport_delay(t, u, 0.0)[:-1], u[:-1])
    assert np.allclose(transport_delay(t, u, 0.05)[5:-1], u[:-6], atol=1e-12)
    # the lag filter equals the model with an extra actuator state (apply_model), driven by u
    base = _oscillator()
    lagged = EFFECTS["actuator_lag"].apply_model(base, "u", (0.15,))
    assert lagged.state_names == ("p", "v", "u_act")
    X_state = simulate(lagged, [0.0, 0.0, u[0]], t, inputs=u[:, None], substeps=20)
    X_signal = simulate(base, [0.0, 0.0], t, inputs=first_order_lag(t, u, 0.15)[:, None], substeps=20)
    assert np.max(np.abs(X_state[:, :2] - X_signal)) < 2e-4
    # an input offset as a model transformation equals the offset signal
    off = EFFECTS["input_offset"].apply_model(base, "u", (0.3,))
    X1 = simulate(off, [0.0, 0.0], t, inputs=u[:, None])
    X2 = simulate(base, [0.0, 0.0], t, inputs=(u + 0.3)[:, None])
    assert np.allclose(X1, X2)
    # output effects change h only
    sensor = EFFECTS["output_offset"].apply_model(base, "p", (0.1,))
    assert np.allclose(sensor.h([1.0, 2.0], [0.0]), [1.1, 2.0])


def test_diagnose_names_a_withheld_input_lag_and_its_time_constant():
    m, suite = _oscillator_suite(lag=0.2)
    rep = rc.diagnose(m, suite, effects=["actuator_lag", "dead_time", "input_offset", "input_scale", "output_offset"],
                      progress=False)  # fmt: skip
    assert rep.status == "named"
    (named,) = rep.named
    assert (named["effect"], named["target"]) == ("actuator_lag", "u")
    assert abs(named["params"]["tau"] - 0.2) < 0.1 * 0.2
    lo, hi = named["interval"]["tau"]
    assert lo < named["params"]["tau"] < hi and hi - lo < 0.2  # an interval, and not a uselessly wide one
    best = next(e for e in rep.ranked_effects if e["label"] == "actuator_lag(u)")
    assert best["prediction_gain"] > 0.5 and best["admissible"] and best["z_vs_base"] > 3
    assert "actuator_lag on u" in rep.verdict and "explains the gap" in rep.verdict
    assert set(rep.split["train"]).isdisjoint(rep.split["test"])
    d = json.loads(rep.to_json())
    assert {"where", "ranked_effects", "verdict", "decision"} <= set(d)
    assert d["decision"]["status"] == "named" and d["decision"]["named"][0]["effect"] == "actuator_lag"
    assert {"label", "parts", "held_out_loss", "prediction_gain", "z_vs_base"} <= set(d["ranked_effects"][0])
    assert d["before_after"]["W"]["w"]["shrink"] > 1.0
    assert "| actuator_lag | u | tau |" in rep.summary()


def test_diagnose_finds_an_offset_and_says_so_when_nothing_explains_the_gap():
    # without a spring (k = 0) an input offset is not an output offset in disguise (with k > 0 it is: c / k on p)
    m, suite = _oscillator_suite(offset=0.4, seed=10, k=0.0)
    rep = rc.diagnose(m, suite, effects=["actuator_lag", "input_offset", "output_offset"], progress=False)
    assert rep.status == "named"
    assert [(e["effect"], e["target"]) for e in rep.named] == [("input_offset", "u")]
    assert abs(rep.named[0]["params"]["c"] - 0.4) < 0.1
    m, suite = _oscillator_suite(seed=20)
    rep = rc.diagnose(m, suite, effects=["actuator_lag", "input_offset", "output_offset"], progress=False)
    assert rep.status == "none" and rep.named == []
    assert rep.verdict.startswith("no effect in the library explains the gap")


def test_diagnose_bad_input():
    m, suite = _oscillator_suite(n=3)
    with pytest.raises(ConformanceError):
        rc.diagnose(m, TestSuite(list(suite)[:1]), progress=False)
    with pytest.raises(OptionsError):
        rc.diagnose(m, suite, effects=["warp_drive"], progress=False)
    with pytest.raises(OptionsError):
        rc.diagnose(m, suite, effects=[("actuator_lag", "p")], progress=False)  # p is not an input
    with pytest.raises(OptionsError):
        rc.diagnose(m, suite, holdout=1.5, progress=False)
    with pytest.raises(OptionsError):
        rc.diagnose(m, suite, fit_params=["nope"], progress=False)
    with pytest.raises(OptionsError):
        DiagnoseOptions(window=0)
    with pytest.raises(OptionsError):
        DiagnoseOptions(smooth=4)
    for bad in ({"z_name": -1.0}, {"min_improvement": 1.0}, {"interval": 1.5}, {"interval_method": "bootstrap"},
                {"start_state": "future"}, {"pair_top": -1}, {"screen": 0}, {"compare_step": 0.0}):  # fmt: skip
        with pytest.raises(OptionsError):
            DiagnoseOptions(**bad)
    no_w = rc.Model(name="no_w", states=("p", "v"), inputs=("u",), dynamics=lambda s: [s.v, -s.p + s.u])
    with pytest.raises(ConformanceError):
        rc.diagnose(no_w, suite, progress=False)
    with pytest.raises(ConformanceError):
        rc.locate_gap(no_w, suite)


def test_cli_diagnose(tmp_path):
    from reachconf.cli import main
    from reachconf.io import save_suite

    m, suite = _oscillator_suite(lag=0.2, n=4)
    save_suite(suite, tmp_path / "suite")
    (tmp_path / "osc.py").write_text(
        "import reachconf as rc\n"
        "model = rc.Model(name='oscillator', states=('p', 'v'), inputs=('u',), disturbances=('w',),\n"
        "                 params={'k': 4.0, 'd': 0.8}, dynamics=lambda s: [s.v, -s.k*s.p - s.d*s.v + s.u + s.w])\n"
    )
    run = tmp_path / "run.toml"
    run.write_text('model = "osc:model"\nsuite = "suite"\n[diagnose]\neffects = ["actuator_lag", ["input_offset", "u"]]\n'
                   'holdout = 0.5\n')  # fmt: skip
    import sys

    sys.path.insert(0, str(tmp_path))
    try:
        rc_code = main(["diagnose", str(run), "--json", str(tmp_path / "r.json"), "--out", str(tmp_path / "out"),
                        "--workers", "2"])  # fmt: skip
        assert rc_code == 0
        d = json.loads((tmp_path / "r.json").read_text())
        assert d["decision"]["named"][0]["effect"] == "actuator_lag"
        assert d["base"]["workers"] == (2 if sys.platform.startswith("linux") else 1)
        assert (tmp_path / "out" / "report.md").exists() and (tmp_path / "out" / "effects.png").exists()
        run.write_text('model = "osc:model"\nsuite = "suite"\n[diagnose]\neffects = ["warp"]\n')
        assert main(["diagnose", str(run)]) == 2
        run.write_text('model = "osc:model"\nsuite = "suite"\n[diagnose]\nwindw = 1.0\n')
        assert main(["diagnose", str(run)]) == 2
    finally:
        sys.path.remove(str(tmp_path))


def test_report_files_and_reach_tubes(tmp_path):
    m, suite = _oscillator_suite(lag=0.2, n=4, seed=3)
    rep = rc.diagnose(m, suite, effects=["actuator_lag", "dead_time"], progress=False,
                      options=DiagnoseOptions(tube_horizon=1.0))  # fmt: skip
    drawn = [tb for tb in rep.tubes if "tube" in tb]
    assert [tb["label"] for tb in drawn] == ["base", "with effect"]
    paths = rep.plot(tmp_path)
    assert {"effects.png", "boxes.png", "tubes.png"} <= {p.split("/")[-1] for p in paths}
    # soundness of the drawn tube: the measured positions lie in the tube's (X, Y) hull inflated by V
    for tb in drawn:
        lo = np.min([s.interval().lo[:2] for s in tb["tube"].time_point_sets], axis=0)
        hi = np.max([s.interval().hi[:2] for s in tb["tube"].time_point_sets], axis=0)
        vr = np.array(rep.base["V"])[:2, 1]
        assert np.all(tb["measured"] >= lo - vr - 1e-9) and np.all(tb["measured"] <= hi + vr + 1e-9)


def test_diagnose_with_defaults_alone():
    """The whole library on every target, all parameters refitted, V estimated from the data."""
    m, suite = _oscillator_suite(lag=0.2, n=4, seed=7)
    rep = rc.diagnose(m, suite, progress=False)
    assert rep.status == "named" and (rep.named[0]["effect"], rep.named[0]["target"]) == ("actuator_lag", "u")
    targets = {(e["effect"], e["target"]) for e in rep.ranked_effects if "effect" in e}
    assert ("drag", "v") in targets and ("output_offset", "p") in targets and ("dead_time", "u") in targets
    assert len(rep.base["V"]) == 2 and all(lo < 0 < hi for lo, hi in rep.base["V"])


def test_locate_gap_names_the_outputs_that_drive_a_channel():
    """A push on x2 is seen in the x2 measurements: ignoring them collapses w2's box."""
    m = rc.Model(name="two_decay", states=("x1", "x2"), inputs=("u",), disturbances=("w1", "w2"),
                 dynamics=lambda s: [-s.x1 + s.u + s.w1, -2.0 * s.x2 + 0.5 * s.x1 + s.w2])  # fmt: skip
    cases = []
    for seed in range(3):
        rng = np.random.default_rng(seed)
        t = np.round(np.arange(0, 4.0 + 1e-9, 0.05), 10)
        u = np.sin(t + seed)
        w = rng.normal(scale=0.01, size=(t.size, 2))
        w[(t >= 1.0) & (t < 2.0), 1] += 1.0
        X = simulate(m, [0.0, 0.0], t, inputs=u[:, None], disturbances=w, substeps=10)
        cases.append(TestCase(f"c{seed}", "m", t, u[:, None], X, ("u",), ("x1", "x2")))
    V = rc.Interval(-0.01 * np.ones(2), 0.01 * np.ones(2))
    rep = rc.locate_gap(m, TestSuite(cases), V=V)
    assert max(rep.drivers["w2"], key=rep.drivers["w2"].get) == "x2"
    assert rep.drivers["w2"]["x2"] > 0.5 and rep.drivers["w1"]["x1"] > 0.5
    assert "w2: " in rep.summary() and "driven by the errors of x2" in rep.summary()


def test_reachset_conformant_W_before_and_after():
    m, suite = _oscillator_suite(lag=0.2, n=4, seed=5)
    rep = rc.diagnose(m, suite, effects=["actuator_lag"], progress=False, reach=True)
    row = rep.before_after["W_reachset"]["w"]
    assert row["shrink"] > 1.0
    assert rep.before_after["W_reachset_conformant"]["after"] is True


def test_cases_shorter_than_half_a_box_segment_are_taken_whole():
    """Audit: held-out cases shorter than box_segment / 2 left no segment, and np.min([]) raised a bare ValueError."""
    from reachconf.demo import demo_run_file
    from reachconf.io import load_suite
    from reachconf.runfile import load_run

    spec = load_run(demo_run_file())
    suite = load_suite(demo_run_file().parent / "suite", model=spec.model)
    short = suite.map(lambda c: c.segment(c.t[0], c.t[0] + 0.98))
    report = rc.diagnose(spec.model, short, V=spec.V, options=DiagnoseOptions(window=0.2, stride=0.2))
    assert report.base["box"] is not None  # the minimal box of the whole short cases
