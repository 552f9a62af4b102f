"""Interior-point solver for the banded QP of Alg. 2 (a discrete-time optimal-control problem).

The linearised problem of Alg. 2 (eqs. 29–41), in scaled variables, is

    min  sum_j 1/2 x_j' diag(qx) x_j  +  1/2 w_j' diag(rw) w_j + rl_j' w_j
    s.t. x_{j+1} = A_j x_j + B_j w_j + f_j                 (eqs. 30–32)
         ylo_j <= C_j x_j <= yhi_j                         (eqs. 39/40, at the sample stages)
         wlo_j <= w_j <= whi_j                             (eqs. 37/38)
         x_0 = 0  (a window continuing a trace)  or  x_0 free

Every constraint touches one stage, so a Newton step of a primal-dual
interior-point method is an equality-constrained linear-quadratic problem,
solved by a Riccati recursion in time linear in the number of stages and
cubic only in the (small) state and disturbance dimensions — the structure a
general sparse solver has to rediscover by reordering a KKT matrix.
Mehrotra's predictor-corrector with one factorisation per iteration.

Infinite bounds are ignored.  The solver does not certify infeasibility:
it reports "not converged" (status 1) and the caller falls back to a
general solver that does.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from reachconf_kernels.lqr import riccati_factor, riccati_solve, small_matvec

STEP = 0.99


@njit(cache=True)
def ocp_qp(A, B, f, qx, rw, rl, C, ylo, yhi, wlo, whi, x0_free, tol, max_iter):
    """Solve the banded QP of the module docstring.

    Parameters
    ----------
    A : (J, n, n); B : (J, n, q); f : (J, n)
    qx : (n,) diagonal state cost; rw : (n,) diagonal disturbance cost; rl : (J, q) linear cost
    C : (J+1, p, n) output rows per stage (zero rows where none); ylo, yhi : (J+1, p), ``-inf``/``inf`` = none
    wlo, whi : (J, q), ``-inf``/``inf`` = none
    x0_free : bool; tol : float; max_iter : int

    Returns
    -------
    (status, x (J+1, n), w (J, q), iterations) — status 0 solved, 1 not converged, 2 numerical failure.
    """
    J, n, q = B.shape
    p = C.shape[1]
    x = np.zeros((J + 1, n))
    w = np.zeros((J, q))
    # inequality data: output rows (lower/upper) and disturbance bounds (lower/upper), masks of finite ones
    mlo = np.isfinite(ylo)
    mhi = np.isfinite(yhi)
    mwl = np.isfinite(wlo)
    mwh = np.isfinite(whi)
    # slacks and multipliers (ones where the constraint is absent: they stay inert)
    s_lo = np.ones((J + 1, p))
    s_hi = np.ones((J + 1, p))
    l_lo = np.ones((J + 1, p))
    l_hi = np.ones((J + 1, p))
    s_wl = np.ones((J, q))
    s_wh = np.ones((J, q))
    l_wl = np.ones((J, q))
    l_wh = np.ones((J, q))
    nu = np.zeros((J, n))
    # initial slacks: the constraint values at x = 0, w = 0, pushed to at least 1
    for j in range(J + 1):
        for i in range(p):
            if mlo[j, i]:
                s_lo[j, i] = max(-ylo[j, i], 1.0)
            if mhi[j, i]:
                s_hi[j, i] = max(yhi[j, i], 1.0)
    for j in range(J):
        for i in range(q):
            if mwl[j, i]:
                s_wl[j, i] = max(-wlo[j, i], 1.0)
            if mwh[j, i]:
                s_wh[j, i] = max(whi[j, i], 1.0)
    m_count = 2 * p * (J + 1) + 2 * q * J
    P = np.empty((J + 1, n, n))
    K = np.empty((J, q, n))
    Lq = np.empty((J, q, q))
    Hx = np.empty((J + 1, n, n))
    Hw = np.empty((J, q, q))
    gx = np.empty((J + 1, n))
    gw = np.empty((J, q))
    dx = np.empty((J + 1, n))
    dw = np.empty((J, q))
    dnu = np.empty((J, n))
    rx = np.empty((J + 1, n))
    rwv = np.empty((J, q))
    re = np.empty((J, n))
    Cx = np.empty((J + 1, p))
    Cdx = np.empty((J + 1, p))
    scale = 1.0
    for j in range(J):
        for i in range(n):
            scale = max(scale, abs(f[j, i]))
    ds_hi_aff = np.zeros((J + 1, p))
    ds_lo_aff = np.zeros((J + 1, p))
    dl_hi_aff = np.zeros((J + 1, p))
    dl_lo_aff = np.zeros((J + 1, p))
    ds_wh_aff = np.zeros((J, q))
    ds_wl_aff = np.zeros((J, q))
    dl_wh_aff = np.zeros((J, q))
    dl_wl_aff = np.zeros((J, q))
    ds_hi = np.zeros((J + 1, p))
    ds_lo = np.zeros((J + 1, p))
    dl_hi = np.zeros((J + 1, p))
    dl_lo = np.zeros((J + 1, p))
    ds_wh = np.zeros((J, q))
    ds_wl = np.zeros((J, q))
    dl_wh = np.zeros((J, q))
    dl_wl = np.zeros((J, q))
    status = 1
    it = 0
    for it in range(1, max_iter + 1):
        # residuals
        for j in range(J + 1):
            small_matvec(C[j], x[j], Cx[j], False, False, 1.0)
        mu = 0.0
        for j in range(J + 1):
            for i in range(p):
                if mlo[j, i]:
                    mu += s_lo[j, i] * l_lo[j, i]
                if mhi[j, i]:
                    mu += s_hi[j, i] * l_hi[j, i]
        for j in range(J):
            for i in range(q):
                if mwl[j, i]:
                    mu += s_wl[j, i] * l_wl[j, i]
                if mwh[j, i]:
                    mu += s_wh[j, i] * l_wh[j, i]
        mu = mu / max(1, m_count)
        rmax = 0.0
        lam = np.empty(p)
        for j in range(J + 1):
            for i in range(p):
                lam[i] = (l_hi[j, i] if mhi[j, i] else 0.0) - (l_lo[j, i] if mlo[j, i] else 0.0)
            for a in range(n):
                rx[j, a] = qx[a] * x[j, a]
            small_matvec(C[j], lam, rx[j], True, True, 1.0)
            if j < J:
                small_matvec(A[j], nu[j], rx[j], True, True, 1.0)
            if j > 0:
                for a in range(n):
                    rx[j, a] -= nu[j - 1, a]
        if not x0_free:
            rx[0] = 0.0  # x_0 is fixed: its stationarity row belongs to the free multiplier of x_0 = 0
        for j in range(J):
            for a in range(q):
                rwv[j, a] = rw[a] * w[j, a] + rl[j, a]
            small_matvec(B[j], nu[j], rwv[j], True, True, 1.0)
            for i in range(q):
                if mwh[j, i]:
                    rwv[j, i] += l_wh[j, i]
                if mwl[j, i]:
                    rwv[j, i] -= l_wl[j, i]
            for a in range(n):
                re[j, a] = f[j, a] - x[j + 1, a]
            small_matvec(A[j], x[j], re[j], False, True, 1.0)
            small_matvec(B[j], w[j], re[j], False, True, 1.0)
        for j in range(J + 1):
            for i in range(n):
                rmax = max(rmax, abs(rx[j, i]))
        for j in range(J):
            for i in range(q):
                rmax = max(rmax, abs(rwv[j, i]))
            for i in range(n):
                rmax = max(rmax, abs(re[j, i]) / scale)
        pres = 0.0
        for j in range(J + 1):
            for i in range(p):
                if mlo[j, i]:
                    pres = max(pres, abs(-Cx[j, i] + s_lo[j, i] + ylo[j, i]))
                if mhi[j, i]:
                    pres = max(pres, abs(Cx[j, i] + s_hi[j, i] - yhi[j, i]))
        for j in range(J):
            for i in range(q):
                if mwl[j, i]:
                    pres = max(pres, abs(-w[j, i] + s_wl[j, i] + wlo[j, i]))
                if mwh[j, i]:
                    pres = max(pres, abs(w[j, i] + s_wh[j, i] - whi[j, i]))
        if not (np.isfinite(rmax) and np.isfinite(pres) and np.isfinite(mu)):
            status = 2
            break
        if rmax < tol and pres < tol and mu < tol:
            status = 0
            break
        # Hessian blocks with the barrier terms
        for j in range(J + 1):
            Hx[j] = 0.0
            for a in range(n):
                Hx[j, a, a] = qx[a]
            for i in range(p):
                d = 0.0
                if mlo[j, i]:
                    d += l_lo[j, i] / s_lo[j, i]
                if mhi[j, i]:
                    d += l_hi[j, i] / s_hi[j, i]
                if d != 0.0:
                    for a in range(n):
                        ca = C[j, i, a]
                        if ca != 0.0:
                            for b in range(n):
                                Hx[j, a, b] += d * ca * C[j, i, b]
        for j in range(J):
            Hw[j] = 0.0
            for a in range(q):
                Hw[j, a, a] = rw[a]
            for i in range(q):
                if mwl[j, i]:
                    Hw[j, i, i] += l_wl[j, i] / s_wl[j, i]
                if mwh[j, i]:
                    Hw[j, i, i] += l_wh[j, i] / s_wh[j, i]
        riccati_factor(A, B, Hx, Hw, P, K, Lq)
        for j in range(J + 1):
            for a in range(n):
                if not np.isfinite(P[j, a, a]):
                    status = 2
        if status == 2:
            break
        # predictor (sigma = 0), then corrector with Mehrotra's centring
        sig = 0.0
        alpha = 1.0
        for phase in range(2):
            for j in range(J + 1):
                gx[j] = rx[j]
                for i in range(p):
                    t = 0.0
                    if mhi[j, i]:  # upper: C x + s = yhi
                        ri = Cx[j, i] + s_hi[j, i] - yhi[j, i]
                        rc = s_hi[j, i] * l_hi[j, i] - sig * mu
                        if phase == 1:
                            rc += ds_hi_aff[j, i] * dl_hi_aff[j, i]
                        t += (l_hi[j, i] * ri - rc) / s_hi[j, i]
                    if mlo[j, i]:  # lower: -C x + s = -ylo
                        ri = -Cx[j, i] + s_lo[j, i] + ylo[j, i]
                        rc = s_lo[j, i] * l_lo[j, i] - sig * mu
                        if phase == 1:
                            rc += ds_lo_aff[j, i] * dl_lo_aff[j, i]
                        t -= (l_lo[j, i] * ri - rc) / s_lo[j, i]
                    if t != 0.0:
                        for a in range(n):
                            gx[j, a] += t * C[j, i, a]
            if not x0_free:
                gx[0] = 0.0
            for j in range(J):
                gw[j] = rwv[j]
                for i in range(q):
                    if mwh[j, i]:
                        ri = w[j, i] + s_wh[j, i] - whi[j, i]
                        rc = s_wh[j, i] * l_wh[j, i] - sig * mu
                        if phase == 1:
                            rc += ds_wh_aff[j, i] * dl_wh_aff[j, i]
                        gw[j, i] += (l_wh[j, i] * ri - rc) / s_wh[j, i]
                    if mwl[j, i]:
                        ri = -w[j, i] + s_wl[j, i] + wlo[j, i]
                        rc = s_wl[j, i] * l_wl[j, i] - sig * mu
                        if phase == 1:
                            rc += ds_wl_aff[j, i] * dl_wl_aff[j, i]
                        gw[j, i] -= (l_wl[j, i] * ri - rc) / s_wl[j, i]
            riccati_solve(A, B, gx, gw, re, x0_free, P, K, Lq, dx, dw, dnu)
            # slack and multiplier steps
            for j in range(J + 1):
                small_matvec(C[j], dx[j], Cdx[j], False, False, 1.0)
            ds_hi = np.zeros((J + 1, p))
            ds_lo = np.zeros((J + 1, p))
            dl_hi = np.zeros((J + 1, p))
            dl_lo = np.zeros((J + 1, p))
            ds_wh = np.zeros((J, q))
            ds_wl = np.zeros((J, q))
            dl_wh = np.zeros((J, q))
            dl_wl = np.zeros((J, q))
            for j in range(J + 1):
                for i in range(p):
                    if mhi[j, i]:
                        ri = Cx[j, i] + s_hi[j, i] - yhi[j, i]
                        rc = s_hi[j, i] * l_hi[j, i] - sig * mu
                        if phase == 1:
                            rc += ds_hi_aff[j, i] * dl_hi_aff[j, i]
                        ds_hi[j, i] = -ri - Cdx[j, i]
                        dl_hi[j, i] = (-rc - l_hi[j, i] * ds_hi[j, i]) / s_hi[j, i]
                    if mlo[j, i]:
                        ri = -Cx[j, i] + s_lo[j, i] + ylo[j, i]
                        rc = s_lo[j, i] * l_lo[j, i] - sig * mu
                        if phase == 1:
                            rc += ds_lo_aff[j, i] * dl_lo_aff[j, i]
                        ds_lo[j, i] = -ri + Cdx[j, i]
                        dl_lo[j, i] = (-rc - l_lo[j, i] * ds_lo[j, i]) / s_lo[j, i]
            for j in range(J):
                for i in range(q):
                    if mwh[j, i]:
                        ri = w[j, i] + s_wh[j, i] - whi[j, i]
                        rc = s_wh[j, i] * l_wh[j, i] - sig * mu
                        if phase == 1:
                            rc += ds_wh_aff[j, i] * dl_wh_aff[j, i]
                        ds_wh[j, i] = -ri - dw[j, i]
                        dl_wh[j, i] = (-rc - l_wh[j, i] * ds_wh[j, i]) / s_wh[j, i]
                    if mwl[j, i]:
                        ri = -w[j, i] + s_wl[j, i] + wlo[j, i]
                        rc = s_wl[j, i] * l_wl[j, i] - sig * mu
                        if phase == 1:
                            rc += ds_wl_aff[j, i] * dl_wl_aff[j, i]
                        ds_wl[j, i] = -ri + dw[j, i]
                        dl_wl[j, i] = (-rc - l_wl[j, i] * ds_wl[j, i]) / s_wl[j, i]
            # largest step keeping slacks and multipliers positive
            alpha = 1.0
            for j in range(J + 1):
                for i in range(p):
                    if mhi[j, i]:
                        if ds_hi[j, i] < 0:
                            alpha = min(alpha, -s_hi[j, i] / ds_hi[j, i])
                        if dl_hi[j, i] < 0:
                            alpha = min(alpha, -l_hi[j, i] / dl_hi[j, i])
                    if mlo[j, i]:
                        if ds_lo[j, i] < 0:
                            alpha = min(alpha, -s_lo[j, i] / ds_lo[j, i])
                        if dl_lo[j, i] < 0:
                            alpha = min(alpha, -l_lo[j, i] / dl_lo[j, i])
            for j in range(J):
                for i in range(q):
                    if mwh[j, i]:
                        if ds_wh[j, i] < 0:
                            alpha = min(alpha, -s_wh[j, i] / ds_wh[j, i])
                        if dl_wh[j, i] < 0:
                            alpha = min(alpha, -l_wh[j, i] / dl_wh[j, i])
                    if mwl[j, i]:
                        if ds_wl[j, i] < 0:
                            alpha = min(alpha, -s_wl[j, i] / ds_wl[j, i])
                        if dl_wl[j, i] < 0:
                            alpha = min(alpha, -l_wl[j, i] / dl_wl[j, i])
            if phase == 0:
                ds_hi_aff[:] = ds_hi
                ds_lo_aff[:] = ds_lo
                dl_hi_aff[:] = dl_hi
                dl_lo_aff[:] = dl_lo
                ds_wh_aff[:] = ds_wh
                ds_wl_aff[:] = ds_wl
                dl_wh_aff[:] = dl_wh
                dl_wl_aff[:] = dl_wl
                mu_aff = 0.0
                for j in range(J + 1):
                    for i in range(p):
                        if mhi[j, i]:
                            mu_aff += (s_hi[j, i] + alpha * ds_hi[j, i]) * (l_hi[j, i] + alpha * dl_hi[j, i])
                        if mlo[j, i]:
                            mu_aff += (s_lo[j, i] + alpha * ds_lo[j, i]) * (l_lo[j, i] + alpha * dl_lo[j, i])
                for j in range(J):
                    for i in range(q):
                        if mwh[j, i]:
                            mu_aff += (s_wh[j, i] + alpha * ds_wh[j, i]) * (l_wh[j, i] + alpha * dl_wh[j, i])
                        if mwl[j, i]:
                            mu_aff += (s_wl[j, i] + alpha * ds_wl[j, i]) * (l_wl[j, i] + alpha * dl_wl[j, i])
                mu_aff /= max(1, m_count)
                sig = (mu_aff / mu) ** 3 if mu > 0 else 0.0
        a = min(1.0, STEP * alpha)
        x += a * dx
        w += a * dw
        nu += a * dnu
        s_hi += a * ds_hi
        s_lo += a * ds_lo
        l_hi += a * dl_hi
        l_lo += a * dl_lo
        s_wh += a * ds_wh
        s_wl += a * ds_wl
        l_wh += a * dl_wh
        l_wl += a * dl_wl
    return status, x, w, it
