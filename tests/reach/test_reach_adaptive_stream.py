"""The streamed adaptive reach: chunk by chunk, the state set carried across chunks as a union of pieces.

Soundness as for the unstreamed algorithms (``test_reach.py``): 200 sampled trajectories of Van der Pol, through a
reach of several chunks whose set was split before a chunk boundary, lie in every kept time-point set and in the
bounds of every sample interval (time points and dense samples).
"""

import numpy as np
import pytest

import reachconf as rc
import reachconf.reach_adaptive_stream as ras
from reachconf.model.simulate import simulate_ivp
from reachconf.models import vanderpol
from reachconf.reach_stream import reach_streamed
from reachconf.sets import SetUnion

RNG_SEED = 20261125
VDP_X0 = rc.Interval([1.25, 2.35], [1.55, 2.45])
TIMES = np.round(np.arange(0.0, 3.0 + 1e-9, 0.05), 10)
#: a small budget makes it split early (before the first chunk boundary, t = 0.5)
SPLITTING = rc.ReachOptions(algorithm=rc.AdaptiveReach(error_budget=0.05), max_splits=6)


@pytest.fixture(scope="module")
def trajectories():
    rng = np.random.default_rng(RNG_SEED)
    m = vanderpol()
    corners = np.array([[a, b] for a in (VDP_X0.lo[0], VDP_X0.hi[0]) for b in (VDP_X0.lo[1], VDP_X0.hi[1])])
    pts = np.vstack([corners, rng.uniform(VDP_X0.lo, VDP_X0.hi, size=(196, 2))])
    runs = [simulate_ivp(m, x0, TIMES, rtol=1e-10, atol=1e-12, dense=4) for x0 in pts]
    return np.array([r[0] for r in runs]), runs[0][1], np.array([r[2] for r in runs])


@pytest.fixture(scope="module")
def streamed_tube():
    mp = pytest.MonkeyPatch()
    mp.setattr(ras, "CHUNK_SAMPLES", 10)  # six chunks
    try:
        yield reach_streamed(vanderpol(), VDP_X0, TIMES, options=SPLITTING, max_sets=10_000)
    finally:
        mp.undo()


def test_streamed_adaptive_is_sound_across_chunks(trajectories, streamed_tube):
    X, td, Xd = trajectories
    tube = streamed_tube
    assert X.shape[0] == 200 and tube.meta["chunks"] == 6 and tube.keep_every == 1
    # split before the first boundary (t = 0.5): the union of pieces was carried into later chunks
    assert tube.splits > 0 and tube.log.split_time.min() < 0.5
    assert isinstance(tube.at(2.0), SetUnion)
    assert np.allclose(tube.times, TIMES)
    for k, S in enumerate(tube.time_point_sets):
        inside = np.asarray(S.contains(X[:, k], tol=1e-9))
        assert inside.all(), f"t = {TIMES[k]}: {np.count_nonzero(~inside)} of 200 outside"
    b = tube.bounds()
    assert b.shape == (TIMES.size - 1, 2, 2)
    for j in range(TIMES.size - 1):  # both ends of every sample interval and the dense samples within
        pts = np.concatenate([X[:, j], X[:, j + 1], Xd[:, j].reshape(-1, 2)])
        assert np.all(pts >= b[j, 0] - 1e-9) and np.all(pts <= b[j, 1] + 1e-9), f"interval {j}"
    assert td.shape[0] == TIMES.size - 1 and np.all(td[:, 0] >= TIMES[:-1]) and np.all(td[:, -1] <= TIMES[1:])
    # ... and tight: every interval's bounds at most 1.25 times the sampled spread (measured: at most 1.05)
    ends = np.stack([X[:, :-1], X[:, 1:]])
    spread = ends.max(axis=(0, 1)) - ends.min(axis=(0, 1))
    assert np.all(b[:, 1] - b[:, 0] <= 1.25 * spread)


def test_streamed_adaptive_log_and_sets(streamed_tube):
    tube = streamed_tube
    log = tube.log
    # the log of every chunk: steps cover the horizon once per live piece, branch numbers unique over chunks
    assert log.steps == tube.meta["steps"] and np.isclose((log.t0 + log.dt).max(), 3.0)
    for b in np.unique(log.branch):
        t0, dt = log.t0[log.branch == b], log.dt[log.branch == b]
        assert np.allclose(t0[1:], t0[:-1] + dt[:-1])
    assert log.splits == tube.splits
    # a kept time-interval set is the union of the adaptive steps in its sample interval; bounds hold it
    iv = tube.time_interval_sets[30].interval()
    assert np.all(tube.bounds()[30, 0] <= iv.lo + 1e-12) and np.all(iv.hi <= tube.bounds()[30, 1] + 1e-12)


def test_streamed_adaptive_keeps_every_kth_set_and_bounds_every_interval():
    full = reach_streamed(vanderpol(), VDP_X0, TIMES, options=rc.ReachOptions(algorithm="adaptive"), max_sets=10_000)
    some = reach_streamed(vanderpol(), VDP_X0, TIMES, options=rc.ReachOptions(algorithm="adaptive"), max_sets=12)
    assert some.keep_every == 5 and len(some.time_interval_sets) == 12 and len(some.times) == 13
    assert np.array_equal(some.bounds(), full.bounds())  # one chunk: the same run
    with pytest.raises(rc.ReachError, match="keeps the sets of every 5th step"):
        some.at(0.12)


def test_streamed_adaptive_final_time_is_cut_into_a_grid():
    tube = reach_streamed(vanderpol(), VDP_X0, 1.0, options=rc.ReachOptions(algorithm="adaptive", time_step=0.05))
    assert tube.all_times.size == 21 and tube.bounds().shape[0] == 20
    assert np.isclose(tube.times[-1], 1.0)


def test_streamed_adaptive_split_budget_is_shared_over_chunks(monkeypatch):
    monkeypatch.setattr(ras, "CHUNK_SAMPLES", 5)
    run = rc.reach_run(vanderpol(), VDP_X0, TIMES, options=SPLITTING, stream=lambda *a: None)
    assert isinstance(run, ras.StreamedAdaptiveRun) and run.chunks == 12
    assert 0 < run.splits <= 6 and run.pieces == run.splits + 1
