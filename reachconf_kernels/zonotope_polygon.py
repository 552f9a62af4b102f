"""The polygon of a 2-D zonotope: an outward enclosure, exactly convex and counter-clockwise.

The vertices of ``Z(c, G)`` follow from walking its generators in the order of
their angles, ``c - sum g``, then ``+ 2 g`` and ``- 2 g`` each.  In floating
point the walk's vertices lie a few ulps off the exact ones, inside as often as
outside, and a misordered pair of near-parallel generators (or two edges
shorter than the coordinates' ulps) turns the walk clockwise.  So
:func:`polygon`

1. walks the generators of ``Z`` plus a box ``[-e, e]^2`` (two more
   generators), where ``e`` is twice a bound of how far (in any direction)
   the rounding of the walk's sums, the slivers a misordering leaves out and
   what step 2 cuts off can pull the result inside the exact ``Z + [-e, e]^2``,
   which reaches at least ``e`` beyond ``Z`` (see :func:`_margin`);
2. keeps the convex hull of the walk's points (Andrew's monotone chain) whose
   every turn is certified left: the sign test of :func:`_left` accepts a
   turn only if its computed cross product exceeds the bound of its rounding.

Every point of ``Z`` then lies inside the polygon (exact containment, no
tolerance), whose consecutive vertices turn strictly left in exact arithmetic.
The margin is about a thousand ulps of the generators' sum per generator (and
ten of the coordinates): invisible in a plot, far below containment tolerances.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

_U = 1.1102230246251565e-16  # unit roundoff 2^-53
_TINY = 5e-324  # the smallest subnormal, 2^-1074


@njit(cache=True)
def _margin(c, G):
    """Half-width ``e`` of the box added to ``Z(c, G)`` (2-D, ``m`` generators); see :func:`polygon`.

    The support of the result in any unit direction falls short of that of the
    exact ``Z + [-e, e]^2`` (which exceeds ``Z``'s by at least ``e``) by at most
    the sum of

    * ``r``, the 2-norm error of the walk's vertices.  With ``k = m + 2``
      generators, each is a recursive sum of at most ``3 k + 1`` terms whose
      magnitudes add up to ``A'_i = |c_i| + 5 D'_i`` (``D'_i = sum_j |G_ij| + e``):
      ``r <= sqrt 2 (3 k) u max A'``;
    * ``sigma``, the slivers that misordered near-parallel generators leave
      out (their ``atan2`` err by an ulp of pi): below ``16 pi u sum |g|``;
    * ``l``, what the hull cuts off: at most ``4 k`` points, each within twice
      ``16 u`` times the walk's diameter ``2 sqrt 2 max D'`` of its chord.

    ``e`` is twice their sum, rounded up: ``9 (m + 3) u max A + 1000 (m + 4) u
    max D`` plus 64 smallest subnormals, times 1.01 for ``A' > A``, ``D' > D``
    (``e < 1e-3 A`` below 10^10 generators) and the rounding of these sums.
    """
    d0 = 0.0
    d1 = 0.0
    for j in range(G.shape[1]):
        d0 += abs(G[0, j])
        d1 += abs(G[1, j])
    m = G.shape[1]
    A = max(abs(c[0]) + 5.0 * d0, abs(c[1]) + 5.0 * d1)
    e = (9.0 * (m + 3) * _U) * A + (1000.0 * (m + 4) * _U) * max(d0, d1) + 64.0 * _TINY  # no overflow before u
    return np.nextafter(1.01 * e, np.inf)


@njit(cache=True)
def _walk(c, G, e):
    """The vertex walk (2 m' points, counter-clockwise up to rounding) of ``Z(c, [G, e I])``."""
    m = G.shape[1]
    Gs = np.empty((2, m + 2))
    Gs[:, :m] = G
    Gs[0, m], Gs[1, m] = e, 0.0
    Gs[0, m + 1], Gs[1, m + 1] = 0.0, e
    k = m + 2
    ang = np.empty(k)
    for j in range(k):
        if Gs[1, j] < 0.0 or (Gs[1, j] == 0.0 and Gs[0, j] < 0.0):  # orient to the upper half plane
            Gs[0, j] = -Gs[0, j]
            Gs[1, j] = -Gs[1, j]
        ang[j] = math.atan2(Gs[1, j], Gs[0, j])
    idx = np.argsort(ang)
    V = np.empty((2 * k, 2))
    p0 = c[0]
    p1 = c[1]
    for j in range(k):
        p0 -= Gs[0, j]
        p1 -= Gs[1, j]
    for s in range(2):
        sign = 2.0 if s == 0 else -2.0
        for t in range(k):
            V[s * k + t, 0] = p0
            V[s * k + t, 1] = p1
            p0 += sign * Gs[0, idx[t]]
            p1 += sign * Gs[1, idx[t]]
    return V


@njit(cache=True)
def _unit(x, y):
    """``(x, y)`` times the power of two that brings its larger entry into [0.5, 1) (the direction unchanged).

    Only outside ``[2^-500, 2^500]``: inside, the products of two such vectors neither overflow nor underflow
    by more than ``2^-1075`` each, which the ``8 * 2^-1074`` of :func:`_left` covers.
    """
    s = max(abs(x), abs(y))
    if 3.054936363499605e-151 <= s <= 3.273390607896142e150 or s == 0.0 or not s < np.inf:
        return x, y
    k = math.frexp(s)[1]
    return math.ldexp(x, -k), math.ldexp(y, -k)


@njit(cache=True)
def _left(a0, a1, b0, b1, c0, c1):
    """Do ``a, b, c`` turn strictly left, certified: the exact ``(b - a) x (c - a)`` of the floats is > 0?

    A difference outside ``[2^-500, 2^500]`` is scaled by a power of two (:func:`_unit`; the sign is unchanged);
    the computed cross product ``p1 - p2`` then errs by less than ``4.1 u (|p1| + |p2|)`` plus four
    ``2^-1075``, and a turn counts as left only beyond twice that.  A point this drops lies within
    ``16 u |b - a| + 16 * 2^-1074 / |c - a|`` of the chord ``a c``, the last term negligible as
    ``|c - a| >= 2^-500`` (or is scaled to at least 1/2).
    """
    d1x, d1y = _unit(b0 - a0, b1 - a1)
    d2x, d2y = _unit(c0 - a0, c1 - a1)
    p1 = d1x * d2y
    p2 = d1y * d2x
    return p1 - p2 > 8.0 * _U * (abs(p1) + abs(p2)) + 8.0 * _TINY


@njit(cache=True)
def _hull(P):
    """Convex hull of the points ``P`` (k, 2), counter-clockwise from the lowest-leftmost, every turn certified."""
    k = P.shape[0]
    order = np.argsort(P[:, 0])
    for t in range(1, k):  # by x, then y: insertion sort of the (few) runs of equal x
        o = order[t]
        r = t
        while r > 0 and P[order[r - 1], 0] == P[o, 0] and P[order[r - 1], 1] > P[o, 1]:
            order[r] = order[r - 1]
            r -= 1
        order[r] = o
    H = np.empty((2 * k + 1, 2))
    h = 0
    for half in range(2):
        start = h
        for t in range(k):
            q = P[order[t] if half == 0 else order[k - 1 - t]]
            if h > start and H[h - 1, 0] == q[0] and H[h - 1, 1] == q[1]:
                continue  # a repeated point
            while h >= start + 2 and not _left(H[h - 2, 0], H[h - 2, 1], H[h - 1, 0], H[h - 1, 1], q[0], q[1]):
                h -= 1
            H[h] = q
            h += 1
        h -= 1  # the last point of each chain starts the other
    return H[: max(h, 1)].copy()


@njit(cache=True)
def polygon(c, G):
    """Vertices (V, 2) of a polygon that contains the 2-D zonotope ``Z(c, G)``: counter-clockwise, convex.

    At most ``2 m + 4`` vertices for ``m`` generators (the box of the rounding
    margin adds two edge directions): see the module notes for the guarantee.
    """
    return _hull(_walk(c, G, _margin(c, G)))
