"""``reachconf pareto`` and ``reachconf warmup`` (issue 20), and a lost cluster through the command line."""

import importlib
import json
import shutil

import numpy as np
import pytest

from reachconf import cli
from reachconf.conformance.pareto import ParetoFront
from reachconf.conformance.synthesis import CaseSynthesis
from reachconf.demo import demo_run_file
from reachconf.runner import WorkersLost
from reachconf.sets.core import Interval


@pytest.fixture()
def run_file(tmp_path):
    dst = tmp_path / "demo"
    shutil.copytree(demo_run_file().parent, dst)
    return dst / "run.toml"


def main(capsys, *argv):
    status = cli.main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return status, out, err.strip().splitlines()


def patch(monkeypatch, dotted, value):
    module, name = dotted.rsplit(".", 1)
    monkeypatch.setattr(importlib.import_module(module), name, value)


def no_work(*args, **kwargs):
    pytest.fail("the work started although the command had to stop before it")


@pytest.mark.parametrize("address, needle", [("127.0.0.1:8786x", "expected an address like"),
                                             ("tcp://127.0.0.1:1", "cannot connect"),
                                             ("tcp://127.0.0.1:99999", "bad port"),
                                             ("http://127.0.0.1:8786", "unknown scheme")])  # fmt: skip
def test_pareto_checks_the_scheduler_before_any_work(run_file, tmp_path, capsys, monkeypatch, address, needle):
    patch(monkeypatch, "reachconf.conformance.pareto.pareto_front", no_work)
    patch(monkeypatch, "reachconf.conformance.synthesis.synthesize_W", no_work)
    status, _, err = main(capsys, "pareto", run_file, "--out", tmp_path / "o", "--scheduler", address)
    assert status == 2 and len(err) == 1 and err[0].startswith("reachconf: error:") and needle in err[0], err
    assert not (tmp_path / "o" / "front.json").exists()


@pytest.mark.parametrize("argv, needle", [((), "the following arguments are required: --out"),
                                          (("--iterations", "0"), "must be a positive integer"),
                                          (("--iterations", "1000000"), "must be at most 60"),
                                          (("--check", "both"), "invalid choice"),
                                          (("--workers", "0"), "must be a positive integer")])  # fmt: skip
def test_pareto_bad_arguments_are_one_line_errors(run_file, tmp_path, capsys, monkeypatch, argv, needle):
    patch(monkeypatch, "reachconf.conformance.pareto.pareto_front", no_work)
    out = () if argv == () else ("--out", tmp_path / "o")
    status, _, err = main(capsys, "pareto", run_file, *out, *argv)
    assert status == 2 and len(err) == 1 and needle in err[0], err


def test_pareto_writes_the_front_and_its_plot(run_file, tmp_path, capsys):
    out = tmp_path / "o"
    status, stdout, _ = main(capsys, "pareto", run_file, "--out", out, "--case", "lane_change_01", "--iterations", "1")
    assert status == 0
    front = ParetoFront.load(out / "front.json")
    assert (out / "front.png").stat().st_size > 1000
    W = Interval.from_list(json.loads((out / "front.json").read_text())["start"])
    # one bisection step per channel from the run file's W: every channel of every box is halved or kept
    for box in front.boxes:
        ratio = (box.hi - box.lo) / (W.hi - W.lo)
        assert np.all(np.isin(np.round(ratio, 12), (0.5, 1.0))), ratio
    assert "non-dominated" in stdout and front.check == "reachset"
    assert main(capsys, "plot", out / "front.json")[0] == 0


def test_pareto_without_W_starts_from_the_synthesis_on_the_same_pool(run_file, tmp_path, capsys, monkeypatch):
    text = run_file.read_text()
    run_file.write_text("\n".join(line for line in text.splitlines() if not line.startswith("W =")))
    from reachconf.conformance import pareto, synthesis

    pools, real_synth, real_front = [], synthesis.synthesize_W, pareto.pareto_front

    def synth(*args, **kwargs):
        pools.append(kwargs["pool"])
        return real_synth(*args, **kwargs)

    def front(*args, **kwargs):
        pools.append(kwargs["pool"])
        return real_front(*args, **kwargs)

    monkeypatch.setattr(synthesis, "synthesize_W", synth)
    monkeypatch.setattr(pareto, "pareto_front", front)
    out = tmp_path / "o"
    status, stdout, _ = main(capsys, "pareto", run_file, "--out", out, "--case", "lane_change_01", "--iterations", "1")
    assert status == 0, stdout
    assert len(pools) == 2 and pools[0] is pools[1]  # one pool for the run
    synth_json = json.loads((out / "synthesis.json").read_text())
    start = json.loads((out / "front.json").read_text())["start"]
    assert start == synth_json["groups"]["lane_change"]


def test_no_worker_left_keeps_the_finished_cases_and_exits_4(run_file, tmp_path, capsys, monkeypatch):
    def lost(model, suite, V, *args, **kwargs):
        W = Interval(-np.ones(model.q), np.ones(model.q))
        done = CaseSynthesis("lane_change_01", "lane_change", W, W, W, 1.0, True, 0.1)
        raise WorkersLost("no Dask worker left for 60 s (2 of 3 jobs unfinished)", partial=[done, None, None])

    patch(monkeypatch, "reachconf.conformance.synthesis.synthesize_W", lost)
    status, _, err = main(capsys, "synth", run_file, "--json", tmp_path / "s.json")
    assert status == cli.EXIT_WORKERS_LOST == 4
    assert len(err) == 1 and "no Dask worker left" in err[0] and "partial results in" in err[0], err
    saved = json.loads((tmp_path / "s.partial.json").read_text())
    assert saved["complete"] is False and [c["name"] for c in saved["partial"]] == ["lane_change_01"]
    assert not (tmp_path / "s.json").exists()


def test_warmup_builds_here_and_reports(tmp_path, capsys):
    status, stdout, _ = main(capsys, "warmup", "vanderpol", "--json", tmp_path / "w.json")
    assert status == 0 and "vanderpol" in stdout and "this machine is ready" in stdout
    report = json.loads((tmp_path / "w.json").read_text())
    assert set(report["here"]) == {"vanderpol"} and report["workers"] == {}


@pytest.mark.parametrize("argv, needle", [(("nosuchmodel",), "unknown model"),
                                          (("vanderpol", "--scheduler", "localhost"), "expected an address"),
                                          (("vanderpol", "--orders", "4"), "invalid choice")])  # fmt: skip
def test_warmup_bad_input_is_one_line(capsys, argv, needle):
    status, stdout, err = main(capsys, "warmup", *argv)
    assert status == 2 and len(err) == 1 and needle in err[0], err
    assert "ready" not in stdout


def test_scheduler_overrides_the_run_files_workers(run_file, tmp_path, capsys, monkeypatch):
    import socket

    from reachconf.conformance.synthesis import SynthesisResult

    seen = {}

    def fake(model, suite, V, options, workers=None, scheduler=None, **kwargs):
        seen.update(workers=workers, scheduler=scheduler)
        W = Interval(-np.ones(model.q), np.ones(model.q))
        cases = {c.name: CaseSynthesis(c.name, c.group, W, W, W, 1.0, True, 0.1) for c in suite}
        return SynthesisResult(cases, {}, {}, {}, V, model.disturbance_names, 0.1)

    patch(monkeypatch, "reachconf.conformance.synthesis.synthesize_W", fake)
    run_file.write_text("workers = 2\n" + run_file.read_text())
    with socket.socket() as server:  # something listening, for the address probe
        server.bind(("127.0.0.1", 0))
        server.listen()
        address = f"tcp://127.0.0.1:{server.getsockname()[1]}"
        assert main(capsys, "synth", run_file, "--scheduler", address)[0] == 0
        assert seen == {"workers": None, "scheduler": address}
        assert main(capsys, "synth", run_file)[0] == 0
        assert seen == {"workers": 2, "scheduler": None}
