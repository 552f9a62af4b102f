"""The adaptive reach over a horizon of many minutes with the defaults: it finishes, and it is sound.

The error budget is spread over at most ``AdaptiveReach.budget_horizon`` (100 s): spread over the
whole horizon, the budget per unit time of a 400-s reach is so small that the abstraction error of
a disturbed oscillator's steady set cannot meet it at any step: the reach follows the error floor with
steps of a third the length (until the floor was measured again near the step limit, it stopped at
1.7 s, calling the set exploded).
"""

import math

import numpy as np
import pytest

import reachconf as rc
from reachconf.model.simulate import simulate
from reachconf.reach_options import AdaptiveReach

T_END = 400.0
TIMES = np.arange(0.0, T_END + 0.5, 1.0)
X0 = rc.Interval([0.9, -0.1], [1.1, 0.1])
W = rc.Interval([-0.05], [0.05])


def duffing():
    """A damped hardening spring driven by a bounded disturbance: its set settles, its errors do not pile up."""
    return rc.Model(name="duffing_long", states=("p", "v"), disturbances=("w",), params={"a": 0.3, "d": 0.5},
                    dynamics=lambda s: [s.v, -s.p - s.a * s.p**3 - s.d * s.v + s.w])  # fmt: skip


@pytest.fixture(scope="module")
def tube():
    return rc.reach(duffing(), X0, TIMES, W=W, options=rc.ReachOptions())


def test_a_reach_of_minutes_with_the_defaults_holds_every_sampled_trajectory(tube):
    model = duffing()
    rng = np.random.default_rng(7)
    sets = tube.time_point_sets
    assert len(sets) == TIMES.size
    lo = np.array([s.interval().lo for s in sets])
    hi = np.array([s.interval().hi for s in sets])
    assert np.all(hi[-1] - lo[-1] < 1.0)  # it settled (a steady set of about +-0.15), it did not blow up
    fine = np.arange(0.0, T_END + 1e-9, 0.25)  # disturbances held 0.25 s
    for k in range(30):
        x0 = rng.uniform(X0.lo, X0.hi) if k else X0.hi
        w = rng.choice([-0.05, 0.05], size=(fine.size, 1)) if k % 2 else rng.uniform(-0.05, 0.05, size=(fine.size, 1))
        X = simulate(model, x0, fine, disturbances=w, substeps=20)[::4]
        assert np.all(X >= lo - 1e-7) and np.all(X <= hi + 1e-7), k
        inside = np.array([sets[i].contains(X[i][None, :], tol=1e-7)[0] for i in range(0, TIMES.size, 20)])
        assert inside.all(), k
    # the extreme trajectories: the disturbance at +-0.05 with the sign of the linear part's impulse response to p
    # (resp. v) at the end (from the centre of X0, long forgotten); they are inside, and the reach is tight: the last box within 1.25x their extremes
    wd, s = np.sqrt(1 - 1 / 16), T_END - fine
    extreme = []
    for h in (np.exp(-0.25 * s) * np.sin(wd * s) / wd, np.exp(-0.25 * s) * (np.cos(wd * s) - 0.25 / wd * np.sin(wd * s))):
        for sign in (1.0, -1.0):
            X = simulate(model, X0.center, fine, disturbances=(sign * 0.05 * np.sign(h))[:, None], substeps=20)[::4]
            assert sets[-1].contains(X[-1][None, :], tol=1e-7)[0] and np.all(X[-1] <= hi[-1] + 1e-7)
            extreme.append(X[-1])
    reach = hi[-1] - lo[-1]
    worst = np.array([extreme[0][0] - extreme[1][0], extreme[2][1] - extreme[3][1]])  # about 0.26 and 0.26
    assert np.all(worst > 0.2) and np.all(reach <= 1.25 * worst), (reach, worst)


def test_the_budget_over_the_whole_horizon_cannot_be_met(tube):
    """The old rule (``budget_horizon=inf``): a budget per unit time four times smaller, below the steady set's error
    floor; the reach goes on over budget with shorter steps (measured: 324,472 steps to the defaults' 142,127, for the
    same final widths, 0.28), so it stops at the defaults' step count, saying why."""
    steps = len(tube.log.dt)
    assert steps < 200_000
    options = rc.ReachOptions(algorithm=AdaptiveReach(budget_horizon=math.inf, max_steps=steps))
    with pytest.raises(rc.ReachError, match=f"max_steps = {steps}"):
        rc.reach(duffing(), X0, TIMES, W=W, options=options)


@pytest.mark.parametrize("bad", [0.0, -1.0, float("nan"), "100", True])
def test_budget_horizon_must_be_a_positive_number(bad):
    with pytest.raises(rc.OptionsError, match="budget_horizon"):
        rc.ReachOptions(algorithm=AdaptiveReach(budget_horizon=bad))
