"""Wind turbine: the OpenFAST readers and the per-step trace conformance on the real output."""

import importlib.util
import json

import numpy as np
import pytest

import reachconf as rc
from conftest import DATA_ROOT, REPO_ROOT
from reachconf.datasets.openfast import read_csv, read_outb

WT = DATA_ROOT / "windturbine"
needs_data = pytest.mark.skipif(not (WT / "5MW_Land_DLL_WTurb.outb").exists(), reason="wind-turbine data not available")


def load_run():
    spec = importlib.util.spec_from_file_location("wt_run", REPO_ROOT / "examples" / "windturbine" / "run.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


@needs_data
def test_outb_reader_agrees_with_csv():
    b = read_outb(WT / "5MW_Land_DLL_WTurb.outb")
    c = read_csv(WT / "5MW_Land_DLL_WTurb.csv.gz")
    assert b.time.size == c.time.size == 9601 and np.isclose(b.time[1] - b.time[0], 1 / 160)
    shared = [n for n in c.channels if n in b.channels]
    assert len(shared) >= 12
    for n in shared:
        step = np.ptp(b[n]) / 65536  # quantisation of the int16 binary
        # the CSV keeps 4-5 decimals: differences stay within one quantisation step or the CSV rounding
        assert np.max(np.abs(b[n] - c[n])) <= step + 5e-5 * max(1.0, np.max(np.abs(c[n]))), n


def test_reader_errors(tmp_path):
    f = tmp_path / "x.outb"
    f.write_bytes(np.array([4, 9], dtype="<i2").tobytes() + np.array([3, 10], dtype="<i4").tobytes())
    with pytest.raises(rc.DataError, match="truncated"):
        read_outb(f)
    f.write_bytes(np.array([7], dtype="<i2").tobytes())
    with pytest.raises(rc.DataError, match="unknown OpenFAST FileID 7"):
        read_outb(f)
    g = tmp_path / "y.csv"
    g.write_text("# c\nTime,A\n(s),(m)\n0,1\n0.1,abc\n")
    with pytest.raises(rc.DataError, match="non-numeric"):
        read_csv(g)
    with pytest.raises(rc.DataError, match="unknown channel 'B'"):
        read_csv(_good_csv(tmp_path))["B"]


def _good_csv(tmp_path):
    g = tmp_path / "z.csv"
    g.write_text("# c\nTime,A\n(s),(m)\n0,1\n0.1,2\n")
    return g


@needs_data
def test_reduced_run_resimulates_within_0_1_percent(tmp_path):
    run = load_run()
    assert run.main(["--data", str(WT), "--out", str(tmp_path), "--seconds", "8"]) == 0
    result = json.loads((tmp_path / "windturbine.json").read_text())
    assert set(result) == set(run.FILES)
    for entry in result.values():
        assert entry["conformant"]
        assert all(v < 1e-3 for v in entry["max_rel_deviation"].values())
        assert len(entry["W_box"]) == 3
    assert (tmp_path / "5MW_Land_DLL_WTurb_disturbances.png").exists()
