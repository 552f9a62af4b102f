"""Layout of a tube whose branches have their own time steps (``algorithm="adaptive"``).

After a split, every piece (branch) of the set chooses its own steps.  The
tube's time intervals are the common refinement of all branches' steps; the
set over one of them is the union of, per live branch, the time-interval set
of the step that covers it.  Time-point sets are taken at the sample times
(every branch ends a step there) or, for a scalar horizon, at every step end
of any branch (a branch without a step end there contributes the
time-interval set that covers the time).

Sets are built lazily (:class:`PieceSets`): a run with many branches has many
more (interval, piece) pairs than a user will look at; bounds are computed
from the arrays directly.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from reachconf.errors import ReachError
from reachconf.timestamps import stamp_rounding
from reachconf_kernels import tube_layout as tl

__all__ = ["PieceSets", "PieceLayout", "piece_layout"]


def _as_ids(indices):
    ids = np.asarray(indices)
    return ids if ids.dtype.kind == "i" else ids.astype(np.int64)


class PieceSets(Sequence):
    """Read-only list of sets built on first access from groups of stored pieces.

    ``make(ids)`` returns the set of the pieces ``ids`` (one Zonotope or a union); ``indices`` is the
    CSR's column array or a function that returns it (called once, when a set is first asked for);
    ``polygons(dims)``, optional, draws :meth:`distinct_polygons` from the stored arrays; ``row(j)``,
    optional, gives the ids of entry ``j`` without the column array (for the first :attr:`ROW_LOOKUPS`
    entries asked for one by one: a final set, a set at one time).
    """

    #: entries looked up one by one (``row``) before the whole column array is built instead
    ROW_LOOKUPS = 256

    def __init__(self, indptr, indices, make, polygons=None, row=None):
        self._indptr = np.asarray(indptr, dtype=np.int64)
        self._row = row  # j -> piece ids of entry j, without the column array (a few entries asked for)
        self._lookups = 0
        self._polygons = polygons  # dims -> polygons of distinct_pieces(), computed from the stored arrays
        self._pending = indices if callable(indices) else None  # built on first use (PieceLayout's)
        self._ids = None if callable(indices) else _as_ids(indices)
        self._make = make
        self._cache = {}

    @property
    def _indices(self):
        if self._ids is None:
            self._ids = _as_ids(self._pending())
            self._pending = None
        return self._ids

    def __len__(self):
        return self._indptr.size - 1

    def __getitem__(self, j):
        if isinstance(j, slice):
            return [self[i] for i in range(*j.indices(len(self)))]
        j = int(j)
        if j < 0:
            j += len(self)
        if not 0 <= j < len(self):
            raise IndexError(j)
        out = self._cache.get(j)
        if out is None:
            if self._ids is None and self._row is not None and self._lookups < self.ROW_LOOKUPS:
                self._lookups += 1
                ids = self._row(j)
            else:
                ids = self._indices[self._indptr[j] : self._indptr[j + 1]]
            out = self._make(ids)
            self._cache[j] = out
        return out

    def __iter__(self):
        self._indices  # every entry: the column array at once
        for j in range(len(self)):
            yield self[j]

    def distinct_pieces(self) -> list:
        """Every stored piece once (a piece of a branch's long step serves several entries): for drawing."""
        out = []
        if np.any(np.diff(self._indptr) == 0):  # an entry that is not made of stored pieces (an adaptive tube's X0)
            out.extend(self._make(np.zeros(0, dtype=np.int64)).pieces)
        for i in np.unique(self._indices):
            out.extend(self._make(np.array([i], dtype=np.int64)).pieces)
        return out

    def distinct_polygons(self, dims) -> list:
        """The 2-D polygons (vertices (V, 2)) of :meth:`distinct_pieces` projected on ``dims``, in that order."""
        if self._polygons is not None:
            return self._polygons(dims)
        return [p.project(dims).polygon() for p in self.distinct_pieces()]

    def __reduce__(self):
        # pickled (to or from a worker process) as the plain list of its sets: ``make`` is a closure
        return (list, (list(self),))

    def groups(self):
        """``(indptr, indices)``: the pieces of every entry."""
        return self._indptr, self._indices


class PieceLayout:
    """Which stored pieces make up each set of the tube.

    ``ti_*``: CSR over the time intervals (piece ids of time-interval sets);
    ``tp_*``: CSR over the sample times 1.. (ids ``p`` of time-point pieces,
    ``P + p`` for a time-interval piece standing in at that time).  The row
    pointers are built at once; the column arrays (one entry per live branch
    and row: 10^7-10^8 after many splits) on first use
    (:attr:`ti_indices`, :attr:`tp_indices`, or the functions
    :attr:`ti_fill`, :attr:`tp_fill` for :class:`PieceSets`).
    :meth:`interval_hulls` needs neither.
    """

    def __init__(self, times, intervals, ti_indptr, tp_indptr, ti_fill, tp_fill, hulls, ti_distinct, tp_distinct,
                 ti_row, tp_row):  # fmt: skip
        self.times = times
        self.intervals = intervals
        self.ti_indptr = ti_indptr
        self.tp_indptr = tp_indptr
        self._fill = {"ti": ti_fill, "tp": tp_fill}
        self._built = {}
        self._hulls = hulls
        #: sorted ids of the pieces the time intervals (time points) list, without the lists
        self.ti_distinct = ti_distinct
        self.tp_distinct = tp_distinct
        #: ``j -> ids`` of one row, without the column arrays
        self.ti_row = ti_row
        self.tp_row = tp_row

    def _indices(self, which):
        if which not in self._built:
            self._built[which] = self._fill[which]()
        return self._built[which]

    def ti_fill(self):
        """The time intervals' column array (built once)."""
        return self._indices("ti")

    def tp_fill(self):
        """The time points' column array (built once)."""
        return self._indices("tp")

    @property
    def ti_indices(self):
        """The time intervals' column array (built on first use)."""
        return self.ti_fill()

    @property
    def tp_indices(self):
        """The time points' column array (built on first use)."""
        return self.tp_fill()

    def interval_hulls(self, lo, hi):
        """``(lo, hi)`` (intervals, n): per time interval the hull of its pieces' hulls ``lo, hi`` (P, n)."""
        return self._hulls(lo, hi)


_NO_MARK = np.zeros(0, dtype=np.bool_)


def _index_dtype(P):
    """32-bit piece ids where they fit (ids go up to ``2 P``): the index arrays can hold 10^8 entries."""
    return np.int32 if 2 * P + 1 < np.iinfo(np.int32).max else np.int64


def _csr(parts, count, P):
    """CSR of the pieces per row from ``(rows, ids)`` per branch (a branch's rows distinct; few pairs)."""
    counts = np.zeros(count + 1, dtype=np.int64)
    for rows, _ in parts:
        counts[rows + 1] += 1
    indptr = np.cumsum(counts)
    indices = np.empty(int(indptr[-1]), dtype=_index_dtype(P))
    fill = indptr[:-1].copy()
    for rows, ids in parts:
        indices[fill[rows]] = ids
        fill[rows] += 1
    return indptr, indices


def piece_layout(samples, scalar, t0, branches) -> PieceLayout:
    """Layout of the pieces of an adaptive run.

    Parameters
    ----------
    samples : ndarray (K,)
    scalar : bool
        The horizon was a number: time-point sets at every step end.
    t0 : ndarray (P,)
        Start time of every stored step (piece).
    branches : list
        Objects with ``t_begin``, ``t_end``, ``rec_lo``, ``rec_hi`` (their
        pieces) and ``sample_step`` (piece ending at each sample, -1 if none).
    """
    P = t0.size
    # the times are exact copies where they coincide (sample times, split times, a step's end and the next start):
    # merged only within a few ulps of their magnitude (it was 1e-12 of at least 1: 1.7 ms for Unix time stamps,
    # every step at time scales of 1e-12)
    tol = stamp_rounding(samples[0], samples[-1])
    live = [b for b in branches if b.rec_hi > b.rec_lo]
    starts = {b.index: t0[b.rec_lo : b.rec_hi] for b in live}
    ends = {b.index: np.append(t0[b.rec_lo + 1 : b.rec_hi], b.t_end) for b in live}
    raw = np.sort(np.concatenate([[samples[0], samples[-1]], *starts.values(), *ends.values()]))
    grid = tl.merged_grid(raw, tol)
    mids = 0.5 * (grid[:-1] + grid[1:])
    live = sorted(live, key=lambda b: b.rec_lo)  # rows list their pieces in increasing id
    rec_lo = np.array([b.rec_lo for b in live], dtype=np.int64)
    rec_hi = np.array([b.rec_hi for b in live], dtype=np.int64)
    t_begin = np.array([b.t_begin for b in live], dtype=float)
    t_end = np.array([b.t_end for b in live], dtype=float)
    # time intervals: a branch covers the mids strictly inside (t_begin, t_end)
    row_lo, row_hi = np.searchsorted(mids, t_begin, side="right"), np.searchsorted(mids, t_end, side="left")
    ti_indptr = tl.range_indptr(mids.size, row_lo, row_hi)
    ti_rows = (row_lo, row_hi)

    def ti_fill(used=_NO_MARK):
        indices = np.empty(0 if used.size else int(ti_indptr[-1]), dtype=_index_dtype(P))
        tl.fill_interval_pieces(ti_indptr, indices, mids, *ti_rows, rec_lo, rec_hi, t0, used)
        return indices

    def ti_distinct():
        used = np.zeros(P, dtype=np.bool_)
        ti_fill(used)
        return np.flatnonzero(used)

    def ti_row(j):  # the walk of fill_interval_pieces for row j alone
        ids = [rec_lo[b] + int(np.searchsorted(t0[rec_lo[b] : rec_hi[b]], mids[j], side="right")) - 1
               for b in np.flatnonzero((row_lo <= j) & (j < row_hi))]  # fmt: skip
        return np.array(ids, dtype=np.int64)

    def hulls(lo, hi):
        return tl.interval_hulls(mids.size, mids, *ti_rows, rec_lo, rec_hi, t0, lo, hi)

    if scalar:  # a time-point set at every step end of any branch: the times in (t_begin, t_end] (rows from 1)
        times = grid
        tp_lo = np.searchsorted(times, t_begin + tol, side="right") - 1
        tp_hi = np.searchsorted(times, t_end + tol, side="right") - 1
        tp_indptr = tl.range_indptr(times.size - 1, tp_lo, tp_hi)

        def tp_fill(used=_NO_MARK):
            indices = np.empty(0 if used.size else int(tp_indptr[-1]), dtype=_index_dtype(P))
            tl.fill_point_pieces(tp_indptr, indices, times, tp_lo, tp_hi, rec_lo, rec_hi, t_end, t0, tol, P, used)
            return indices

        def tp_distinct():
            used = np.zeros(2 * P, dtype=np.bool_)
            tp_fill(used)
            return np.flatnonzero(used)

        def tp_row(j):  # the walk of fill_point_pieces for row j alone
            T, ids = times[j + 1], []
            for b in np.flatnonzero((tp_lo <= j) & (j < tp_hi)):
                lo, n = rec_lo[b], rec_hi[b] - rec_lo[b]
                k = int(np.searchsorted(t0[lo + 1 : lo + n], T - tol, side="left"))
                e = t0[lo + k + 1] if k < n - 1 else t_end[b]
                ids.append(lo + k if abs(e - T) <= tol else P + lo + k)
            return np.array(ids, dtype=np.int64)
    else:  # at the sample times each branch reached (few: one per sample and live branch)
        times = samples
        parts = []
        for b in live:
            js = np.nonzero(b.sample_step >= 0)[0]
            js = js[js >= 1]
            parts.append((js - 1, b.sample_step[js]))
        tp_indptr, tp_indices = _csr(parts, times.size - 1, P)

        def tp_fill():
            return tp_indices

        def tp_distinct():
            return np.unique(tp_indices)

        def tp_row(j):
            return tp_indices[tp_indptr[j] : tp_indptr[j + 1]]
    if np.any(np.diff(ti_indptr) == 0) or np.any(np.diff(tp_indptr) == 0):
        raise ReachError("internal error: a time of the adaptive tube has no reachable set")
    return PieceLayout(times, np.column_stack([grid[:-1], grid[1:]]), ti_indptr, tp_indptr, ti_fill, tp_fill, hulls,
                       ti_distinct, tp_distinct, ti_row, tp_row)  # fmt: skip
