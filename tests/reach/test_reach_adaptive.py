"""``algorithm="adaptive"``: its record of what it chose, its limits and its informative failure.

Soundness against 200 sampled trajectories per system is in ``test_reach.py`` (the "adaptive" cases).
"""

import numpy as np
import pytest

import reachconf as rc
from reachconf.models import vanderpol

VDP_X0 = rc.Interval([1.25, 2.35], [1.55, 2.45])


@pytest.fixture(scope="module")
def vdp_tube():
    return rc.reach(vanderpol(), VDP_X0, 3.0, options=rc.ReachOptions(algorithm="adaptive"))


def test_adaptive_records_steps_orders_and_splits(vdp_tube, tmp_path):
    tube = vdp_tube
    log = tube.log
    assert log is not None and log.steps >= len(tube.time_interval_sets) > 10
    # each branch's steps follow each other without gaps; they were chosen, not fixed
    assert log.t0.min() == 0.0 and np.isclose((log.t0 + log.dt).max(), 3.0)
    for b in np.unique(log.branch):
        t0, dt = log.t0[log.branch == b], log.dt[log.branch == b]
        assert np.allclose(t0[1:], t0[:-1] + dt[:-1])
    assert log.dt.max() > 1.5 * log.dt.min()
    assert set(np.unique(log.tensor_order)) <= {2, 3}
    assert np.all(log.zonotope_order > 0) and np.all(log.error_rate >= 0)
    assert log.splits == tube.splits == len(log.split_time)
    # every piece but the first comes from a recorded split (or restart from a halved start set)
    assert set(np.unique(log.branch).tolist()) - {0} <= set(log.split_children.ravel().tolist())
    assert "steps" in log.summary() and "adaptive" in repr(tube)
    # the record travels with the tube
    path = tmp_path / "vdp.npz"
    tube.save(path)
    back = rc.ReachTube.load(path)
    assert back.log is not None and np.array_equal(back.log.dt, log.dt)
    assert np.array_equal(back.log.tensor_order, log.tensor_order)
    # the bounds come from the arrays and hold every set
    b = tube.bounds()
    for s in (0, len(tube.time_interval_sets) // 2, -1):
        iv = tube.time_interval_sets[s].interval()
        assert np.all(b[s, 0] <= iv.lo + 1e-12) and np.all(iv.hi <= b[s, 1] + 1e-12)


def test_adaptive_tube_is_tight(vdp_tube):
    """Not sound by being huge: at t = 3 the box is within 3x the hull of simulated corners."""
    from reachconf.model.simulate import simulate_ivp

    m = vanderpol()
    corners = np.array([[a, b] for a in (1.25, 1.55) for b in (2.35, 2.45)])
    ends = np.array([simulate_ivp(m, x0, np.array([0.0, 3.0]), rtol=1e-10, atol=1e-12)[-1] for x0 in corners])
    spread = ends.max(axis=0) - ends.min(axis=0)
    iv = vdp_tube.time_point_sets[-1].interval()
    assert np.all(iv.hi - iv.lo <= 3 * spread + 0.02)


def test_adaptive_tube_draws_every_stored_piece_once(vdp_tube):
    """The lazily built sets share pieces (a long step of one branch covers several intervals of the common
    grid); the picture draws each stored piece once (Van der Pol T = 7: 158,041 polygons before, 18.7 s)."""
    import matplotlib.pyplot as plt

    ax = vdp_tube.plot()
    fill = ax.collections[0]
    assert len(fill.get_paths()) == vdp_tube.log.steps  # every step's time-interval set, once
    shared = sum(len(s.pieces) for s in vdp_tube.time_interval_sets)
    assert vdp_tube.splits == 0 or shared > vdp_tube.log.steps
    b = vdp_tube.bounds()
    (x0, x1), (y0, y1) = ax.get_xlim(), ax.get_ylim()
    assert x0 <= b[:, 0, 0].min() and b[:, 1, 0].max() <= x1 and y0 <= b[:, 0, 1].min() and b[:, 1, 1].max() <= y1
    plt.close(ax.figure)


def test_adaptive_failure_says_what_it_tried_and_where():
    X0 = rc.Interval([-6.0, -6.0], [6.0, 6.0])
    with pytest.raises(rc.ReachError) as info:
        rc.reach(vanderpol(), X0, 7.0, options=rc.ReachOptions(algorithm="adaptive", max_splits=2))
    e = info.value
    msg = str(e)
    assert "vanderpol" in msg and "at t = " in msg
    assert "time steps down to" in msg and "tensor order up to" in msg and "splits" in msg
    assert e.time is not None and 0 <= e.time < 7.0
    assert set(e.tried) >= {"smallest_step", "highest_tensor_order", "splits", "max_splits", "steps"}
    assert e.tried["splits"] <= 2 and e.tried["smallest_step"] > 0


def _vdp_samples(times, n=60, seed=0):
    """``n`` Van der Pol trajectories from corners and random points of ``VDP_X0`` at ``times``."""
    from scipy.integrate import solve_ivp

    rng = np.random.default_rng(seed)
    lo, hi = VDP_X0.lo, VDP_X0.hi
    pts = np.vstack([rng.uniform(lo, hi, size=(n - 4, 2)), [lo, hi, [lo[0], hi[1]], [hi[0], lo[1]]]])
    f = lambda t, z: [z[1], (1 - z[0] ** 2) * z[1] - z[0]]  # noqa: E731
    return np.array([solve_ivp(f, (0, times[-1]), p, t_eval=times, rtol=1e-10, atol=1e-12).y.T for p in pts])


def test_adaptive_retries_with_half_the_budget_when_the_error_cannot_be_bounded():
    times = np.linspace(0.0, 7.0, 15)
    once = rc.ReachOptions(algorithm=rc.AdaptiveReach(error_budget=5.0, budget_retries=0))
    with pytest.raises(rc.ReachError, match="could not bound"):
        rc.reach(vanderpol(), VDP_X0, times, options=once)
    tube = rc.reach(vanderpol(), VDP_X0, times, options=rc.ReachOptions(algorithm=rc.AdaptiveReach(error_budget=5.0)))
    assert list(tube.log.budgets_tried) == [5.0, 2.5, 1.25]  # two retries (the default), the last one kept
    # each retry may split a quarter as often (RETRY_SPLITS): 256, 64, 16
    assert tube.meta["options"]["max_splits"] == 16 and tube.splits <= 16
    assert "after the error could not be bounded with 5, 2.5" in tube.log.summary()
    assert tube.bounds()[:, 1, 1].max() < 2.9  # and tight: the true largest y from VDP_X0 is about 2.70
    # the kept run is sound: every sampled trajectory lies in its time-point set at every sample
    X = _vdp_samples(times)
    for k in range(times.size):
        inside = np.asarray(tube.time_point_sets[k].contains(X[:, k], tol=1e-9))
        assert inside.all(), (times[k], X[~inside, k])


def test_adaptive_failure_after_retries_names_every_budget_tried():
    opts = rc.ReachOptions(algorithm=rc.AdaptiveReach(error_budget=80.0, budget_retries=3))
    with pytest.raises(rc.ReachError, match="error budgets tried, each from the start: 80, 40, 20, 10, and 10 "
                       "again holding the step over budget") as info:
        rc.reach(vanderpol(), VDP_X0, 7.0, options=opts)
    # the last budget runs in the ordinary mode first, then once more holding the step over budget
    assert info.value.tried["error_budgets"] == [80.0, 40.0, 20.0, 10.0, 10.0]


def test_adaptive_last_budget_runs_the_ordinary_mode_before_holding_over_budget(monkeypatch):
    import reachconf.reach_adaptive as ra

    modes = []
    once = ra._run_once

    def spy(*args, last=False, **kw):
        modes.append((kw["options"].alg.error_budget if "options" in kw else args[5].alg.error_budget, last))
        return once(*args, last=last, **kw)

    monkeypatch.setattr(ra, "_run_once", spy)
    opts = rc.ReachOptions(algorithm=rc.AdaptiveReach(error_budget=80.0, budget_retries=1))
    with pytest.raises(rc.ReachError, match="80, 40, and 40 again holding"):
        rc.reach(vanderpol(), VDP_X0, 7.0, options=opts)
    assert modes == [(80.0, False), (40.0, False), (40.0, True)]
    modes.clear()
    tube = rc.reach(vanderpol(), VDP_X0, 7.0)  # verified on the first budget: one ordinary run
    assert modes == [(0.7, False)] and list(tube.log.budgets_tried) == [0.7]


def test_adaptive_stops_at_max_steps_instead_of_allocating():
    opts = rc.ReachOptions(algorithm=rc.AdaptiveReach(max_steps=30))
    with pytest.raises(rc.ReachError, match="max_steps = 30") as info:
        rc.reach(vanderpol(), VDP_X0, 7.0, options=opts)
    assert info.value.tried["steps"] >= 30 and info.value.term == "steps/memory"


def test_adaptive_stops_at_its_memory_share(monkeypatch):
    import reachconf.reach_adaptive as ra

    monkeypatch.setattr(ra, "available_memory", lambda: 4e5)
    with pytest.raises(rc.ReachError, match="available memory"):
        rc.reach(vanderpol(), VDP_X0, 7.0, options=rc.ReachOptions(algorithm="adaptive"))


@pytest.mark.parametrize("kw", [{"error_budget": 0.0}, {"error_budget": float("inf")}, {"max_order": 0.5},
                                {"max_steps": 0}, {"max_steps": 2.5}, {"max_order": 1e6}, {"budget_retries": -1},
                                {"budget_retries": 1.5}, {"budget_retries": True}, {"rtol": -1e-3},
                                {"atol": float("nan")}, {"rtol": float("inf")}, {"atol": True}])  # fmt: skip
def test_adaptive_bad_parameters(kw):
    with pytest.raises(rc.OptionsError, match="AdaptiveReach"):
        rc.ReachOptions(algorithm=rc.AdaptiveReach(**kw))


def test_lineages_stop_restarting_where_restarts_only_postpone_the_error(monkeypatch):
    """Laub-Loomis W = 0.1: restarting from a halved start set lowers the error rate where the parent got stuck by
    only ~18 %, so the lineage rule (geometric mean of those ratios over RESTART_FEEDBACK) stops after a restart
    or two; with the rule off the same run uses every split it is given."""
    import reachconf.reach_adaptive as ra
    from reachconf.models import laub_loomis

    x0 = np.array([1.2, 1.05, 1.5, 2.4, 1.0, 0.1, 0.45])
    X0 = rc.Interval(x0 - 0.1, x0 + 0.1)
    tube = rc.reach(laub_loomis(), X0, 20.0, options=rc.ReachOptions(algorithm="adaptive"))
    assert tube.splits <= 4 and tube.bounds()[:, 1, 3].max() < 5.0
    monkeypatch.setattr(ra, "RESTART_FEEDBACK", 2.0)
    off = rc.reach(laub_loomis(), X0, 20.0, options=rc.ReachOptions(algorithm="adaptive", max_splits=12))
    assert off.splits >= 6 > tube.splits  # 7: all the per-lineage shares of 12 allow


def test_piece_layout_matches_a_brute_force_enumeration_of_the_branches_steps():
    """The adaptive tube's layout (built in place without sorting all pairs): every interval of the common
    refinement and every step end lists exactly the pieces of the live branches that cover it, and the
    interval hulls are those of these pieces."""
    from types import SimpleNamespace

    from reachconf.tube_pieces import piece_layout
    from reachconf_kernels.tube_layout import csr_hulls

    rng = np.random.default_rng(5)
    T, branches, t0 = 2.0, [], []

    def add(index, t_begin, t_end):
        cuts = np.sort(rng.uniform(t_begin, t_end, size=rng.integers(1, 6)))
        starts = np.concatenate([[t_begin], cuts])
        lo = len(t0)
        t0.extend(starts)
        branches.append(SimpleNamespace(index=index, t_begin=t_begin, t_end=t_end, rec_lo=lo, rec_hi=len(t0),
                                        sample_step=np.full(3, -1)))  # fmt: skip

    add(0, 0.0, 0.7)  # split at 0.7 into 1 and 2; 2 split at 1.3 into 3 and 4
    add(1, 0.7, T)
    add(2, 0.7, 1.3)
    add(3, 1.3, T)
    add(4, 1.3, T)
    t0 = np.array(t0)
    lay = piece_layout(np.array([0.0, T]), True, t0, branches)
    P = t0.size
    mids = lay.intervals.mean(axis=1)
    for j, m in enumerate(mids):
        want = sorted(b.rec_lo + int(np.searchsorted(t0[b.rec_lo : b.rec_hi], m, side="right")) - 1
                      for b in branches if b.t_begin < m < b.t_end)  # fmt: skip
        assert sorted(lay.ti_indices[lay.ti_indptr[j] : lay.ti_indptr[j + 1]].tolist()) == want
    for j, t in enumerate(lay.times[1:]):
        want = []
        for b in branches:
            if not b.t_begin < t <= b.t_end + 1e-12:
                continue
            ends = np.append(t0[b.rec_lo + 1 : b.rec_hi], b.t_end)
            k = int(np.searchsorted(ends, t - 1e-12))
            want.append(b.rec_lo + k if abs(ends[k] - t) < 1e-12 else P + b.rec_lo + k)
        assert sorted(lay.tp_indices[lay.tp_indptr[j] : lay.tp_indptr[j + 1]].tolist()) == sorted(want)
    lo = rng.normal(size=(P, 2))
    hi = lo + rng.uniform(0.1, 1.0, size=(P, 2))
    blo, bhi = csr_hulls(lay.ti_indptr, lay.ti_indices, lo, hi)
    for j in range(mids.size):
        ids = lay.ti_indices[lay.ti_indptr[j] : lay.ti_indptr[j + 1]]
        np.testing.assert_array_equal(blo[j], lo[ids].min(axis=0))
        np.testing.assert_array_equal(bhi[j], hi[ids].max(axis=0))
    # the tube's bounds come from the same walk without the CSR's column array
    fresh = piece_layout(np.array([0.0, T]), True, t0, branches)
    wlo, whi = fresh.interval_hulls(lo, hi)
    np.testing.assert_array_equal(wlo, blo)
    np.testing.assert_array_equal(whi, bhi)
    # and so does every single row (the first entries a user asks for), in the same order
    for j in range(mids.size):
        assert fresh.ti_row(j).tolist() == lay.ti_indices[lay.ti_indptr[j] : lay.ti_indptr[j + 1]].tolist()
    for j in range(lay.times.size - 1):
        assert fresh.tp_row(j).tolist() == lay.tp_indices[lay.tp_indptr[j] : lay.tp_indptr[j + 1]].tolist()


@pytest.mark.parametrize("horizon", ["scalar", "samples"])
def test_adaptive_tube_polygons_from_the_stored_arrays_match_the_sets(horizon):
    """The picture's polygons are computed from the run's arrays (one compiled call, no lists of (interval, piece)
    pairs): the same vertices, in the same order, as projecting every distinct piece (a split run, both the
    time-interval and the time-point sets, with a scalar horizon and with sample times)."""
    T = 7.0 if horizon == "scalar" else np.linspace(0.0, 7.0, 15)
    tube = rc.reach(vanderpol(), VDP_X0, T, options=rc.ReachOptions(algorithm="adaptive"))
    assert tube.splits > 0
    for sets in (tube.time_interval_sets, tube.time_point_sets):
        fast = sets.distinct_polygons([1, 0])
        slow = [p.project([1, 0]).polygon() for p in sets.distinct_pieces()]
        assert len(fast) == len(slow) > 10
        for a, b in zip(fast, slow):
            np.testing.assert_array_equal(a, b)
        # the compiled call has no bounds checks: dimensions are checked before it
        for bad in ([0, 2], [-1, 0], [0]):
            with pytest.raises(rc.SetError, match="two state indices"):
                sets.distinct_polygons(bad)



@pytest.mark.parametrize("horizon", ["scalar", "samples"])
def test_adaptive_tube_sets_looked_up_one_by_one_equal_those_of_the_whole_lists(horizon):
    """A few sets (the final one, one time) are found row by row without building the (interval, piece) lists;
    after ``PieceSets.ROW_LOOKUPS`` of them, or on iteration, the lists are built: the same pieces either way."""
    T = 7.0 if horizon == "scalar" else np.linspace(0.0, 7.0, 15)
    run = lambda: rc.reach(vanderpol(), VDP_X0, T, options=rc.ReachOptions(algorithm="adaptive"))  # noqa: E731
    a, b = run(), run()
    assert a.splits > 0
    for sa, sb in ((a.time_interval_sets, b.time_interval_sets), (a.time_point_sets, b.time_point_sets)):
        picks = [0, 1, len(sa) // 2, len(sa) - 1]
        one_by_one = [sa[j] for j in picks]
        assert sa._ids is None  # not built for these
        whole = list(sb)  # iteration builds the lists
        assert sb._ids is not None
        for j, s1 in zip(picks, one_by_one):
            p1, p2 = getattr(s1, "pieces", [s1]), getattr(whole[j], "pieces", [whole[j]])
            assert len(p1) == len(p2)
            for z1, z2 in zip(p1, p2):
                np.testing.assert_array_equal(z1.interval().lo, z2.interval().lo)
                np.testing.assert_array_equal(z1.interval().hi, z2.interval().hi)
