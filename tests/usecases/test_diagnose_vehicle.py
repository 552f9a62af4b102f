"""Gap diagnosis on vehicle suites whose effect is withheld from the model (multi-body plant, campaign generator)."""

import pytest
from conftest import load_example

import reachconf as rc
from reachconf.models import bicycle

pytest.importorskip("vehiclemodels")
example = load_example("diagnose")
FIT, judge = example.FIT, example.judge
WITHHELD, nominal_bicycle_params, withheld_suite = example.WITHHELD, example.nominal_bicycle_params, example.withheld_suite


@pytest.fixture(scope="module")
def nominal():
    return nominal_bicycle_params()


def _check(name, nominal):
    suite, truth = withheld_suite(name, repetitions=3)
    report = rc.diagnose(bicycle(**nominal), suite, fit_params=FIT, progress=False)
    verdict = judge(report, truth)
    assert verdict["correct"], (name, report.verdict, report.ranked_effects[:3])
    assert set(report.split["train"]).isdisjoint(report.split["test"])
    return report


@pytest.mark.slow  # 40 s; the fast test_protocol_smoke_two_effects diagnoses a yaw-offset vehicle suite the same way
def test_yaw_sensor_offset_is_named_with_its_size(nominal):
    report = _check("yaw_offset", nominal)
    assert report.before_after["W_volume_shrink"] > 2.0  # the offset needs a large yaw-acceleration disturbance
    (named,) = report.named
    lo, hi = named["interval"]["c"]
    assert lo <= WITHHELD["yaw_offset"][1][0]["params"]["c"] <= hi


@pytest.mark.slow
@pytest.mark.parametrize("name", [n for n in WITHHELD if n != "yaw_offset"])
def test_every_withheld_effect_is_named(name, nominal):
    _check(name, nominal)


# ---------------------------------------------------------------------------------------------------------------
# the validation protocol (docs/diagnosis-validation.md)
import protocol  # noqa: E402  (examples/diagnose is on sys.path once run.py is loaded)
import protocol_eval  # noqa: E402


def test_protocol_sets_are_made_differently():
    tuning, test = protocol.tuning_specs(), protocol.test_specs()
    assert len(test) >= 30 and sum(not s.truth for s in test) >= 4
    assert {s.name for s in test} == {s.name for s in protocol.test_specs(seed=2)}  # deterministic
    other = protocol.test_specs(seed=5)
    assert [s.changes for s in other] != [s.changes for s in test]  # another seed: another set
    standard = set(protocol.STANDARD_GROUPS)
    assert all(set(s.maneuvers) <= standard for s in test)
    assert not any(set(s.maneuvers) & standard for s in tuning)  # tuning never sees a standard maneuver
    assert {s.seed for s in tuning}.isdisjoint({s.seed for s in test})
    taus = [t["params"]["tau"] for s in test for t in s.truth if t["effect"] == "actuator_lag"]
    delays = [t["params"]["T"] for s in test for t in s.truth if t["effect"] == "dead_time"]
    assert taus and min(taus) >= 0.05 and max(taus) <= 0.25 and delays and min(delays) >= 0.04 and max(delays) <= 0.2
    assert any(len(s.truth) >= 2 and len({t["target"] for t in s.truth}) == 2 for s in test)  # two effects at once
    assert len({round(s.noise, 3) for s in test}) > 5 and all(0.5 <= s.noise <= 2.0 for s in test)
    assert sum(s.noise == 1.0 for s in tuning) == 24  # the campaign's noise, and a block across the test range
    assert {s.noise for s in tuning} - {1.0} == {0.5, 0.7, 1.4, 2.0}
    assert {s.category for s in tuning if s.noise != 1.0} >= {"clean", "yaw offset", "steering lag", "two effects"}
    order = protocol_eval.interleaved(test)  # a run stopped early has a sample of every category
    assert sorted(s.name for s in order) == sorted(s.name for s in test)
    assert len({s.category for s in order[:8]}) == len({s.category for s in test}) == 8


def test_protocol_smoke_two_effects(tmp_path, nominal):
    """The protocol's machinery on two small suites: generation, diagnosis, judging, threshold choice, tables."""
    from dataclasses import replace

    specs = [replace(s, name=f"smoke-{s.category.replace(' ', '_')}", maneuvers=s.maneuvers[:2], repetitions=1)
             for s in protocol.tuning_specs() if s.changes in ({"k_delta": 1 / 0.12}, protocol.yaw_offset(-1.2)[0])]
    assert len(specs) == 2
    offset = next(i for i, s in enumerate(specs) if "offset" in s.category)
    opts = {}
    rows = [protocol_eval.diagnose_job((s, str(tmp_path), nominal, FIT, opts, False)) for s in specs]
    for r, s in zip(rows, specs):
        # two runs only: judged against the truth (the quality figures come from the full protocol)
        assert set(r["judge"]["effects"]) == {f"{t['effect']}({t['target']})" for t in s.truth}
        assert r["judge"]["status"] == r["decision"]["status"], r["verdict"]
        # the true effect is the best model (on two runs the lag's z may stay below z_name: not asserted)
        assert all(f"{t['effect']}({t['target']})" in r["ranked"][0]["label"] for t in s.truth), r["ranked"][0]
        assert (tmp_path / "suites" / s.name / "spec.json").exists() and (tmp_path / "results" / f"{s.name}.npz").exists()
    assert rows[offset]["judge"]["outcome"] == "all named", rows[offset]["verdict"]  # an offset: even on two runs
    (size,) = rows[offset]["judge"]["params"]  # ... with its size
    assert abs(size["relative_error"]) < 0.1, size
    again = protocol_eval.diagnose_job((specs[0], str(tmp_path), nominal, FIT, opts, False))
    assert again["cpu_seconds"] == rows[0]["cpu_seconds"]  # read back, not recomputed
    choice = protocol_eval.choose_thresholds(rows, tmp_path)
    assert set(choice["chosen"]) == {"z_name", "min_improvement", "z_separate"}
    assert len(choice["grid"]) > 100
    # the re-decision with the defaults reproduces the stored decision
    d = protocol_eval.redecide(rows[0], tmp_path)
    assert d["status"] == rows[0]["decision"]["status"]
    md = protocol_eval.summary_tables(rows, "smoke")
    assert "| steering lag | 1 |" in md and "coverage of the 95 % intervals" in md
    # a suite folder holding a case of another suite (as one written by an older save_suite could) is made again
    folder = tmp_path / "suites" / protocol_eval.stem(specs[0])
    stray = folder / "DLC_2_1.csv"
    stray.write_text(next(folder.glob("*.csv")).read_text())
    suite = protocol_eval.load_or_make(specs[0], tmp_path)
    assert sorted(c.name for c in suite) == sorted(protocol.case_names(specs[0])) and not stray.exists()
    test_spec = protocol.test_specs(seed=5)[0]  # test sets of other seeds keep their own folders
    assert protocol_eval.stem(test_spec) != protocol_eval.stem(protocol.test_specs(seed=6)[0])
