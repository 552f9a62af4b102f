"""Every built-in model's default reach holds its worst cases.

``rc.worst_case`` drives each state furthest up and down at a third of the run and at its end (bang-bang disturbances
from the adjoint: the edge of the reachable set, which random runs fall short of); the trajectories, simulated again
with tight tolerances, must lie in every time-point set and, densely sampled, in every time-interval set.  A scan of
27 Nov with these set-ups and ``"lin"`` order 2 as well found every one inside.
"""

import numpy as np
import pytest
from test_reach import _assert_tube_contains, _worst_runs

import reachconf as rc
import reachconf.models as M
from reachconf.demo import lane_change_reference


def _setup(name):
    """``(model, X0, times, inputs, W)`` of each model's test: a small box around an operating point."""
    m = getattr(M, name)()
    W = None
    if name in ("bicycle_actuated", "single_track"):
        t = np.round(np.arange(0, 2.0 + 1e-9, 0.05), 10)
        U = np.column_stack([0.3 * np.sin(t), 0.05 * np.sin(2 * t)])
        if name == "single_track":
            c, r, w = np.array([10, 0, 0.0]), np.array([0.1, 0.02, 0.01]), np.array([0.1, 0.1, 0.05])
        else:
            c, r = np.array([0, 0, 0, 10, 0, 0, 0, 0.0]), np.array([0.05, 0.05, 0.005, 0.05, 0.02, 0.005, 0.05, 0.005])
            w = np.array([0.05, 0.05, 0.01, 0.1, 0.01])
        W = rc.Interval(-w, w)
    elif name == "bicycle_closed_loop_actuated":
        t = np.round(np.arange(0, 3.0 + 1e-9, 0.05), 10)
        U = lane_change_reference(t, start=3.0, length=20.0)
        c, r = np.array([0, 0, 0, 10, 0, 0, 0, 0.0]), 0.2 * np.array([0.02, 0.02, 0.002, 0.02, 0.01, 0.002, 0.02, 0.002])
        W = rc.Interval(-0.2 * np.array([0.02, 0.02, 0.005, 0.05, 0.05, 0.02]),
                        0.2 * np.array([0.02, 0.02, 0.005, 0.05, 0.05, 0.02]))  # fmt: skip
    elif name == "diff_drive":
        t = np.round(np.arange(0, 5.0 + 1e-9, 0.05), 10)
        U = np.column_stack([np.ones(t.size), 0.5 * np.sin(t)])
        c, r = np.zeros(3), np.array([0.1, 0.1, 0.05])
    elif name == "pedestrian_acc":
        t, U = np.round(np.arange(0, 3.0 + 1e-9, 0.05), 10), None
        c, r, W = np.array([0, 0, 1.2, 0.1]), np.full(4, 0.1), rc.Interval([-0.5, -0.5], [0.5, 0.5])
    elif name == "wind_turbine":  # near the equilibrium at 11 m/s, the wind swinging by 0.5 m/s
        t, p, v0 = np.round(np.arange(0, 5.0 + 1e-9, 0.05), 10), m.params, 11.0
        Mg = m.f([1.2, 0.0, 0.0], [0.0, 0.0, v0], [0, 0, 0])[0] * p["J"] / p["i"]
        c = rc.simulate(m, [1.2, 0.0, 0.0], np.linspace(0, 200, 2001), inputs=[Mg, 0.0, v0])[-1]
        U = np.column_stack([np.full(t.size, Mg), np.zeros(t.size), v0 + 0.5 * np.sin(0.5 * t)])
        r, W = np.array([0.02, 0.01, 0.01]), rc.Interval([-0.002, -0.001, -0.01], [0.002, 0.001, 0.01])
    elif name == "coupled_vanderpol":
        t, U = np.round(np.arange(0, 3.0 + 1e-9, 0.05), 10), None
        c, r = np.array([1.4, 2.4, 1.4, 2.4]), np.array([0.15, 0.05, 0.15, 0.05])
    else:  # laub_loomis
        t, U = np.round(np.arange(0, 10.0 + 1e-9, 0.1), 10), None
        c, r = np.array([1.2, 1.05, 1.5, 2.4, 1.0, 0.1, 0.45]), np.full(7, 0.05)
    return m, rc.Interval(c - r, c + r), t, U, W


@pytest.mark.parametrize("name", ["bicycle_actuated", "bicycle_closed_loop_actuated", "single_track", "diff_drive",
                                  "pedestrian_acc", "wind_turbine", "coupled_vanderpol", "laub_loomis"])  # fmt: skip
def test_default_reach_holds_the_worst_cases(name):
    model, X0, times, U, W = _setup(name)
    K = times.size - 1
    Wq = W if W is not None else rc.Interval(np.zeros(model.q), np.zeros(model.q))
    found, runs = _worst_runs(model, X0, times, Wq, U, range(model.n), (K // 3, K), dense=2)
    assert len(found) == 4 * model.n
    tube = rc.reach(model, X0, times, inputs=U, W=W)
    _assert_tube_contains(tube, *runs)
