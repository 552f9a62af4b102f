"""The adaptive default from a point or a very thin initial set (``AdaptiveReach.rtol``/``atol``).

Measured against the set's radius alone, any abstraction error on a point is an infinite growth rate: the
defaults failed on these systems at t = 0-5e-7 s or took tens of thousands of steps.  None of these systems
was used to choose ``rtol`` and ``atol`` (chosen on Van der Pol and Lotka-Volterra from other points).
"""

import numpy as np
import pytest
import sympy as sp
from scipy.integrate import solve_ivp

import reachconf as rc
from reachconf.model import Model

ROESSLER = Model(name="roessler", states=("x", "y", "z"),
                 dynamics=lambda s: [-s.y - s.z, s.x + 0.2 * s.y, 0.2 + s.z * (s.x - 5.7)])
ROBERTSON = Model(name="robertson", states=("x", "y", "z"),
                  dynamics=lambda s: [-0.4 * s.x + 100 * s.y * s.z, 0.4 * s.x - 100 * s.y * s.z - 1000 * s.y**2,
                                      1000 * s.y**2])
PENDULUM = Model(name="spring_pendulum", states=("r", "th", "dr", "dth"),
                 dynamics=lambda s: [s.dr, s.dth, s.r * s.dth**2 + 9.81 * sp.cos(s.th) - 2 * (s.r - 1),
                                     -(2 * s.dr * s.dth + 9.81 * sp.sin(s.th)) / s.r])  # fmt: skip


def _roessler(t, v):
    x, y, z = v
    return [-y - z, x + 0.2 * y, 0.2 + z * (x - 5.7)]


def _robertson(t, v):
    x, y, z = v
    return [-0.4 * x + 100 * y * z, 0.4 * x - 100 * y * z - 1000 * y**2, 1000 * y**2]


def _pendulum(t, v):
    r, th, dr, dth = v
    return [dr, dth, r * dth**2 + 9.81 * np.cos(th) - 2 * (r - 1), -(2 * dr * dth + 9.81 * np.sin(th)) / r]


CASES = [  # model, right-hand side, x0, horizon, largest width allowed
    (ROESSLER, _roessler, [0.0, -8.4, 0.0], 6.0, 0.02),
    (ROBERTSON, _robertson, [1.0, 0.0, 0.0], 40.0, 0.005),
    (PENDULUM, _pendulum, [1.2, 0.5, 0.0, 0.0], 3.0, 0.01),
]


@pytest.mark.parametrize("model, rhs, x0, horizon, width", CASES, ids=[c[0].name for c in CASES])
@pytest.mark.parametrize("radius", [0.0, 1e-7])
def test_reach_from_a_point_or_a_thin_box_is_sound_thin_and_quick(model, rhs, x0, horizon, width, radius):
    x0 = np.asarray(x0, dtype=float)
    times = np.linspace(0.0, horizon, 101)
    tube = rc.reach(model, rc.Interval(x0 - radius, x0 + radius), times)
    assert tube.log.steps < 5000  # with rtol = atol = 0: a ReachError at t = 0 or 9,000-39,000 steps
    widths = np.array([s.interval().hi - s.interval().lo for s in tube.time_point_sets])
    assert widths.max() < width
    rng = np.random.default_rng(0)
    starts = [x0] if radius == 0.0 else np.vstack([x0 - radius, x0 + radius, rng.uniform(x0 - radius, x0 + radius, (8, x0.size))])
    for p in starts:
        X = solve_ivp(rhs, (0.0, horizon), p, t_eval=times, method="Radau" if model is ROBERTSON else "DOP853",
                      rtol=1e-11, atol=1e-14).y.T
        for k in range(times.size):
            assert tube.time_point_sets[k].contains(X[k], tol=1e-9), (model.name, times[k], X[k])


def test_without_the_floor_a_point_set_fails_as_before():
    """``rtol = atol = 0`` is the radius alone: the Roessler system from a point cannot take a first step."""
    opts = rc.ReachOptions(algorithm=rc.AdaptiveReach(rtol=0.0, atol=0.0))
    with pytest.raises(rc.ReachError, match="could not bound"):
        rc.reach(ROESSLER, rc.Interval([0.0, -8.4, 0.0], [0.0, -8.4, 0.0]), 6.0, options=opts)


def test_smaller_tolerances_give_thinner_tubes_from_a_point():
    x0 = rc.Interval([1.2, 0.5, 0.0, 0.0], [1.2, 0.5, 0.0, 0.0])
    times = np.linspace(0.0, 3.0, 31)
    w = []
    for rtol, atol in ((1e-3, 1e-6), (1e-5, 1e-8)):
        tube = rc.reach(PENDULUM, x0, times, options=rc.ReachOptions(algorithm=rc.AdaptiveReach(rtol=rtol, atol=atol)))
        w.append(max((s.interval().hi - s.interval().lo).max() for s in tube.time_point_sets))
    assert w[1] < 0.2 * w[0]
