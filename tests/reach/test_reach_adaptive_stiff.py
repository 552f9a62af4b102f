"""The adaptive default on stiff linear parts: a step too long for the exponential's Taylor series is halved.

Before, a step needing more than ``MAX_TAYLOR_TERMS`` terms was taken with that many, and the (sound) bound of
the series' remainder through ``|A|`` swamped the set: a two-state system with an eigenvalue of -300 ended
2e17 times wider than its exact reachable set, a 60-state heat equation 9e21 times.
"""

import numpy as np
import pytest
import scipy.linalg as sla

import reachconf as rc
from reachconf.model import Model

STIFF_A = np.array([[-300.0, 300.0], [0.0, -1.0]])
STIFF = Model(name="stiff_pair", states=("x", "y"), dynamics=lambda s: [-300 * s.x + 300 * s.y, -s.y])


@pytest.mark.parametrize("horizon", [1.0, 5.0])
def test_stiff_linear_system_stays_at_its_exact_set(horizon):
    X0 = rc.Interval([0.9, 0.9], [1.1, 1.1])
    times = np.linspace(0.0, horizon, 11)
    tube = rc.reach(STIFF, X0, times)
    # exact: the box's image under e^{A t} (linear, no input): its interval radius is |e^{At}| r
    for k, t in enumerate(times):
        eA = sla.expm(STIFF_A * t)
        iv = tube.time_point_sets[k].interval()
        exact = np.abs(eA) @ np.array([0.1, 0.1])
        assert np.all((iv.hi - iv.lo) / 2 <= 1.01 * exact + 1e-12), (t, (iv.hi - iv.lo) / 2, exact)
        # sound: the images of the box's corners and of random points lie in the set
        rng = np.random.default_rng(k)
        pts = np.vstack([[0.9, 0.9], [1.1, 1.1], [0.9, 1.1], [1.1, 0.9], rng.uniform(0.9, 1.1, (30, 2))])
        assert all(tube.time_point_sets[k].contains(eA @ p, tol=1e-9) for p in pts)
    assert tube.log.taylor_terms.max() <= 20


def test_heat_equation_of_60_states_stays_near_its_exact_set():
    n = 60
    h = 1.0 / (n + 1)
    names = tuple(f"u{i}" for i in range(n))

    def f(s):
        u = [getattr(s, v) for v in names]
        return [0.01 * ((u[i - 1] if i > 0 else 0) - 2 * u[i] + (u[i + 1] if i < n - 1 else 0)) / h**2 for i in range(n)]

    model = Model(name="heat60", states=names, dynamics=f)
    x0 = np.sin(np.pi * np.arange(1, n + 1) * h)
    tube = rc.reach(model, rc.Interval(x0 - 0.01, x0 + 0.01), np.linspace(0.0, 1.0, 11))
    A = 0.01 / h**2 * (np.diag(-2.0 * np.ones(n)) + np.diag(np.ones(n - 1), 1) + np.diag(np.ones(n - 1), -1))
    exact = np.abs(sla.expm(A)) @ np.full(n, 0.01)
    iv = tube.final_set().interval()
    assert np.max((iv.hi - iv.lo) / 2 / exact) < 1.5  # measured 1.30 (before: 9e21)
    assert tube.final_set().contains(sla.expm(A) @ x0, tol=1e-9)
