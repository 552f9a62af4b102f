"""Quadratic maps of zonotopes (CORA's ``quadMap``) and the bound of their rounding.

``quad_map`` and ``quad_map_mixed`` compute the image enclosure in floating
point; ``quad_map_rounding`` bounds how far the computed centre and generators
can lie from the exact ones, so a caller adds that box and the result contains
the exact image (the reach kernels add it to the abstraction error's box).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from reachconf_kernels.small_linalg import abs_terms_times, mat_mat

_EPS = 2.220446049250313e-16
_TINY = 5e-324  # the smallest subnormal, 2^-1074


@njit(cache=True)
def _is_zero(Q, i):
    for a in range(Q.shape[1]):
        for b in range(Q.shape[2]):
            if Q[i, a, b] != 0.0:
                return False
    return True


@njit(cache=True)
def _stacked(c, G):
    """``[c, G]`` as one (n, m + 1) matrix."""
    Zm = np.empty((c.shape[0], G.shape[1] + 1))
    Zm[:, 0] = c
    Zm[:, 1:] = G
    return Zm


@njit(cache=True)
def _bilinear(Q, i, Z1, Z2):
    """``Z1.T @ Q[i] @ Z2`` with plain loops."""
    return mat_mat(Z1.T, mat_mat(Q[i], Z2))


@njit(cache=True)
def quad_map(c, G, Q):
    """Enclosure of ``{(x^T Q_i x)_i | x in Z}``; Q has shape (k, n, n) (CORA's quadMap)."""
    m = G.shape[1]
    k = Q.shape[0]
    Zm = _stacked(c, G)
    ng = m + (m + 1) * m // 2
    cout = np.zeros(k)
    Gout = np.zeros((k, ng))
    for i in range(k):
        if _is_zero(Q, i):
            continue
        Qh = _bilinear(Q, i, Zm, Zm)
        cout[i] = Qh[0, 0]
        for j in range(1, m + 1):
            cout[i] += 0.5 * Qh[j, j]
            Gout[i, j - 1] = 0.5 * Qh[j, j]
        col = m
        for a in range(m + 1):
            for b in range(a + 1, m + 1):
                Gout[i, col] = Qh[a, b] + Qh[b, a]
                col += 1
    return cout, Gout


@njit(cache=True)
def quad_map_mixed(c1, G1, c2, G2, Q):
    """Enclosure of ``{(x^T Q_i y)_i | x in Z1, y in Z2}``."""
    m1 = G1.shape[1]
    m2 = G2.shape[1]
    k = Q.shape[0]
    Z1 = _stacked(c1, G1)
    Z2 = _stacked(c2, G2)
    cout = np.zeros(k)
    Gout = np.zeros((k, (m1 + 1) * (m2 + 1) - 1))
    for i in range(k):
        if _is_zero(Q, i):
            continue
        Qh = _bilinear(Q, i, Z1, Z2)
        cout[i] = Qh[0, 0]
        col = 0
        for a in range(m1 + 1):
            for b in range(m2 + 1):
                if a == 0 and b == 0:
                    continue
                Gout[i, col] = Qh[a, b]
                col += 1
    return cout, Gout


@njit(cache=True)
def _abs_colsum(c, G):
    s = np.abs(c)
    for j in range(G.shape[1]):
        s = s + np.abs(G[:, j])
    return s


@njit(cache=True)
def _meets(s1, Qi, s2):
    """Is some product ``s1[a] Qi[a, b] s2[b]`` non-zero in exact arithmetic (although it may underflow to 0)?"""
    for a in range(Qi.shape[0]):
        if s1[a] != 0.0:
            for b in range(Qi.shape[1]):
                if Qi[a, b] != 0.0 and s2[b] != 0.0:
                    return True
    return False


@njit(cache=True)
def quad_map_rounding(c1, G1, c2, G2, Q):
    """Radius (k,) of a box that covers the rounding of ``quad_map`` (``Z1 = Z2``) or ``quad_map_mixed``.

    Every computed entry is a sum of at most ``n^2`` products of ``|Z1|``, ``|Q_i|`` and ``|Z2|`` and the centre adds
    ``m`` such entries; together they are bounded by ``s1^T |Q_i| s2`` with ``s`` the row sums of ``|[c, G]|``.  The
    relative part is ``4 (n^2 + m + 4) eps`` times that (``m`` = both zonotopes' generators), far above the classical
    ``gamma_{2n + m + 2}`` bound of the sums.  The absolute part covers underflow, where a product (or a halving)
    errs by up to ``2^-1075`` whatever its size: each of the ``(m1 + 1)(m2 + 1)`` entries of ``Z1^T (Q_i Z2)`` takes
    ``n`` of them in ``Q_i Z2``, scaled by the ``|Z1|`` that multiplies them, and ``n`` more, so the sum over all
    entries and halvings is below ``2^-1075 (n (m2 + 1) (m1 + 1 + |Z1|_1) + m1 + m2)``; the bound adds twice that
    (plus four ``2^-1074``).  Rounded up; exactly 0 where every product is exactly 0 (a zero row of ``Q``).
    """
    n = c1.shape[0]
    m1, m2 = G1.shape[1], G2.shape[1]
    s1 = _abs_colsum(c1, G1)
    s2 = _abs_colsum(c2, G2)
    k = Q.shape[0]
    scale = 4.0 * (n * n + m1 + m2 + 4) * _EPS
    ab = n * (m2 + 1)
    absolute = (ab * _TINY) * np.sum(s1) + (ab * (m1 + 1) + m1 + m2 + 4) * _TINY
    out = np.zeros(k)
    for i in range(k):
        row = abs_terms_times(Q[i : i + 1], s2)  # |Q_i| s2
        acc = 0.0
        for a in range(n):
            acc += s1[a] * row[a]
        if acc > 0.0 or _meets(s1, Q[i], s2):  # else every product is exactly 0 (no subnormal box)
            out[i] = np.nextafter(scale * acc * (1.0 + 4.0 * (n + 1) * _EPS) + absolute, np.inf)
    return out
