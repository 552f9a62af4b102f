"""Wind turbine: the OpenFAST readers, the aero-map fit and the per-step trace conformance on the real output."""

import json

import numpy as np
import pytest

import reachconf as rc
from conftest import DATA_ROOT, load_example
from reachconf.datasets.aero import cp_poly, fit_aero, read_performance_table
from reachconf.datasets.openfast import read_csv, read_outb, read_output

WT = DATA_ROOT / "windturbine"
needs_data = pytest.mark.skipif(not (WT / "5MW_Land_DLL_WTurb.outb").exists(), reason="wind-turbine data not available")


def load_run():
    return load_example("windturbine")


def write_outb(path, file_id, t, values, names, units, desc="test"):
    """A small .outb writer (the documented layout) for round trips."""
    n_t, n_ch = values.shape
    len_name = 12 if file_id == 4 else 10
    head = np.array([file_id], "<i2").tobytes()
    if file_id == 4:
        head += np.array([len_name], "<i2").tobytes()
    head += np.array([n_ch, n_t], "<i4").tobytes()
    body = b""
    if file_id == 3:
        head += np.array([t[0], t[1] - t[0]], "<f8").tobytes()
        data = values.astype("<f8").tobytes()
    else:
        lo, hi = values.min(axis=0), values.max(axis=0)
        scl = (65535.0 / np.where(hi > lo, hi - lo, 1.0)).astype("<f4")
        off = (-32768.0 - lo * scl).astype("<f4")
        packed = np.clip(np.round(values * scl + off), -32768, 32767).astype("<i2")
        if file_id == 1:
            tscl, toff = 1e4, 0.0
            head += np.array([tscl, toff], "<f8").tobytes()
            body = np.round(t * tscl + toff).astype("<i4").tobytes()
        else:
            head += np.array([t[0], t[1] - t[0]], "<f8").tobytes()
        head += scl.tobytes() + off.tobytes()
        data = packed.tobytes()
    d = desc.encode()
    head += np.array([len(d)], "<i4").tobytes() + d
    for s in ["Time", *names]:
        head += s.ljust(len_name).encode()
    for s in ["(s)", *units]:
        head += s.ljust(len_name).encode()
    path.write_bytes(head + body + data)


@pytest.mark.parametrize("file_id", [1, 2, 3, 4])
def test_outb_round_trip_and_truncation(tmp_path, file_id):
    t = np.arange(50) * 0.05
    vals = np.column_stack([np.sin(t), 100 + 3 * np.cos(t), t**2])
    f = tmp_path / f"x{file_id}.outb"
    write_outb(f, file_id, t, vals, ["A", "B", "C"], ["(m)", "(kN)", "(-)"])
    out = read_output(f)
    assert out.file_id == file_id and out.names == ["Time", "A", "B", "C"] and out.units["B"] == "kN"
    assert np.allclose(out.time, t, atol=1e-4)
    for i, n in enumerate("ABC"):
        tol = 1e-12 if file_id == 3 else 0.51 * out.quantisation_step(n) + 1e-6 * np.max(np.abs(vals[:, i]))
        assert np.max(np.abs(out[n] - vals[:, i])) <= tol
    raw = f.read_bytes()
    f.write_bytes(raw[:-7])
    with pytest.raises(rc.DataError, match=r"x\d\.outb: truncated file"):
        read_outb(f)
    f.write_bytes(raw[:40])
    with pytest.raises(rc.DataError, match="truncated file"):
        read_outb(f)
    f.write_bytes(raw + b"\0\0")
    with pytest.raises(rc.DataError, match="unexpected bytes"):
        read_outb(f)


def test_reader_errors(tmp_path):
    f = tmp_path / "x.outb"
    f.write_bytes(np.array([7], dtype="<i2").tobytes())
    with pytest.raises(rc.DataError, match="unknown OpenFAST FileID 7"):
        read_outb(f)
    with pytest.raises(rc.DataError, match="no such file"):
        read_outb(tmp_path / "missing.outb")
    g = tmp_path / "y.csv"
    g.write_text("# c\nTime,A\n(s),(m)\n0,1\n0.1,abc\n")
    with pytest.raises(rc.DataError, match="non-numeric"):
        read_csv(g)
    g.write_text("# c\nTime,A\n(s),(m)\n0,1\n0.1,2\n")
    with pytest.raises(rc.DataError, match=r"y\.csv: unknown channel 'B'"):
        read_csv(g)["B"]
    g.write_text("# c\nTime,A\n(s),(m)\n0,1\n0.1\n")
    with pytest.raises(rc.DataError, match="row 5 has 1 columns"):
        read_csv(g)


@needs_data
def test_outb_reader_agrees_with_csv():
    b = read_outb(WT / "5MW_Land_DLL_WTurb.outb")
    c = read_csv(WT / "5MW_Land_DLL_WTurb.csv.gz")
    assert b.file_id == 4 and len(b.names) == 42 and "FAST Certification Test #18" in b.description
    assert b.time.size == c.time.size == 9601 and np.allclose(np.diff(b.time), 1 / 160)
    derived = {"TTVelFA_fd"}
    assert set(c.names) - derived <= set(b.names)
    for n in set(c.names) - derived:
        assert b.units[n] == c.units[n], n
        # the CSV was decoded from this very file and printed with 6 significant digits: the difference is
        # within one quantisation step of the int16 binary or that rounding, whichever is larger
        rounding = 0.5 * 10.0 ** (np.floor(np.log10(np.maximum(np.abs(c[n]), 1e-30))) - 5)
        assert np.all(np.abs(b[n] - c[n]) <= np.maximum(b.quantisation_step(n), rounding) * (1 + 1e-6)), n
    v = np.gradient(b["TTDspFA"], b.time)
    assert np.max(np.abs(v - c["TTVelFA_fd"])) < 1e-3


@needs_data
def test_aero_fit_reproduces_performance_table_notes():
    tab = read_performance_table(WT / "Cp_Ct_Cq.NREL5MW.txt")
    assert tab.cp.shape == tab.ct.shape == (26, 36)
    i, j = np.unravel_index(np.argmax(tab.cp), tab.cp.shape)
    assert np.isclose(tab.cp[i, j], 0.4659, atol=1e-4) and tab.tsr[i] == 7.5 and tab.pitch_deg[j] == 0.0
    fit = fit_aero(tab)  # TSR 3..12, pitch 0..15 deg (PERFORMANCE_TABLE.md)
    assert np.isclose(fit.cp["p02"], -11.727, atol=1e-3) and np.isclose(fit.ct["t01"], 3.6397, atol=1e-4)
    assert np.isclose(fit.rms_cp, 0.046, atol=1e-3) and np.isclose(fit.rms_ct, 0.082, atol=1e-3)
    narrow = fit_aero(tab, tsr_range=(6.5, 9.0), pitch_range_deg=(0, 2))
    assert narrow.rms_cp < 0.01
    assert np.isclose(cp_poly(narrow.cp, 7.5, 0.0), tab.cp[i, j], atol=0.01)


@needs_data
def test_reduced_run_resimulates_within_0_1_percent(tmp_path):
    run = load_run()
    assert run.main(["--data", str(WT), "--out", str(tmp_path), "--quick"]) == 0
    result = json.loads((tmp_path / "windturbine.json").read_text())
    assert set(result) == set(run.FILES)
    for entry in result.values():
        assert entry["samples"] >= 80 and entry["seconds"] > 0
        assert entry["conformant"]
        assert set(entry["max_rel_deviation"]) == {"Omega", "xT", "MyT"}
        assert all(v < 1e-3 for v in entry["max_rel_deviation"].values())
        assert len(entry["W_box"]) == 3 and all(lo <= hi for lo, hi in entry["W_box"])
    assert (tmp_path / "figure9_disturbances.png").exists()
    assert (tmp_path / "FASTFarm_TSinflow_8mps_T1_undisturbed.png").exists()


def test_bad_data_folder_exits_2(tmp_path, capsys):
    run = load_run()
    assert run.main(["--data", str(tmp_path / "nowhere"), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("windturbine: error:") and "\n" not in err
    assert not (tmp_path / "o" / "windturbine.json").exists()


@needs_data
def test_a_broken_later_file_stops_the_run_before_any_work(tmp_path, capsys):
    """A channel missing in the second file was found after the first file's work and picture (an outside review)."""
    import gzip
    import shutil

    run = load_run()
    data = tmp_path / "data"
    shutil.copytree(WT, data, ignore=shutil.ignore_patterns("*.md"))
    name = run.FILES["FASTFarm_TSinflow_8mps_T1"][0]
    with gzip.open(data / name, "rt") as fh:
        lines = fh.read().splitlines()
    head = next(i for i, line in enumerate(lines) if "GenTq" in line)
    lines[head] = lines[head].replace("GenTq", "GenTorque")  # the channel the model needs is not there
    with gzip.open(data / name, "wt") as fh:
        fh.write("\n".join(lines) + "\n")
    out = tmp_path / "o"
    assert run.main(["--data", str(data), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("windturbine: error:") and "\n" not in err and name in err
    assert not out.exists()  # nothing written: the first file was not processed first


@needs_data
def test_too_short_a_window_says_so(tmp_path, capsys):
    run = load_run()
    assert run.main(["--data", str(WT), "--out", str(tmp_path / "o"), "--seconds", "0.15", "--no-plots"]) == 2
    err = capsys.readouterr().err.strip()
    assert "a longer --seconds?" in err and "\n" not in err
