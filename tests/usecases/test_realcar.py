"""Real-car use case (issue 17): the suite, V from the data, Table 3 per |ay| band, reachset windows."""

import json

import numpy as np
import pytest
from conftest import DATA_ROOT, load_example

from reachconf.io import load_suite

REAL = DATA_ROOT / "realcar"
needs_data = pytest.mark.skipif(not (REAL / "stanford_track_100hz.csv.gz").is_file(), reason="no real-car data")


@pytest.fixture(scope="module")
def ex():
    return load_example("realcar")


@pytest.fixture(scope="module")
def data_mod():
    import importlib.util

    from conftest import REPO_ROOT

    spec = importlib.util.spec_from_file_location("realcar_data", REPO_ROOT / "examples" / "realcar" / "data.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


@pytest.fixture(scope="module")
def quick(ex, tmp_path_factory):
    out = tmp_path_factory.mktemp("realcar")
    assert ex.main(["--data", str(REAL), "--out", str(out), "--quick", "--no-diagnosis"]) == 0
    return out, json.loads((out / "realcar.json").read_text())


@pytest.mark.parametrize("seed", range(5))
def test_noise_sigma_recovers_white_noise_on_a_smooth_signal(data_mod, seed):
    rng = np.random.default_rng(seed)
    t = np.arange(0, 60, 0.01)
    sigma = rng.uniform(0.002, 0.05)
    smooth = rng.uniform(1, 3) * np.sin(2 * np.pi * rng.uniform(0.05, 0.5) * t) + rng.uniform(-5, 5)
    est = data_mod.noise_sigma(smooth + rng.normal(0, sigma, t.size))
    assert 0.9 * sigma < est < 1.15 * sigma
    # no noise: only the signal's own curvature, at most its largest second difference / sqrt(6)
    assert data_mod.noise_sigma(smooth) <= 1.4826 * np.max(np.abs(np.diff(smooth, 2))) / np.sqrt(6)


def test_glitch_repair_removes_isolated_spikes_only(data_mod):
    t = np.arange(0, 10, 0.01)
    x = 0.2 * np.sin(t)
    y = x.copy()
    y[[100, 555]] += [0.5, -0.4]
    fixed, idx = data_mod.repair_glitches(y)
    assert list(idx) == [100, 555]
    np.testing.assert_allclose(fixed, x, atol=1e-4)
    same, none = data_mod.repair_glitches(x)
    assert none.size == 0 and np.array_equal(same, x)


def test_bad_data_folder_is_one_line_exit_2(ex, tmp_path, capsys):
    assert ex.main(["--data", str(tmp_path / "nowhere"), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "no such data folder" in err[0]
    (tmp_path / "d").mkdir()
    assert ex.main(["--data", str(tmp_path / "d"), "--out", str(tmp_path / "o")]) == 2
    assert "missing stanford_track_100hz.csv.gz" in capsys.readouterr().err


def test_bad_workers_is_one_line_exit_2(ex, tmp_path, capsys):
    assert ex.main(["--data", str(REAL), "--out", str(tmp_path / "o"), "--workers", "0"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--workers must be >= 1" in err[0]


def test_default_workers_are_the_cores_capped(ex, monkeypatch):
    monkeypatch.setattr(ex.os, "cpu_count", lambda: 2)
    assert ex.default_workers() == 2
    monkeypatch.setattr(ex.os, "cpu_count", lambda: 64)
    assert ex.default_workers() == ex.MAX_DEFAULT_WORKERS
    monkeypatch.setattr(ex.os, "cpu_count", lambda: None)
    assert ex.default_workers() == 1


@needs_data
def test_suite_is_written_in_the_documented_format_with_ay(quick):
    out, res = quick
    suite = load_suite(out / "suite")
    assert len(suite) == res["cases"] == 6
    c = suite[0]
    assert c.input_names == ("ax", "delta") and c.output_names == ("vx", "vy", "omega")
    assert "ay" in c.extras and c.t.size == 1001
    assert abs(c.duration - 10.0) < 1e-6
    # the four isolated steering glitches of the recording (repaired before it is cut)
    assert np.allclose(res["steering_glitches_repaired_at"], [207.27, 503.49, 524.85, 671.67])


@needs_data
def test_table3_bands_and_their_hull(quick):
    out, res = quick
    tab = res["table3"]
    run = np.array(tab["whole run"])
    bands = [np.array(b) for g, b in tab.items() if g != "whole run" and b is not None]
    assert len(bands) >= 3
    for b in bands:
        assert np.all(b[:, 0] <= b[:, 1]) and np.all(run[:, 0] <= b[:, 0]) and np.all(b[:, 1] <= run[:, 1])
    assert np.allclose(run[:, 0], np.min([b[:, 0] for b in bands], axis=0))
    # the hard band needs a larger yaw disturbance than the calm one (the tyres leave their linear range)
    calm, hard = np.array(tab["|ay| 0-4"]), np.array(tab["|ay| 8-12"])
    assert np.ptp(hard[2]) > 2 * np.ptp(calm[2])
    v = res["V"]["per_output"]
    assert all(0 < h < 0.1 for _, h in v.values())
    assert sum(res["table3_windows"].values()) == 30
    md = (out / "realcar.md").read_text()
    assert "Table 3 analogue" in md and "\\|ay\\| 8-12" in md


@needs_data
def test_reachset_windows_are_decided_and_pictures_written(quick):
    out, res = quick
    share = res["reachset"]["all"]
    assert share["windows"] == 30
    assert share["conformant"] >= 27  # measured: 30 of 30 with the band's W
    assert len(res["reachset_windows"]) == 30
    for name in ("tube_calm.png", "tube_hard.png", "W_bands.png"):
        assert (out / name).stat().st_size > 10_000


@needs_data
def test_gap_location_names_ay_with_rank_correlations_and_binned_envelopes(quick):
    from reachconf.diagnose import locate_gap
    from reachconf.diagnose.fit import Candidate, transformed_case
    from reachconf.models import single_track

    out, _ = quick
    suite = load_suite(out / "suite")
    car = single_track()
    # the diagnosis hands the location the cases as the candidate model sees them: the extras travel along
    assert "ay" in transformed_case(car, suite[0], Candidate(()), {}).extras
    loc = locate_gap(car, suite).to_dict()
    for ch in car.disturbance_names:
        assert "ay" in loc["conditions"][ch]
        bins = loc["binned"][ch]["ay"]
        assert bins["abs"] and len(bins["bins"]) == 5
    # the yaw channel's (per-step, noise-laden) gap is larger at high |ay| (measured on the first 60 s: 1.25x)
    q = [b["q95"] for b in loc["binned"]["w_omega"]["ay"]["bins"]]
    assert q[-1] > 1.1 * q[0]
    assert loc["conditions"]["w_omega"]["ay"] != 0


@needs_data
@pytest.mark.slow
def test_diagnosis_on_the_quick_run_writes_its_report(ex, tmp_path):
    assert ex.main(["--data", str(REAL), "--out", str(tmp_path), "--quick", "--no-plots"]) == 0
    res = json.loads((tmp_path / "realcar.json").read_text())
    d = res["diagnosis"]
    assert "ay" in d["where"]["location"]["conditions"]["w_omega"]
    labels = " ".join(e.get("label", "") for e in d["ranked_effects"])
    assert "tire_fiala" in labels
    assert (tmp_path / "diagnosis" / "report.json").is_file()
    assert "Gap diagnosis" in (tmp_path / "realcar.md").read_text()


def _withheld():
    import importlib.util

    from conftest import REPO_ROOT

    spec = importlib.util.spec_from_file_location("realcar_withheld", REPO_ROOT / "examples" / "realcar" / "withheld.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


@pytest.mark.parametrize("tau", [0.03, 0.1, 0.25])
def test_lag_injection_is_the_exact_inverse_of_the_library_lag(tau):
    from reachconf_kernels.signals import first_order_lag

    rng = np.random.default_rng(7)
    t = np.arange(0, 20, 0.01)
    y = 0.1 * np.sin(0.8 * t) + 0.02 * np.sin(3.1 * t) + rng.normal(0, 1e-4, t.size)
    u = _withheld().lag_request(t, y, tau)
    np.testing.assert_allclose(first_order_lag(t, u, tau)[:-1], y[:-1], atol=1e-9)


def test_injections_change_what_the_model_is_given_and_report_the_truth():
    from reachconf_kernels.signals import transport_delay

    w = _withheld()
    t = np.arange(0, 20, 0.01)
    cols = {"t": t, "delta": 0.1 * np.sin(0.8 * t), "ax": np.cos(t), "omega": 0.2 * np.sin(0.5 * t),
            "vx": 20 + t, "vy": 0 * t, "ay": np.sin(t)}  # fmt: skip
    rec, truth = w.inject(cols, "dead_time", 0.08)
    assert truth == {"effect": "dead_time", "target": "delta", "params": {"T": 0.08}}
    real = transport_delay(t, rec["delta"], 0.08)
    np.testing.assert_allclose(real[10:-10], cols["delta"][10:-10], atol=1e-4)  # the delayed record is the truth
    rec, _ = w.inject(cols, "steer_offset", 0.01)
    np.testing.assert_allclose(rec["delta"] + 0.01, cols["delta"])
    rec, _ = w.inject(cols, "yaw_bias", 0.02)
    np.testing.assert_allclose(rec["omega"] - 0.02, cols["omega"])
    rec, truth = w.inject(cols, "ax_scale", 0.8)
    np.testing.assert_allclose(0.8 * rec["ax"], cols["ax"])
    assert truth["effect"] == "input_scale" and np.array_equal(rec["vx"], cols["vx"])
    with pytest.raises(ValueError, match="unknown injection"):
        w.inject(cols, "gravity", 1.0)


def _realcar_modules():
    """The example's data, diagnosis and withheld modules (examples/realcar on sys.path)."""
    import sys

    from conftest import REPO_ROOT

    folder = str(REPO_ROOT / "examples" / "realcar")
    if folder not in sys.path:
        sys.path.insert(0, folder)
    import data
    import diagnosis

    # by its path: examples/diagnose has a withheld.py too, which another test may have imported as "withheld"
    return data, diagnosis, _withheld()


def _V(data, cols):
    import reachconf as rc

    half = np.array([h for _, h in data.noise_V(cols).values()])
    return rc.Interval(-half, half)


#: the default checks: the first SHORT_SECONDS of the run (12 cases) with the signal candidates only
#: (the tyre candidates need minutes of code generation on a fresh cache; the slow checks have them all)
SHORT_SECONDS = 120.0


@pytest.fixture(scope="module")
def short_clean():
    """The clean first 120 s diagnosed with the signal candidates (the reference the injections are sized against)."""
    from reachconf.models import single_track

    data, diagnosis, withheld = _realcar_modules()
    cols = data.read_run(REAL)
    stop = cols["t"][0] + SHORT_SECONDS
    V = _V(data, cols)
    report = diagnosis.run_diagnosis(single_track(), data.make_suite(cols, stop=stop), V,
                                     effects=withheld.SIGNAL_CANDIDATES)  # fmt: skip
    return cols, stop, V, report


@needs_data
@pytest.mark.parametrize("name, value", [("steer_offset", 0.015), ("ax_scale", 0.8)])
def test_injected_effect_on_a_short_stretch_is_named_first_and_sized(short_clean, name, value):
    """Measured (120 s, 6 signal candidates, default options): steering offset 0.015 rad and ax scale 0.8 are
    named first and sized to within a few per cent of the truth relative to the clean fit."""
    from reachconf.models import single_track

    data, diagnosis, withheld = _realcar_modules()
    cols, stop, V, clean = short_clean
    inj, truth = withheld.inject(cols, name, value)
    report = diagnosis.run_diagnosis(single_track(), data.make_suite(inj, stop=stop), V,
                                     effects=withheld.SIGNAL_CANDIDATES)  # fmt: skip
    j = withheld.judge(report, clean, truth)
    assert j["named_first"], j["verdict"]
    assert j["sized"], j
    assert abs(j["relative_error"]) <= 0.3
    # the clean stretch names nothing of the kind: the injection made the difference
    assert (truth["effect"], truth["target"]) not in {(e["effect"], e["target"]) for e in clean.named}


@needs_data
def test_an_injection_that_cancels_the_cars_own_bias_is_named_against_the_clean_run(short_clean):
    """The car's yaw-rate record has a bias of its own (about +0.02 rad/s); an injected -0.02 cancels it, so the
    base model's misfit *falls*.  The difference of the residuals against the clean run
    (``reference_loss="difference"``) holds the whole change: named first, moved by the injected value within
    30 % (by the excess of the losses, the previous default, the verdict was "no change")."""
    from reachconf.models import single_track

    data, diagnosis, withheld = _realcar_modules()
    cols, stop, V, clean = short_clean
    inj, truth = withheld.inject(cols, "yaw_bias", -0.02)
    report = diagnosis.run_diagnosis(single_track(), data.make_suite(inj, stop=stop), V,
                                     effects=withheld.SIGNAL_CANDIDATES, reference=data.make_suite(cols, stop=stop))  # fmt: skip
    ref = report.decision["reference"]
    assert ref["z"] < 3 and ref["loss"] == "difference", report.verdict  # the base's excess sees no rise
    j = withheld.judge(report, clean, truth)
    assert j["named_first"] and abs(j["relative_error"]) <= 0.3, j
    assert len(report.named) == 1, report.verdict


@needs_data
def test_the_withheld_command_diagnoses_against_the_clean_run_by_default(tmp_path):
    """``withheld.py`` without ``--no-reference`` compares every injected run with the clean one (the workflow
    that names the injections first); 60 s, the signal candidates, one injection."""
    import json

    _, _, withheld = _realcar_modules()
    args = ["--data", str(REAL), "--out", str(tmp_path), "--stop", "60", "--signal-only", "--only", "steer_offset",
            "--value", "steer_offset=0.015"]  # fmt: skip
    assert withheld.main(args) == 0
    result = json.loads((tmp_path / "withheld.json").read_text())
    assert result["reference"] is True
    row = result["rows"]["steer_offset"]
    assert row["named_first"] and abs(row["relative_error"]) <= 0.3, row
    assert withheld.main(args + ["--no-reference", "--out", str(tmp_path / "alone")]) == 0
    assert json.loads((tmp_path / "alone" / "withheld.json").read_text())["reference"] is False


def test_judge_sizes_offsets_additively_and_scales_relative_to_the_clean_fit():
    _, _, withheld = _realcar_modules()

    class Rep:
        def __init__(self, named, ranked, status="named"):
            self.named, self.ranked_effects, self.verdict = named, ranked, "v"
            self.decision = {"status": status}

    clean = Rep([], [{"label": "input_offset(delta)", "params": {"c": 0.002}},
                     {"label": "input_scale(ax)", "params": {"k": 0.95}}], "none")  # fmt: skip
    found = Rep([{"effect": "input_offset", "target": "delta", "params": {"c": 0.0135}}],
                [{"label": "input_offset(delta)", "parts": [["input_offset", "delta"]], "held_out_loss": 1.0,
                  "params": {"c": 0.0135}}])  # fmt: skip
    j = withheld.judge(found, clean, {"effect": "input_offset", "target": "delta", "params": {"c": 0.01}})
    assert j["named_first"] and j["sized"] and j["best_rank"] == 1
    assert j["moved"] == pytest.approx(0.0115) and j["relative_error"] == pytest.approx(0.15)
    # a scale: found / clean - 1 against k - 1 (0.95 * 0.8 = 0.76 is exact; 0.9 is 47 % off)
    for k_found, ok in ((0.76, True), (0.9, False)):
        rep = Rep([{"effect": "input_scale", "target": "ax", "params": {"k": k_found}}], [])
        j = withheld.judge(rep, clean, {"effect": "input_scale", "target": "ax", "params": {"k": 0.8}})
        assert j["named_first"] and j["sized"] is ok
    # named, but not first: not sized
    both = Rep([{"effect": "input_scale", "target": "ax", "params": {"k": 0.76}},
                {"effect": "input_offset", "target": "delta", "params": {"c": 0.012}}], [])  # fmt: skip
    j = withheld.judge(both, clean, {"effect": "input_offset", "target": "delta", "params": {"c": 0.01}})
    assert not j["named_first"] and not j["sized"] and j["from_named_model"]
    # the car's own effect, named in the clean run too, does not count: the injected one is the first new name
    own = Rep([{"effect": "tire_fiala", "target": "axles", "params": {"mu": 1.4}}], clean.ranked_effects)
    tyre_first = Rep([{"effect": "tire_fiala", "target": "axles", "params": {"mu": 1.4}}, found.named[0]], [])
    assert withheld.judge(tyre_first, own, {"effect": "input_offset", "target": "delta", "params": {"c": 0.01}})["named_first"]
    assert not withheld.judge(tyre_first, clean, {"effect": "input_offset", "target": "delta",
                                                  "params": {"c": 0.01}})["named_first"]  # fmt: skip
    # an "indistinguishable" verdict listing the injected effect among its explanations is marked, not first
    lag = Rep([{"effect": "actuator_lag", "target": "delta", "params": {"tau": 0.06}}],
              [{"label": "dead_time(delta)", "parts": [["dead_time", "delta"]], "held_out_loss": 1.0,
                "params": {"T": 0.06}}], "indistinguishable")  # fmt: skip
    lag.decision["alternatives"] = [{"parts": [["dead_time", "delta"]]}]
    clean_t = Rep([], [{"label": "dead_time(delta)", "params": {"T": 0.0}}], "none")
    j = withheld.judge(lag, clean_t, {"effect": "dead_time", "target": "delta", "params": {"T": 0.06}})
    assert j["indistinguishable"] and not j["named_first"] and j["moved"] == pytest.approx(0.06)
    lag.decision["alternatives"] = [{"parts": [["input_offset", "delta"]]}]
    assert not withheld.judge(lag, clean_t, {"effect": "dead_time", "target": "delta",
                                             "params": {"T": 0.06}})["indistinguishable"]  # fmt: skip


#: the slow checks: values other than the example's (withheld.VALUES) and the default checks'.  The steering
#: offset and the ax scale are named (next to the car's own tyre saturation); the others are found (sized within
#: 5 % with the default case weights) but not *named*: next to the tyre each removes far less than the naming
#: rule's 30 % of the remaining held-out loss, most of which is the car's own lateral-velocity misfit.
_NOT_RELEVANT = ("measured (full run, default options, 25 Nov): {} sized within {} of the truth and ranked {}, "
                 "but only the car's own tyre saturation is named")  # fmt: skip
SLOW_CASES = [
    ("steer_offset", 0.01),
    ("ax_scale", 0.9),
    pytest.param("yaw_bias", 0.03, marks=pytest.mark.xfail(reason=_NOT_RELEVANT.format(
        "a 0.025 rad/s bias", "5 %", "2nd"), strict=False)),
    pytest.param("dead_time", 0.05, marks=pytest.mark.xfail(reason=_NOT_RELEVANT.format(
        "a 0.06 s dead time", "1 %", "14th"), strict=False)),
    pytest.param("lag", 0.1, marks=pytest.mark.xfail(reason=_NOT_RELEVANT.format(
        "a 0.08 s lag", "2 %", "4th"), strict=False)),
]


@pytest.fixture(scope="module")
def clean_diagnosis():
    """The diagnosis of the clean run (the reference the injected effects are sized against)."""
    from reachconf.models import single_track

    data, diagnosis, _ = _realcar_modules()
    cols = data.read_run(REAL)
    V = _V(data, cols)
    return cols, V, diagnosis.run_diagnosis(single_track(), data.make_suite(cols), V)


@needs_data
@pytest.mark.slow
@pytest.mark.parametrize("name, value", SLOW_CASES)
def test_injected_effect_is_named_first_and_sized_within_30_percent(clean_diagnosis, name, value):
    """The whole run, every candidate (tyres included), default options."""
    from reachconf.models import single_track

    data, diagnosis, withheld = _realcar_modules()
    cols, V, clean = clean_diagnosis
    inj, truth = withheld.inject(cols, name, value)
    j = withheld.judge(diagnosis.run_diagnosis(single_track(), data.make_suite(inj), V), clean, truth)
    assert j["named_first"], j["verdict"]
    assert j["sized"], j


#: against the clean run as the reference (``rc.diagnose(..., reference=)``, the difference of the residuals): the
#: same values as the slow checks above, and two that move the car's own yaw-rate bias and ax scale towards none
#: (the base model's misfit falls: "no change" by the excess of the losses); and a slow lag, 0.25 s, which came out
#: 42 % small while a lag started at the request's first sample (the inverse lag amplifies the record's noise)
@needs_data
@pytest.mark.slow
@pytest.mark.parametrize("name, value", [("steer_offset", 0.01), ("ax_scale", 0.9), ("yaw_bias", 0.03),
                                         ("dead_time", 0.05), ("lag", 0.1), ("yaw_bias", -0.03),
                                         ("ax_scale", 1.05), ("lag", 0.25), ("lag", 0.05)])  # fmt: skip
def test_injected_effect_against_the_clean_run_is_named_first_and_sized_within_30_percent(clean_diagnosis, name,
                                                                                           value):  # fmt: skip
    """The whole run, every candidate, the clean run as the reference (what changed)."""
    from reachconf.models import single_track

    data, diagnosis, withheld = _realcar_modules()
    cols, V, clean = clean_diagnosis
    inj, truth = withheld.inject(cols, name, value)
    report = diagnosis.run_diagnosis(single_track(), data.make_suite(inj), V, reference=data.make_suite(cols))
    j = withheld.judge(report, clean, truth)
    assert j["named_first"], j["verdict"]  # the dead time too: its difference from a lag no longer drowns
    assert abs(j["relative_error"]) <= 0.3, j
    # nothing the clean run also has is named: only the injected effect
    assert len(report.named) == 1, report.verdict


@needs_data
@pytest.mark.slow
def test_a_lag_at_the_resolution_limit_is_not_named_a_dead_time(clean_diagnosis):
    """A 0.03-s lag on top of the car's own timing: named first or reported indistinguishable (naming it among the
    explanations), never a dead time alone.  With the lag's start fitted on the scored windows it was named a dead
    time (the start absorbed the first windows' noise, a freedom the dead time lacks); measured since: indistinguishable,
    +3 %."""
    from reachconf.models import single_track

    data, diagnosis, withheld = _realcar_modules()
    cols, V, clean = clean_diagnosis
    inj, truth = withheld.inject(cols, "lag", 0.03)
    report = diagnosis.run_diagnosis(single_track(), data.make_suite(inj), V, reference=data.make_suite(cols))
    j = withheld.judge(report, clean, truth)
    assert j["named_first"] or j["indistinguishable"], j["verdict"]
    assert abs(j["relative_error"]) <= 0.3, j


def _adopt_module():
    _realcar_modules()
    import adopt

    return adopt


def test_adopted_corrections_undo_an_injection_and_the_timing_shifts_the_steering():
    adopt = _adopt_module()
    _, _, withheld = _realcar_modules()
    t = np.arange(0, 20, 0.01)
    cols = {"t": t, "delta": 0.1 * np.sin(0.8 * t), "ax": np.cos(t), "omega": 0.2 * np.sin(0.5 * t),
            "vx": 20 + t, "vy": 0 * t, "ay": np.sin(t)}  # fmt: skip
    rec, _ = withheld.inject(cols, "ax_scale", 0.8)
    a = adopt.Adopted(None, [("input_scale", "ax")], {}, {}, [("input_scale", "ax", (0.8,))], 0.0)
    np.testing.assert_allclose(a.apply(rec)["ax"], cols["ax"])
    rec, _ = withheld.inject(cols, "yaw_bias", 0.02)
    b = adopt.Adopted(None, [("output_offset", "omega")], {}, {}, [("output_offset", "omega", (0.02,))], 0.0)
    np.testing.assert_allclose(b.apply(rec)["omega"], cols["omega"])
    # a lead of 0.03 s removed: the shifted record at t is the recorded one at t + 0.03
    c = adopt.Adopted(None, [], {}, {}, [], -0.03).apply(cols)
    np.testing.assert_allclose(c["delta"][:-10], 0.1 * np.sin(0.8 * (t[:-10] + 0.03)), atol=1e-6)
    assert np.array_equal(c["ax"], cols["ax"])


def test_adopted_are_the_named_effects_else_a_significant_best_model():
    from types import SimpleNamespace

    adopt = _adopt_module()
    th = {"thresholds": {"z_name": 3.0}}
    best = {"parts": [["input_scale", "ax"], ["tire_fiala", "axles"]], "held_out_loss": 1.0, "z_vs_base": 6.4}
    named = [{"effect": "input_offset", "target": "delta"}]
    assert adopt.found_parts(SimpleNamespace(named=named, ranked_effects=[best], decision=th)) == [("input_offset", "delta")]
    assert adopt.found_parts(SimpleNamespace(named=[], ranked_effects=[best], decision=th)) == [
        ("input_scale", "ax"), ("tire_fiala", "axles")]  # fmt: skip
    weak = {**best, "z_vs_base": 1.9}
    unscored = {"parts": [["dead_time", "delta"]], "held_out_loss": None}
    assert adopt.found_parts(SimpleNamespace(named=[], ranked_effects=[unscored, weak], decision=th)) == []


@needs_data
def test_adoption_fits_the_found_effects_and_the_signed_steering_timing_on_a_short_stretch():
    """The first 120 s: adopting input_scale(ax) on the clean and on injected stretches (ax scale 0.8, a 0.05 s
    steering dead time) moves the fitted scale by the injected ratio and the signed timing by the delay."""
    from reachconf.models import single_track

    adopt = _adopt_module()
    data, diagnosis, withheld = _realcar_modules()
    cols = data.read_run(REAL)
    short = {k: v[cols["t"] <= cols["t"][0] + SHORT_SECONDS] for k, v in cols.items()}

    from types import SimpleNamespace

    # what a diagnosis found: input_scale(ax) named
    Found = SimpleNamespace(named=[{"effect": "input_scale", "target": "ax"}], ranked_effects=[], base={"params": {}})

    car = single_track()
    clean = adopt.adopt(car, short, Found, diagnosis.FIT)
    assert clean.parts == [("input_scale", "ax")] and set(clean.params) == set(diagnosis.FIT)
    assert abs(clean.timing) < 0.06  # the car's own steering timing
    scaled = adopt.adopt(car, withheld.inject(short, "ax_scale", 0.8)[0], Found, diagnosis.FIT, timing=False)
    ratio = scaled.effect_params["input_scale(ax)"]["k"] / clean.effect_params["input_scale(ax)"]["k"]
    assert ratio == pytest.approx(0.8, rel=0.01)  # measured: 0.80004
    delayed = adopt.adopt(car, withheld.inject(short, "dead_time", 0.05)[0], Found, diagnosis.FIT)
    assert delayed.timing - clean.timing == pytest.approx(0.05, rel=0.1)  # measured: 0.04998 (clean: -0.015 s)


#: the options the two-stage checks were measured with (the defaults before loss_scale="case", min_improvement 0.4;
#: with those, the clean run names the tyre alone and an ax scale of 1.1 is not named in either stage)
TWO_STAGE_OPTIONS = {"loss_scale": "sensor", "min_improvement": 0.3}


@pytest.fixture(scope="module")
def two_stages():
    """The clean run diagnosed, its findings adopted (adopt.py) and the stage-2 diagnosis of a recording with them."""
    import reachconf as rc
    from reachconf.models import single_track

    adopt = _adopt_module()
    data, diagnosis, withheld = _realcar_modules()
    opts = rc.DiagnoseOptions(**TWO_STAGE_OPTIONS)
    cols = data.read_run(REAL)
    V = _V(data, cols)
    clean = diagnosis.run_diagnosis(single_track(), data.make_suite(cols), V, options=opts)
    adopted = adopt.adopt(single_track(), cols, clean, diagnosis.FIT, options=opts)

    def diag(c):
        return diagnosis.run_diagnosis(adopted.model, data.make_suite(adopted.apply(c)), V,
                                       effects=withheld.SIGNAL_CANDIDATES, fit_params=(), options=opts)  # fmt: skip

    return cols, adopted, diag, diag(cols)


@needs_data
@pytest.mark.slow
def test_two_stages_name_an_ax_scale_that_one_stage_misses(two_stages):
    """Measured (whole run, TWO_STAGE_OPTIONS): one stage finds an ax scale of 1.1 exactly but does not name it
    (23.5 % alone: the car's own scale of 0.96 halves it); with the clean run's input_scale(ax) +
    tire_fiala(axles) and its steering lead of 0.027 s adopted, it is named first (51 %, z 12.5) and sized exactly."""
    _, _, withheld = _realcar_modules()
    cols, adopted, diag, clean2 = two_stages
    assert adopted.parts == [("input_scale", "ax"), ("tire_fiala", "axles")]
    assert -0.05 < adopted.timing < 0.0  # the car's own steering lead
    assert clean2.decision["status"] == "none"
    inj, truth = withheld.inject(cols, "ax_scale", 1.1)
    j = withheld.judge(diag(inj), clean2, truth)
    assert j["named_first"] and j["sized"], j


@pytest.mark.parametrize("cell, message", [("nan", r"line 5, column 'vx': nan \(1 NaN/inf in all\)"),
                                           ("x", r"cannot read \(could not convert string 'x' .* at line 5, column 7")])
def test_a_bad_cell_is_named_by_the_file_line(data_mod, tmp_path, cell, message):
    """The errors named numpy's data-row index (row 3 for the file's line 5) or no row at all (an outside review)."""
    import gzip

    import reachconf as rc

    cols = data_mod.COLUMNS
    rows = [",".join(cols)] + [",".join(f"{0.01 * k if c == 't' else 1.0:g}" for c in cols) for k in range(300)]
    rows[4] = rows[4].split(",", 6)
    rows[4][6] = cell + "," + rows[4][6].split(",", 1)[1]  # column 7 (vx) of line 5
    rows[4] = ",".join(rows[4])
    with gzip.open(tmp_path / data_mod.FILE, "wt") as fh:
        fh.write("\n".join(rows) + "\n")
    with pytest.raises(rc.DataError, match=message):
        data_mod.read_run(tmp_path)


@pytest.mark.parametrize("factor, column, ok", [(1.0, "vx", True), (3.6, "vx", False), (180 / np.pi, "omega", False)])
def test_speeds_in_other_units_are_refused(data_mod, tmp_path, factor, column, ok):
    """A copy with vx in km/h ran as usual, with W boxes 3-5 times larger (an outside review); ay = vy' + vx omega
    on a car, the data README's own check, tells."""
    import gzip

    import reachconf as rc

    t = np.arange(3000) * 0.01
    vals = {c: np.zeros_like(t) for c in data_mod.COLUMNS}
    vals.update(t=t, vx=12 + 3 * np.sin(0.3 * t), omega=0.4 * np.sin(0.9 * t))
    vals["ay"] = vals["vx"] * vals["omega"] + 0.2 * np.cos(0.9 * t)  # (+ vy', which averages out)
    vals[column] = vals[column] * factor
    with gzip.open(tmp_path / data_mod.FILE, "wt") as fh:
        fh.write(",".join(data_mod.COLUMNS) + "\n")
        np.savetxt(fh, np.column_stack([vals[c] for c in data_mod.COLUMNS]), delimiter=",", fmt="%.9g")
    if ok:
        assert data_mod.read_run(tmp_path)["vx"].size == t.size
    else:
        with pytest.raises(rc.DataError, match=r"not in m/s, rad/s and m/s\^2"):
            data_mod.read_run(tmp_path)


@needs_data
def test_the_withheld_checks_default_data_folder_is_the_shared_one(monkeypatch):
    import importlib.util

    from conftest import REPO_ROOT

    monkeypatch.delenv("REACHCONF_DATA", raising=False)
    spec = importlib.util.spec_from_file_location("realcar_withheld", REPO_ROOT / "examples" / "realcar" / "withheld.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    assert (mod.default_data() / "stanford_track_100hz.csv.gz").is_file()  # was /shared/data/realcar
