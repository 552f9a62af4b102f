"""The adjoint sweep of a trajectory: gradients of a function of the end state with respect to the disturbances.

Used by :func:`reachconf.model.worst_case` (Pontryagin's condition for a box of
disturbances).  The model's compiled Jacobian arrives as a first-class function
(:mod:`reachconf_kernels.signatures`), so this module is compiled once for every
model.
"""

from __future__ import annotations

import numpy as np
from numba import njit, types

from reachconf_kernels.signatures import FN_POINT_MAT, f8_1, f8_2
from reachconf_kernels.small_linalg import mat_mat, mat_vec


@njit(types.void(f8_2, f8_2, f8_2, f8_1, f8_1, FN_POINT_MAT, types.int64, f8_1, f8_2), cache=True)
def adjoint_sweep(X, U, Wt, dts, p, jac, substeps, lam, gw):
    """Backward sweep along the trajectory linearised step by step, as the simulation integrates it.

    Each sample interval is linearised at its start, ``x' = A x + B w`` with the
    model's Jacobian, and mapped as ``substeps`` classical RK4 steps map a linear
    system: ``x+ = P x + Q B w`` per substep of length ``h``, with ``P`` and ``Q / h``
    the degree-4 Taylor polynomials of ``exp(A h)`` and ``(exp(A h) - I) / (A h)``
    (exact gradients for a linear model simulated with RK4).

    Parameters
    ----------
    X : (K + 1, n) states at the sample times; U : (K + 1, m) inputs; Wt : (K, q) disturbances of the steps;
    dts : (K,) step lengths; p : parameters; jac : the model's compiled ``jac(z, p, out)``; substeps : RK4 steps per
    sample interval.
    lam : (n,) in: the gradient of the function at ``X[K]``; out: its gradient with respect to ``X[0]``.
    gw : (K, q) out: the gradient with respect to each step's disturbance.

    A search direction, not a bound: the caller keeps a step only when the simulated value grows.
    """
    K = Wt.shape[0]
    n = X.shape[1]
    m = U.shape[1]
    q = Wt.shape[1]
    z = np.empty(n + m + q)
    J = np.zeros((n, n + m + q))
    eye = np.eye(n)
    for k in range(K - 1, -1, -1):
        z[:n] = X[k]
        z[n : n + m] = U[k]
        z[n + m :] = Wt[k]
        J[:, :] = 0.0
        jac(z, p, J)
        h = dts[k] / substeps
        Ah = np.ascontiguousarray(J[:, :n]) * h
        # Horner: S = I + Ah/2 (I + Ah/3 (I + Ah/4)); P = I + Ah S; Q = h S
        S = eye + mat_mat(Ah, eye + mat_mat(Ah, eye + Ah / 4.0) / 3.0) / 2.0
        P = eye + mat_mat(Ah, S)
        QB = mat_mat(S * h, np.ascontiguousarray(J[:, n + m :]))
        # over the substeps: lam <- P^T lam, and the disturbance collects (P^i Q B)^T lam
        PT = np.ascontiguousarray(P.T)
        QBT = np.ascontiguousarray(QB.T)
        g = np.zeros(q)
        for _ in range(substeps):
            g += mat_vec(QBT, lam)
            lam[:] = mat_vec(PT, lam)
        gw[k] = g
