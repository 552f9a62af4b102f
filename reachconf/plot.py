"""Drawing reach tubes with measurements (matplotlib, imported when drawing) and saving figures atomically."""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np

from reachconf.errors import DataError, SetError
from reachconf.io.atomic import atomic_write

__all__ = ["plot_tube", "plot_measured", "save_figure", "VerdictSummary"]


def plot_tube(tube, dims=None, ax=None, color="C0", alpha=0.35, outline=True, label=None, measured=None):
    """Draw a :class:`~reachconf.ReachTube` projected on two states, and measured points on top.

    Time-interval sets are filled polygons (one ``PolyCollection``), time-point
    sets are outlined.  One state (``dims`` a single name or index, or a
    one-state model's tube by default) is drawn against time: each
    time-interval set's bounds over its step.

    Parameters
    ----------
    tube : ReachTube
    dims : pair of str or int, or one str or int, optional
        States to draw (default: the first two; the only one of a one-state tube).
    ax : matplotlib Axes, optional
    color, alpha, outline, label
        Style of the tube.
    measured : TestCase, array (K, 2), or a list of these, optional
        Drawn as black dots by :func:`plot_measured`.

    Returns
    -------
    matplotlib Axes
    """
    import matplotlib.pyplot as plt
    from matplotlib.collections import PolyCollection

    if isinstance(dims, (str, int, np.integer)) or (dims is None and len(tube.state_names) == 1):
        return _plot_over_time(tube, tube.dim_indices((0,) if dims is None else (dims,))[0], ax, color, alpha,
                               label, measured)  # fmt: skip
    idx = tube.dim_indices(tuple(tube.state_names[:2]) if dims is None else dims)
    if len(idx) != 2:
        raise SetError(f"plot needs two dimensions (or one, drawn against time), got {dims!r}")
    if ax is None:
        _, ax = plt.subplots(figsize=(8, 5))
    polys = _polygons(tube.time_interval_sets, idx)
    ax.add_collection(PolyCollection(polys, facecolors=color, edgecolors="none", alpha=alpha, label=label))
    if outline:
        outs = _polygons(tube.time_point_sets, idx)
        ax.add_collection(PolyCollection(outs, facecolors="none", edgecolors=color, linewidths=0.4))
    allpts = np.vstack(polys)
    lo, hi = allpts.min(axis=0), allpts.max(axis=0)
    pad = 0.05 * np.maximum(hi - lo, 1e-9)
    ax.set_xlim(lo[0] - pad[0], hi[0] + pad[0])
    ax.set_ylim(lo[1] - pad[1], hi[1] + pad[1])
    names = [tube.state_names[i] for i in idx]
    ax.set_xlabel(names[0])
    ax.set_ylabel(names[1])
    if measured is not None:
        plot_measured(ax, measured, names)
    return ax


def _plot_over_time(tube, i, ax, color, alpha, label, measured):
    """One state against time: a rectangle per time-interval set (its bounds over its step), measurements as dots."""
    import matplotlib.pyplot as plt
    from matplotlib.collections import PolyCollection

    if ax is None:
        _, ax = plt.subplots(figsize=(8, 5))
    spans = np.asarray(tube.time_intervals, dtype=float).reshape(-1, 2)
    b = tube.bounds()  # the time-interval sets' hulls (stored for an adaptive tube)
    if b.shape[0] != spans.shape[0]:  # a streamed tube: the bounds of every step, the sets of every keep_every-th
        b = np.stack([np.stack([iv.lo, iv.hi]) for iv in (s.interval() for s in tube.time_interval_sets)])
    lo, hi = b[:, 0, i], b[:, 1, i]
    rects = [np.array([[a, l], [b, l], [b, h], [a, h]]) for (a, b), l, h in zip(spans, lo, hi)]
    ax.add_collection(PolyCollection(rects, facecolors=color, edgecolors="none", alpha=alpha, label=label))
    pad_t = 0.02 * max(spans[-1, 1] - spans[0, 0], 1e-9)
    pad_y = 0.05 * max(hi.max() - lo.min(), 1e-9)
    ax.set_xlim(spans[0, 0] - pad_t, spans[-1, 1] + pad_t)
    ax.set_ylim(lo.min() - pad_y, hi.max() + pad_y)
    name = tube.state_names[i]
    ax.set_xlabel("t")
    ax.set_ylabel(name)
    if measured is not None:
        items = measured if isinstance(measured, (list, tuple)) else [measured]
        # a case's clock is moved to the tube's (a reach runs from the case's first sample, often from t = 0)
        points = [np.column_stack([c.t - c.t[0] + spans[0, 0], c.signal(name)]) for c in items
                  if hasattr(c, "signals") and name in c.signals]  # fmt: skip
        if points:
            plot_measured(ax, points, ("t", name))
    return ax


def _polygons(sets, idx):
    """Polygons of the pieces of a list of sets on ``idx``; each stored piece once where the list shares them
    (an adaptive tube's, drawn from its stored arrays)."""
    distinct = getattr(sets, "distinct_polygons", None)
    if distinct is not None:
        return distinct(idx)
    return [p.project(idx).polygon() for s in sets for p in s.pieces]


def plot_measured(ax, measured, dims, label="measured", **style):
    """Draw measured points on an X-Y plot: black dots, one legend entry for all.

    Parameters
    ----------
    ax : matplotlib Axes
    measured : TestCase, array (K, 2), or a list of these
        A test case contributes its signals named ``dims`` (and nothing if it
        lacks them, e.g. states that are not measured).
    dims : pair of str
        Signal names of the two axes.
    label : str
        Legend entry (given once per axes).
    **style
        Passed to ``ax.plot`` (default ``"k."``, ``ms=1.5``).

    Returns
    -------
    matplotlib Axes
    """
    items = measured if isinstance(measured, (list, tuple)) else [measured]
    style = {"marker": ".", "ls": "none", "color": "k", "ms": 1.5, **style}
    if label in ax.get_legend_handles_labels()[1]:
        label = None  # one legend entry per label, however many calls draw it
    for item in items:
        if hasattr(item, "signals"):
            if not all(d in item.signals for d in dims):
                continue
            xy = np.column_stack([item.signal(dims[0]), item.signal(dims[1])])
        else:
            xy = np.asarray(item, dtype=float)
            if xy.ndim != 2 or xy.shape[1] != 2:
                raise DataError(f"measured points must have shape (K, 2), got {xy.shape}")
        ax.plot(xy[:, 0], xy[:, 1], label=label, **style)
        label = None
    return ax


def save_figure(fig, path, dpi=130, **savefig):
    """Save a figure atomically (rendered to memory, then :func:`reachconf.io.atomic_write`).

    Parameters
    ----------
    fig : matplotlib.figure.Figure
    path : path-like
        The format follows the suffix (``.png``, ``.pdf``, ``.svg``).
    dpi : int, default 130
    **savefig
        Further arguments of ``Figure.savefig`` (default ``bbox_inches="tight"``).

    Returns
    -------
    Path
    """
    path = Path(path)
    savefig.setdefault("bbox_inches", "tight")
    buf = io.BytesIO()
    fig.savefig(buf, format=path.suffix.lstrip(".") or "png", dpi=dpi, **savefig)
    return atomic_write(path, buf.getvalue())


class VerdictSummary:
    """The per-case verdicts of ``reachconf conform`` (its ``conformance.json``), drawn by ``reachconf plot``.

    Parameters
    ----------
    entries : dict
        Case name -> ``{"trace": {...}, "reachset": {...}}`` (either or both), each with its ``"verdict"``.
    """

    KINDS = ("trace", "reachset")
    COLORS = {"conformant": "#4daf4a", "not_conformant": "#e41a1c", "undecided": "#bdbdbd"}

    def __init__(self, entries: dict):
        self.entries = dict(entries)

    @classmethod
    def from_dict(cls, d: dict):
        """The summary if ``d`` is a ``conformance.json`` of ``reachconf conform``, else None."""
        def number(v):
            return v is None or (isinstance(v, (int, float)) and not isinstance(v, bool))

        def entry(v):  # a verdict, and the margins or first violation _detail reads
            return (isinstance(v, dict) and v.get("verdict") in cls.COLORS
                    and isinstance(v.get("margins", {}), dict) and all(map(number, v.get("margins", {}).values()))
                    and number(v.get("first_violation_time")))  # fmt: skip

        ok = bool(d) and all(isinstance(e, dict) and e and set(e) <= set(cls.KINDS) and all(map(entry, e.values()))
                             for e in d.values())  # fmt: skip
        return cls(d) if ok else None

    @staticmethod
    def _detail(kind: str, e: dict) -> str:
        if kind == "trace":
            known = {k: v for k, v in (e.get("margins") or {}).items() if v is not None}
            if not known:
                return ""
            ch = min(known, key=known.get)
            return f"smallest margin {ch}: {known[ch]:.3g}"
        t = e.get("first_violation_time")
        return "" if t is None else f"leaves the reach at t = {t:g} s"

    def plot(self, ax=None):
        """One row per case, one column per kind of conformance, coloured by verdict; returns the Axes."""
        import matplotlib.pyplot as plt
        from matplotlib.patches import Patch

        names = list(self.entries)
        kinds = [k for k in self.KINDS if any(k in e for e in self.entries.values())]
        if ax is None:
            _, ax = plt.subplots(figsize=(4.5 * len(kinds) + 2, min(40.0, 1.2 + 0.35 * len(names))))
        for i, name in enumerate(names):
            for j, kind in enumerate(kinds):
                e = self.entries[name].get(kind)
                if e is None:
                    continue
                ax.add_patch(plt.Rectangle((j, i), 1, 1, color=self.COLORS[e["verdict"]], ec="white"))
                ax.text(j + 0.5, i + 0.5, self._detail(kind, e), ha="center", va="center", fontsize=7)
        ax.set_xlim(0, len(kinds))
        ax.set_ylim(len(names), 0)
        ax.set_xticks(np.arange(len(kinds)) + 0.5, kinds)
        ax.set_yticks(np.arange(len(names)) + 0.5, names)
        ax.tick_params(length=0)
        ax.legend(handles=[Patch(color=c, label=v.replace("_", " ")) for v, c in self.COLORS.items()],
                  loc="upper left", bbox_to_anchor=(1.0, 1.0), fontsize=8)  # fmt: skip
        ax.set_title("conformance per case")
        ax.figure.tight_layout()
        return ax
