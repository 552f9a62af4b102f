"""Plotting helpers (matplotlib, imported lazily)."""

from __future__ import annotations

import numpy as np

__all__ = ["plot_tube", "save_figure"]


def _pieces(s):
    from reachconf.tube import SetUnion

    return s.pieces if isinstance(s, SetUnion) else (s,)


def plot_tube(tube, dims=("X", "Y"), ax=None, color="C0", alpha=0.35, outline=True, label=None):
    """Draw a :class:`~reachconf.ReachTube` projected on two states.

    Time-interval sets are filled polygons (one ``PolyCollection``), time-point
    sets are outlined.
    """
    import matplotlib.pyplot as plt
    from matplotlib.collections import PolyCollection

    idx = tube._dims(dims)
    if len(idx) != 2:
        from reachconf.errors import SetError

        raise SetError(f"plot needs two dimensions, got {dims!r}")
    if ax is None:
        _, ax = plt.subplots(figsize=(8, 5))
    polys = [p.project(idx).polygon() for s in tube.time_interval_sets for p in _pieces(s)]
    ax.add_collection(PolyCollection(polys, facecolors=color, edgecolors="none", alpha=alpha, label=label))
    if outline:
        outs = [p.project(idx).polygon() for s in tube.time_point_sets for p in _pieces(s)]
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


def save_figure(fig, path, dpi=130):
    """Save a figure atomically (write to a temporary file, then rename)."""
    import os
    import tempfile
    from pathlib import Path

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=path.stem, suffix=path.suffix)
    os.close(fd)
    fig.savefig(tmp, dpi=dpi, bbox_inches="tight")
    os.replace(tmp, path)
    return path
