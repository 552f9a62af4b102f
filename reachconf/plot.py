"""Drawing reach tubes (matplotlib, imported when drawing) and saving figures atomically."""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np

from reachconf.errors import SetError
from reachconf.io.atomic import atomic_write

__all__ = ["plot_tube", "save_figure"]


def plot_tube(tube, dims=("X", "Y"), ax=None, color="C0", alpha=0.35, outline=True, label=None):
    """Draw a :class:`~reachconf.ReachTube` projected on two states.

    Time-interval sets are filled polygons (one ``PolyCollection``), time-point
    sets are outlined.  Returns the axes.
    """
    import matplotlib.pyplot as plt
    from matplotlib.collections import PolyCollection

    idx = tube.dim_indices(dims)
    if len(idx) != 2:
        raise SetError(f"plot needs two dimensions, got {dims!r}")
    if ax is None:
        _, ax = plt.subplots(figsize=(8, 5))
    polys = [p.project(idx).polygon() for s in tube.time_interval_sets for p in s.pieces]
    ax.add_collection(PolyCollection(polys, facecolors=color, edgecolors="none", alpha=alpha, label=label))
    if outline:
        outs = [p.project(idx).polygon() for s in tube.time_point_sets for p in s.pieces]
        ax.add_collection(PolyCollection(outs, facecolors="none", edgecolors=color, linewidths=0.4))
    allpts = np.vstack(polys)
    lo, hi = allpts.min(axis=0), allpts.max(axis=0)
    pad = 0.05 * np.maximum(hi - lo, 1e-9)
    ax.set_xlim(lo[0] - pad[0], hi[0] + pad[0])
    ax.set_ylim(lo[1] - pad[1], hi[1] + pad[1])
    names = [tube.state_names[i] for i in idx]
    ax.set_xlabel(names[0])
    ax.set_ylabel(names[1])
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
