"""Compiled kernels of trace conformance (source report section 3.2).

* :func:`perstep_fit` — DISTURBANCETRACE of section 3.2.1: for every step the
  disturbance ``w_k`` that brings the model from a start state to the next
  measured state (eq. 25), in the least-squares sense of eq. 26/27, by
  Gauss–Newton with finite-difference Jacobians of the RK4 flow.  All steps in
  one compiled loop.
* :func:`discrete_linearization` — the discrete-time matrices of eq. 30 along a
  trace (``[[A, B], [0, 0]]`` exponentiated per step), the building block of
  the optimal-control QP (Alg. 2, eqs. 29–41).
"""

from __future__ import annotations

import numpy as np
from numba import njit, types

from reachconf_kernels.integrate import rk4_step
from reachconf_kernels.signatures import FN_POINT_MAT, FN_POINT_VEC, f8_1, f8_2, f8_3


@njit(cache=True)
def _flow(f, x0, u, w, p, dt, substeps, n, m, z, k1, k2, k3, k4, tmp):
    x = x0.copy()
    z[n : n + m] = u
    z[n + m :] = w
    h = dt / substeps
    for s in range(substeps):
        rk4_step(f, x, z, n, p, h, k1, k2, k3, k4, tmp)
    return x


@njit(
    types.Tuple((f8_2, f8_2))(FN_POINT_VEC, f8_2, f8_2, f8_2, f8_1, f8_1, f8_2, f8_2, types.int64, types.int64,
                              types.boolean),
    cache=True,
)  # fmt: skip
def perstep_fit(f, S, Y, U, dts, p, weights, W0, substeps, iterations, sequential):
    """Per-step disturbance fit (eqs. 25–27).

    Parameters
    ----------
    f : compiled model dynamics
    S : (K, n) start states; row k is the start of step k (only row 0 is used
        when ``sequential``: later starts are the simulated end states).
    Y : (K, n) target states; step k aims at ``Y[k + 1]``.
    U : (K-1, m) inputs; dts : (K-1,) step lengths; p : parameters
    weights : (K-1, n) weights of the squared residual components
    W0 : (K-1, q) initial disturbances
    sequential : start each step from the end of the previous simulated step
        (the IVP trace, no drift) instead of from ``S[k]``.

    Returns
    -------
    W : (K-1, q) disturbances; X : (K, n) start states used (row 0 = S[0],
    then the end states of the fitted steps).
    """
    K = Y.shape[0]
    n = Y.shape[1]
    m = U.shape[1]
    q = W0.shape[1]
    z = np.zeros(n + m + q)
    k1 = np.empty(n)
    k2 = np.empty(n)
    k3 = np.empty(n)
    k4 = np.empty(n)
    tmp = np.empty(n)
    W = W0.copy()
    X = np.empty((K, n))
    X[0] = S[0]
    J = np.empty((n, q))
    for k in range(K - 1):
        start = X[k] if sequential else S[k]
        w = W[k].copy()
        wt = weights[k]
        for it in range(iterations):
            x1 = _flow(f, start, U[k], w, p, dts[k], substeps, n, m, z, k1, k2, k3, k4, tmp)
            r = x1 - Y[k + 1]
            for j in range(q):
                hstep = 1e-6 * (1.0 + abs(w[j]))
                wp = w.copy()
                wp[j] += hstep
                xp = _flow(f, start, U[k], wp, p, dts[k], substeps, n, m, z, k1, k2, k3, k4, tmp)
                for i in range(n):
                    J[i, j] = (xp[i] - x1[i]) / hstep
            # weighted normal equations with a tiny Levenberg term
            JtJ = np.zeros((q, q))
            Jtr = np.zeros(q)
            for a in range(q):
                for i in range(n):
                    Jtr[a] += J[i, a] * wt[i] * r[i]
                for b in range(q):
                    s = 0.0
                    for i in range(n):
                        s += J[i, a] * wt[i] * J[i, b]
                    JtJ[a, b] = s
            lam = 1e-12
            for a in range(q):
                lam = max(lam, 1e-12 * JtJ[a, a])
            for a in range(q):
                JtJ[a, a] += lam
            step = np.linalg.solve(JtJ, -Jtr)
            w = w + step
            small = True
            for a in range(q):
                if abs(step[a]) > 1e-12 * (1.0 + abs(w[a])):
                    small = False
            if small:
                break
        W[k] = w
        X[k + 1] = _flow(f, start, U[k], w, p, dts[k], substeps, n, m, z, k1, k2, k3, k4, tmp)
    return W, X


@njit(cache=True)
def _expm_taylor(M):
    """exp(M) by scaling and squaring with a 12-term Taylor series (small matrices)."""
    d = M.shape[0]
    norm = 0.0
    for i in range(d):
        s = 0.0
        for j in range(d):
            s += abs(M[i, j])
        norm = max(norm, s)
    if not np.isfinite(norm):  # a diverged trace: no exponential (halving an infinite norm never ends)
        return np.full((d, d), np.nan)
    squarings = 0
    while norm > 0.25:
        norm *= 0.5
        squarings += 1
    A = M / (2.0**squarings)
    E = np.eye(d)
    term = np.eye(d)
    for i in range(1, 13):
        term = (term @ A) / i
        E = E + term
    for s in range(squarings):
        E = E @ E
    return E


@njit(
    types.Tuple((f8_3, f8_3))(FN_POINT_MAT, f8_2, f8_2, f8_2, f8_1, f8_1),
    cache=True,
)
def discrete_linearization(jac, X, U, Wt, dts, p):
    """Discrete-time ``Ad[k], Bd[k]`` of eq. 30 at ``(X[k], U[k], Wt[k])`` over ``dts[k]``."""
    K1 = dts.shape[0]
    n = X.shape[1]
    m = U.shape[1]
    q = Wt.shape[1]
    nz = n + m + q
    Ad = np.empty((K1, n, n))
    Bd = np.empty((K1, n, q))
    z = np.empty(nz)
    J = np.zeros((n, nz))
    M = np.zeros((n + q, n + q))
    for k in range(K1):
        z[:n] = X[k]
        z[n : n + m] = U[k]
        z[n + m :] = Wt[k]
        J[:, :] = 0.0
        jac(z, p, J)
        M[:, :] = 0.0
        for i in range(n):
            for j in range(n):
                M[i, j] = J[i, j] * dts[k]
            for j in range(q):
                M[i, n + j] = J[i, n + m + j] * dts[k]
        E = _expm_taylor(M)
        Ad[k] = E[:n, :n]
        Bd[k] = E[:n, n:]
    return Ad, Bd
