"""Fuzzed run files and result files through ``load_run`` and the command line (issue 19).

Property: a run file either passes every check — the command then reaches
the work, which is replaced here by a stand-in — or the command exits with
status 2 and one line naming the run file (or the suite it names); never
another exception, never a traceback, and never a file written into
``--out`` or ``--json`` before the stop.
"""

import json
import os
import shutil
import tempfile
import tomllib
from pathlib import Path
from unittest import mock

from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

from conftest import toml_text
from reachconf import cli
from reachconf.demo import demo_run_file
from reachconf.errors import DataError
from reachconf.runfile import load_run

#: examples per fuzz test; REACHCONF_FUZZ_EXAMPLES=5000 for a long run
FUZZ = settings(max_examples=int(os.environ.get("REACHCONF_FUZZ_EXAMPLES", 60)), deadline=None, suppress_health_check=[HealthCheck.too_slow])
BASE = tomllib.loads(demo_run_file().read_text())


scalars = st.one_of(st.text(max_size=6), st.integers(-3, 10**12), st.floats(allow_nan=True), st.booleans())
values = st.recursive(scalars, lambda inner: st.one_of(st.lists(inner, max_size=3),
                                                       st.dictionaries(st.sampled_from(["a", "W", "time_step"]), inner,
                                                                       max_size=2)),
                      max_leaves=5)  # fmt: skip
#: models are imported by name: only names that are safe to import
models = st.sampled_from(["bicycle_closed_loop", "vanderpol", "bicycle", "nope", "os.path:join", "math:pi",
                          "reachconf.models:get_model", "reachconf.models.benchmarks:vanderpol", ""])  # fmt: skip
boxes = st.lists(st.lists(st.one_of(st.floats(-10, 10), st.integers(-5, 5), st.text(max_size=2)), min_size=1,
                          max_size=3), max_size=7)  # fmt: skip
TABLE_KEYS = {
    "reach": ["time_step", "zonotope_order", "taylor_terms", "tensor_order", "algorithm", "max_splits", "max_error",
              "reduction", "progress", "rounding", "colour"],
    "trace": ["method", "substeps", "epsilon", "objective", "anchor", "solver"],
    "synthesis": ["alpha_iterations", "alpha_max", "optimize", "merge_iterations", "step2_decimate", "reach"],
    "sets": ["W", "V", "X0", "Z", "unmeasured"],
}  # fmt: skip
#: [sets] values: lists of [lo, hi] pairs, or tables of them (X0 per case) or of pairs (unmeasured states)
set_values = st.one_of(boxes, boxes, st.dictionaries(
    st.sampled_from(["lane_change_01", "lane_change_02", "lane_change_03", "vx", "delta", "q"]),
    st.one_of(boxes, st.lists(st.one_of(st.floats(-2, 2), st.integers(-2, 2), st.booleans()), max_size=3)),
    max_size=3))  # fmt: skip


@st.composite
def run_files(draw):
    doc = json.loads(json.dumps(BASE))  # a deep copy of the demo run file
    for _ in range(draw(st.sampled_from([0, 1, 1, 2, 3]))):
        where = draw(st.sampled_from(["top", "top", "reach", "trace", "synthesis", "sets", "delete"]))
        if where == "top":
            key = draw(st.sampled_from(["model", "suite", "workers", "description", "params", "reach", "colour"]))
            doc[key] = draw(models) if key == "model" else draw(st.one_of(values, st.integers(-2, 4)))
        elif where == "delete" and doc:
            del doc[draw(st.sampled_from(sorted(doc)))]
        else:
            table = doc.setdefault(where, {})
            if not isinstance(table, dict):
                continue
            key = draw(st.sampled_from(TABLE_KEYS[where]))
            table[key] = draw(set_values if where == "sets" else st.one_of(values, st.floats(0, 1e12)))
    return doc


def test_the_demo_run_file_passes_every_check():
    assert load_run(demo_run_file()).model.name == "bicycle_closed_loop"


class WorkStarted(Exception):
    pass


def started(*args, **kwargs):
    raise WorkStarted


@FUZZ
@given(run_files())
def test_fuzzed_run_files_pass_every_check_or_stop_with_one_line_before_writing(doc):
    with tempfile.TemporaryDirectory() as d:
        root = Path(d)
        shutil.copytree(demo_run_file().parent, root / "demo")
        path = root / "demo" / "run.toml"
        path.write_text(toml_text(doc), encoding="utf-8")
        try:
            load_run(path)
            loads = True
        except DataError as exc:
            assert str(path) in str(exc)
            loads = False
        out, json_path = root / "out", root / "res" / "r.json"
        # the work starts where the cases are handed to map_cases (with ``workers`` in the run file they run in
        # worker processes, which the patches of the conformance functions here do not reach)
        with (mock.patch("reachconf.conformance.trace.trace_conformance", started),
              mock.patch("reachconf.conformance.reachset.reachset_conformance", started),
              mock.patch("reachconf.cli_cases.map_cases", started),
              mock.patch("sys.stderr.write") as write):  # fmt: skip
            try:
                status = cli.main(["conform", str(path), "--out", str(out), "--json", str(json_path)])
            except WorkStarted:
                event("reached the work")
                assert loads
                return
        event("stopped")
        text = "".join(c.args[0] for c in write.call_args_list)
        assert status == 2, text
        lines = text.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith("reachconf: error: ") and str(root / "demo") in lines[0], text
        assert list(out.iterdir()) == [] and list(json_path.parent.iterdir()) == []  # nothing written, no lock left


json_values = st.recursive(st.one_of(st.none(), st.booleans(), st.floats(allow_nan=False), st.text(max_size=4)),
                           lambda inner: st.one_of(st.lists(inner, max_size=3),
                                                   st.dictionaries(st.sampled_from(["front", "groups", "disturbances",
                                                                                    "start", "box", "g", "check"]),
                                                                   inner, max_size=4)),
                           max_leaves=8)  # fmt: skip


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(json_values)
def test_plot_of_fuzzed_json_draws_or_stops_with_one_line(value):
    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / "result.json"
        path.write_text(json.dumps(value))
        with mock.patch("sys.stderr.write") as write, mock.patch("sys.stdout.write"):
            status = cli.main(["plot", str(path)])
        text = "".join(c.args[0] for c in write.call_args_list)
        if status == 0:
            assert path.with_suffix(".png").stat().st_size > 1000
        else:
            assert status == 2 and len(text.strip().splitlines()) == 1 and str(path) in text, text
            assert not path.with_suffix(".png").exists()


def test_plot_of_saved_results(tmp_path):
    import numpy as np

    from reachconf.conformance.pareto import ParetoFront
    from reachconf.conformance.synthesis import CaseSynthesis, SynthesisResult
    from reachconf.sets.core import Interval

    W = Interval([-1.0, -2.0], [1.0, 2.0])
    case = CaseSynthesis("c", "g", W, W, W, 1.0, True, 0.1)
    results = {"s.json": SynthesisResult({"c": case}, {"g": W}, {"g": 1.0}, {"g": True}, W, ("w1", "w2"), 0.1),
               "p.json": ParetoFront([W], [(0, 1)], W, ("w1", "w2"), "reachset")}  # fmt: skip
    for name, result in results.items():
        result.save(tmp_path / name)
        assert cli.main(["plot", str(tmp_path / name)]) == 0
        assert (tmp_path / name).with_suffix(".png").stat().st_size > 1000
    d = json.loads((tmp_path / "s.json").read_text())
    d["groups"]["g"] = [[0, 1]]  # one box for two channels
    (tmp_path / "bad.json").write_text(json.dumps(d))
    assert cli.main(["plot", str(tmp_path / "bad.json")]) == 2
    assert not np.any([p.name == "bad.png" for p in tmp_path.iterdir()])


def test_plot_of_a_conformance_summary(tmp_path):
    """reachconf conform's conformance.json (verdicts per case) is drawn: one row per case, coloured by verdict."""
    from reachconf.drawable import load_drawable
    from reachconf.plot import VerdictSummary

    d = {"a": {"trace": {"verdict": "conformant", "margins": {"w1": 0.5, "y": 0.01}},
               "reachset": {"verdict": "not_conformant", "first_violation_time": 1.5}},
         "b": {"trace": {"verdict": "undecided", "margins": {"w1": None, "y": -3.0}}}}  # fmt: skip
    (tmp_path / "conformance.json").write_text(json.dumps(d))
    summary = load_drawable(tmp_path / "conformance.json")
    assert isinstance(summary, VerdictSummary) and list(summary.entries) == ["a", "b"]
    ax = summary.plot()
    assert [t.get_text() for t in ax.get_yticklabels()] == ["a", "b"]
    texts = {t.get_text() for t in ax.texts}
    assert {"smallest margin y: 0.01", "leaves the reach at t = 1.5 s", "smallest margin y: -3"} <= texts
    assert len(ax.patches) == 3
    assert cli.main(["plot", str(tmp_path / "conformance.json")]) == 0
    assert (tmp_path / "conformance.png").stat().st_size > 1000
    for bad in ({"a": {"trace": {"verdict": "maybe"}}}, {"a": {"other": {"verdict": "conformant"}}},
                {"a": {"trace": {"verdict": "conformant", "margins": "w1"}}},
                {"a": {"trace": {"verdict": "conformant", "margins": {"w1": "x"}}}},
                {"a": {"reachset": {"verdict": "not_conformant", "first_violation_time": "soon"}}}):
        assert VerdictSummary.from_dict(bad) is None
        (tmp_path / "bad.json").write_text(json.dumps(bad))  # one line, status 2, no picture
        assert cli.main(["plot", str(tmp_path / "bad.json")]) == 2 and not (tmp_path / "bad.png").exists()
