"""The same reach in other units of the states: the adaptive default's absolute floor ``atol``.

With ``atol = 1e-6`` absolute, Van der Pol in units where its states are of order 1e-8 let the abstraction error
grow the set to its own size and failed (ReachError at t = 1.5 s), while in units of 1 it is verified.
"""

import numpy as np
import pytest
from scipy.integrate import solve_ivp

import reachconf as rc

LO, HI = np.array([1.25, 2.35]), np.array([1.55, 2.45])


def _vdp_in_units(s):
    """Van der Pol with both states in units of ``1 / s`` (the trajectory ``s x(t)`` of the unscaled one)."""
    return rc.Model(name="vdp_s", states=("x", "y"), params={"s": s},
                    dynamics=lambda v: [v.y, (1 - (v.x / v.s) ** 2) * v.y - v.x])  # fmt: skip


@pytest.mark.parametrize("s", [1e-6, 1e-8, 1e-10])
def test_vanderpol_in_tiny_units_is_the_scaled_tube(s):
    times = np.linspace(0.0, 3.0, 16)
    ref = rc.reach(_vdp_in_units(1.0), rc.Interval(LO, HI), times)
    tube = rc.reach(_vdp_in_units(s), rc.Interval(s * LO, s * HI), times)
    assert tube.bounds().shape == ref.bounds().shape  # the same steps
    np.testing.assert_allclose(tube.bounds() / s, ref.bounds(), rtol=0, atol=1e-4)
    for x0 in (LO, HI, [LO[0], HI[1]], [HI[0], LO[1]]):
        sol = solve_ivp(lambda t, v: [v[1], (1 - v[0] ** 2) * v[1] - v[0]], (0.0, 3.0), x0, method="DOP853",
                        rtol=1e-12, atol=1e-12, t_eval=times)  # fmt: skip
        for k in range(times.size):
            assert bool(tube.time_point_sets[k].contains(s * sol.y[:, k])), (s, x0, k)


def test_atol_capped_by_the_initial_sets_magnitude():
    alg = rc.AdaptiveReach()
    assert alg.for_initial_set(2.45e-8).atol == pytest.approx(2.45e-11)
    assert alg.for_initial_set(1.0) is alg  # states of order 1e-3 and more: unchanged
    assert alg.for_initial_set(0.0) is alg  # a point at the origin keeps the absolute floor
