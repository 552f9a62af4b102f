"""Pedestrian use case: the BIWI reader, the exact reachable sets, and Table 9 on the real data."""

import json

import numpy as np
import pytest

import reachconf as rc
from conftest import DATA_ROOT, load_example
from reachconf.datasets.biwi import prediction_cases, read_obsmat, read_sequence

PED = DATA_ROOT / "pedestrians"


def load_run():
    return load_example("pedestrians")


def test_reader_rejects_bad_files(tmp_path):
    f = tmp_path / "hotel" / "obsmat.txt"
    f.parent.mkdir()
    f.write_text("1 1 0 0 0 0 0 0\n11 1 0.4 0 0 1 0 0\n21 1 abc 0 0 1 0 0\n")
    with pytest.raises(rc.DataError, match=r"obsmat.txt: row 3, column 3: not a number"):
        read_obsmat(f)
    f.write_text("1 1 0 0 0 0 0\n")
    with pytest.raises(rc.DataError, match="row 1: 7 columns"):
        read_obsmat(f)
    f.write_text("")
    with pytest.raises(rc.DataError, match="empty"):
        read_obsmat(f)
    f.write_text("1 1 nan 0 0 0 0 0\n")
    with pytest.raises(rc.DataError, match="NaN"):
        read_obsmat(f)


def test_backward_velocity_uses_only_the_past(tmp_path):
    f = tmp_path / "hotel" / "obsmat.txt"
    f.parent.mkdir()
    # constant velocity 1 m/s in x, then a jump at the last sample: the backward estimate must not see it
    rows = [f"{1 + 10 * k} 7 {0.4 * k} 0 0 1 0 0" for k in range(8)] + ["81 7 10 0 0 1 0 0"]
    f.write_text("\n".join(rows) + "\n")
    cases = prediction_cases(read_obsmat(f), horizon=1.6, start_step=0.4, velocity="backward")
    np.testing.assert_allclose(cases.v0[:, 0], 1.0)
    assert len(cases) == 4  # t0 = 0.4 .. 1.6: one past sample and 1.6 s of future each


def test_exact_sets_are_sound_and_tight():
    run = load_run()
    rng = np.random.default_rng(0)
    N = 4000
    p0, v0 = rng.normal(size=(N, 2)), rng.normal(size=(N, 2))
    t = np.array([0.4, 0.8, 1.2, 1.6])
    # true motions: initial errors in the boxes, accelerations in the disk (constant direction)
    dp = rng.uniform(-0.1, 0.1, (N, 2))
    dv = rng.uniform(-0.1, 0.1, (N, 2))
    ang = rng.uniform(0, 2 * np.pi, N)
    a = run.A_MAX * np.sqrt(rng.uniform(0, 1, N))[:, None] * np.column_stack([np.cos(ang), np.sin(ang)])
    fut = (p0 + dp)[:, None] + t[None, :, None] * (v0 + dv)[:, None] + 0.5 * t[None, :, None] ** 2 * a[:, None]
    cases = type("C", (), {})()
    cases.p0, cases.v0, cases.future, cases.offsets = p0, v0, fut, t
    a_req, _ = run.required(cases)
    assert np.all(a_req <= run.A_MAX + 1e-9)  # every true motion is inside (soundness)
    # tightness: an acceleration 5 % above a_max along the axis, at the corner errors, is outside
    fut_out = p0[:, None] + 0.1 + t[None, :, None] * (v0 + 0.1)[:, None] + 0.5 * t[None, :, None] ** 2 * 1.05 * run.A_MAX
    cases.future = fut_out
    a_req, _ = run.required(cases)
    assert np.all(a_req > run.A_MAX)


def test_exact_set_inside_reachconf_tube():
    """The closed-form acceleration-model set is inside the reach tube of eq. 73 computed by reachconf."""
    from reachconf.models.pedestrian import pedestrian_acc
    from reachconf.sets import disk_zonotope

    m = pedestrian_acc()
    X0 = rc.Interval([-0.1, -0.1, 0.9, -0.1], [0.1, 0.1, 1.1, 0.1])
    W = disk_zonotope(0.6, 8)
    tube = rc.reach(m, X0, np.array([0.0, 0.4, 0.8, 1.2, 1.6]), W=W)
    rng = np.random.default_rng(1)
    for k, t in enumerate([0.4, 0.8, 1.2, 1.6]):
        ang = rng.uniform(0, 2 * np.pi, 500)
        disk = 0.5 * 0.6 * t * t * np.column_stack([np.cos(ang), np.sin(ang)])
        box = rng.choice([-1, 1], size=(500, 2)) * (0.1 + 0.1 * t)
        pts = np.array([t * 1.0, 0.0]) + box + disk
        S = tube.time_point_sets[k + 1].project([0, 1])
        assert S.contains(pts, tol=1e-9).all()


@pytest.mark.skipif(not (PED / "hotel" / "obsmat.txt").exists(), reason="BIWI data not available")
def test_table9_on_real_hotel_data(tmp_path):
    tracks = read_sequence(PED, "hotel")
    assert len(tracks) == 390 and max(t.pid for t in tracks) == 420
    run = load_run()
    assert run.main(["--data", str(PED), "--out", str(tmp_path)]) == 0
    table = json.loads((tmp_path / "table9.json").read_text())
    assert 90.0 <= table["rate"] <= 100.0
    assert table["passed"] + sum(table["failures"].values()) == table["test_cases"]
    # the default is causal: it starts on the annotations (until 2 Dec it interpolated every 0.1 s, which takes the
    # start position and its "backward" velocity partly from the next annotation)
    assert table["setup"] == "hotel, start every 0.4 s, backward velocity"
    causal = prediction_cases(tracks, 1.6)  # (the default start_step: on the annotations)
    annotated = np.vstack([tr.p for tr in tracks])
    nearest = [np.min(np.abs(annotated - p).sum(axis=1)) for p in causal.p0[::10]]
    assert max(nearest) < 1e-9  # every start position is an annotated one
    assert table["test_cases"] == len(causal)
    assert table["seconds"] < 60
    assert (tmp_path / "pass_rate_curve.png").exists()


@pytest.mark.skipif(not (PED / "hotel" / "obsmat.txt").exists(), reason="BIWI data not available")
def test_the_default_data_folder_does_not_depend_on_the_working_directory(tmp_path, monkeypatch):
    # until 3 Dec the default was "../shared/data/pedestrians" from the caller's directory: only the repo root worked
    monkeypatch.chdir(tmp_path)
    assert load_run().main(["--out", str(tmp_path / "out")]) == 0
    assert json.loads((tmp_path / "out" / "table9.json").read_text())["test_cases"] > 0
