"""The result of :func:`reachconf.reach`: a tube of reachable sets over time."""

from __future__ import annotations

import io
import json
import zipfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from reachconf.errors import DataError, ReachError, SetError
from reachconf.io.atomic import atomic_write
from reachconf.model.outputs import output_enclosure
from reachconf.plot import plot_tube
from reachconf.reach_log import ReachLog
from reachconf.sets.convert import as_zonotope
from reachconf.sets.core import Interval, Zonotope
from reachconf.sets.union import SetUnion
from reachconf.timestamps import stamp_rounding
from reachconf.tube_pieces import PieceSets, piece_layout

__all__ = ["ReachTube", "SetUnion", "Containment"]


@dataclass
class Containment:
    """Result of :meth:`ReachTube.contains` (eqs. 42/43).

    Attributes
    ----------
    inside : ndarray of bool, (K,)
        Per sample: is the measurement inside the (output) reachable set ⊕ V.
    times : ndarray (K,)
    first_violation : int or None
        Index of the first sample outside, or None if all are inside.
    """

    inside: np.ndarray
    times: np.ndarray
    first_violation: int | None

    @property
    def conformant(self) -> bool:
        """Every measurement inside its set."""
        return bool(np.all(self.inside))

    @property
    def first_violation_time(self):
        """Time of the first measurement outside, or None."""
        return None if self.first_violation is None else float(self.times[self.first_violation])

    def __repr__(self):
        out = int(np.size(self.inside) - np.count_nonzero(self.inside))
        first = "" if self.first_violation is None else f", first outside at t = {self.first_violation_time:g} s"
        verdict = "conformant" if self.conformant else "not conformant"
        return f"Containment({verdict}: {out} of {np.size(self.inside)} samples outside{first})"


def _zono(c, G, ng):
    # kernel output (float64, right shapes): skip re-validation, it was a third of a short reach
    return Zonotope.from_kernel(np.array(c, dtype=np.float64), np.ascontiguousarray(G[:, :ng], dtype=np.float64))


class ReachTube:
    """Reachable sets of a model over time.

    Attributes
    ----------
    times : ndarray (K,)
        Sample times; ``time_point_sets[k]`` encloses the states at ``times[k]``.
    time_point_sets : list of Zonotope or SetUnion
    time_intervals : ndarray (S, 2)
        ``[t_start, t_end]`` of each integration step.
    time_interval_sets : list of Zonotope or SetUnion
        ``time_interval_sets[s]`` encloses the states over ``time_intervals[s]``.
    state_names : tuple of str
    splits : int
        Number of set splits that were needed.
    seconds : float
        Wall-clock time of the reach.
    keep_every : int
        1, or for a streamed reach (:func:`reachconf.reach_stream.reach_streamed`)
        the spacing of the steps whose sets were kept; ``bounds()`` still covers
        every step, ``at``/``contains`` only the kept times.
    log : ReachLog or None
        With ``algorithm="adaptive"``: the steps, orders and splits it chose
        (:meth:`summary` prints them).
    """

    def __init__(self, times, time_point_sets, time_intervals, time_interval_sets, state_names,
                 model=None, inputs=None, splits=0, seconds=0.0, meta=None, keep_every=1, step_bounds=None,
                 all_times=None, log=None):  # fmt: skip
        self.times = np.asarray(times, dtype=float)
        # an adaptive run's sets are built when first used (PieceSets)
        lazy = isinstance(time_point_sets, PieceSets)
        self.time_point_sets = time_point_sets if lazy else list(time_point_sets)
        self.time_intervals = np.asarray(time_intervals, dtype=float).reshape(-1, 2)
        lazy = isinstance(time_interval_sets, PieceSets)
        self.time_interval_sets = time_interval_sets if lazy else list(time_interval_sets)
        self.state_names = tuple(state_names)
        self.model = model
        self.inputs = None if inputs is None else np.asarray(inputs, dtype=float)
        self.splits = int(splits)
        self.seconds = float(seconds)
        self.meta = dict(meta or {})
        self.keep_every = int(keep_every)
        self.step_bounds = None if step_bounds is None else np.asarray(step_bounds, dtype=float)
        self.all_times = self.times if all_times is None else np.asarray(all_times, dtype=float)
        self.log = log

    # ----------------------------------------------------------- building
    @classmethod
    def from_run(cls, run, model) -> "ReachTube":
        """The tube of a finished :func:`reachconf.reach.reach_run` (a :class:`~reachconf.reach.ReachRun`)."""
        if getattr(run, "log", None) is not None:
            return cls.from_pieces(run, model)
        return cls.from_branches(model=model, samples=run.samples, step_offsets=run.step_offsets,
                                 t_start=run.t_start, dts=run.dts, X0=run.X0, branches=run.branches,
                                 options=run.options, W=run.W, splits=run.splits, seconds=run.seconds)  # fmt: skip

    @classmethod
    def from_branches(cls, *, model, samples, step_offsets, t_start, dts, X0, branches, options, W, splits, seconds):
        """The tube from the arrays of :func:`reachconf.reach.reach_run`'s branches (use :meth:`from_run`)."""
        S = dts.size
        ti_pieces = [[] for _ in range(S)]
        tp_pieces = [[] for _ in range(S)]
        for first, stop, store in branches:
            for k in range(first, stop):
                ti_pieces[k].append(_zono(store["ti_c"][k], store["ti_G"][k], store["ng_ti"][k]))
                tp_pieces[k].append(_zono(store["tp_c"][k], store["tp_G"][k], store["ng_tp"][k]))
        if any(not p for p in ti_pieces):
            raise ReachError("internal error: a time step has no reachable set")

        def one(pieces):
            return pieces[0] if len(pieces) == 1 else SetUnion(pieces)

        ti_sets = [one(p) for p in ti_pieces]
        tp_sets = [X0] + [one(tp_pieces[int(step_offsets[k]) - 1]) for k in range(1, samples.size)]
        intervals = np.column_stack([t_start, t_start + dts])
        meta = {"model": model.name, "options": {k: _plain(v) for k, v in options.__dict__.items()}}
        return cls(samples, tp_sets, intervals, ti_sets, model.state_names, model=model,
                   splits=splits, seconds=seconds, meta=meta)  # fmt: skip

    @classmethod
    def from_pieces(cls, run, model) -> "ReachTube":
        """The tube of an adaptive run (:class:`reachconf.reach_adaptive.AdaptiveRun`): branches with own steps.

        The layout is :func:`reachconf.tube_pieces.piece_layout`; sets (and the lists of their pieces)
        are built when first used, the bounds directly from the arrays.
        """
        from reachconf_kernels.adaptive import piece_hulls
        from reachconf_kernels.tube_layout import piece_polygons

        lay = piece_layout(run.samples, run.scalar, run.rec[:, 0], run.branches)
        P = run.rec.shape[0]
        off_tp = np.concatenate([[0], np.cumsum(run.ng_tp)])
        off_ti = np.concatenate([[0], np.cumsum(run.ng_ti)])

        def piece(p):
            if p < P:
                return _zono(run.tp_c[p], run.tp_G[:, off_tp[p] :], run.ng_tp[p])
            p -= P
            return _zono(run.ti_c[p], run.ti_G[:, off_ti[p] :], run.ng_ti[p])

        def make(ids):
            return piece(int(ids[0])) if ids.size == 1 else SetUnion([piece(int(p)) for p in ids])

        def plane(dims):  # checked here: the compiled call has no bounds checks
            dims = [int(d) for d in dims]
            if len(dims) != 2 or not all(0 <= d < len(model.state_names) for d in dims):
                raise SetError(f"polygons need two state indices in 0..{len(model.state_names) - 1}, got {dims!r}")
            return dims

        def polygons(c, G, off, ids, dims):
            V, starts = piece_polygons(c, G, off, np.ascontiguousarray(ids, dtype=np.int64), dims[0], dims[1])
            return np.split(V, starts[1:-1]) if ids.size else []

        def tp_polygons(dims):  # X0 first, then the distinct pieces in id order, as distinct_pieces()
            dims = plane(dims)
            ids = lay.tp_distinct()
            own, standing = ids[ids < P], ids[ids >= P] - P
            return ([p.project(dims).polygon() for p in run.X0.pieces]
                    + polygons(run.tp_c, run.tp_G, off_tp, own, dims)
                    + polygons(run.ti_c, run.ti_G, off_ti, standing, dims))  # fmt: skip

        # (no copies of the index arrays: entry 0 of tp is X0, an empty group; ti ids are offset by P in make)
        tp = PieceSets(np.concatenate([[0], lay.tp_indptr]), lay.tp_fill,
                       lambda ids: run.X0 if ids.size == 0 else make(ids), tp_polygons,
                       lambda j: np.zeros(0, dtype=np.int64) if j == 0 else lay.tp_row(j - 1))  # fmt: skip
        ti = PieceSets(lay.ti_indptr, lay.ti_fill, lambda ids: make(np.asarray(ids, dtype=np.int64) + P),
                       lambda dims: polygons(run.ti_c, run.ti_G, off_ti, lay.ti_distinct(), plane(dims)), lay.ti_row)  # fmt: skip
        meta = {"model": model.name, "options": {k: _plain(v) for k, v in run.options.__dict__.items()}}
        tube = cls(lay.times, tp, lay.intervals, ti, model.state_names, model=model, splits=run.splits,
                   seconds=run.seconds, meta=meta, log=run.log)  # fmt: skip
        lo, hi = piece_hulls(run.ti_c, np.ascontiguousarray(run.ti_G), run.ng_ti)
        tube.step_bounds = np.stack(lay.interval_hulls(lo, hi), axis=1)
        return tube

    def summary(self) -> str:
        """What the reach chose (steps, orders, splits over time, with "adaptive") and the tube's extent."""
        lines = [repr(self)]
        if self.log is not None:
            lines.append(self.log.summary())
        hull = self.interval_hull()
        lines.append("  hull: " + ", ".join(f"{nm} in [{a:.4g}, {b:.4g}]"
                                            for nm, a, b in zip(self.state_names, hull.lo, hull.hi)))  # fmt: skip
        return "\n".join(lines)

    # ------------------------------------------------------------ queries
    def __len__(self):
        return self.times.size

    def dim_indices(self, dims) -> list[int]:
        """State indices of ``dims`` (names or indices), checked (:class:`SetError` naming a bad one)."""
        if isinstance(dims, (str, int, np.integer)):
            dims = (dims,)
        if not hasattr(dims, "__iter__"):
            raise SetError(f"dims must be state names or indices, got {dims!r}")
        idx = []
        for d in dims:
            if isinstance(d, bool) or not isinstance(d, (str, int, np.integer)):
                raise SetError(f"dims must be state names or indices, got {d!r} in {dims!r}")
            if isinstance(d, str):
                if d not in self.state_names:
                    if d.strip().lstrip("+-").isdigit():  # an index given as text (the command line's --dims)
                        raise SetError(f"dimension {d.strip()} out of range 0..{len(self.state_names) - 1}")
                    raise SetError(f"unknown state {d!r}; states are {self.state_names}")
                idx.append(self.state_names.index(d))
            else:
                d = int(d)
                if not 0 <= d < len(self.state_names):
                    raise SetError(f"dimension {d} out of range 0..{len(self.state_names) - 1}")
                idx.append(d)
        return idx

    def at(self, t: float):
        """The set at time ``t``: the time-point set if ``t`` is a sample time, else the time-interval set."""
        try:
            t = float(t)
        except (TypeError, ValueError):
            raise DataError(f"ReachTube.at: t must be one time (a number), got {t!r}"[:200]) from None
        if not np.isfinite(t):
            raise ReachError(f"time {t} is outside the tube [{self.times[0]}, {self.times[-1]}]")
        # a time off a sample by its stamps' rounding (a few ulps) is that sample; any further off, it gets the
        # time-interval sets around it, which hold the state at every time of their step.  It was 1e-9 of the tube's
        # span: 1e-5 s on a 10,000-s tube, where a state moving at 1000 units/s left the sample's set it was given
        tol = stamp_rounding(t, self.all_times[0], self.all_times[-1])
        k = int(np.argmin(np.abs(self.times - t)))
        if abs(self.times[k] - t) <= tol:
            return self.time_point_sets[k]
        s = np.nonzero((self.time_intervals[:, 0] <= t + tol) & (self.time_intervals[:, 1] >= t - tol))[0]
        if s.size == 0 and self.keep_every > 1 and self.all_times[0] - tol <= t <= self.all_times[-1] + tol:
            raise ReachError(f"time {t}: this streamed tube keeps the sets of every {self.keep_every}th step only "
                             "(its bounds() cover every step); use reachconf.reach for all sets")  # fmt: skip
        if s.size == 0:
            raise ReachError(f"time {t} is outside the tube [{self.times[0]}, {self.times[-1]}]")
        sets = [self.time_interval_sets[i] for i in s]
        return sets[0] if len(sets) == 1 else SetUnion([p for st in sets for p in st.pieces])

    def project(self, dims) -> "ReachTube":
        """The tube projected onto some states (names or indices)."""
        idx = self.dim_indices(dims)
        return ReachTube(
            self.times,
            [s.project(idx) for s in self.time_point_sets],
            self.time_intervals,
            [s.project(idx) for s in self.time_interval_sets],
            [self.state_names[i] for i in idx],
            splits=self.splits,
            seconds=self.seconds,
            meta=self.meta,
            keep_every=self.keep_every,
            step_bounds=None if self.step_bounds is None else self.step_bounds[:, :, idx],
            all_times=self.all_times,
        )

    def interval_hull(self) -> Interval:
        """Box enclosing the whole tube (all time-interval sets)."""
        b = self.bounds()
        return Interval(b[:, 0, :].min(axis=0), b[:, 1, :].max(axis=0))

    def bounds(self) -> np.ndarray:
        """Interval hulls of the time-interval sets, shape (S, 2, n): ``[:, 0]`` lower, ``[:, 1]`` upper."""
        if self.step_bounds is not None:
            return self.step_bounds.copy()
        out = np.empty((len(self.time_interval_sets), 2, len(self.state_names)))
        for s, st in enumerate(self.time_interval_sets):
            iv = st.interval()
            out[s, 0], out[s, 1] = iv.lo, iv.hi
        return out

    def final_set(self):
        """The time-point set at the last sample time."""
        return self.time_point_sets[-1]

    # -------------------------------------------------------- conformance
    def output_sets(self, inputs=None):
        """Enclosures of ``h(R(t_k), u_k)`` for every sample time (without V)."""
        if self.model is None:
            raise ReachError("this tube has no model attached (loaded from a file); pass output=False")
        return [output_enclosure(self.model, s, None if inputs is None else inputs[k])
                for k, s in enumerate(self.time_point_sets)]  # fmt: skip

    def contains(self, times, Y, V=None, output=True, inputs=None, tol=1e-9) -> Containment:
        """Check eq. 42/43: ``Y(t_i) in h(R(t_i)) ⊕ V`` for each sample.

        Parameters
        ----------
        times : array_like (K,)
            Times of the measurements; each must be a sample time of the tube
            (otherwise the time-interval set containing it is used).
        Y : array_like (K, p)
            Measurements (outputs if ``output``, else states).
        V : Interval or Zonotope, optional
            Measurement-error set (additive).
        inputs : array_like (K, m), optional
            Known inputs at the sample times, needed if ``h`` depends on ``u``.
        tol : float
            Containment tolerance (zonotope norm <= 1 + tol).
        """
        try:
            times = np.asarray(times, dtype=float).reshape(-1)
            Y = np.asarray(Y, dtype=float)
            U = None if inputs is None else np.asarray(inputs, dtype=float)
        except (TypeError, ValueError):
            raise DataError("ReachTube.contains: times, Y and inputs must be numeric arrays") from None
        if Y.ndim == 1:
            Y = Y[:, None]
        if Y.ndim != 2:
            raise DataError(f"Y must be an array (K, p) of K measurements, got shape {Y.shape}")
        if U is not None and (U.ndim != 2 or U.shape[0] != times.size or (self.model is not None
                                                                          and U.shape[1] != self.model.m)):
            raise DataError(f"inputs must be an array (K, m) of the {times.size} times' inputs, got shape {U.shape}")
        if Y.shape[0] != times.size:
            raise DataError(f"Y has {Y.shape[0]} rows for {times.size} times")
        if not np.all(np.isfinite(Y)):
            raise DataError("Y contains NaN or inf")
        if output and self.model is None:
            raise ReachError("this tube has no model attached (loaded from a file), so its outputs are unknown: "
                             "check states (output=False), or compute the tube again with reachconf.reach")  # fmt: skip
        inside = np.zeros(times.size, dtype=bool)
        for i, t in enumerate(times):
            S = self.at(t)
            if output:
                u = None if U is None else U[i]
                S = output_enclosure(self.model, S, u)
            if V is not None:
                S = S + as_zonotope(V, name="V")
            if S.dim != Y.shape[1]:
                raise DataError(f"Y has {Y.shape[1]} columns, the set has dimension {S.dim}")
            inside[i] = bool(S.contains(Y[i], tol=tol))
        bad = np.nonzero(~inside)[0]
        return Containment(inside, times, int(bad[0]) if bad.size else None)

    # ------------------------------------------------------------- output
    def plot(self, ax=None, dims=None, color="C0", alpha=0.35, outline=True, label=None, measured=None):
        """Draw the 2-D projection: filled time-interval sets, outlined time-point sets, measured points.

        Parameters
        ----------
        ax : matplotlib Axes, optional
            New axes if None.
        dims : pair of str or int, optional
            States to draw (default: the first two).
        color, alpha, outline, label
            Style of the tube.
        measured : TestCase, array (K, 2), or a list of these, optional
            Measurements drawn on top (a case by its signals named ``dims``).

        Returns
        -------
        matplotlib Axes
        """
        if isinstance(ax, (tuple, list)):  # the old order plot(dims, ax)
            ax, dims = (dims if hasattr(dims, "add_collection") else None), ax
        return plot_tube(self, dims=dims, ax=ax, color=color, alpha=alpha, outline=outline, label=label,
                         measured=measured)  # fmt: skip

    def to_dict(self) -> dict:
        """A JSON-able summary: names, times, the interval hulls of the time-interval sets, metadata.

        The sets themselves are saved by :meth:`save` (``.npz``).
        """
        return {"state_names": list(self.state_names), "times": self.times.tolist(),
                "time_intervals": self.time_intervals.tolist(), "bounds": self.bounds().tolist(),
                "splits": self.splits, "seconds": self.seconds, "meta": self.meta}  # fmt: skip

    def to_json(self, path=None) -> str:
        """JSON text of :meth:`to_dict`; written atomically to ``path`` if given."""
        text = json.dumps({"result": "ReachTube", **self.to_dict()}, indent=2)
        if path is not None:
            atomic_write(path, text)
        return text

    def save(self, path) -> Path:
        """Write the tube to ``.npz`` atomically (sets, times, names, metadata)."""
        path = Path(path)
        arrays = {"times": self.times, "time_intervals": self.time_intervals,
                  "state_names": np.array(self.state_names, dtype=str)}  # fmt: skip
        for prefix, sets in (("tp", self.time_point_sets), ("ti", self.time_interval_sets)):
            cs, Gs, owner = [], [], []
            for k, s in enumerate(sets):
                for piece in s.pieces:
                    cs.append(piece.center)
                    Gs.append(piece.generators)
                    owner.append(k)
            gmax = max(G.shape[1] for G in Gs)
            G_arr = np.zeros((len(Gs), len(self.state_names), gmax))
            for i, G in enumerate(Gs):
                G_arr[i, :, : G.shape[1]] = G
            arrays[f"{prefix}_c"] = np.array(cs)
            arrays[f"{prefix}_G"] = G_arr
            arrays[f"{prefix}_ng"] = np.array([G.shape[1] for G in Gs])
            arrays[f"{prefix}_owner"] = np.array(owner)
        if self.step_bounds is not None:
            arrays["step_bounds"] = self.step_bounds
            arrays["all_times"] = self.all_times
        arrays["meta"] = np.array(json.dumps({**self.meta, "splits": self.splits, "seconds": self.seconds,
                                              "keep_every": self.keep_every}))  # fmt: skip
        if self.log is not None:
            arrays.update(self.log.to_arrays())
        buf = io.BytesIO()
        np.savez_compressed(buf, **arrays)
        return atomic_write(path, buf.getvalue())

    @classmethod
    def load(cls, path) -> "ReachTube":
        """Read a tube written by :meth:`save` (without the model)."""
        from reachconf.checks import require_file

        path = Path(path)
        require_file(path, "tube file")
        try:
            data = np.load(path, allow_pickle=False)
            sets = {}
            for prefix, count in (("tp", data["times"].size), ("ti", data["time_intervals"].shape[0])):
                pieces = [[] for _ in range(count)]
                for c, G, ng, k in zip(data[f"{prefix}_c"], data[f"{prefix}_G"], data[f"{prefix}_ng"],
                                       data[f"{prefix}_owner"]):  # fmt: skip
                    pieces[int(k)].append(Zonotope(c, G[:, : int(ng)]))
                sets[prefix] = [p[0] if len(p) == 1 else SetUnion(p) for p in pieces]
            meta = json.loads(str(data["meta"]))
            extra = {k: data[k] for k in ("step_bounds", "all_times") if k in data.files}
            log = ReachLog.from_arrays(data)
        except (KeyError, ValueError, OSError, EOFError, zipfile.BadZipFile) as exc:
            raise DataError(f"{path}: not a reachconf tube file ({exc})") from None
        return cls(data["times"], sets["tp"], data["time_intervals"], sets["ti"],
                   [str(s) for s in data["state_names"]], splits=meta.pop("splits", 0),
                   seconds=meta.pop("seconds", 0.0), keep_every=meta.pop("keep_every", 1), meta=meta,
                   log=log, **extra)  # fmt: skip

    def __repr__(self):
        chosen = ""
        if self.log is not None and self.log.steps:
            lg = self.log
            chosen = (f", adaptive: dt {lg.dt.min():.3g}..{lg.dt.max():.3g} s, tensor order "
                      f"{'/'.join(str(k) for k in sorted(set(int(v) for v in lg.tensor_order)))}, zonotope order "
                      f"{lg.zonotope_order.min():.3g}..{lg.zonotope_order.max():.3g}")  # fmt: skip
        return (f"ReachTube({len(self.times)} sample times from {self.times[0]:g} to {self.times[-1]:g} s, "
                f"{len(self.time_interval_sets)} steps, states {self.state_names}, splits={self.splits}{chosen})")


def _plain(v):
    if isinstance(v, (tuple, list)):
        return [_plain(x) for x in v]
    if isinstance(v, float) and not np.isfinite(v):
        return str(v)
    if v is None or isinstance(v, (bool, int, float, str)):
        return v
    return str(v)  # an algorithm or reduction method: its name
