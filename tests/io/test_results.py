"""Results behave alike: plot(ax=None, ...) returns the axes, save/load round-trips, the CLI plots each file."""

import json

import matplotlib.pyplot as plt
import numpy as np
import pytest

import reachconf as rc
from reachconf.cli import main
from reachconf.conformance import CaseSynthesis, ParetoFront, ReachsetResult, SynthesisResult, TraceResult
from reachconf.diagnose import GapLocation, GapReport, Identification
from reachconf.io import TestCase


@pytest.fixture(scope="module")
def tube():
    m = rc.Model(name="spiral", states=("a", "b"), disturbances=("w",),
                 dynamics=lambda s: [-0.2 * s.a - s.b, s.a - 0.2 * s.b + s.w])  # fmt: skip
    return rc.reach(m, rc.Interval([0.9, -0.1], [1.1, 0.1]), np.linspace(0, 2, 11), W=rc.Interval([-0.1], [0.1]))


def _box(lo, hi):
    return rc.Interval(lo, hi)


def _results(tube):
    t = np.linspace(0, 1, 5)
    trace = TraceResult("c1", t, True, np.zeros(2), np.ones((5, 2)), np.full((4, 1), 0.1), np.zeros((5, 2)),
                        {"w": 0.05, "a": 0.01, "b": 0.02}, "perstep (measured)", 0.5, "", np.full(2, 1e-9), ("w",),
                        ("a", "b"))  # fmt: skip
    Y = np.column_stack([np.cos(t), np.sin(t)])
    reachset = ReachsetResult("c1", False, 0.75, 0.2, np.array([True, True, True, False, True]), tube, 1.0, "",
                              {0.75: 0.2}, t, Y, ("a", "b"))  # fmt: skip
    case = CaseSynthesis("c1", "g", _box([-1.0], [1.0]), _box([-0.5], [0.5]), _box([-0.6], [0.6]), 0.6, True, 2.0,
                         {"step1": 0.1}, True, "", [(1.0, True), (0.5, False)])  # fmt: skip
    synth = SynthesisResult({"c1": case}, {"g": _box([-0.6], [0.6])}, {"g": 0.6}, {"g": True}, _box([-0.1, -0.1],
                            [0.1, 0.1]), ("w",), 3.0, {"g": 1.0})  # fmt: skip
    front = ParetoFront([_box([-0.5, -1.0], [0.5, 1.0]), _box([-1.0, -0.2], [1.0, 0.2])], [(0, 1), (1, 0)],
                        _box([-1.0, -1.0], [1.0, 1.0]), ("w1", "w2"), "trace")  # fmt: skip
    location = GapLocation(["w"], {"w": 1.0}, {"w": [-1.0, 1.0]}, {"c1": []}, {}, {"w": {"a": 0.5}})
    effect = {"label": "dead_time(u)", "parts": [["dead_time", "u"]], "held_out_loss": 0.5, "prediction_gain": 0.5,
              "z_vs_base": 4.0, "admissible": True, "tests": [], "params_by_effect": {"dead_time(u)": {"T": 0.1}},
              "effect": "dead_time", "target": "u", "params": {"T": 0.1}}  # fmt: skip
    report = GapReport({"location": location.to_dict()}, [effect], "dead_time on u explains the gap",
                       {"prediction_cost": 1.0}, None, [],
                       {"W": {"w": {"before": [-1.0, 1.0], "after": [-0.5, 0.5], "shrink": 2.0}}},
                       {"train": ["c1"], "test": ["c2"]}, 4.0)  # fmt: skip
    ident = Identification({"k": 1.1}, {"k": 1.0}, {"k": 0.05}, 0.3, 100, "prediction")
    return {"trace": trace, "reachset": reachset, "synthesis": synth, "pareto": front, "location": location,
            "report": report, "identification": ident}  # fmt: skip


@pytest.mark.parametrize("kind", ["trace", "reachset", "synthesis", "pareto", "location", "report", "identification"])
def test_every_result_plots_saves_and_loads(kind, tube, tmp_path):
    res = _results(tube)[kind]
    axes = res.plot()
    assert all(hasattr(a, "figure") for a in np.atleast_1d(axes))
    fig, own = plt.subplots()
    if kind not in ("trace", "synthesis"):  # these draw on several axes
        assert res.plot(ax=own) is own
    plt.close("all")
    path = res.save(tmp_path / f"{kind}.json")
    assert json.loads(path.read_text())["result"] == type(res).__name__
    back = type(res).load(path)
    assert back.to_dict() == res.to_dict()
    if kind != "identification":
        assert main(["plot", str(path), "--out", str(tmp_path)]) == 0
        assert (tmp_path / f"{kind}.png").stat().st_size > 0
    other = next(t for k, t in _results(tube).items() if k != kind)
    with pytest.raises(rc.DataError, match="holds a"):
        type(other).load(path)


def test_tube_plots_with_measurements_and_old_argument_order(tube, tmp_path):
    case = TestCase("m", "g", np.linspace(0, 2, 11), np.zeros((11, 0)), np.ones((11, 2)), (), ("a", "b"))
    ax = tube.plot(measured=case)
    assert ax.get_xlabel() == "a" and ax.get_ylabel() == "b"
    assert [t for t in ax.get_legend_handles_labels()[1]] == ["measured"]
    _, own = plt.subplots()
    assert tube.plot(("b", "a"), own) is own and own.get_xlabel() == "b"  # plot(dims, ax) of old scripts
    plt.close("all")
    assert json.loads(tube.to_json())["state_names"] == ["a", "b"]
    tube.save(tmp_path / "t.npz")
    assert main(["plot", str(tmp_path / "t.npz"), "--dims", "1", "0"]) == 0
    assert main(["plot", str(tmp_path / "t.npz"), "--dims", "b", "a"]) == 0


def test_loading_a_bad_result_file_names_it(tmp_path):
    bad = tmp_path / "bad.json"
    bad.write_text("[1, 2]")
    with pytest.raises(rc.DataError, match="bad.json"):
        TraceResult.load(bad)
    bad.write_text('{"result": "TraceResult", "case": "x"}')
    with pytest.raises(rc.DataError, match="not a TraceResult file"):
        TraceResult.load(bad)
    assert main(["plot", str(bad)]) == 2
