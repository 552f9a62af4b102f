"""Gap location: a disturbance pulse injected in one channel and time window is found there."""

import numpy as np

import reachconf as rc
from reachconf.io import TestCase, TestSuite
from reachconf.simulate import simulate


def test_locate_gap_finds_channel_segment_and_condition():
    m = rc.Model(name="two_decay", states=("x1", "x2"), inputs=("u",), disturbances=("w1", "w2"),
                 dynamics=lambda s: [-s.x1 + s.u + s.w1, -2.0 * s.x2 + 0.5 * s.x1 + s.w2])  # fmt: skip
    cases = []
    for seed in range(4):
        rng = np.random.default_rng(seed)
        t = np.round(np.arange(0, 5.0 + 1e-9, 0.02), 10)
        u = np.sin(t + seed)
        w = rng.normal(scale=0.02, size=(t.size, 2))
        w[(t >= 2.0) & (t < 3.0), 1] += 1.5  # the unmodelled effect: a push on x2 between 2 and 3 s
        X = simulate(m, [0.0, 0.0], t, inputs=u[:, None], disturbances=w, substeps=10)
        cases.append(TestCase(f"c{seed}", "maneuver", t, u[:, None], X, ("u",), ("x1", "x2")))
    rep = rc.locate_gap(m, TestSuite(cases))
    assert max(rep.shares, key=rep.shares.get) == "w2"
    segs = [s for s in rep.group_segments["maneuver"] if s["channel"] == "w2"]
    assert segs and abs(segs[0]["t0"] - 2.0) < 0.15 and abs(segs[0]["t1"] - 3.0) < 0.15
    assert not [s for s in rep.group_segments["maneuver"] if s["channel"] == "w1" and s["t1"] - s["t0"] > 0.5]
    assert "w2" in rep.conditions and rep.conditions["w2"]
    assert "w2, 2.0-3.0 s" in rep.summary() or "w2, 1.9" in rep.summary() or "w2, 2.1" in rep.summary()
    assert '"shares"' in rep.to_json()
