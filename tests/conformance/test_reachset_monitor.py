"""Eq. 43 checked along the reach by the compiled kernel agrees with the set-by-set check.

The kernel path (affine output map) and the early stop of the α-search must give
exactly the verdicts of :meth:`ReachTube.contains`; the kernel's decided statuses
must agree with the reference LP on points on both sides of the boundary.
"""

import numpy as np
import pytest
import sympy as sp

import reachconf as rc
from reachconf.sets import contains_points_lp
from reachconf.conformance import reachset_conformance
from reachconf.io import TestCase
from reachconf.model.simulate import simulate
from reachconf_kernels.containment import contains_mapped_sequence

W_STAR = rc.Interval([-0.4], [0.4])
V_RAD = np.array([0.02, 0.02])


def affine_model():
    return rc.Model(
        name="osc_affine_out",
        states=("x1", "x2"),
        inputs=("u",),
        disturbances=("w",),
        dynamics=lambda s: [s.x2, -s.x1 - 0.5 * s.x2 + 0.3 * sp.sin(s.x1) + s.u + s.w],
        outputs=lambda s: {"y1": s.x1 + 0.5 * s.x2 + 0.1 * s.u, "y2": s.x2 - 0.2},
    )


def make_case(model, seed, duration=6.0, dt=0.05):
    rng = np.random.default_rng(seed)
    t = np.round(np.arange(0.0, duration + 1e-9, dt), 10)
    u = 0.5 * np.sin(0.7 * t + seed)[:, None]
    w = rng.uniform(W_STAR.lo, W_STAR.hi, size=(t.size // 10 + 1, 1)).repeat(10, axis=0)[: t.size]
    X = simulate(model, [0.3, -0.1], t, inputs=u, disturbances=w, substeps=20)
    Y = np.array([model.h(x, uk) for x, uk in zip(X, u)]) + rng.uniform(-V_RAD, V_RAD, size=(t.size, 2))
    return TestCase(f"c{seed}", "g", t, u, Y, model.input_names, model.output_names)


@pytest.fixture(scope="module")
def model():
    return affine_model()


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_kernel_path_and_early_stop_agree_with_set_by_set_check(model, seed):
    case = make_case(model, seed)
    V = rc.Interval(-V_RAD, V_RAD)
    opts = rc.ReachOptions(time_step=0.05, zonotope_order=20)
    verdicts = []
    for scale in (1.0, 0.6, 0.3, 0.1):
        W = rc.Interval(W_STAR.lo * scale, W_STAR.hi * scale)
        full = reachset_conformance(model, case, W, V, options=opts, keep_tube=True, violation_distance=False)
        generic = full.tube.contains(case.t - case.t[0], case.Y, V=V, output=True, inputs=case.U)
        np.testing.assert_array_equal(full.inside, generic.inside)
        assert full.conformant == generic.conformant
        fast = reachset_conformance(model, case, W, V, options=opts, keep_tube=False, violation_distance=False,
                                    stop_at_first_violation=True)  # fmt: skip
        assert fast.conformant == full.conformant
        assert fast.first_violation_time == full.first_violation_time
        assert not np.any(fast.inside & ~full.inside)  # never inside where the full check says outside
        verdicts.append(full.conformant)
    assert verdicts[0] and not verdicts[-1]  # both kinds of verdict were exercised


def test_kernel_statuses_match_reference_lp():
    rng = np.random.default_rng(7)
    K, n, p, g = 60, 3, 2, 7
    c = rng.normal(size=(K, n))
    G = np.zeros((K, n, g + 3))
    ng = rng.integers(1, g + 1, size=K)
    for k in range(K):
        G[k, :, : ng[k]] = rng.normal(size=(n, ng[k]))
    C = rng.normal(size=(p, n))
    off = rng.normal(size=(K, p))
    v_rad = np.array([0.05, 0.0])  # one degenerate direction of V
    P = np.empty((K, p))
    for k in range(K):  # 0.8-1.2 x the support point in a random direction: about half outside
        a = rng.normal(size=p)
        CG = C @ G[k, :, : ng[k]]
        support = CG @ np.sign(CG.T @ a) + v_rad * np.sign(a)
        P[k] = C @ c[k] + off[k] + rng.uniform(0.8, 1.2) * support
    st = contains_mapped_sequence(c, G, ng.astype(np.int64), C, off, v_rad, P, 1e-9, False)
    decided = st >= 0
    assert decided.mean() > 0.9 and (st == 1).any() and (st == 0).any()
    for k in np.nonzero(decided)[0]:
        Gk = np.hstack([C @ G[k, :, : ng[k]], np.array([[0.05], [0.0]])])
        ref = contains_points_lp(C @ c[k] + off[k], Gk, P[k][None, :], 1e-9)[0]
        assert bool(st[k]) == bool(ref), k
    stopped = contains_mapped_sequence(c, G, ng.astype(np.int64), C, off, v_rad, P, 1e-9, True)
    first = int(np.nonzero(st == 0)[0][0])
    np.testing.assert_array_equal(stopped[: first + 1], st[: first + 1])
    assert np.all(stopped[first + 1 :] == -2)


@pytest.mark.parametrize("scale", [1e-12, 1e-9, 1.0, 1e6])
@pytest.mark.parametrize("keep_tube", [True, False])
def test_verdict_does_not_depend_on_the_units(scale, keep_tube):
    """Eq. 43 on data of order 1e-12 .. 1e6: exact data conformant, a jump of 1000 V not.

    The containment slack was an absolute 1e-9 (``max(1, ...)`` scale): data
    of order 1e-9 were "conformant" whatever the jump.
    """
    m = rc.Model(name="decay_units", states=("x",), disturbances=("w",), dynamics=lambda s: [-0.5 * s.x + s.w])
    t = np.arange(50) * 0.1
    x = scale * np.exp(-0.5 * t)
    W, V = rc.Interval([0.0], [0.0]), rc.Interval([-1e-4 * scale], [1e-4 * scale])
    exact = TestCase("exact", "g", t, np.zeros((50, 0)), x[:, None], (), ("x",))
    jump = TestCase("jump", "g", t, np.zeros((50, 0)), (x + np.r_[np.zeros(49), 0.1 * scale])[:, None], (), ("x",))
    assert reachset_conformance(m, exact, W, V, keep_tube=keep_tube).conformant
    res = reachset_conformance(m, jump, W, V, keep_tube=keep_tube)
    assert not res.conformant and res.verdict.value == "not_conformant"
    assert res.first_violation_time == pytest.approx(t[-1])


def test_kernel_slack_is_per_output():
    """Outputs of 1e-8 and 1e2 in one set: a measurement 5 radii outside in the small output is outside."""
    c = np.zeros((2, 2))
    G = np.zeros((2, 2, 2))
    G[:, 0, 0], G[:, 1, 1], G[:, 1, 0] = 1e-8, 100.0, 1e-9
    C, off, v_rad = np.eye(2), np.zeros((2, 2)), np.zeros(2)
    P = np.array([[5e-8, 0.0], [0.9e-8, 0.0]])
    st = contains_mapped_sequence(c, G, np.array([2, 2]), C, off, v_rad, P, 1e-9, False)
    np.testing.assert_array_equal(st, [0, 1])
