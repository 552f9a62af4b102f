"""Robot among the replayed BIWI crowds: the safety layers, the robot's reach sets, a reduced run."""

import json

import numpy as np
import pytest

from conftest import DATA_ROOT, load_example

PED = DATA_ROOT / "pedestrians"


@pytest.fixture(scope="module")
def run():
    return load_example("robot")


def test_online_verification_rejects_a_motion_into_a_pedestrian_set(run):
    L = run.L
    pose = (0.0, 0.0, 0.0)
    cands = np.array([[1.0, 0.0], [0.0, 0.0]])
    far, near = np.array([[10.0, 10.0]]), np.array([[1.6, 0.0]])
    towards = np.array([[-1.0, 0.0]])
    assert L.safe_candidates("online_verification", pose, cands, far, towards).all()
    assert list(L.safe_candidates("online_verification", pose, cands, near, towards)) == [False, True]
    assert not L.safe_candidates("braking_ics", pose, cands, near, np.zeros((1, 2)))[0]
    # without a velocity estimate only the velocity model bounds the pedestrian
    assert not L.safe_candidates("online_verification", pose, cands, np.array([[2.5, 0.0]]), np.full((1, 2), np.nan))[0]
    # a pedestrian lost from view 1 s ago keeps a grown set
    lost = np.array([[3.5, 0.0]])
    assert L.safe_candidates("online_verification", pose, cands, lost, towards)[0]
    assert not L.safe_candidates("online_verification", pose, cands, lost, towards, age=np.array([1.0]))[0]
    # phantom pedestrians: a motion towards an entry zone is rejected, standing still is not
    zones = L.EntryZones([[2.5, 0.0]])
    ok = L.safe_candidates("online_verification", pose, cands, np.zeros((0, 2)), np.zeros((0, 2)), zones)
    assert list(ok) == [False, True]
    assert L.safe_candidates("braking_ics", pose, cands, np.zeros((0, 2)), np.zeros((0, 2)), zones).all()


def _simulate(L, pose, cmd, rng, n=200, sub=20):
    """Sampled trajectories of the fail-safe maneuver from initial states in the localisation box."""
    X = np.column_stack([pose[0] + rng.uniform(-1, 1, n) * L.LOC_UNC, pose[1] + rng.uniform(-1, 1, n) * L.LOC_UNC,
                         pose[2] + rng.uniform(-1, 1, n) * L.HEAD_UNC])  # fmt: skip
    X[:8, :2] = pose[:2] + L.LOC_UNC * np.array([[1, 1], [1, -1], [-1, 1], [-1, -1]] * 2)  # corners, extreme headings
    X[:8, 2] = pose[2] + L.HEAD_UNC * np.repeat([1, -1], 4)
    times, pts = [0.0], [X[:, :2].copy()]
    for j, (v, w) in enumerate(cmd):
        for s in range(1, sub + 1):
            x, y, th = L.step_pose(X[:, 0], X[:, 1], X[:, 2], v, w, L.DT / sub)
            X = np.column_stack([x, y, th])
            times.append((j + s / sub) * L.DT)
            pts.append(X[:, :2].copy())
    return np.array(times), np.array(pts)  # (T,), (T, n, 2)


@pytest.mark.parametrize("pose, v, w", [((0.0, 0.0, 0.0), 1.5, 0.0), ((1.0, -2.0, 0.7), 1.2, 2.0),
                                        ((3.0, 1.0, -2.5), 0.6, -1.3)])  # fmt: skip
def test_robot_reach_sets_enclose_sampled_braking_trajectories(run, pose, v, w):
    """reachconf.reach on diff_drive encloses sampled fail-safe trajectories, and the planner's cheap
    disks enclose the reach sets (so the in-loop check is at least as safe as the reach sets)."""
    L = run.L
    cmd = L.braking_commands(v, w)
    tube = L.braking_reach_tube(pose, v, w).project((0, 1))
    times, pts = _simulate(L, np.array(pose), cmd, np.random.default_rng(1))
    for t, P in zip(times[::3], pts[::3]):
        assert np.all(tube.at(t).contains(P, tol=1e-6)), f"sampled trajectory leaves the reach set at t={t}"
    mid, radius, t_hi, moving = L.maneuvers(pose, np.array([[v, w]]))
    assert moving[0].all() and t_hi[-1] == pytest.approx(tube.times[-1])
    r_ref = radius[0] - L.R_ROBOT  # the disks around the reference point (footprint added on both sides)
    for S, (t0, t1) in zip(tube.time_interval_sets, tube.time_intervals):
        j = min(int((0.5 * (t0 + t1)) // L.DT), len(t_hi) - 1)
        for Z in getattr(S, "pieces", (S,)):
            V = Z.polygon()
            assert np.all(np.hypot(*(V - mid[0, j]).T) <= r_ref[j] + 1e-9), f"disk misses the reach set in {t0, t1}"
    for t, P in zip(times, pts):
        j = min(int(t / L.DT - 1e-9), len(t_hi) - 1) if t > 0 else 0
        assert np.all(np.hypot(*(P - mid[0, j]).T) <= r_ref[j] + 1e-9)


def test_safety_field_covers_a_full_speed_pedestrian(run):
    t_stop, d_stop = run.L.stopping(run.L.V_MAX)
    assert t_stop == pytest.approx(1.0) and d_stop == pytest.approx(0.825)
    assert run.L.safety_field_radius() > d_stop + run.L.V_PED * t_stop


@pytest.mark.skipif(not (PED / "hotel" / "obsmat.txt").exists(), reason="BIWI data not available")
def test_reduced_run_online_verification_never_collides_while_moving(run, tmp_path):
    assert run.main(["--data", str(PED), "--out", str(tmp_path), "--starts", "3", "--sequences", "hotel"]) == 0
    res = json.loads((tmp_path / "robot.json").read_text())
    assert set(run.LAYERS) <= set(res)
    for layer in run.LAYERS:
        for entry in res[layer].values():
            assert {"at_goal", "time_s", "velocity", "collisions"} <= set(entry)
            assert entry["collision_causes"].get("other", 0) == 0  # a hit inside a verified set would be a bug
    for entry in res["online_verification"].values():
        assert entry["collisions"] == 0
        assert entry["at_goal"] >= entry["runs"] - 1
    assert (tmp_path / "robot_run.png").exists()


@pytest.mark.slow
@pytest.mark.skipif(not (PED / "hotel" / "obsmat.txt").exists(), reason="BIWI data not available")
def test_full_run(run, tmp_path):
    assert run.main(["--data", str(PED), "--out", str(tmp_path), "--starts", "12"]) == 0
    res = json.loads((tmp_path / "robot.json").read_text())
    ov = res["online_verification"].values()
    assert sum(e["collision_causes"]["other"] for e in ov) == 0
    assert sum(e["collisions"] for e in ov) <= 1  # the one appearance outside the entry zones (ETH, pedestrian 194)
    assert sum(e["at_goal"] for e in ov) >= 0.9 * sum(e["runs"] for e in ov)


@pytest.mark.skipif(not (PED / "eth" / "obsmat.txt").exists(), reason="BIWI data not available")
def test_with_the_flow_is_the_way_most_pedestrians_walk(run):
    """The principal axis of the walking velocities has no sign; on ETH it pointed against 59 % of the walkers, so
    "with the flow" meant against it (an outside review)."""
    from reachconf.datasets.biwi import read_sequence

    for seq in ("eth", "hotel"):
        tracks = read_sequence(PED, seq)
        scene = run.Scene(tracks)
        V = np.concatenate([tr.v for tr in tracks])
        walking = V[np.linalg.norm(V, axis=1) > 0.3]
        share = float(np.mean(walking @ scene.axis > 0))
        assert share >= 0.5 and share == pytest.approx(scene.flow_share)
