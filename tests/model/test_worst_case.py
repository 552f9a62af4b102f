"""reachconf.worst_case: the trajectory that drives a function of the state furthest (an inner bound of the reachable set).

On a linear system with piecewise-constant disturbances the maximum principle's bang-bang signal is the exact
maximiser, so the search must find the exact support of the discrete-time reachable set; on nonlinear models it is a
point of the reachable set (a simulated trajectory) that the reach tubes must hold (tests/reach)."""

import numpy as np
import pytest
from scipy.linalg import expm

import reachconf as rc

A = np.array([[-0.1, 2.0, 0.0], [-2.0, -0.1, 1.0], [0.0, -0.5, -0.3]])
B = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])
W = rc.Interval([-0.02, -0.01], [0.03, 0.05])
X0 = rc.Interval([0.9, -0.05, 0.0], [1.1, 0.05, 0.02])
TIMES = np.round(np.arange(0.0, 3.0 + 1e-9, 0.05), 10)


def _lin3():
    a = A
    return rc.Model(name="lin3_wc", states=("a", "b", "c"), disturbances=("w1", "w2"),
                    dynamics=lambda s: [a[0, 0] * s.a + a[0, 1] * s.b, a[1, 0] * s.a + a[1, 1] * s.b + s.c + s.w1,
                                        a[2, 1] * s.b + a[2, 2] * s.c + s.w2])  # fmt: skip


def _exact_support(c, K, dt):
    """max c . x(K dt) over X0 and disturbances constant on each step (discrete-time, exact)."""
    M = np.zeros((5, 5))
    M[:3, :3], M[:3, 3:] = A, B
    E = expm(M * dt)
    Phi, Gam = E[:3, :3], E[:3, 3:]
    row = c @ np.linalg.matrix_power(Phi, K)
    s = row @ X0.center + np.abs(row) @ X0.radius
    for k in range(K):
        g = c @ np.linalg.matrix_power(Phi, K - 1 - k) @ Gam
        s += g @ W.center + np.abs(g) @ W.radius
    return s


@pytest.mark.parametrize("at", [20, -1])
def test_linear_worst_case_is_the_exact_support(at):
    model = _lin3()
    K = at % TIMES.size
    for c in (np.array([1.0, 0.0, 0.0]), np.array([0.0, -1.0, 0.0]), np.array([0.3, 0.5, -1.0])):
        found = rc.worst_case(model, X0, TIMES, c, W=W, at=at)
        exact = _exact_support(c, K, 0.05)
        assert found.value == pytest.approx(exact, rel=1e-6, abs=1e-9)  # RK4 against expm: 1.2e-7 measured
        assert found.states.shape == (K + 1, 3) and found.disturbances.shape == (K, 2)
        assert np.all(found.disturbances >= W.lo - 1e-12) and np.all(found.disturbances <= W.hi + 1e-12)
        assert np.all(found.x0 >= X0.lo - 1e-12) and np.all(found.x0 <= X0.hi + 1e-12)
        assert found.value == pytest.approx(c @ found.states[-1], rel=1e-12)


def test_worst_case_beats_random_trajectories_and_a_callable_is_the_same_as_weights():
    """The searched worst case exceeds every one of 300 random extreme trajectories (they understate the reach)."""
    model = _lin3()
    rng = np.random.default_rng(7)
    best_random = -np.inf
    for _ in range(300):
        x0 = np.where(rng.random(3) < 0.5, X0.lo, X0.hi)
        w = np.where(rng.random((TIMES.size - 1, 2)) < 0.5, W.lo, W.hi)
        best_random = max(best_random, rc.simulate(model, x0, TIMES, disturbances=w)[-1, 1])
    found = rc.worst_case(model, X0, TIMES, lambda x, u: x[1], W=W)
    assert found.value > best_random + 0.01  # measured 0.082 above
    assert found.value == pytest.approx(rc.worst_case(model, X0, TIMES, [0.0, 1.0, 0.0], W=W).value, rel=1e-12)


def test_reach_holds_the_worst_cases_and_is_close_to_them():
    """The default reach of the linear system holds every worst case and its box is within 15 % of them."""
    model = _lin3()
    tube = rc.reach(model, X0, TIMES, W=W)
    iv = tube.final_set().interval()
    for i in range(3):
        hi = rc.worst_case(model, X0, TIMES, np.eye(3)[i], W=W).value
        lo = -rc.worst_case(model, X0, TIMES, -np.eye(3)[i], W=W).value
        assert iv.lo[i] - 1e-9 <= lo and hi <= iv.hi[i] + 1e-9
        assert iv.hi[i] - iv.lo[i] <= 1.15 * (hi - lo)


def test_worst_case_bad_arguments():
    model = _lin3()
    with pytest.raises(rc.OptionsError, match="at = 0"):
        rc.worst_case(model, X0, TIMES, [1, 0, 0], W=W, at=0)
    with pytest.raises(rc.OptionsError, match="at = 99"):
        rc.worst_case(model, X0, TIMES, [1, 0, 0], W=W, at=99)
    with pytest.raises(rc.DataError, match="3 finite weights"):
        rc.worst_case(model, X0, TIMES, [1, 0], W=W)
    with pytest.raises(rc.SetError, match="W"):
        rc.worst_case(model, X0, TIMES, [1, 0, 0], W=rc.Interval([0], [1]))
    with pytest.raises(rc.DataError, match="strictly increasing"):
        rc.worst_case(model, X0, TIMES[::-1], [1, 0, 0], W=W)
    with pytest.raises(rc.SetError, match="X0"):
        rc.worst_case(model, rc.Interval([0, 0], [1, 1]), TIMES, [1, 0, 0], W=W)
    with pytest.raises(rc.ModelError, match="worst_case"):
        rc.worst_case("model", X0, TIMES, [1, 0, 0])
    with pytest.raises(rc.OptionsError, match="iterations"):
        rc.worst_case(model, X0, TIMES, [1, 0, 0], W=W, iterations=0)
    for kw in ({"at": 2.5}, {"at": True}, {"substeps": 1.0}):
        with pytest.raises(rc.OptionsError, match="must be an integer"):
            rc.worst_case(model, X0, TIMES, [1, 0, 0], W=W, **kw)
    with pytest.raises(rc.DataError, match="must return one number"):
        rc.worst_case(model, X0, TIMES, lambda x, u: x, W=W)
    with pytest.raises(rc.DataError, match="value.x, u. failed: TypeError") as info:  # a callable of one argument
        rc.worst_case(model, X0, TIMES, lambda x: x[0], W=W)
    assert info.value.__context__ is None or info.value.__suppress_context__  # one error, not two chained ones
    with pytest.raises(rc.DataError, match="inputs contains NaN"):
        rc.worst_case(rc.models.diff_drive(), rc.Interval([0, 0, 0], [0.1, 0.1, 0.1]), TIMES, [1, 0, 0],
                      inputs=np.full((TIMES.size, 2), np.nan))
    with pytest.raises(rc.DataError, match="inputs must have shape"):
        rc.worst_case(rc.models.diff_drive(), rc.Interval([0, 0, 0], [0.1, 0.1, 0.1]), TIMES, [1, 0, 0],
                      inputs=np.ones((3, 2)))
