"""Interior-point solver for the banded QP of Alg. 2 (a discrete-time optimal-control problem).

The linearised problem of Alg. 2 (eqs. 29–41), in scaled variables, is::

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
def _rows(C, ylo, yhi, wlo, whi):
    """The finite inequalities as rows ``g' z <= h``: on states (coefficients) and on disturbances (one entry)."""
    J1, p, n = C.shape
    J, q = wlo.shape
    mx = 0
    for j in range(J1):
        for i in range(p):
            mx += np.isfinite(ylo[j, i]) + np.isfinite(yhi[j, i])
    mw = 0
    for j in range(J):
        for i in range(q):
            mw += np.isfinite(wlo[j, i]) + np.isfinite(whi[j, i])
    xs = np.empty(mx, dtype=np.int64)
    xg = np.empty((mx, n))
    xh = np.empty(mx)
    ws = np.empty(mw, dtype=np.int64)
    wc = np.empty(mw, dtype=np.int64)
    wg = np.empty(mw)
    wh = np.empty(mw)
    r = 0
    for j in range(J1):
        for i in range(p):
            for sign, bound in ((1.0, yhi[j, i]), (-1.0, -ylo[j, i])):
                if np.isfinite(bound):
                    xs[r] = j
                    xg[r] = sign * C[j, i]
                    xh[r] = bound
                    r += 1
    r = 0
    for j in range(J):
        for i in range(q):
            for sign, bound in ((1.0, whi[j, i]), (-1.0, -wlo[j, i])):
                if np.isfinite(bound):
                    ws[r] = j
                    wc[r] = i
                    wg[r] = sign
                    wh[r] = bound
                    r += 1
    return xs, xg, xh, ws, wc, wg, wh


@njit(cache=True)
def _step_length(s, ds, lam, dlam, alpha):
    """Largest step (at most ``alpha``) keeping ``s + a ds`` and ``lam + a dlam`` positive."""
    for r in range(s.size):
        if ds[r] < 0:
            alpha = min(alpha, -s[r] / ds[r])
        if dlam[r] < 0:
            alpha = min(alpha, -lam[r] / dlam[r])
    return alpha


@njit(cache=True)
def ocp_qp(A, B, f, qx, rw, rl, C, ylo, yhi, wlo, whi, x0_free, tol, max_iter):
    """Solve the banded QP of the module docstring.

    Parameters
    ----------
    A : (J, n, n); B : (J, n, q); f : (J, n)
    qx : (n,) diagonal state cost; rw : (q,) diagonal disturbance cost; rl : (J, q) linear cost
    C : (J+1, p, n) output rows per stage; ylo, yhi : (J+1, p), ``-inf``/``inf`` where there is no bound
    wlo, whi : (J, q), ``-inf``/``inf`` where there is no bound
    x0_free : bool; tol : float; max_iter : int

    Returns
    -------
    (status, x (J+1, n), w (J, q), iterations) — status 0 solved, 1 not converged, 2 numerical failure.
    """
    J, n, q = B.shape
    xs, xg, xh, ws, wc, wg, wh = _rows(C, ylo, yhi, wlo, whi)
    mx, mw = xh.size, wh.size
    m_count = max(1, mx + mw)
    x = np.zeros((J + 1, n))
    w = np.zeros((J, q))
    nu = np.zeros((J, n))
    # slacks at x = 0, w = 0 pushed to at least 1; multipliers 1
    sx = np.maximum(xh, 1.0)
    sw = np.maximum(wh, 1.0)
    lx = np.ones(mx)
    lw = np.ones(mw)
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
    rix = np.empty(mx)
    riw = np.empty(mw)
    dsx, dlx, dsw, dlw = np.empty(mx), np.empty(mx), np.empty(mw), np.empty(mw)
    ax_s, ax_l, aw_s, aw_l = np.zeros(mx), np.zeros(mx), np.zeros(mw), np.zeros(mw)  # the predictor's steps
    scale = 1.0
    for j in range(J):
        for i in range(n):
            scale = max(scale, abs(f[j, i]))
    status = 1
    it = 0
    for it in range(1, max_iter + 1):
        # residuals of the KKT conditions
        for a in range(J + 1):
            for b in range(n):
                rx[a, b] = qx[b] * x[a, b]
        for j in range(J):
            for a in range(q):
                rwv[j, a] = rw[a] * w[j, a] + rl[j, a]
            small_matvec(A[j], nu[j], rx[j], True, True, 1.0)
            small_matvec(B[j], nu[j], rwv[j], True, True, 1.0)
            for a in range(n):
                rx[j + 1, a] -= nu[j, a]
                re[j, a] = f[j, a] - x[j + 1, a]
            small_matvec(A[j], x[j], re[j], False, True, 1.0)
            small_matvec(B[j], w[j], re[j], False, True, 1.0)
        mu = 0.0
        pres = 0.0
        for r in range(mx):
            j = xs[r]
            gz = 0.0
            for a in range(n):
                gz += xg[r, a] * x[j, a]
                rx[j, a] += lx[r] * xg[r, a]
            rix[r] = gz + sx[r] - xh[r]
            mu += sx[r] * lx[r]
            pres = max(pres, abs(rix[r]))
        for r in range(mw):
            j, a = ws[r], wc[r]
            rwv[j, a] += lw[r] * wg[r]
            riw[r] = wg[r] * w[j, a] + sw[r] - wh[r]
            mu += sw[r] * lw[r]
            pres = max(pres, abs(riw[r]))
        mu /= m_count
        if not x0_free:
            rx[0] = 0.0  # x_0 is fixed: its stationarity row belongs to the free multiplier of x_0 = 0
        dres = max(np.max(np.abs(rx)), np.max(np.abs(rwv)) if J else 0.0, np.max(np.abs(re)) / scale if J else 0.0)
        if not (np.isfinite(dres) and np.isfinite(pres) and np.isfinite(mu)):
            status = 2
            break
        if dres < tol and pres < tol and mu < tol:
            status = 0
            break
        # Hessian blocks with the barrier terms, and the factorisation
        for j in range(J + 1):
            Hx[j] = 0.0
            for a in range(n):
                Hx[j, a, a] = qx[a]
        for r in range(mx):
            j = xs[r]
            d = lx[r] / sx[r]
            for a in range(n):
                if xg[r, a] != 0.0:
                    for b in range(n):
                        Hx[j, a, b] += d * xg[r, a] * xg[r, b]
        for j in range(J):
            Hw[j] = 0.0
            for a in range(q):
                Hw[j, a, a] = rw[a]
        for r in range(mw):
            Hw[ws[r], wc[r], wc[r]] += lw[r] / sw[r]
        riccati_factor(A, B, Hx, Hw, P, K, Lq)
        if not np.all(np.isfinite(P[0])):
            status = 2
            break
        # predictor (sigma = 0), then corrector with Mehrotra's centring, one factorisation
        sig = 0.0
        alpha = 1.0
        for phase in range(2):
            gx[:] = rx
            gw[:] = rwv
            for r in range(mx):
                rc = sx[r] * lx[r] - sig * mu + phase * ax_s[r] * ax_l[r]
                t = (lx[r] * rix[r] - rc) / sx[r]
                for a in range(n):
                    gx[xs[r], a] += t * xg[r, a]
            for r in range(mw):
                rc = sw[r] * lw[r] - sig * mu + phase * aw_s[r] * aw_l[r]
                gw[ws[r], wc[r]] += wg[r] * (lw[r] * riw[r] - rc) / sw[r]
            if not x0_free:
                gx[0] = 0.0
            riccati_solve(A, B, gx, gw, re, x0_free, P, K, Lq, dx, dw, dnu)
            for r in range(mx):
                gdz = 0.0
                for a in range(n):
                    gdz += xg[r, a] * dx[xs[r], a]
                rc = sx[r] * lx[r] - sig * mu + phase * ax_s[r] * ax_l[r]
                dsx[r] = -rix[r] - gdz
                dlx[r] = (-rc - lx[r] * dsx[r]) / sx[r]
            for r in range(mw):
                rc = sw[r] * lw[r] - sig * mu + phase * aw_s[r] * aw_l[r]
                dsw[r] = -riw[r] - wg[r] * dw[ws[r], wc[r]]
                dlw[r] = (-rc - lw[r] * dsw[r]) / sw[r]
            alpha = _step_length(sx, dsx, lx, dlx, 1.0)
            alpha = _step_length(sw, dsw, lw, dlw, alpha)
            if phase == 0:
                ax_s[:] = dsx
                ax_l[:] = dlx
                aw_s[:] = dsw
                aw_l[:] = dlw
                mu_aff = (np.sum((sx + alpha * dsx) * (lx + alpha * dlx))
                          + np.sum((sw + alpha * dsw) * (lw + alpha * dlw))) / m_count  # fmt: skip
                sig = (mu_aff / mu) ** 3 if mu > 0 else 0.0
        a = min(1.0, STEP * alpha)
        x += a * dx
        w += a * dw
        nu += a * dnu
        sx += a * dsx
        lx += a * dlx
        sw += a * dsw
        lw += a * dlw
    return status, x, w, it
