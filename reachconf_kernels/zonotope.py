"""Zonotope kernels: ``Z = {c + G b | b in [-1, 1]^m}`` with ``c`` (n,) and ``G`` (n, m).

Pure numba functions on float64 arrays.  Operations that are exact in real
arithmetic (linear map, Minkowski sum, Cartesian product, enclose) are
computed in floating point, rounded to nearest: their result may miss a true point by a few ulps of the
numbers' magnitude (all of a width that underflows), which they do not enclose (``quad_map`` has a rounding
bound: :mod:`reachconf_kernels.quadmap`); operations that create boxes
(interval hull, order reduction, from_interval) round the box outward so the
result always contains the input.  The reachability kernels add a small
relative allowance per step for the rounding of the float operations.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit


_EPS = 2.220446049250313e-16
_TINY = 5e-324  # the smallest subnormal, 2^-1074


@njit(cache=True)
def _up(x):
    return np.nextafter(x, np.inf)


@njit(cache=True)
def _abs_sum_rows(G):
    """Row sums of |G| rounded up (sound radius of the interval hull)."""
    n, m = G.shape
    r = np.zeros(n)
    for i in range(n):
        s = 0.0
        for j in range(m):
            s += abs(G[i, j])
        # sum of m non-negative terms: relative error <= m eps
        r[i] = _up(s * (1.0 + (m + 1) * _EPS))
    return r


@njit(cache=True)
def interval_hull(c, G):
    """Smallest axis-aligned box ``(lo, hi)`` containing Z, rounded outward."""
    r = _abs_sum_rows(G)
    n = c.shape[0]
    lo = np.empty(n)
    hi = np.empty(n)
    for i in range(n):
        lo[i] = np.nextafter(c[i] - r[i], -np.inf)
        hi[i] = np.nextafter(c[i] + r[i], np.inf)
    return lo, hi


@njit(cache=True)
def scale_box(lo, hi, alpha):
    """The box ``[lo, hi]`` scaled about its centre by ``alpha >= 0``, rounded outward (``(lo, hi)`` arrays).

    ``c = lo/2 + hi/2`` (``lo + hi`` may overflow) and ``r = (alpha (hi - lo)) / 2`` (halved last: ``alpha`` would
    scale the halving's error) and ``c -+ r`` err by less than ``eps (|c| + r)`` plus ``3.5 * 2^-1075`` (a halving or
    an underflowing product of subnormals errs by an absolute ``2^-1075``, which no relative term covers): the bounds
    are widened by ``4 eps (|c| + r) + 4 * 2^-1074`` and then one float outward.  Overflow gives ``inf`` bounds.
    """
    n = lo.shape[0]
    slo = np.empty(n)
    shi = np.empty(n)
    for i in range(n):
        c = 0.5 * lo[i] + 0.5 * hi[i]
        r = 0.5 * (alpha * (hi[i] - lo[i]))
        slack = 4.0 * _EPS * (abs(c) + r) + 4.0 * _TINY
        slo[i] = np.nextafter(c - r - slack, -np.inf)
        shi[i] = np.nextafter(c + r + slack, np.inf)
    return slo, shi


@njit(cache=True)
def from_interval(lo, hi):
    """Zonotope of a box; degenerate dimensions get no generator; contains the box."""
    n = lo.shape[0]
    c = 0.5 * lo + 0.5 * hi
    k = 0
    for i in range(n):
        if hi[i] > lo[i]:
            k += 1
    G = np.zeros((n, k))
    j = 0
    for i in range(n):
        if hi[i] > lo[i]:
            r = max(hi[i] - c[i], c[i] - lo[i])
            G[i, j] = _up(r * (1.0 + 2 * _EPS))
            j += 1
    return c, G


@njit(cache=True)
def linear_map(M, c, G):
    """``(M c, M G)`` with plain loops (faster than BLAS calls for the small sizes used here)."""
    k, n = M.shape
    m = G.shape[1]
    c2 = np.zeros(k)
    G2 = np.zeros((k, m))
    for i in range(k):
        acc = 0.0
        for r in range(n):
            a = M[i, r]
            acc += a * c[r]
            if a != 0.0:
                for j in range(m):
                    G2[i, j] += a * G[r, j]
        c2[i] = acc
    return c2, G2


@njit(cache=True)
def minkowski_sum(c1, G1, c2, G2):
    """Minkowski sum of ``Z(c1, G1)`` and ``Z(c2, G2)``: ``(c1 + c2, [G1 G2])`` (the centre sum rounded to nearest)."""
    n = c1.shape[0]
    G = np.empty((n, G1.shape[1] + G2.shape[1]))
    G[:, : G1.shape[1]] = G1
    G[:, G1.shape[1] :] = G2
    return c1 + c2, G


@njit(cache=True)
def add_interval(c, G, lo, hi):
    """``Z(c, G)`` plus the box ``[lo, hi]``: its centre added, one generator per non-degenerate dimension."""
    cb, Gb = from_interval(lo, hi)
    return minkowski_sum(c, G, cb, Gb)


@njit(cache=True)
def cartesian_product(c1, G1, c2, G2):
    """Cartesian product of two zonotopes (block-diagonal generators)."""
    n1, n2 = c1.shape[0], c2.shape[0]
    m1, m2 = G1.shape[1], G2.shape[1]
    c = np.empty(n1 + n2)
    c[:n1] = c1
    c[n1:] = c2
    G = np.zeros((n1 + n2, m1 + m2))
    G[:n1, :m1] = G1
    G[n1:, m1:] = G2
    return c, G


@njit(cache=True)
def _nonzero_columns(G):
    m = G.shape[1]
    keep = np.zeros(m, dtype=np.bool_)
    for j in range(m):
        for i in range(G.shape[0]):
            if G[i, j] != 0.0:
                keep[j] = True
                break
    return keep


@njit(cache=True)
def _girard_split(G, order):
    """Indices of generators to keep and to box (CORA's Girard selection)."""
    n = G.shape[0]
    keep_mask = _nonzero_columns(G)
    idx = np.nonzero(keep_mask)[0]
    m = idx.shape[0]
    if m <= n * order:
        return idx, idx[:0]
    n_keep = int(math.floor(n * (order - 1.0)))
    if n_keep < 0:
        n_keep = 0
    score = np.empty(m)
    for k in range(m):
        j = idx[k]
        s1 = 0.0
        smax = 0.0
        for i in range(n):
            a = abs(G[i, j])
            s1 += a
            if a > smax:
                smax = a
        score[k] = s1 - smax
    order_idx = np.argsort(-score)
    return idx[order_idx[:n_keep]], idx[order_idx[n_keep:]]


@njit(cache=True)
def reduce_girard(c, G, order):
    """Girard's order reduction: keep the generators with the largest ``|g|_1 - |g|_inf``, box the rest.

    One pass for the scores, a partial sort (``np.partition``) for the
    threshold and one pass that copies kept generators and sums the rest into
    an outward-rounded box.
    """
    n, m = G.shape
    score = np.empty(m)
    nonzero = 0
    for j in range(m):
        s1 = 0.0
        smax = 0.0
        for i in range(n):
            a = abs(G[i, j])
            s1 += a
            if a > smax:
                smax = a
        if s1 > 0.0:
            nonzero += 1
            score[j] = s1 - smax
        else:
            score[j] = -1.0  # zero generator: dropped
    if nonzero <= n * order:
        out = np.empty((n, nonzero))
        k = 0
        for j in range(m):
            if score[j] >= 0.0:
                for r in range(n):
                    out[r, k] = G[r, j]
                k += 1
        return c.copy(), out
    n_keep = int(math.floor(n * (order - 1.0)))
    if n_keep < 0:
        n_keep = 0
    thr = np.inf
    if n_keep > 0:
        thr = -np.partition(-score, n_keep - 1)[n_keep - 1]  # n_keep-th largest score
    above = 0
    for j in range(m):
        if score[j] > thr:
            above += 1
    ties = n_keep - above  # generators with score == thr that may still be kept
    out = np.empty((n, n_keep + n))
    box = np.zeros(n)
    k = 0
    for j in range(m):
        sj = score[j]
        if sj < 0.0:
            continue
        if sj > thr or (sj == thr and ties > 0):
            if sj == thr:
                ties -= 1
            for r in range(n):
                out[r, k] = G[r, j]
            k += 1
        else:
            for i in range(n):
                box[i] += abs(G[i, j])
    for i in range(n):
        if box[i] > 0.0:
            for r in range(n):
                out[r, k] = 0.0
            out[i, k] = _up(box[i] * (1.0 + (m + 1) * _EPS))
            k += 1
    return c.copy(), out[:, :k]


@njit(cache=True)
def reduce_pca(c, G, order):
    """Like Girard, but the rest is boxed in the frame of its principal axes."""
    keep, rest = _girard_split(G, order)
    n = c.shape[0]
    if rest.shape[0] == 0:
        out = np.empty((n, keep.shape[0]))
        for k in range(keep.shape[0]):
            out[:, k] = G[:, keep[k]]
        return c.copy(), out
    R = G[:, rest]
    big = np.max(np.abs(R))
    if not (big > 0.0 and big < np.inf):
        # NaN/inf generators (an exploded set: eigh would raise LinAlgError) or only zero ones: the Girard box
        # (NaN/inf propagate to the caller's finiteness check)
        return reduce_girard(c, G, order)
    Rs = R / big  # the axes do not depend on the scale; R R^T of entries beyond 1e154 overflowed
    cov = Rs @ Rs.T
    w, U = np.linalg.eigh(cov)
    # box in the rotated frame: U diag(sum |U^T R|) ; U orthonormal up to rounding
    T = U.T @ R
    rad = _abs_sum_rows(T)
    # allowance for U not being exactly orthonormal
    rad = rad * (1.0 + 1e-12) + 1e-15 * np.max(rad)
    B = U * rad
    # the map U (float) of the box: add a tiny axis box for the rounding of U * rad
    out = np.zeros((n, keep.shape[0] + n))
    for k in range(keep.shape[0]):
        out[:, k] = G[:, keep[k]]
    out[:, keep.shape[0] :] = B
    # soundness: U U^T = I only approximately; inflate by the orthogonality defect
    defect = np.max(np.abs(U.T @ U - np.eye(n)))
    if defect > 0.0:
        out[:, keep.shape[0] :] *= 1.0 + 4.0 * defect * n
    return c.copy(), out


@njit(cache=True)
def enclose(c1, G1, c2, G2):
    """Zonotope enclosing the convex hull of Z1 and Z2 (generators paired by index)."""
    if G1.shape[1] < G2.shape[1]:
        return enclose(c2, G2, c1, G1)
    n = c1.shape[0]
    m2 = G2.shape[1]
    m1 = G1.shape[1]
    out = np.empty((n, 2 * m2 + 1 + (m1 - m2)))
    for j in range(m2):
        for i in range(n):
            out[i, j] = 0.5 * (G1[i, j] + G2[i, j])
            out[i, m2 + 1 + j] = 0.5 * (G1[i, j] - G2[i, j])
    for i in range(n):
        out[i, m2] = 0.5 * (c1[i] - c2[i])
    out[:, 2 * m2 + 1 :] = G1[:, m2:]
    return 0.5 * (c1 + c2), out


@njit(cache=True)
def _directional(c, G, d):
    """``(d.c, sum_j |d.g_j|, err)``: ``err`` bounds the rounding of both sums (``gamma_k`` times the terms' sum)."""
    n = c.shape[0]
    m = G.shape[1]
    mid = 0.0
    mag = 0.0
    for i in range(n):
        t = d[i] * c[i]
        mid += t
        mag += abs(t)
    rad = 0.0
    for j in range(G.shape[1]):
        t = 0.0
        for i in range(n):
            a = d[i] * G[i, j]
            t += a
            mag += abs(a)
        rad += abs(t)
    # each dot product and the sums of |.| are recursive sums of at most n + m terms; products may underflow
    err = _up((2 * n + m + 2) * _EPS * mag * (1.0 + 1e-6) + (n * (m + 1) + 1) * 5e-324)
    return mid, rad, err


@njit(cache=True)
def support(c, G, d):
    """``max_{x in Z} d.x``, rounded up."""
    mid, rad, err = _directional(c, G, d)
    return _up(_up(mid + rad) + err)


@njit(cache=True)
def bounds_along(c, G, d):
    """``(min, max)`` of ``d.x`` over Z, rounded outward."""
    mid, rad, err = _directional(c, G, d)
    return np.nextafter(np.nextafter(mid - rad, -np.inf) - err, -np.inf), _up(_up(mid + rad) + err)


@njit(cache=True)
def compact(c, G, tol):
    """Delete zero generators and merge parallel ones; the result encloses the input.

    Generators of 2-norm ``<= tol`` are deleted and (near-)parallel ones merged;
    whatever this drops (the small generators, the non-parallel residual of a
    merge) is added back as an axis-aligned box, so the result is sound for any
    ``tol``.
    """
    n, m = G.shape
    norms = np.zeros(m)
    for j in range(m):
        # scaled by the largest entry: the squares of entries beyond 1e154 overflowed (every norm inf, every pair
        # "parallel", all boxed) and below 1e-162 underflowed (norm 0: dropped into the box)
        big = 0.0
        for i in range(n):
            big = max(big, abs(G[i, j]))
        if big == 0.0:
            continue
        s = 0.0
        for i in range(n):
            s += (G[i, j] / big) ** 2
        norms[j] = big * math.sqrt(s)
    out = np.zeros((n, m + n))
    box = np.zeros(n)
    used = np.zeros(m, dtype=np.bool_)
    k = 0
    for j in range(m):
        if used[j]:
            continue
        used[j] = True
        if norms[j] <= tol:
            for i in range(n):
                box[i] += abs(G[i, j])
            continue
        g = G[:, j].copy()
        uj = G[:, j] / norms[j]
        for l in range(j + 1, m):
            if used[l] or norms[l] <= tol:
                continue
            dot = 0.0
            for i in range(n):
                dot += uj[i] * G[i, l]
            if abs(abs(dot) - norms[l]) <= 1e-12 * norms[l]:
                # G_l = dot * uj + r with a tiny residual r: merge dot * uj, box |r|
                adot = abs(dot)
                for i in range(n):
                    par = dot * uj[i]
                    g[i] += adot * uj[i]
                    box[i] += abs(G[i, l] - par) + 4e-16 * abs(par)
                used[l] = True
        out[:, k] = g
        k += 1
    for i in range(n):
        if box[i] > 0.0:
            out[i, k] = box[i] * (1.0 + 4e-16)
            k += 1
    return c.copy(), out[:, :k].copy()


@njit(cache=True)
def piece_hulls(c, G, ng):
    """Interval hulls ``(lo, hi)`` (P, n) of sets stored back to back: centres ``c`` (P, n), generators in the
    columns of ``G`` (n, sum ng), set ``p`` owning ``ng[p]`` consecutive columns; rounded outward."""
    P, n = c.shape
    lo = np.empty((P, n))
    hi = np.empty((P, n))
    col = 0
    for s in range(P):
        g = ng[s]
        lo[s], hi[s] = interval_hull(c[s], G[:, col : col + g])
        col += g
    return lo, hi
