"""The same reach at other time origins and scales: Unix time stamps, picosecond samples.

Times entered the adaptive tube's layout through an absolute tolerance (1e-12 of at least 1: 1.7 ms of a
Unix time stamp, every step of a picosecond reach), the recorded step ends through rounding of ``t + dt``
(1.2e-7 s at 1.7e9) and ``ReachTube.at`` through 1e-9 of ``|t|`` (1.7 s at 1.7e9).
"""

import numpy as np
from scipy.integrate import solve_ivp

import reachconf as rc
from reachconf.models import vanderpol
from reachconf.reach import reach_run
from reachconf_kernels import adaptive as ak

X0 = rc.Interval([1.25, 2.35], [1.55, 2.45])


def _vdp_scaled(k):
    """Van der Pol with time in units of ``k`` (trajectory ``x(t / k)`` of the unscaled one)."""
    return rc.Model(name="vdp_k", states=("x", "y"), params={"k": k},
                    dynamics=lambda v: [v.y / v.k, ((1 - v.x**2) * v.y - v.x) / v.k])  # fmt: skip


def _vdp(t, v):
    return [v[1], (1 - v[0] ** 2) * v[1] - v[0]]


def test_unix_time_stamps_cover_the_whole_horizon():
    """From t0 = 1.7e9 the time-interval sets covered all but the last 3.5 ms (a run of short steps dropped)."""
    t0 = 1.7e9
    times = t0 + np.linspace(0.0, 3.0, 16)
    tube = rc.reach(vanderpol(), X0, times)
    I = tube.time_intervals
    assert I[0, 0] == times[0] and I[-1, 1] == times[-1]
    assert np.all(I[1:, 0] == I[:-1, 1])
    assert len(I) >= tube.log.steps - 40  # (the steps of the split-off pieces interleave; none merged away)
    # the true trajectories from the corners over the last 5 ms lie in the time-interval sets covering them
    for x0 in ([1.25, 2.35], [1.55, 2.45], [1.25, 2.45], [1.55, 2.35]):
        te = np.linspace(2.995, 3.0, 11)[:-1]
        sol = solve_ivp(_vdp, (0.0, 3.0), x0, method="DOP853", rtol=1e-12, atol=1e-12, t_eval=te)
        for t, x in zip(te + t0, sol.y.T):
            rows = np.nonzero((I[:, 0] <= t) & (t <= I[:, 1]))[0]
            assert rows.size, f"t0 + {t - t0} is in no time interval of the tube"
            assert any(bool(tube.time_interval_sets[r].contains(x)) for r in rows)


def test_recorded_steps_are_the_integrated_ones_at_unix_time():
    """Each step's recorded end (the next step's start) is its start plus the length it was integrated over."""
    t0 = 1.7e9
    run = reach_run(vanderpol(), X0, t0 + np.linspace(0.0, 1.0, 6))
    for br in run.branches:
        rec = run.rec[br.rec_lo : br.rec_hi]
        spans = rec[1:, ak.REC_T0] - rec[:-1, ak.REC_T0]  # exact (Sterbenz); the steps were 1.2e-7 s off
        assert np.array_equal(spans, rec[:-1, ak.REC_DT])


def test_picosecond_time_scale_gives_the_scaled_tube():
    """Time in units of 1e-12: the same steps and bounds (every step was merged away: an empty tube)."""
    times = np.linspace(0.0, 3.0, 16)
    ref = rc.reach(_vdp_scaled(1.0), X0, times)
    for k in (1e-6, 1e-12):
        tube = rc.reach(_vdp_scaled(k), X0, times * k)
        assert len(tube.time_intervals) == len(ref.time_intervals)
        np.testing.assert_allclose(tube.time_intervals / k, ref.time_intervals, rtol=1e-6, atol=1e-12)
        np.testing.assert_allclose(tube.bounds(), ref.bounds(), rtol=0, atol=1e-6)


def test_at_between_samples_of_unix_time_stamps():
    """``at`` between 100-Hz samples at t0 = 1.7e9 is the time-interval set, not the nearest time-point set."""
    drift = rc.Model(name="drift", states=("x",), dynamics=lambda s: [1.0])
    t0 = 1.7e9
    times = t0 + 0.01 * np.arange(11)
    for alg in ("adaptive", "lin"):
        tube = rc.reach(drift, rc.Interval([0.0], [0.0]), times, options=rc.ReachOptions(algorithm=alg))
        for dt in (0.005, 0.0425, 0.0999):
            x = np.array([(t0 + dt) - t0])  # the state at that time
            assert bool(tube.at(t0 + dt).contains(x, tol=1e-6)), (alg, dt)
            assert tube.contains([t0 + dt], [x], output=False, tol=1e-6).inside.all()
        assert tube.at(times[3]) is tube.time_point_sets[3]


def test_fixed_steps_at_unix_time_stamps():
    """100-Hz samples at t0 = 1.7e9 with 0.01-s steps: one step per sample (their spacing's rounding made two)."""
    from reachconf.reach import integration_steps

    opts = rc.ReachOptions(algorithm="lin", time_step=0.01)
    for t0 in (0.0, 1.7e9):
        assert integration_steps(t0 + 0.01 * np.arange(101), opts) == 100


def test_adaptive_grid_with_a_very_short_sample_interval():
    """One sample interval of 1e-8 s among 0.5-s ones: the memory estimate counted 2e8 steps (ResourceError)."""
    times = np.array([0.0, 0.5, 0.5 + 1e-8, 1.0, 2.0])
    tube = rc.reach(vanderpol(), X0, times)
    ref = rc.reach(vanderpol(), X0, np.array([0.0, 0.5, 1.0, 2.0]))
    assert tube.time_point_sets[-1].interval().is_subset(ref.time_point_sets[-1].interval().scale(1.5))
    sol = solve_ivp(_vdp, (0.0, 2.0), [1.55, 2.45], method="DOP853", rtol=1e-12, atol=1e-12, t_eval=times)
    for k in range(times.size):
        assert bool(tube.time_point_sets[k].contains(sol.y[:, k]))


def test_fixed_steps_cover_their_stamps_at_large_time_origins():
    """The fixed-step grid integrated ``(t_k+1 - t_k) / count`` per step while its stamps were ``t_k + j dt`` rounded:
    from t0 = 1e6 (seeded linear fuzz: pure drift, 'lin', 0.02-s steps) the states at the stamps ending or starting
    steps were up to half an ulp of the stamp (5.8e-11 s; 1.2e-7 s at 1.7e9) of drift outside their sets."""
    drift = rc.Model(name="drift", states=("x",), dynamics=lambda s: [1.0])
    for t0 in (1e6, 1.7e9):
        times = t0 + np.array([0.0, 0.7, 1.3, 2.0])
        opts = rc.ReachOptions(algorithm="lin", time_step=0.02)
        tube = rc.reach(drift, rc.Interval([0.0], [0.0]), times, options=opts)
        I = tube.time_intervals
        assert np.array_equal(I[1:, 0], I[:-1, 1]) and I[0, 0] == times[0] and I[-1, 1] == times[-1]
        for s in range(len(I)):  # the states at both stamps (exact differences: Sterbenz)
            assert tube.time_interval_sets[s].contains((I[s] - t0)[:, None]).all(), (t0, s)
        for k, t in enumerate(times):
            assert bool(tube.time_point_sets[k].contains([t - t0])), (t0, k)
