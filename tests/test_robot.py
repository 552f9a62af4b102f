"""Robot among the replayed BIWI crowds: a reduced run of the three safety layers."""

import json

import numpy as np
import pytest

from conftest import DATA_ROOT, load_example

PED = DATA_ROOT / "pedestrians"


def load_run():
    return load_example("robot")


def test_online_verification_rejects_a_motion_into_a_pedestrian_set():
    run = load_run()
    t = np.array([0.0, 0.5, 1.0])
    path = np.array([[0.0, 0.0], [0.5, 0.0], [1.0, 0.0]])
    far = np.array([[10.0, 10.0]])
    near = np.array([[1.6, 0.0]])  # walking towards the robot
    v = np.array([[-1.0, 0.0]])
    assert run.safe("online_verification", path, t, far, v)
    assert not run.safe("online_verification", path, t, near, v)
    assert not run.safe("braking_ics", path, t, near, np.zeros((1, 2)))
    # a pedestrian without a velocity estimate is bounded by the velocity model only
    assert not run.safe("online_verification", path, t, np.array([[2.5, 0.0]]), np.array([[np.nan, np.nan]]))


@pytest.mark.skipif(not (PED / "hotel" / "obsmat.txt").exists(), reason="BIWI data not available")
def test_reduced_run(tmp_path):
    run = load_run()
    assert run.main(["--data", str(PED), "--out", str(tmp_path), "--starts", "1", "--sequences", "hotel"]) == 0
    res = json.loads((tmp_path / "robot.json").read_text())
    assert set(run.LAYERS) <= set(res)
    for layer in run.LAYERS:
        for entry in res[layer].values():
            assert {"at_goal", "time_s", "velocity", "collisions"} <= set(entry)
    for entry in res["online_verification"].values():
        # online verification only collides with pedestrians that were invisible at verification time or
        # left the reachable set the model predicted for them: never "other" (that would be a bug)
        assert entry["collision_causes"].get("other", 0) == 0
    assert (tmp_path / "robot_run.png").exists()
