"""The sparse QP of Alg. 2 and the box SCP: its rows are the linearised model, its solutions optimal."""

import numpy as np
import pytest
import scipy.sparse as sps

import reachconf as rc
from reachconf.conformance.bounds import box_scp
from reachconf.conformance.optctrl import TraceQP, solve_sparse_qp
from reachconf.models import bicycle


@pytest.fixture(scope="module")
def problem():
    model = bicycle()
    rng = np.random.default_rng(1)
    t = np.round(np.arange(0.0, 1.0 + 1e-9, 0.01), 10)
    U = np.column_stack([0.3 * np.sin(t), 0.04 * np.cos(2 * t)])
    W = rng.uniform(-0.2, 0.2, size=(t.size - 1, model.q))
    X = rc.simulate(model, [0, 0, 0.1, 10, 0.2, 0.05], t, inputs=U, disturbances=np.vstack([W, W[-1:]]))
    Y = X + rng.uniform(-0.01, 0.01, size=X.shape)
    vr = np.full(6, 0.02)
    qp = TraceQP(model, t, np.ascontiguousarray(U), Y, -vr, vr)
    qp.sw = np.full(model.q, 0.2)
    return model, qp, X[0], W


def test_equality_rows_are_the_linearised_flow(problem):
    """A small (dx0, dw) propagated by the rows agrees with the simulator to second order."""
    model, qp, x0, W = problem
    X = qp.simulate(x0, W)
    P, c, A, b, n_eq, (nx, nw, _) = qp.build(X, W, "alg2", W_lo=np.full(3, -1.0), W_hi=np.full(3, 1.0),
                                             V_lo=qp.V_lo, V_hi=qp.V_hi)  # fmt: skip
    rng = np.random.default_rng(2)
    for eps in (1e-3, 1e-4):
        dx0 = eps * rng.normal(size=6)
        dw = eps * rng.normal(size=W.shape)
        Xp = qp.simulate(x0 + dx0, W + dw)
        # the rows' prediction: solve the equality rows for dx given dx0 and dw (scaled variables)
        Aeq = A[:n_eq].tocsc()
        known = np.concatenate([dx0 / qp.sx, (dw / qp.sw).ravel()])
        cols_known = np.concatenate([np.arange(6), nx + np.arange(nw)])
        cols_free = np.arange(6, nx)
        rhs = b[:n_eq] - Aeq[:, cols_known] @ known
        xi = sps.linalg.spsolve(Aeq[:, cols_free].tocsc(), rhs)
        DX = np.concatenate([dx0, xi * np.tile(qp.sx, qp.J)]).reshape(-1, 6)
        err = np.max(np.abs(Xp - (X + DX)))
        assert err < 50 * eps**2, (eps, err)


def test_alg2_qp_is_optimal_and_feasible(problem):
    """KKT check by perturbation: no feasible direction improves the QP optimum."""
    model, qp, x0, W = problem
    X = qp.simulate(x0, W)
    lo, hi = np.full(3, -0.25), np.full(3, 0.25)
    P, c, A, b, n_eq, _ = qp.build(X, W, "alg2", W_lo=lo, W_hi=hi, V_lo=qp.V_lo, V_hi=qp.V_hi)
    status, z = solve_sparse_qp(P, c, A, b, n_eq)
    assert status == "optimal"
    assert np.max(np.abs(A[:n_eq] @ z - b[:n_eq])) < 1e-6
    assert np.max(A[n_eq:] @ z - b[n_eq:]) < 1e-6
    f = lambda v: 0.5 * v @ (P @ v) + c @ v  # noqa: E731
    # the optimum of eq. 36 within the box: the zero trace change is feasible here and not better
    assert f(z) <= f(np.zeros_like(z)) + 1e-9


def test_box_scp_never_widens_a_feasible_start(problem):
    """From the true trace (a feasible box), the SCP's box is no larger in the sum of normalised widths."""
    model, qp, x0, W = problem
    from reachconf.conformance.trace import TraceOptions

    lo, hi, x0s, Wopt = box_scp(model, qp.t, qp.U, qp.Y, qp.V_lo, qp.V_hi, x0, W, TraceOptions(), scale=np.ones(3))
    assert np.sum(hi - lo) <= np.sum(W.max(axis=0) - W.min(axis=0)) + 1e-9
    assert np.all(Wopt >= lo - 1e-12) and np.all(Wopt <= hi + 1e-12)


def test_infeasible_qp_is_reported(problem):
    model, qp, x0, W = problem
    X = qp.simulate(x0, W)
    zero = np.zeros(3)
    tiny = np.full(6, 1e-6)  # V of a micrometre with noise of a centimetre: no trace
    P, c, A, b, n_eq, _ = qp.build(X, W, "alg2", W_lo=zero, W_hi=zero, V_lo=-tiny, V_hi=tiny)
    status, z = solve_sparse_qp(P, c, A, b, n_eq)
    assert status == "infeasible" and z is None


def test_riccati_kernel_matches_the_general_solver(problem):
    """The structured interior-point kernel and Clarabel reach the same optimum of Alg. 2's QP (free and fixed x0)."""
    from reachconf_kernels.ocp_ipm import ocp_qp

    model, qp, x0, W = problem
    X = qp.simulate(x0, W)
    lo, hi = np.full(3, -0.25), np.full(3, 0.25)
    for fixed in (False, True):
        P, c, A, b, n_eq, (nx, nw, _) = qp.build(X, W, "alg2", W_lo=lo, W_hi=hi, V_lo=qp.V_lo, V_hi=qp.V_hi,
                                                 x0_fixed=fixed)  # fmt: skip
        status, z = solve_sparse_qp(P, c, A, b, n_eq)
        st, DX, DW, _ = qp.solve_alg2(X, W, lo, hi, qp.V_lo, qp.V_hi, x0_fixed=fixed)
        zz = np.concatenate([(DX / qp.sx).ravel(), (DW / qp.sw).ravel()])
        f = lambda v: 0.5 * v @ (P @ v) + c @ v  # noqa: E731
        assert status == st == "optimal"
        assert abs(f(zz) - f(z)) <= 1e-6 * (1 + abs(f(z)))
        assert np.max(np.abs(A[:n_eq] @ zz - b[:n_eq])) < 1e-8 and np.max(A[n_eq:] @ zz - b[n_eq:]) < 1e-7
    # an infeasible problem: the kernel does not converge (status 1), the general solver says why
    J = qp.J
    n, q = 6, 3
    Ad, Bd, defect = qp.linearisation(X, W)
    Ct = np.zeros((J + 1, 6, 6))
    Ct[:, range(6), range(6)] = 1.0
    ylo = np.full((J + 1, 6), 1.0)
    yhi = np.full((J + 1, 6), -1.0)  # lo > hi
    st, _, _, _ = ocp_qp(np.ascontiguousarray(Ad), np.ascontiguousarray(Bd), np.ascontiguousarray(defect),
                         np.full(n, 1e-6), np.full(q, 2.0), np.zeros((J, q)), Ct, ylo, yhi, np.full((J, q), -1.0),
                         np.full((J, q), 1.0), True, 1e-8, 30)  # fmt: skip
    assert st != 0


def test_read_only_start_state_is_accepted(problem):
    """A TestCase's arrays are read-only: ``simulate(case.Y[0], W)`` must work (it failed in the compiled kernel)."""
    model, qp, x0, W = problem
    frozen = np.array(x0)
    frozen.flags.writeable = False
    np.testing.assert_array_equal(qp.simulate(frozen, W), qp.simulate(np.array(x0), W))


def test_a_reused_solver_gives_the_fresh_solvers_optimum(problem):
    """The SCP keeps one Clarabel solver per pattern and updates its data: same optimum as a solver set up anew."""
    model, qp, x0, W = problem
    X = qp.simulate(x0, W)
    reuse = {}
    kw = {"V_lo": qp.V_lo, "V_hi": qp.V_hi, "weights": np.ones(3)}
    first = qp.build(X, W, "box", **kw)
    assert solve_sparse_qp(*first[:5], reuse=reuse)[0] == "optimal"
    assert "solver" in reuse  # the pattern's solver is kept
    X2 = qp.simulate(x0, 0.5 * W)  # another linearisation point: new data, same sparsity pattern
    P, c, A, b, n_eq, _ = qp.build(X2, 0.5 * W, "box", **kw)
    status_r, z_r = solve_sparse_qp(P, c, A, b, n_eq, reuse=reuse)
    status_f, z_f = solve_sparse_qp(P, c, A, b, n_eq)
    assert status_r == status_f == "optimal"
    f = lambda v: 0.5 * v @ (P @ v) + c @ v  # noqa: E731
    assert abs(f(z_r) - f(z_f)) <= 1e-6 * max(1.0, abs(f(z_f)))
    assert np.max(np.abs(A[:n_eq] @ z_r - b[:n_eq])) < 1e-6 and np.max(A[n_eq:] @ z_r - b[n_eq:]) < 1e-6

