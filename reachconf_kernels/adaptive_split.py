"""Where to split a set in the adaptive reach: the generator whose halving lowers the error floor most.

Used by :mod:`reachconf.reach_adaptive` when :func:`reachconf_kernels.adaptive.adaptive_run` asks for a split
(its ``SPLIT`` code): the floor of each half is :func:`reachconf_kernels.adaptive.floor_rate`.
"""

from __future__ import annotations

import numpy as np
from numba import njit, types

from reachconf_kernels import zonotope as Z
from reachconf_kernels.adaptive import floor_rate
from reachconf_kernels.signatures import FN_IV_REMAINDER, FN_POINT_T3, f8_1, f8_2

__all__ = ["split_choice"]

_i8 = types.int64
_f8 = types.float64


@njit(cache=True)
def _halves(c, G, j):
    g = G[:, j].copy()
    Gh = G.copy()
    Gh[:, j] = 0.5 * g
    return c - 0.5 * g, c + 0.5 * g, Gh


@njit(cache=True)
def _halves_rate(c, G, j, u, wc, WG, p, hess, lagrange_iv, kappa, fpar, dt):
    ca, cb, Gh = _halves(c, G, j)
    ra = floor_rate(ca, Gh, u, wc, WG, p, hess, lagrange_iv, kappa, fpar, dt)
    rb = floor_rate(cb, Gh, u, wc, WG, p, hess, lagrange_iv, kappa, fpar, dt)
    return max(ra, rb)


@njit((f8_1, f8_2, f8_1, f8_1, f8_2, f8_1, FN_POINT_T3, FN_IV_REMAINDER, _i8, f8_1, _f8, _i8, _i8), cache=True)
def split_choice(c, G, u, wc, WG, p, hess, lagrange_iv, kappa, fpar, dt, keep, candidates):
    """Which generator to halve, judged by the error floor of the halves.

    Returns ``(rate, j_keep, rate_keep, j_other, rate_other)``: the floor of
    ``Z(c, G)`` itself; the best of the first ``keep`` generators (the images
    of the start set's generators: halving one of them here is what halving
    it at the start does, to first order) and its halves' floor; the best of
    the ``candidates`` other generators that are longest relative to the hull.
    ``j = -1`` where there is no candidate.
    """
    n, m = G.shape
    rate = floor_rate(c, G, u, wc, WG, p, hess, lagrange_iv, kappa, fpar, dt)
    j_keep, r_keep = -1, np.inf
    for j in range(min(keep, m)):
        r = _halves_rate(c, G, j, u, wc, WG, p, hess, lagrange_iv, kappa, fpar, dt)
        if r < r_keep:
            j_keep, r_keep = j, r
    lo, hi = Z.interval_hull(c, G)
    score = np.zeros(m)
    for j in range(keep, m):
        for i in range(n):
            w = hi[i] - lo[i]
            if w > 0.0:
                score[j] += abs(G[i, j]) / w
    order = np.argsort(-score)
    j_other, r_other = -1, np.inf
    for a in range(min(candidates, m - keep)):
        j = order[a]
        if score[j] <= 0.0:
            break
        r = _halves_rate(c, G, j, u, wc, WG, p, hess, lagrange_iv, kappa, fpar, dt)
        if r < r_other:
            j_other, r_other = j, r
    return rate, j_keep, r_keep, j_other, r_other
