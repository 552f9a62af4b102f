"""Which stored pieces make up each set of an adaptive tube (:mod:`reachconf.tube_pieces`), as CSR arrays.

An adaptive run's branches each have their own steps; the tube's time
intervals are the common refinement of all of them, and the set over one
interval is the union of, per live branch, the piece (step) covering it.  With
hundreds of live branches over 10^5 intervals there are 10^7-10^8 (interval,
piece) pairs (Van der Pol mu = 2: 77 million), so they are counted and
filled here in place, branch after branch, walking each branch's steps along
the sorted times (no sort, no per-pair temporaries) — and only when a set is
asked for: the interval hulls per time interval, which every tube carries,
come from the same walk without storing the pairs (:func:`interval_hulls`).
Within a row the pieces keep the order of the branches given (the caller
sorts them by their first piece, so ids increase).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from reachconf_kernels.zonotope import compact
from reachconf_kernels.zonotope_polygon import polygon

__all__ = ["merged_grid", "range_indptr", "fill_interval_pieces", "fill_point_pieces", "csr_hulls", "interval_hulls",
           "piece_polygons"]


@njit(cache=True)
def merged_grid(raw, tol):
    """The sorted times ``raw`` without those within ``tol`` of the last one kept (the last time always kept).

    Compared with the last time *kept*, not with the previous one: a run of steps each shorter than ``tol``
    is merged into steps of at least ``tol``, not dropped as a whole (which left the tube's last 3.5 ms
    without a time-interval set when ``tol`` was 1e-12 of Unix time stamps).
    """
    keep = np.zeros(raw.size, dtype=np.bool_)
    last = 0
    keep[0] = True
    for i in range(1, raw.size):
        if raw[i] - raw[last] > tol:
            keep[i] = True
            last = i
    if raw.size > 1 and last != raw.size - 1:  # the end within tol of a kept time: the end replaces it
        keep[last] = last == 0
        keep[raw.size - 1] = True
    return raw[keep]


@njit(cache=True)
def range_indptr(count, row_lo, row_hi):
    """CSR row pointer (count + 1,) when branch ``b`` covers the rows from ``row_lo[b]`` up to ``row_hi[b]`` (excl.)."""
    diff = np.zeros(count + 1, dtype=np.int64)
    for b in range(row_lo.size):
        if row_hi[b] > row_lo[b]:
            diff[row_lo[b]] += 1
            diff[row_hi[b]] -= 1
    indptr = np.zeros(count + 1, dtype=np.int64)
    run = 0
    for j in range(count):
        run += diff[j]
        indptr[j + 1] = indptr[j] + run
    return indptr


@njit(cache=True)
def fill_interval_pieces(indptr, indices, mids, row_lo, row_hi, rec_lo, rec_hi, t0, used):
    """Fill ``indices``: for each row ``j`` of branch ``b``, its step covering ``mids[j]``.

    That is the last of the branch's pieces (ids from ``rec_lo[b]`` up to ``rec_hi[b]``, excl.; start times
    ``t0``) starting at or before it.  ``used`` (bool, ids), unless empty, marks every id listed; with
    ``indices`` empty only that is done.
    """
    store, mark = indices.size > 0, used.size > 0
    fill = indptr[:-1].copy()
    for b in range(row_lo.size):
        p = rec_lo[b]
        for j in range(row_lo[b], row_hi[b]):
            while p + 1 < rec_hi[b] and t0[p + 1] <= mids[j]:
                p += 1
            if store:
                indices[fill[j]] = p
                fill[j] += 1
            if mark:
                used[p] = True


@njit(cache=True)
def fill_point_pieces(indptr, indices, times, row_lo, row_hi, rec_lo, rec_hi, t_end, t0, tol, P, used):
    """Fill ``indices``: for row ``j`` (the time ``times[j + 1]``) of branch ``b``, the step ending then.

    Its id, or, when no step of the branch ends then, the step covering the time (id ``P + step``: its
    time-interval set stands in).  ``used`` as in :func:`fill_interval_pieces` (``2 P`` ids).
    """
    store, mark = indices.size > 0, used.size > 0
    fill = indptr[:-1].copy()
    for b in range(row_lo.size):
        lo = rec_lo[b]
        n = rec_hi[b] - lo
        k = 0
        for j in range(row_lo[b], row_hi[b]):
            T = times[j + 1]
            while k < n - 1 and t0[lo + k + 1] < T - tol:  # end of step k: t0 of the next, t_end for the last
                k += 1
            e = t0[lo + k + 1] if k < n - 1 else t_end[b]
            q = lo + k if abs(e - T) <= tol else P + lo + k
            if store:
                indices[fill[j]] = q
                fill[j] += 1
            if mark:
                used[q] = True


@njit(cache=True, inline="always")  # called once per (row, piece) pair: 10^8 times
def _widen(out_lo, out_hi, j, lo, hi, p):
    """Row ``j`` of the hull ``out_lo, out_hi`` widened by piece ``p``'s hull."""
    for i in range(lo.shape[1]):
        if lo[p, i] < out_lo[j, i]:
            out_lo[j, i] = lo[p, i]
        if hi[p, i] > out_hi[j, i]:
            out_hi[j, i] = hi[p, i]


@njit(cache=True)
def csr_hulls(indptr, indices, lo, hi):
    """Interval hull per row of the pieces it lists, from every piece's hull ``lo, hi`` (P, n)."""
    count = indptr.size - 1
    n = lo.shape[1]
    out_lo = np.full((count, n), np.inf)
    out_hi = np.full((count, n), -np.inf)
    for j in range(count):
        for q in range(indptr[j], indptr[j + 1]):
            _widen(out_lo, out_hi, j, lo, hi, indices[q])
    return out_lo, out_hi


@njit(cache=True)
def interval_hulls(count, mids, row_lo, row_hi, rec_lo, rec_hi, t0, lo, hi):
    """Interval hull per row of the pieces covering it, by the walk of :func:`fill_interval_pieces`.

    The same as :func:`csr_hulls` on the CSR that :func:`fill_interval_pieces` fills (``count`` rows;
    per piece the hull ``lo, hi`` (P, n)), without storing the (row, piece) pairs.
    """
    n = lo.shape[1]
    out_lo = np.full((count, n), np.inf)
    out_hi = np.full((count, n), -np.inf)
    for b in range(row_lo.size):
        p = rec_lo[b]
        for j in range(row_lo[b], row_hi[b]):
            while p + 1 < rec_hi[b] and t0[p + 1] <= mids[j]:
                p += 1
            _widen(out_lo, out_hi, j, lo, hi, p)
    return out_lo, out_hi


@njit(cache=True)
def piece_polygons(c, G, off, ids, i0, i1):
    """Vertices of the 2-D projections (dimensions ``i0, i1``) of the stored sets ``ids``, for drawing.

    Set ``p``: centre ``c[p]``, generators the columns ``off[p]`` to ``off[p + 1]`` (excl.) of ``G``.  Each is
    compacted (:func:`~reachconf_kernels.zonotope.compact`, tol 0) and turned into its polygon
    (:func:`~reachconf_kernels.zonotope_polygon.polygon`; a point without generators), as ``Zonotope.polygon`` does.
    Returns ``(V, starts)``: the vertices of set ``ids[k]`` are ``V[starts[k]:starts[k + 1]]``.
    """
    cap = 0
    for k in range(ids.size):
        cap += 2 * (off[ids[k] + 1] - off[ids[k]]) + 8  # compact may add 2 generators, the polygon's margin 2
    V = np.empty((cap, 2))
    starts = np.zeros(ids.size + 1, dtype=np.int64)
    pos = 0
    for k in range(ids.size):
        p = ids[k]
        m = off[p + 1] - off[p]
        cz = np.array([c[p, i0], c[p, i1]])
        Gz = np.empty((2, m))
        for j in range(m):
            Gz[0, j] = G[i0, off[p] + j]
            Gz[1, j] = G[i1, off[p] + j]
        cc, Gc = compact(cz, Gz, 0.0)
        if Gc.shape[1] == 0:
            V[pos] = cc
            pos += 1
        else:
            P = polygon(cc, Gc)
            V[pos : pos + P.shape[0]] = P
            pos += P.shape[0]
        starts[k + 1] = pos
    return V[:pos], starts
