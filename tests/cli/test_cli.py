"""The command line: the demo, subcommands on the shipped run file, and one-line user errors."""

import json
import shutil
import subprocess
import sys

import pytest

from reachconf.demo import demo_run_file


def run(*args, timeout=300):
    return subprocess.run([sys.executable, "-m", "reachconf.cli", *map(str, args)], capture_output=True, text=True,
                          timeout=timeout)  # fmt: skip


def test_demo_runs_and_writes_results(tmp_path):
    proc = run("demo", "--out", tmp_path / "demo")
    assert proc.returncode == 0, proc.stderr
    summary = json.loads((tmp_path / "demo" / "summary.json").read_text())
    assert summary["cases"] == 3
    assert summary["synthesis"]["group_conformant"]["lane_change"] is True
    assert (tmp_path / "demo" / "reach_tube_xy.png").stat().st_size > 10_000
    assert "minimal reachset-conformant W" in proc.stdout


@pytest.fixture()
def run_copy(tmp_path):
    src = demo_run_file().parent
    dst = tmp_path / "demo"
    shutil.copytree(src, dst)
    return dst / "run.toml"


def test_conform_reach_synth_plot(tmp_path, run_copy):
    out = tmp_path / "out"
    proc = run("conform", run_copy, "--case", "lane_change_02", "--kind", "reachset", "--json", out / "c.json")
    assert proc.returncode == 0, proc.stderr
    verdicts = json.loads((out / "c.json").read_text())
    assert list(verdicts) == ["lane_change_02"]
    assert verdicts["lane_change_02"]["reachset"]["conformant"] is True  # the true W is reachset conformant
    proc = run("plot", out / "c.json", "--out", out)  # conform's per-case verdicts
    assert proc.returncode == 0, proc.stderr
    assert (out / "c.png").stat().st_size > 5_000
    proc = run("reach", run_copy, "--case", "lane_change_01", "--out", out)
    assert proc.returncode == 0, proc.stderr
    assert (out / "lane_change_01_tube.npz").exists() and (out / "lane_change_01_tube.png").exists()
    proc = run("plot", out / "lane_change_01_tube.npz", "--out", out)
    assert proc.returncode == 0, proc.stderr
    text = run_copy.read_text().replace("alpha_iterations = 10", "alpha_iterations = 3")
    run_copy.write_text(text)
    proc = run("synth", run_copy, "--case", "lane_change_01", "--json", out / "s.json", "--out", out)
    assert proc.returncode == 0, proc.stderr
    res = json.loads((out / "s.json").read_text())
    assert res["cases"]["lane_change_01"]["conformant"] is True
    assert (out / "synthesis.png").exists()
    assert run("plot", out / "s.json", "--out", out).returncode == 0


def test_segment_length_checks_every_segment(tmp_path, run_copy):
    """``--segment-length`` / ``segment_length``: each stretch of a case is a case of its own, from its first sample.

    The demo data were made with the run file's W and noise inside V, so every segment is conformant."""
    out = tmp_path / "out"
    proc = run("conform", run_copy, "--case", "lane_change_02", "--segment-length", "1", "--json", out / "c.json",
               "--workers", "1")  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    verdicts = json.loads((out / "c.json").read_text())
    assert list(verdicts) == [f"lane_change_02[{a},{a + 1}]" for a in range(4)]
    assert all(v["reachset"]["conformant"] is True and v["trace"]["conformant"] is True for v in verdicts.values())
    tiny = run_copy.read_text().replace("[-0.05, 0.05], [-0.05, 0.05], [-0.01, 0.01], [-0.1, 0.1], [-0.1, 0.1], "
                                        "[-0.05, 0.05]", "[0, 0], [0, 0], [0, 0], [0, 0], [0, 0], [0, 0]")  # fmt: skip
    small = run_copy.with_name("small.toml")
    small.write_text(tiny)
    proc = run("conform", small, "--case", "lane_change_02", "--kind", "trace", "--segment-length", "1",
               "--json", out / "w0.json")  # fmt: skip
    assert proc.returncode in (0, 3), proc.stderr  # the segments can fail: W = 0 does not explain the data
    assert any(v["trace"]["conformant"] is not True for v in json.loads((out / "w0.json").read_text()).values())
    run_copy.write_text(run_copy.read_text().replace('suite = "suite"', 'suite = "suite"\nsegment_length = 2.5'))
    proc = run("conform", run_copy, "--case", "lane_change_01", "--kind", "trace", "--json", out / "d.json")
    assert proc.returncode == 0, proc.stderr
    assert list(json.loads((out / "d.json").read_text())) == ["lane_change_01[0,2.5]", "lane_change_01[2.5,4]"]
    proc = run("conform", run_copy, "--case", "lane_change_01", "--kind", "trace", "--segment-length", "2",
               "--segment-step", "1", "--json", out / "e.json")  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    assert list(json.loads((out / "e.json").read_text())) == [f"lane_change_01[{a},{a + 2}]" for a in range(3)]


@pytest.mark.parametrize(
    "edit, args, message",
    [
        (lambda t: t.replace('suite = "suite"', 'suite = "suite"\nsegment_length = -1'), (),
         "segment_length must be a positive number of seconds"),
        (lambda t: t.replace('suite = "suite"', 'suite = "suite"\nsegment_length = "2 s"'), (),
         "segment_length must be a positive number of seconds"),
        (lambda t: t.replace("[sets]\n", "[sets]\nX0 = [[0, 0], [0, 0], [0, 0], [10, 10], [0, 0], [0, 0]]\n"),
         ("--segment-length", "1"),
         "--segment-length: segments start from their own first sample"),
        (lambda t: t, ("--segment-length", "0"), "must be a positive, finite number of seconds"),
        (lambda t: t, ("--segment-step", "1"), "--segment-step needs a segment length"),
        (lambda t: t, ("--segment-length", "1", "--segment-step", "2"), "is longer than the segments"),
        (lambda t: t.replace('suite = "suite"', 'suite = "suite"\nsegment_step = 1'), (),
         "segment_step needs a segment length (segment_length)"),
    ],
)
def test_bad_segment_lengths_are_one_line_errors(run_copy, edit, args, message):
    run_copy.write_text(edit(run_copy.read_text()))
    proc = run("conform", run_copy, "--kind", "trace", *args)
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("reachconf: error:"), proc.stderr
    assert message in lines[0]


@pytest.mark.parametrize(
    "edit, message",
    [
        (lambda t: t.replace('model = "bicycle_closed_loop"', 'model = "nope"'), "nope"),
        (lambda t: t.replace("[-0.05, 0.05], [-0.05, 0.05], [-0.01, 0.01]", "[-0.05, 0.05]"), "sets.W: has 4 intervals"),
        (lambda t: t.replace("time_step = 0.02", "time_stepp = 0.02"), "unknown options ['time_stepp']"),
        (lambda t: t.replace('suite = "suite"', 'suite = "missing"'), "does not exist"),
        (lambda t: "colour = 1\n" + t, "unknown keys ['colour']"),
        (lambda t: t.replace("[-0.02, 0.02]", "[0.02, -0.02]", 1), "lo > hi"),
    ],
)
def test_user_errors_are_one_line_with_status_2(run_copy, edit, message):
    run_copy.write_text(edit(run_copy.read_text()))
    proc = run("conform", run_copy, "--kind", "trace")
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("reachconf: error:"), proc.stderr
    assert message in lines[0]


def test_bad_data_file_through_cli(run_copy):
    case = run_copy.parent / "suite" / "lane_change_01.csv"
    lines = case.read_text().splitlines()
    lines[5] = lines[5].replace(lines[5].split(",")[7], "oops", 1)
    case.write_text("\n".join(lines) + "\n")
    proc = run("conform", run_copy)
    assert proc.returncode == 2
    assert "lane_change_01.csv: row 6" in proc.stderr and "not a number: 'oops'" in proc.stderr
