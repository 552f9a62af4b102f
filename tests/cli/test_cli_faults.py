"""Bad input and faults through the command line (issue 19), in-process via ``cli.main``.

Each test names the item of issue 19's "Why" list it covers.  The work
functions are replaced by stand-ins where a test is about what happens
before (or around) the work, so that these tests take milliseconds; the
stand-ins fail the test if the work starts when it must not.
"""

import importlib
import json
import os
import shutil
import socket
import threading
import time

import numpy as np
import pytest

import reachconf as rc
from reachconf import cli
from reachconf.conformance.synthesis import CaseSynthesis, SynthesisResult
from reachconf.demo import demo_run_file
from reachconf.io import OutputLock
from reachconf.runner import Interrupted
from reachconf.sets.core import Interval


@pytest.fixture()
def run_file(tmp_path):
    dst = tmp_path / "demo"
    shutil.copytree(demo_run_file().parent, dst)
    return dst / "run.toml"


def edit(run_file, old, new):
    text = run_file.read_text()
    assert old in text
    run_file.write_text(text.replace(old, new))
    return run_file


def main(capsys, *argv):
    """``cli.main`` in-process: (exit status, stdout, stderr lines)."""
    status = cli.main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return status, out, err.strip().splitlines()


def one_line_error(status, err, *needles):
    assert status == 2, err
    assert len(err) == 1 and err[0].startswith("reachconf: error:"), err
    for n in needles:
        assert str(n) in err[0], err[0]
    assert "Traceback" not in err[0]


def patch(monkeypatch, dotted, value):
    """``monkeypatch.setattr`` on a module found by import (``reachconf.reach`` is also a function name)."""
    module, name = dotted.rsplit(".", 1)
    monkeypatch.setattr(importlib.import_module(module), name, value)


def no_work(*args, **kwargs):
    pytest.fail("the work started although the command had to stop before it")


def fake_synthesis(model, suite, V, *args, **kwargs):
    W = Interval(-np.ones(model.q), np.ones(model.q))
    cases = {c.name: CaseSynthesis(c.name, c.group, W, W, W, 1.0, True, 0.1) for c in suite}
    return SynthesisResult(cases, {"lane_change": W}, {"lane_change": 1.0}, {"lane_change": True},
                           Interval([-1.0] * model.p, [1.0] * model.p), model.disturbance_names, 0.1)  # fmt: skip


WORK = {"synth": "reachconf.conformance.synthesis.synthesize_W", "diagnose": "reachconf.diagnose.pipeline.diagnose",
        "conform": "reachconf.conformance.trace.trace_conformance", "reach": "reachconf.reach.reach"}  # fmt: skip


# ---------------------------------------------------------------- Why 1: outputs checked before the work


@pytest.mark.parametrize("command", sorted(WORK))
def test_out_that_is_a_file_fails_before_the_work(capsys, monkeypatch, run_file, tmp_path, command):
    patch(monkeypatch, WORK[command], no_work)
    (tmp_path / "F").write_text("an existing file")
    status, _, err = main(capsys, command, run_file, "--out", tmp_path / "F")
    one_line_error(status, err, f"{tmp_path / 'F'}: --out must be a folder, but it is a file")
    status, _, err = main(capsys, command, run_file, "--json", tmp_path / "F" / "r.json")
    one_line_error(status, err, "r.json: --json:", "is a file, not a folder")
    assert (tmp_path / "F").read_text() == "an existing file"


@pytest.mark.parametrize("command", sorted(WORK))
def test_outputs_never_overwrite_the_runs_inputs(capsys, monkeypatch, run_file, tmp_path, command):
    """--json onto the run file, a case file or suite.toml, or --out into the suite folder, replaced the user's
    inputs (or left results the next run read as cases): refused before the work, every input unchanged."""
    patch(monkeypatch, WORK[command], no_work)
    suite = run_file.parent / "suite"
    before = {p: p.read_bytes() for p in [run_file, *suite.iterdir()]}
    case = sorted(suite.glob("*.csv"))[0]
    for option, target, needle in [("--json", run_file, "is the run's input"),
                                   ("--json", case, "lies in the test-suite folder"),
                                   ("--json", suite / "suite.toml", "lies in the test-suite folder"),
                                   ("--json", suite / "new.json", "lies in the test-suite folder"),
                                   ("--out", suite, "lies in the test-suite folder"),
                                   ("--out", suite / "sub", "lies in the test-suite folder")]:
        status, _, err = main(capsys, command, run_file, option, target)
        one_line_error(status, err, f"{target}: {option}", needle)
    assert {p: p.read_bytes() for p in [run_file, *suite.iterdir()]} == before


@pytest.mark.parametrize("bad, needle", [("", "the file name is empty"), ("res/", "ends with '/'")])
def test_json_must_be_a_file_name(capsys, monkeypatch, run_file, tmp_path, bad, needle):
    patch(monkeypatch, WORK["conform"], no_work)
    monkeypatch.chdir(tmp_path)
    status, _, err = main(capsys, "conform", run_file, "--json", bad)
    one_line_error(status, err, "--json", needle)
    assert not (tmp_path / "res").exists()


def test_unwritable_output_is_named_by_the_users_path(capsys, monkeypatch, run_file, tmp_path):
    import tempfile

    def mkstemp(suffix=None, prefix=None, dir=None, text=False):  # an unwritable folder (tests run as root)
        raise PermissionError(13, "Permission denied", os.path.join(dir, f"{prefix}b5jlj0z3"))

    patch(monkeypatch, "reachconf.conformance.synthesis.synthesize_W", fake_synthesis)
    monkeypatch.setattr(tempfile, "mkstemp", mkstemp)
    status, _, err = main(capsys, "synth", run_file, "--json", tmp_path / "res" / "synthesis.json")
    one_line_error(status, err, f"{tmp_path / 'res' / 'synthesis.json'}", "Permission denied")
    assert "b5jlj0z3" not in err[0]


def test_only_out_keeps_every_result(capsys, monkeypatch, run_file, tmp_path):
    """Why 1: without --json everything was lost; --out now gets the JSON of every command."""
    patch(monkeypatch, "reachconf.conformance.synthesis.synthesize_W", fake_synthesis)
    status, _, _ = main(capsys, "synth", run_file, "--out", tmp_path / "o")
    assert status == 0
    assert json.loads((tmp_path / "o" / "synthesis.json").read_text())["verdict"] == "conformant"
    assert (tmp_path / "o" / "synthesis.png").stat().st_size > 1000
    assert sorted(p.name for p in (tmp_path / "o").iterdir()) == ["synthesis.json", "synthesis.png"]  # no lock left


# ---------------------------------------------------------------- Why 3: the third verdict


def test_failed_reach_is_undecided_with_exit_3_and_strict_json(capsys, run_file, tmp_path):
    huge = ", ".join(["[-100, 100]"] * 6)
    text = run_file.read_text()
    start = text.index("W = [")
    run_file.write_text(text[:start] + f"W = [{huge}]" + text[text.index("\n", start):])
    status, out, err = main(capsys, "conform", run_file, "--case", "lane_change_01", "--kind", "reachset",
                            "--json", tmp_path / "c.json", "--out", tmp_path / "o")  # fmt: skip
    assert status == cli.EXIT_UNDECIDED == 3, err
    assert "lane_change_01: reachset: undecided (adaptive reachability of model" in out  # the default algorithm
    for path in (tmp_path / "c.json", tmp_path / "o" / "conformance.json"):
        res = json.loads(path.read_text(), parse_constant=lambda c: pytest.fail(f"{c} is not JSON"))
        entry = res["lane_change_01"]["reachset"]
        assert entry["verdict"] == "undecided" and entry["conformant"] is None and entry["max_violation"] is None
        head, _, tail = entry["message"].partition("could not bound the abstraction error at t = ")
        assert tail and float(tail.split()[0]) < 0.1, entry["message"]  # early (measured: 0.049 s)


def test_undecided_reaches_make_synthesis_undecided(monkeypatch):
    from reachconf.conformance import synthesis
    from reachconf.conformance.reachset import ReachsetResult
    from reachconf.runfile import load_run
    from reachconf.verdict import Verdict

    def failing_reach(model, case, W, V, options):
        return ReachsetResult(case.name, False, 0.0, float("inf"), np.zeros(case.t.size, bool), None, 0.0,
                              "reachability failed at t = 0 s", verdict=Verdict.UNDECIDED)  # fmt: skip

    monkeypatch.setattr(synthesis, "reachset_check", failing_reach)
    spec = load_run(demo_run_file())
    suite = spec.suite().select(names=["lane_change_01"])
    res = synthesis.synthesize_W(spec.model, suite, spec.V, rc.SynthesisOptions(optimize=False, alpha_iterations=1))
    case = res.cases["lane_change_01"]
    assert case.verdict is Verdict.UNDECIDED and not case.conformant and "the reach failed" in case.message
    assert res.group_verdict["lane_change"] is Verdict.UNDECIDED and res.verdict is Verdict.UNDECIDED
    d = json.loads(res.to_json(), parse_constant=lambda c: pytest.fail(c))
    assert d["verdict"] == "undecided" and d["group_conformant"] == {"lane_change": None}
    assert "undecided" in res.table()


# ---------------------------------------------------------------- Why 4: concurrent runs into one --out


def test_second_run_into_the_same_out_fails_clearly_while_the_first_keeps_its_results(capsys, monkeypatch, run_file,
                                                                                      tmp_path):  # fmt: skip
    started, release = threading.Event(), threading.Event()

    def slow_synthesis(*args, **kwargs):
        started.set()
        assert release.wait(30)
        return fake_synthesis(*args, **kwargs)

    patch(monkeypatch, "reachconf.conformance.synthesis.synthesize_W", slow_synthesis)
    out = tmp_path / "out"
    first = {}
    thread = threading.Thread(target=lambda: first.update(status=cli.main(["synth", str(run_file), "--out", str(out)])))
    thread.start()
    try:
        assert started.wait(60)
        patch(monkeypatch, "reachconf.conformance.synthesis.synthesize_W", no_work)
        status, _, err = main(capsys, "synth", run_file, "--out", out)
        one_line_error(status, err, f"{out}: another reachconf run is writing this folder (pid {os.getpid()}")
    finally:
        release.set()
        thread.join(60)
    assert first["status"] == 0
    assert json.loads((out / "synthesis.json").read_text())["verdict"] == "conformant"


def test_locked_json_file(capsys, monkeypatch, run_file, tmp_path):
    patch(monkeypatch, "reachconf.conformance.synthesis.synthesize_W", no_work)
    with OutputLock(tmp_path / "r.json", "--json"):
        status, _, err = main(capsys, "synth", run_file, "--json", tmp_path / "r.json")
    one_line_error(status, err, "r.json: another reachconf run is writing this file")


# ---------------------------------------------------------------- Why 5 and 6: run files, options, plot


@pytest.mark.parametrize(
    "old, new, message",
    [
        ('suite = "suite"', 'suite = "suite"\nworkers = "many"', "workers must be a positive integer"),
        ('suite = "suite"', "suite = \"suite\"\nworkers = 0", "workers must be a positive integer"),
        ("time_step = 0.02", "time_step = 0.02\nzonotope_order = 1e9", "zonotope_order must be a number in [1, 1000]"),
        ('model = "bicycle_closed_loop"', 'model = "os.path:join"', "model 'os.path:join': calling it"),
        ("time_step = 0.02", 'time_step = "fast"', "[reach] time_step must be a number or None, got 'fast'"),
        ("alpha_iterations = 10", 'alpha_iterations = "ten"', "[synthesis] alpha_iterations must be an integer"),
        ("alpha_iterations = 10", 'alpha_iterations = 10\nalpha_below_failed_reach = "yes"',
         "[synthesis] alpha_below_failed_reach must be true or false"),
        ('suite = "suite"', 'suite = "suite"\ndiagnose = 5', "[diagnose] must be a table, got 5"),
        ("[-0.02, 0.02]", "[-0.02, true]", "sets.V: must be a list of [lo, hi] pairs of numbers"),
    ],
)
def test_run_file_errors_name_the_key(capsys, monkeypatch, run_file, old, new, message):
    patch(monkeypatch, "reachconf.conformance.synthesis.synthesize_W", no_work)
    status, _, err = main(capsys, "synth", edit(run_file, old, new))
    one_line_error(status, err, f"{run_file}:", message)


@pytest.mark.parametrize("workers", ["0", "-3", "many"])
def test_workers_must_be_positive(capsys, monkeypatch, run_file, workers):
    patch(monkeypatch, "reachconf.conformance.synthesis.synthesize_W", no_work)
    status, _, err = main(capsys, "synth", run_file, f"--workers={workers}")
    one_line_error(status, err, "argument --workers: must be a positive integer")


def test_scheduler_that_does_not_answer(capsys, monkeypatch, run_file):
    """Why 6: the message read ``error: : Timed out``."""
    patch(monkeypatch, "reachconf.conformance.synthesis.synthesize_W", no_work)
    with socket.socket() as s:  # a port nobody listens on
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    status, _, err = main(capsys, "synth", run_file, "--scheduler", f"tcp://127.0.0.1:{port}")
    one_line_error(status, err, f"scheduler 'tcp://127.0.0.1:{port}': cannot connect to 127.0.0.1:{port}")
    status, _, err = main(capsys, "synth", run_file, "--scheduler", "127.0.0.1:8786")
    one_line_error(status, err, "scheduler '127.0.0.1:8786': expected an address like 'tcp://host:8786'")


def test_dask_timeout_says_what_happened():
    pytest.importorskip("distributed")
    import dask

    from reachconf.runner import run_cases

    with socket.socket() as s, dask.config.set({"distributed.comm.timeouts.connect": "1s"}):
        s.bind(("127.0.0.1", 0))
        s.listen()  # accepts the TCP connection, never speaks Dask
        address = f"tcp://127.0.0.1:{s.getsockname()[1]}"
        with pytest.raises(rc.OptionsError, match=rf"scheduler '{address}': cannot connect to the Dask scheduler: "):
            run_cases(abs, [1, 2], scheduler=address)


PLOT_FILES = {
    "binary.json": bytes(range(256)),
    "list.json": b"[1, 2, 3]",
    "number.json": b"5",
    "front.json": b'{"front": 5}',
    "front_list.json": b'{"front": [5], "disturbances": ["w"], "start": [[0, 1]]}',
    "shape.json": json.dumps({"disturbances": ["w1", "w2"], "groups": {"g": [[0, 1]]}}).encode(),
    "nulls.json": json.dumps({"disturbances": ["w1"], "groups": {"g": [[None, 1]]}}).encode(),
    "names.json": json.dumps({"disturbances": "w1", "groups": {"g": [[0, 1]]}}).encode(),
    "deep.json": b"[" * 100_000,
}


@pytest.mark.parametrize("name", sorted(PLOT_FILES))
def test_plot_on_bad_json_is_one_line(capsys, tmp_path, name):
    (tmp_path / name).write_bytes(PLOT_FILES[name])
    status, _, err = main(capsys, "plot", tmp_path / name)
    one_line_error(status, err, f"{tmp_path / name}:")
    assert not (tmp_path / name).with_suffix(".png").exists()


# ---------------------------------------------------------------- Why 5: the API


def test_api_arguments_are_checked_and_named():
    from reachconf.runfile import load_run
    from reachconf.runner import run_cases

    spec = load_run(demo_run_file())
    suite = spec.suite()
    with pytest.raises(rc.OptionsError, match=r"synthesize_W: workers must be a positive integer.*'2'"):
        rc.synthesize_W(spec.model, suite, spec.V, workers="2")
    with pytest.raises(rc.DataError, match=r"synthesize_W: the suite is empty"):
        rc.synthesize_W(spec.model, [], spec.V)
    with pytest.raises(rc.DataError, match=r"synthesize_W: suite must hold TestCase"):
        rc.synthesize_W(spec.model, ["lane_change_01"], spec.V)
    with pytest.raises(rc.OptionsError, match=r"trace_conformance: options must be a TraceOptions.*got ReachOptions"):
        rc.trace_conformance(spec.model, suite[0], spec.W, spec.V, options=rc.ReachOptions())
    with pytest.raises(rc.DataError, match=r"case must be a reachconf TestCase, got str"):
        rc.trace_conformance(spec.model, "lane_change_01", spec.W, spec.V)
    with pytest.raises(rc.OptionsError, match=r"reachset_conformance: options must be a ReachOptions"):
        rc.reachset_conformance(spec.model, suite[0], spec.W, spec.V, options=rc.TraceOptions())
    with pytest.raises(rc.ModelError, match=r"trace_conformance: model must be a reachconf Model, got str"):
        rc.trace_conformance("bicycle", suite[0], spec.W, spec.V)
    with pytest.raises(rc.OptionsError, match=r"workers must be a positive integer"):
        run_cases(abs, [1], workers=0)


# ---------------------------------------------------------------- Why 7: Ctrl-C keeps results apart


def _interrupting_synthesis(model, suite, V, *args, **kwargs):
    done = fake_synthesis(model, suite, V)
    raise Interrupted([next(iter(done.cases.values())), None, None])


def test_ctrl_c_never_replaces_an_earlier_complete_result(capsys, monkeypatch, run_file, tmp_path):
    complete = tmp_path / "synthesis.json"
    complete.write_text('{"complete": "an earlier run"}')
    patch(monkeypatch, "reachconf.conformance.synthesis.synthesize_W", _interrupting_synthesis)
    status, _, err = main(capsys, "synth", run_file, "--json", complete)
    assert status == cli.EXIT_INTERRUPTED == 130
    assert complete.read_text() == '{"complete": "an earlier run"}'
    partial = tmp_path / "synthesis.partial.json"
    assert err == [f"reachconf: interrupted; partial results in {partial}"]
    saved = json.loads(partial.read_text())
    assert saved["interrupted"] is True and saved["partial"][0]["name"] == "lane_change_01"
    assert main(capsys, "synth", run_file, "--json", complete)[0] == 130  # again: a new file, the old one stays
    assert (tmp_path / "synthesis.partial-2.json").exists() and partial.exists()


def test_ctrl_c_with_only_out_saves_into_the_folder(capsys, monkeypatch, run_file, tmp_path):
    patch(monkeypatch, "reachconf.conformance.synthesis.synthesize_W", _interrupting_synthesis)
    status, _, err = main(capsys, "synth", run_file, "--out", tmp_path / "o")
    assert status == 130
    saved = json.loads((tmp_path / "o" / "synth.partial.json").read_text())
    assert saved["command"] == "synth" and len(saved["partial"]) == 1


def test_ctrl_c_during_conform_keeps_the_finished_cases(capsys, monkeypatch, run_file, tmp_path):
    from reachconf.conformance.trace import TraceResult

    calls = []

    def trace(model, case, W, V, **kwargs):
        calls.append(case.name)
        if len(calls) == 2:
            raise KeyboardInterrupt
        z = np.zeros((case.t.size, model.n))
        return TraceResult(case.name, case.t, True, z[0], z, z[:-1, : model.q], z[:, : model.p], {"w1": 0.1})

    patch(monkeypatch, "reachconf.conformance.trace.trace_conformance", trace)
    status, out, err = main(capsys, "conform", run_file, "--kind", "trace", "--json", tmp_path / "c.json")
    assert status == 130 and "lane_change_01: trace: conformant" in out
    saved = json.loads((tmp_path / "c.partial.json").read_text())
    assert list(saved["partial"]) == ["lane_change_01"]  # the finished case only
    assert not (tmp_path / "c.json").exists()


def test_ctrl_c_inside_compiled_code_callbacks_is_still_an_interrupt(capsys, monkeypatch, run_file, tmp_path):
    """A Ctrl-C while numba unpickles a function surfaces as a SystemError caused by the KeyboardInterrupt
    (seen in the subprocess test under load): still status 130 and the partial results, not a traceback."""

    def work(*args, **kwargs):
        try:
            raise KeyboardInterrupt
        except KeyboardInterrupt as exc:
            raise SystemError("<function _numba_unpickle> returned a result with an exception set") from exc

    patch(monkeypatch, "reachconf.conformance.synthesis.synthesize_W", work)
    status, _, err = main(capsys, "synth", run_file, "--json", tmp_path / "s.json")
    assert status == 130 and err == ["reachconf: interrupted; no results finished yet"]
    patch(monkeypatch, "reachconf.conformance.synthesis.synthesize_W", lambda *a, **k: 1 / 0)
    with pytest.raises(ZeroDivisionError):  # a bug stays a traceback (status 1)
        cli.main(["synth", str(run_file)])


def test_ctrl_c_lost_inside_a_c_extension_import_is_still_an_interrupt(capsys, monkeypatch, run_file, tmp_path):
    """numpy turns a Ctrl-C during its C-extension import into an ImportError that no longer carries the
    KeyboardInterrupt (seen in 1 of 3 subprocess runs under load): the pressed key itself is remembered."""
    import os
    import signal

    def work(*args, **kwargs):
        try:
            os.kill(os.getpid(), signal.SIGINT)  # through cli.main's handler, as a real Ctrl-C
            time.sleep(5)
        except KeyboardInterrupt:
            pass
        raise ImportError('PyCapsule_Import could not import module "datetime"')  # no chained cause

    patch(monkeypatch, "reachconf.conformance.synthesis.synthesize_W", work)
    status, _, err = main(capsys, "synth", run_file, "--json", tmp_path / "s.json")
    assert status == 130 and err == ["reachconf: interrupted; no results finished yet"]
    patch(monkeypatch, "reachconf.conformance.synthesis.synthesize_W", lambda *a, **k: 1 / 0)
    with pytest.raises(ZeroDivisionError):  # the next run without Ctrl-C: a bug stays a traceback
        cli.main(["synth", str(run_file)])


@pytest.mark.parametrize("bad", ["-1", "0", "nan", "inf"])
def test_time_limit_must_be_positive_seconds(capsys, monkeypatch, run_file, bad):
    patch(monkeypatch, WORK["conform"], no_work)
    status, _, err = main(capsys, "conform", run_file, "--time-limit", bad)
    one_line_error(status, err, "--time-limit", "positive, finite number of seconds")


def test_a_model_module_next_to_the_run_file_is_found(capsys, monkeypatch, run_file, tmp_path):
    """``model = "mymodel:model"`` with mymodel.py beside run.toml failed unless its folder was on PYTHONPATH."""
    import sys

    name = f"usermodel_{os.getpid()}_{time.monotonic_ns()}"
    (run_file.parent / f"{name}.py").write_text("from reachconf.models import bicycle_closed_loop as model\n")
    edit(run_file, 'model = "bicycle_closed_loop"', f'model = "{name}:model"')
    monkeypatch.chdir(tmp_path)  # not the run file's folder
    monkeypatch.setattr(sys, "path", list(sys.path))
    patch(monkeypatch, WORK["conform"], no_work)
    status, _, err = main(capsys, "conform", run_file, "--case", "nope")
    one_line_error(status, err, "no test case ['nope']")  # the model was loaded; the case selection fails after it
    status, _, err = main(capsys, "conform", edit(run_file, f'"{name}:model"', '"not_there_xyz:model"'))
    one_line_error(status, err, "No module named 'not_there_xyz'", "next to the run file")


def test_a_suite_name_no_file_system_takes_is_one_line(capsys, monkeypatch, run_file):
    """A NUL character in the run file's folder names (found by the run-file fuzz: a bare ValueError before)."""
    patch(monkeypatch, WORK["conform"], no_work)
    status, _, err = main(capsys, "conform", edit(run_file, 'suite = "suite"', 'suite = "su\\u0000ite"'))
    one_line_error(status, err, f"{run_file}: suite: 'su\\x00ite' is not a usable folder name")


def test_an_empty_out_is_refused(capsys, monkeypatch, run_file, tmp_path):
    patch(monkeypatch, WORK["conform"], no_work)
    monkeypatch.chdir(tmp_path)
    status, _, err = main(capsys, "conform", run_file, "--out", "")
    one_line_error(status, err, "--out: the folder name is empty")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["demo"]  # nothing written beside the run's folder


@pytest.mark.parametrize("table, needle", [
    ("holdout = 2.0", "[diagnose]: holdout must be a number in (0, 1), got 2.0"),
    ("seed = -1", "[diagnose]: seed must be a non-negative integer, got -1"),
    ('effects = [["actuator_lag", "vx"]]', "[diagnose]: "),
    ('reference = "ref\\u0000"', "[diagnose]: reference: 'ref\\x00' is not a usable folder name"),
    ("smooth_span = -0.1", "smooth_span must be a positive number, got -0.1"),
    ("substeps = 0", "substeps must be a positive integer, got 0"),
    ('input_hold = "cubic"', "input_hold must be one of ('zero', 'linear'), got 'cubic'"),
])
def test_diagnose_settings_are_named_with_the_run_file(capsys, monkeypatch, run_file, table, needle):
    patch(monkeypatch, WORK["diagnose"], no_work)
    run_file.write_text(run_file.read_text() + f"\n[diagnose]\n{table}\n")
    status, _, err = main(capsys, "diagnose", run_file)
    one_line_error(status, err, f"{run_file}: [diagnose]", needle)
