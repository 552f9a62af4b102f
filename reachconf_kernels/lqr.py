"""Riccati recursion of a linear-quadratic optimal-control problem with affine dynamics (small dense blocks).

The Newton step of the interior-point method in :mod:`reachconf_kernels.ocp_ipm`
is the problem::

    min  sum_j 1/2 x_j' Hx_j x_j + gx_j' x_j + 1/2 w_j' Hw_j w_j + gw_j' w_j
    s.t. x_{j+1} = A_j x_j + B_j w_j + f_j,   x_0 free or fixed

solved backwards by dynamic programming (value functions ``1/2 x' P_j x +
p_j' x``, feedback ``w_j = K_j x_j + k_j``) and forwards for the trajectory:
time linear in the number of stages.  The factorisation (:func:`riccati_factor`)
depends only on the matrices, so the predictor and corrector steps share it.
Loops are written out: for 6 x 6 blocks a BLAS call costs more than the work.
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["chol_into", "chol_solve_into", "small_matvec", "riccati_factor", "riccati_solve"]


@njit(cache=True)
def chol_solve_into(L, b, out):
    """``out = (L L')^{-1} b`` (``L`` lower triangular); ``b`` and ``out`` may be the same array."""
    m = L.shape[0]
    for i in range(m):
        s = b[i]
        for k in range(i):
            s -= L[i, k] * out[k]
        out[i] = s / L[i, i]
    for i in range(m - 1, -1, -1):
        s = out[i]
        for k in range(i + 1, m):
            s -= L[k, i] * out[k]
        out[i] = s / L[i, i]


@njit(cache=True)
def chol_into(M, L):
    """Cholesky factor of a symmetric positive definite matrix into ``L`` (a tiny diagonal shift if needed)."""
    m = M.shape[0]
    for i in range(m):
        for j in range(i + 1):
            s = M[i, j]
            for k in range(j):
                s -= L[i, k] * L[j, k]
            if i == j:
                L[i, i] = np.sqrt(max(s, 1e-14 * (1.0 + abs(M[i, i]))))
            else:
                L[i, j] = s / L[j, j]
        for j in range(i + 1, m):
            L[i, j] = 0.0


@njit(cache=True)
def small_matvec(M, x, out, transpose, accumulate, sign):
    """``out (+)= sign * M x`` (or ``M' x``) for small dense matrices, without temporaries."""
    r, c = M.shape
    if transpose:
        for a in range(c):
            s = 0.0
            for b in range(r):
                s += M[b, a] * x[b]
            out[a] = out[a] + sign * s if accumulate else sign * s
    else:
        for a in range(r):
            s = 0.0
            for b in range(c):
                s += M[a, b] * x[b]
            out[a] = out[a] + sign * s if accumulate else sign * s


@njit(cache=True)
def riccati_factor(A, B, Hx, Hw, P, K, Lq):
    """Factor: Riccati matrices ``P_j``, gains ``K_j`` and Cholesky factors of ``Quu_j`` (in place)."""
    J, n, q = B.shape
    PA = np.empty((n, n))
    PB = np.empty((n, q))
    Quu = np.empty((q, q))
    Qux = np.empty((q, n))
    col = np.empty(q)
    P[J] = Hx[J]
    for j in range(J - 1, -1, -1):
        Pn = P[j + 1]
        Aj = A[j]
        Bj = B[j]
        for a in range(n):
            for b in range(n):
                s = 0.0
                for c in range(n):
                    s += Pn[a, c] * Aj[c, b]
                PA[a, b] = s
            for b in range(q):
                s = 0.0
                for c in range(n):
                    s += Pn[a, c] * Bj[c, b]
                PB[a, b] = s
        for a in range(q):
            for b in range(q):
                s = Hw[j, a, b]
                for c in range(n):
                    s += Bj[c, a] * PB[c, b]
                Quu[a, b] = s
            for b in range(n):
                s = 0.0
                for c in range(n):
                    s += Bj[c, a] * PA[c, b]
                Qux[a, b] = s
        chol_into(Quu, Lq[j])
        for b in range(n):
            for a in range(q):
                col[a] = Qux[a, b]
            chol_solve_into(Lq[j], col, col)
            for a in range(q):
                K[j, a, b] = -col[a]
        Pj = P[j]
        for a in range(n):
            for b in range(a, n):
                s = Hx[j, a, b]
                for c in range(n):
                    s += Aj[c, a] * PA[c, b]
                for c in range(q):
                    s += Qux[c, a] * K[j, c, b]
                Pj[a, b] = s
                Pj[b, a] = s


@njit(cache=True)
def riccati_solve(A, B, gx, gw, f, x0_free, P, K, Lq, dx, dw, nu):
    """Back-substitution: the Newton step for linear terms ``gx, gw`` and dynamics residuals ``f``.

    Value function ``V_j(x) = 1/2 x' P_j x + p_j' x``; ``w_j = K_j x_j + k_j``;
    ``nu[j]`` is the multiplier of dynamics ``j``: the costate ``P_{j+1} x_{j+1} + p_{j+1}``.
    """
    J, n, q = B.shape
    p = np.empty((J + 1, n))
    k = np.empty((J, q))
    v = np.empty(n)
    t = np.empty(n)
    qu = np.empty(q)
    p[J] = gx[J]
    for j in range(J - 1, -1, -1):
        Pn = P[j + 1]
        for a in range(n):
            s = p[j + 1, a]
            for c in range(n):
                s += Pn[a, c] * f[j, c]
            v[a] = s
        for a in range(q):
            s = gw[j, a]
            for c in range(n):
                s += B[j, c, a] * v[c]
            qu[a] = s
        chol_solve_into(Lq[j], qu, qu)
        for a in range(q):
            k[j, a] = -qu[a]
        # p_j = gx_j + A' (v + P_{j+1} B k)
        for a in range(n):
            s = 0.0
            for c in range(q):
                s += B[j, a, c] * k[j, c]
            t[a] = s
        for a in range(n):  # v <- v + P_{j+1} B k (row a reads only v[a] and t)
            s = v[a]
            for c in range(n):
                s += Pn[a, c] * t[c]
            v[a] = s
        for a in range(n):
            s = gx[j, a]
            for c in range(n):
                s += A[j, c, a] * v[c]
            p[j, a] = s
    if x0_free:
        L0 = np.zeros((n, n))
        chol_into(P[0], L0)
        chol_solve_into(L0, p[0], t)
        for a in range(n):
            dx[0, a] = -t[a]
    else:
        dx[0] = 0.0
    for j in range(J):
        for a in range(q):
            s = k[j, a]
            for c in range(n):
                s += K[j, a, c] * dx[j, c]
            dw[j, a] = s
        for a in range(n):
            s = f[j, a]
            for c in range(n):
                s += A[j, a, c] * dx[j, c]
            for c in range(q):
                s += B[j, a, c] * dw[j, c]
            dx[j + 1, a] = s
        for a in range(n):
            s = p[j + 1, a]
            for c in range(n):
                s += P[j + 1, a, c] * dx[j + 1, c]
            nu[j, a] = s
