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


def test_yaw_sensor_offset_is_named_with_its_size(nominal):
    report = _check("yaw_offset", nominal)
    assert report.best["shrink_volume"] > 2.0  # the offset needs a large yaw-acceleration disturbance


@pytest.mark.slow
@pytest.mark.parametrize("name", [n for n in WITHHELD if n != "yaw_offset"])
def test_every_withheld_effect_is_named(name, nominal):
    _check(name, nominal)
