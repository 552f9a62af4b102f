"""Certified point-in-zonotope tests with a compiled bounded-variable simplex.

``p`` is in ``Z(c, G)`` (with tolerance ``tol``) iff some ``b`` with
``|b|_inf <= 1 + tol`` has ``|(G b - (p - c))_i| <= tol * s_i`` in every row,
``s_i = max(sum_j |G_ij|, REL_MAGNITUDE * max(|c_i|, |p_i|))``: the slack is
relative to the set's extent in that coordinate (and, where it has none, to
the numbers' magnitude, for the rounding of ``p - c``), never an absolute
amount that would swallow a set of tiny numbers (outputs of order 1e-9), nor
one set by another coordinate (one scale for all rows let a point 5 times a
row's radius outside in a coordinate of 1e-8 pass when another was of 1e2).
The test runs on the problem with row ``i`` divided by ``s_i`` (the
simplex's pivot tolerances are absolute; ``s_i = 0``, a row of zeros where
``c_i = p_i = 0``, is left as it is).

For each point a phase-1 simplex solves ``G beta + S a = d + G 1`` with
``0 <= beta <= 2`` (``b = beta - 1``) and artificials ``a >= 0``, minimising
``sum(a)``.  Each answer is *certified* before it is returned:

* inside: the primal ``b`` (clipped to ``[-1, 1]``) reproduces ``d`` within
  ``tol * s``;
* outside: the simplex duals ``y`` separate ``d`` from the tolerance-widened
  zonotope: ``y.d > (1 + tol) |G^T y|_1 + tol s |y|_1``.

When neither certificate holds (degenerate or ill-conditioned cases) the
status is ``-1`` and the caller decides with a reference LP.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

INSIDE = 1
OUTSIDE = 0
UNDECIDED = -1

#: the tolerance's scale is at least this fraction of the numbers' magnitude (rounding of ``p - c``: 1e-14 of it
#: with ``tol = 1e-9``); it was ``max(1, ...)``, an absolute floor that made data of order 1e-9 always "inside"
REL_MAGNITUDE = 1e-5


@njit(cache=True)
def _phase1(G, d, tol, s):
    n, m = G.shape
    N = m + n
    r0 = d.copy()
    for i in range(n):
        for j in range(m):
            r0[i] += G[i, j]
    sgn = np.empty(n)
    for i in range(n):
        sgn[i] = 1.0 if r0[i] >= 0.0 else -1.0
    x = np.zeros(N)
    upper = np.empty(N)
    upper[:m] = 2.0
    upper[m:] = np.inf
    cost = np.zeros(N)
    cost[m:] = 1.0
    basis = np.empty(n, dtype=np.int64)
    is_basic = np.zeros(N, dtype=np.bool_)
    at_upper = np.zeros(N, dtype=np.bool_)
    Binv = np.zeros((n, n))
    for i in range(n):
        basis[i] = m + i
        is_basic[m + i] = True
        x[m + i] = abs(r0[i])
        Binv[i, i] = sgn[i]
    col = np.empty(n)
    y = np.empty(n)
    w = np.empty(n)
    eps = 1e-11
    max_iter = 20 * (n + m)
    degenerate = 0
    for it in range(max_iter):
        # duals y = B^-T c_B
        for i in range(n):
            acc = 0.0
            for k in range(n):
                acc += cost[basis[k]] * Binv[k, i]
            y[i] = acc
        # pricing (Dantzig; Bland after a run of degenerate pivots)
        q = -1
        best = 0.0
        for j in range(N):
            if is_basic[j]:
                continue
            if j < m:
                yg = 0.0
                for i in range(n):
                    yg += y[i] * G[i, j]
            else:
                yg = y[j - m] * sgn[j - m]
            rc = cost[j] - yg
            score = -rc if not at_upper[j] else rc
            if score > eps * (1.0 + abs(cost[j])):
                if degenerate > 2 * n:
                    q = j
                    break
                if score > best:
                    best = score
                    q = j
        if q < 0:
            return x, y, True
        # column of q and direction
        if q < m:
            for i in range(n):
                col[i] = G[i, q]
        else:
            for i in range(n):
                col[i] = 0.0
            col[q - m] = sgn[q - m]
        for i in range(n):
            acc = 0.0
            for k in range(n):
                acc += Binv[i, k] * col[k]
            w[i] = acc
        direction = -1.0 if at_upper[q] else 1.0  # entering variable moves up (from 0) or down (from upper)
        theta = upper[q]  # bound flip
        leave = -1
        leave_to_upper = False
        for i in range(n):
            delta = -direction * w[i]  # d x_B[i] / d theta
            bi = basis[i]
            if delta < -1e-12:
                t = x[bi] / -delta
                if t < theta:
                    theta = t
                    leave = i
                    leave_to_upper = False
            elif delta > 1e-12 and upper[bi] < np.inf:
                t = (upper[bi] - x[bi]) / delta
                if t < theta:
                    theta = t
                    leave = i
                    leave_to_upper = True
        if theta == np.inf:
            return x, y, False  # cannot happen in phase 1 (bounded objective)
        degenerate = degenerate + 1 if theta <= 1e-14 else 0
        for i in range(n):
            bi = basis[i]
            x[bi] -= direction * w[i] * theta
        x[q] += direction * theta
        if leave < 0:
            at_upper[q] = not at_upper[q]
            continue
        out = basis[leave]
        x[out] = upper[out] if leave_to_upper else 0.0
        at_upper[out] = leave_to_upper
        is_basic[out] = False
        is_basic[q] = True
        at_upper[q] = False
        basis[leave] = q
        # product-form update of B^-1 with pivot w[leave]
        piv = w[leave]
        for k in range(n):
            Binv[leave, k] /= piv
        for i in range(n):
            if i != leave and w[i] != 0.0:
                f = w[i]
                for k in range(n):
                    Binv[i, k] -= f * Binv[leave, k]
    return x, y, False


@njit(cache=True)
def _certify(G, d, x, y, tol, s):
    n, m = G.shape
    # inside: b = clip(beta - 1) reproduces d
    worst = 0.0
    for i in range(n):
        acc = 0.0
        for j in range(m):
            b = x[j] - 1.0
            if b > 1.0:
                b = 1.0
            elif b < -1.0:
                b = -1.0
            acc += G[i, j] * b
        r = abs(acc - d[i])
        if r > worst:
            worst = r
    if worst <= tol * s:
        return INSIDE
    # outside: y (or -y) separates
    yd = 0.0
    ynorm = 0.0
    for i in range(n):
        yd += y[i] * d[i]
        ynorm += abs(y[i])
    gnorm = 0.0
    for j in range(m):
        acc = 0.0
        for i in range(n):
            acc += y[i] * G[i, j]
        gnorm += abs(acc)
    bound = (1.0 + tol) * gnorm + tol * s * ynorm
    bound += 1e-13 * (abs(yd) + gnorm + ynorm * s)  # rounding of the sums above
    if abs(yd) > bound:
        return OUTSIDE
    return UNDECIDED


@njit(cache=True)
def _row_abs_sums(G):
    """``sum_j |G_ij|`` per row: the interval-hull radius of ``Z(0, G)``."""
    n, m = G.shape
    r = np.zeros(n)
    for i in range(n):
        for j in range(m):
            r[i] += abs(G[i, j])
    return r


@njit(cache=True)
def _unit_if_zero(s):
    """``s`` with its zeros (rows of zeros where the numbers are zero) replaced by 1."""
    out = s.copy()
    for i in range(out.shape[0]):
        if out[i] == 0.0:
            out[i] = 1.0
    return out


@njit(cache=True)
def _rows_divided(G, s):
    """``G`` with row ``i`` divided by ``s[i]``."""
    out = np.empty_like(G)
    for i in range(G.shape[0]):
        for j in range(G.shape[1]):
            out[i, j] = G[i, j] / s[i]
    return out


@njit(cache=True, parallel=True)
def contains_batch(c, G, P, tol):
    """Status per row of ``P``: 1 inside, 0 outside, -1 undecided (see module docstring)."""
    n = G.shape[0]
    r = _row_abs_sums(G)
    raw0 = np.empty(n)
    for i in range(n):
        raw0[i] = max(r[i], REL_MAGNITUDE * abs(c[i]))
    sig0 = _unit_if_zero(raw0)
    G0 = _rows_divided(G, sig0)  # scaled once for every point whose own magnitude does not raise it
    out = np.empty(P.shape[0], dtype=np.int64)
    for k in prange(P.shape[0]):
        d = P[k] - c
        raw = np.empty(n)
        for i in range(n):
            raw[i] = max(raw0[i], REL_MAGNITUDE * abs(P[k, i]))
        sig = _unit_if_zero(raw)
        Gs = G0 if np.all(sig == sig0) else _rows_divided(G, sig)
        ds = d / sig
        x, y, _ = _phase1(Gs, ds, tol, 1.0)
        # the certificates are checked independently of the simplex's own verdict
        out[k] = _certify(Gs, ds, x, y, tol, 1.0)
    return out


@njit(cache=True)
def contains_mapped_sequence(tp_c, tp_G, ng, C, off, v_rad, P, tol, stop_at_outside):
    """Status of ``P[k]`` in ``C Z_k + off[k] ⊕ box(0, v_rad)`` for every k (eq. 43 along a tube).

    ``Z_k = Z(tp_c[k], tp_G[k, :, :ng[k]])``; 1 inside, 0 outside, -1
    undecided (decide with the reference LP), -2 not checked (after the first
    outside point when ``stop_at_outside``).  Per point the same test as
    :func:`contains_batch` after the interval-hull rejection of
    ``reachconf.containment.contains_points``.
    """
    K = P.shape[0]
    p, n = C.shape
    out = np.full(K, -2, dtype=np.int64)
    nv = 0
    for i in range(p):
        if v_rad[i] > 0.0:
            nv += 1
    for k in range(K):
        m0 = ng[k]
        m = m0 + nv
        G = np.zeros((p, m))
        c = off[k].copy()
        for i in range(p):
            for r in range(n):
                a = C[i, r]
                if a != 0.0:
                    c[i] += a * tp_c[k, r]
                    for j in range(m0):
                        G[i, j] += a * tp_G[k, r, j]
        j = m0
        for i in range(p):
            if v_rad[i] > 0.0:
                G[i, j] = v_rad[i]
                j += 1
        r = _row_abs_sums(G)
        d = P[k] - c
        s = np.empty(p)  # per row (see the module docstring): the extent, or the magnitude of the numbers
        for i in range(p):
            mi = abs(off[k, i]) + abs(P[k, i])  # the terms of the centre and the point: their rounding
            for rr in range(n):
                mi += abs(C[i, rr] * tp_c[k, rr])
            s[i] = max(r[i], REL_MAGNITUDE * mi)
        s = _unit_if_zero(s)  # a row all zero: d_i == 0 exactly
        G = _rows_divided(G, s)
        d /= s
        r /= s
        inside_hull = True
        for i in range(p):
            if abs(d[i]) > r[i] * (1.0 + tol) + tol:
                inside_hull = False
                break
        if not inside_hull:
            out[k] = OUTSIDE
        elif m == 0:
            out[k] = INSIDE
        else:
            x, y, _ = _phase1(G, d, tol, 1.0)
            out[k] = _certify(G, d, x, y, tol, 1.0)
        if stop_at_outside and out[k] == OUTSIDE:
            break
    return out
