"""Binned envelopes of the gap location (issue 17): how |w| depends on an operating condition."""

import numpy as np

from reachconf.diagnose.locate import BINS, GapLocation, binned_envelope


def test_bins_follow_the_condition_and_cover_every_sample():
    rng = np.random.default_rng(1)
    ay = rng.uniform(-15, 15, 5000)
    w = rng.normal(size=ay.size) * (0.1 + 0.05 * ay**2)  # the gap grows with |ay|
    env = binned_envelope(ay, w)
    assert env["abs"] is True and len(env["bins"]) == BINS
    assert sum(b["count"] for b in env["bins"]) == ay.size
    q = [b["q95"] for b in env["bins"]]
    assert all(a < b for a, b in zip(q, q[1:]))  # monotone in |ay|
    for b in env["bins"]:
        sel = (np.abs(ay) >= b["edges"][0]) & (np.abs(ay) <= b["edges"][1])
        assert b["lo"] >= w[sel].min() - 1e-12 and b["hi"] <= w[sel].max() + 1e-12
    one_sign = binned_envelope(np.abs(ay) + 1, w)
    assert one_sign["abs"] is False


def test_binned_survives_the_json_round_trip():
    env = {"w1": {"ay": binned_envelope(np.linspace(-1, 1, 50), np.linspace(0, 1, 50))}}
    loc = GapLocation(["w1"], {"w1": 1.0}, {"w1": [0, 1]}, {}, {}, {"w1": {}}, {}, {}, env)
    assert GapLocation.from_dict(loc.to_dict()).binned == env
