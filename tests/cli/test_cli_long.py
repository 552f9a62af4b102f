"""The command line on long recordings: streamed reach tubes, pre-flight memory and time checks."""

import json
import shutil

import numpy as np
import pytest

import reachconf.cli as cli
from reachconf.demo import demo_run_file
from reachconf.tube import ReachTube


@pytest.fixture()
def run_copy(tmp_path):
    dst = tmp_path / "demo"
    shutil.copytree(demo_run_file().parent, dst)
    return dst / "run.toml"


def test_reach_streams_a_tube_too_large_to_keep(tmp_path, run_copy, monkeypatch, capsys):
    """Above the threshold the tube is streamed: every step's bounds in the .npz, every k-th set, a picture."""
    out = tmp_path / "out"
    assert cli.main(["reach", str(run_copy), "--case", "lane_change_01", "--out", str(out), "--json",
                     str(out / "r.json")]) == 0  # fmt: skip
    kept = json.loads((out / "r.json").read_text())["lane_change_01"]
    monkeypatch.setattr(cli, "STREAM_TUBE_BYTES", 0)
    out2 = tmp_path / "out2"
    assert cli.main(["reach", str(run_copy), "--case", "lane_change_01", "--out", str(out2), "--json",
                     str(out2 / "r.json")]) == 0  # fmt: skip
    streamed = json.loads((out2 / "r.json").read_text())["lane_change_01"]
    assert streamed["streamed"] is True and "bounds" not in streamed
    tube = ReachTube.load(out2 / "lane_change_01_tube.npz")
    b = np.asarray(kept["bounds"])
    assert np.allclose(tube.bounds(), b, atol=1e-9)
    assert np.allclose(streamed["interval_hull"], [b[:, 0].min(axis=0), b[:, 1].max(axis=0)], atol=1e-9)
    assert (out2 / "lane_change_01_tube.png").stat().st_size > 5_000


def test_memory_and_time_limits_stop_before_the_work(run_copy, monkeypatch, capsys):
    monkeypatch.setenv("REACHCONF_MEMORY_LIMIT", "1e6")
    assert cli.main(["conform", str(run_copy), "--kind", "trace"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "nothing was computed" in err[0] and "lane_change_01" in err[0]
    assert cli.main(["reach", str(run_copy)]) == 2
    assert "nothing was computed" in capsys.readouterr().err
    monkeypatch.delenv("REACHCONF_MEMORY_LIMIT")
    text = run_copy.read_text().replace("[trace]", "[trace]\nwindow = 50")
    run_copy.write_text(text)
    assert cli.main(["conform", str(run_copy), "--kind", "trace", "--time-limit", "1e-9"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "exceeds the time limit" in err[0]
