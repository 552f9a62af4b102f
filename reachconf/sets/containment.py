"""Batch point containment in zonotopes, exact up to a stated tolerance.

A point ``p`` is inside ``Z(c, G)`` iff some ``b`` with ``|b|_inf <= 1 + tol``
satisfies ``|(G b - (p - c))_i| <= tol * s_i`` in every row, with
``s_i = max(sum_j |G_ij|, 1e-5 max(|c_i|, |p_i|))`` (the zonotope norm
with a small slack so that degenerate zonotopes are handled; relative to the
set's extent and the numbers' magnitude in each coordinate, so that a set of
tiny numbers, or a coordinate of tiny numbers beside large ones, is not
swallowed by it; the tests run on the problem with row ``i`` divided by ``s_i``).  Strategy for many points: reject outside the interval hull,
in 2-D use the half-spaces normal to the generators, otherwise run the compiled simplex of
:mod:`reachconf_kernels.containment`, whose every answer carries a checked
certificate (a coefficient vector inside, a separating direction outside);
points without a certificate are decided by one LP each (HiGHS via scipy),
the reference method.
"""

from __future__ import annotations

import numpy as np

from reachconf_kernels.containment import REL_MAGNITUDE, contains_batch

__all__ = ["contains_points", "contains_points_lp"]


# HiGHS' default feasibility tolerance (1e-7) is far looser than the containment tolerance
_LP_OPTIONS = {"primal_feasibility_tolerance": 1e-10, "dual_feasibility_tolerance": 1e-10}


def contains_points_lp(c, G, P, tol=1e-9):
    """Reference: one LP per point (``min t`` s.t. ``|G b - d| <= slack``, ``|b| <= t``)."""
    from scipy.optimize import linprog

    n, m = G.shape
    c, G, P, _ = _normalized(c, G, P)
    slack = tol
    out = np.zeros(P.shape[0], dtype=bool)
    if m == 0:
        return np.all(np.abs(P - c) <= slack, axis=1)
    cost = np.zeros(m + 1)
    cost[-1] = 1.0
    A_ub = np.vstack([
        np.hstack([G, np.zeros((n, 1))]),
        np.hstack([-G, np.zeros((n, 1))]),
        np.hstack([np.eye(m), -np.ones((m, 1))]),
        np.hstack([-np.eye(m), -np.ones((m, 1))]),
    ])  # fmt: skip
    for k, p in enumerate(P):
        d = p - c
        b_ub = np.concatenate([d + slack, -d + slack, np.zeros(2 * m)])
        res = linprog(cost, A_ub=A_ub, b_ub=b_ub, bounds=[(None, None)] * m + [(0, None)], method="highs",
                      options=_LP_OPTIONS)  # fmt: skip
        out[k] = res.status == 0 and res.x[-1] <= 1.0 + tol
    return out


def _contains_2d(c, G, P, tol):
    """The 2-D test by half-spaces: one facet normal per non-zero generator (``None`` if degenerate: the LP decides).

    The facets of a 2-D zonotope are normal to its generators, so ``|n_j . (p - c)| <= sum_k |n_j . g_k|`` for
    every generator ``g_j`` (and the interval hull, checked before) is exact; widened as the tolerance widens the
    set: ``(1 + tol) Z`` plus the box ``tol`` (in the units of :func:`_normalized`).  (The polygon of the compacted
    generators it used before merged near-parallel ones and boxed the rest: 2-D points up to 70 % of a thin set's
    width outside were "inside".)
    """
    GG = G[:, np.any(G != 0.0, axis=0)]
    m = GG.shape[1]
    if m < 2 or np.linalg.matrix_rank(GG) < 2:
        return None  # degenerate: let the LP decide
    N = np.column_stack([GG[1], -GG[0]]) / np.hypot(GG[0], GG[1])[:, None]
    NG = np.abs(N @ GG)
    h = NG.sum(axis=1)
    dist = np.abs((P - c) @ N.T)
    # rounding of the dot products and sums (a few ulps of the terms' magnitudes; far below any tolerance in use)
    rnd = 8 * np.finfo(float).eps * (m + 2) * (h + np.abs(N) @ np.abs(P - c).T.max(axis=1, initial=0.0))
    return np.all(dist <= h * (1 + tol) + tol * np.abs(N).sum(axis=1) + rnd, axis=1)


def _normalized(c, G, P):
    """``(0, G / s, (P - c) / s, s)``: the problem in units of its tolerance scale (module docstring).

    ``s`` holds one number per coordinate for all points: the largest of their
    scales in it (the points that matter lie in the set's interval hull, whose
    scales barely differ; one far away is rejected by the hull either way).
    ``s_i = 0`` (the coordinate all zero) becomes the smallest float: a point off 0 there is outside.
    """
    c = np.asarray(c, dtype=float)
    G = np.asarray(G, dtype=float)
    P = np.atleast_2d(np.asarray(P, dtype=float))
    r = np.sum(np.abs(G), axis=1)
    near = np.all(np.abs(P - c) <= 2.0 * r + REL_MAGNITUDE * np.abs(c), axis=1)
    mag = np.maximum(np.abs(c), np.max(np.abs(P[near]), axis=0) if near.any() else 0.0)
    s = np.maximum(r, REL_MAGNITUDE * mag)
    # a coordinate all zero (no extent, centre 0, no point near but at 0): any point off 0 is outside, as the scale
    # 1e-5 |p_i| of the module docstring says; the smallest float keeps the quotient finite in sign and order
    s[s == 0.0] = np.nextafter(0.0, 1.0)
    with np.errstate(over="ignore"):  # (a point off 0 there: +-inf, outside)
        return np.zeros_like(c), G / s[:, None], (P - c) / s, s


def contains_points(c, G, P, tol=1e-9):
    """Boolean per row of ``P``: is the point in ``Z(c, G)`` (up to ``tol``, see module docstring)."""
    c = np.asarray(c, dtype=float)
    G = np.asarray(G, dtype=float)
    P = np.atleast_2d(np.asarray(P, dtype=float))
    c0, Gn, D, _ = _normalized(c, G, P)  # the hull and the half-spaces in units of the tolerance scale
    N = P.shape[0]
    n, m = G.shape
    r = np.sum(np.abs(Gn), axis=1)
    out = np.zeros(N, dtype=bool)
    cand = np.all(np.abs(D) <= r * (1 + tol) + tol, axis=1)
    if not cand.any():
        return out
    if m == 0:
        out[cand] = True
        return out
    if n == 2:
        res = _contains_2d(c0, Gn, D[cand], tol)
        if res is not None:
            out[np.nonzero(cand)[0]] = res
            return out
    idx = np.nonzero(cand)[0]
    status = contains_batch(np.ascontiguousarray(c), np.ascontiguousarray(G), np.ascontiguousarray(P[idx]), float(tol))
    out[idx[status == 1]] = True
    rest = idx[status == -1]
    if rest.size:  # no certificate: decide with the reference LP
        out[rest] = contains_points_lp(c, G, P[rest], tol)
    return out
