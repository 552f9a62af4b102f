"""Saved conformance results read back: shape checks and plots of synthesis and Pareto-front JSON.

A file given to ``reachconf plot`` may be anything; these checks turn every
wrong shape (a list or number instead of an object, ``"front": 5``, boxes of
the wrong size, ``null`` where a number belongs) into a
:class:`~reachconf.errors.DataError` naming the file and the key, before
anything is drawn.
"""

from __future__ import annotations

import numpy as np

from reachconf.errors import DataError

__all__ = ["result_kind", "check_synthesis_dict", "check_front_dict", "plot_synthesis_dict"]


def _is_number(v) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool) and np.isfinite(v)


def _check_names(d, where) -> list:
    names = d.get("disturbances")
    if not (isinstance(names, list) and names and all(isinstance(n, str) for n in names)):
        raise DataError(f"{where}: 'disturbances' must be a non-empty list of names, got {names!r}"[:300])
    return names


def _check_box(box, q, where):
    ok = (isinstance(box, list) and len(box) == q
          and all(isinstance(p, list) and len(p) == 2 and all(_is_number(v) for v in p) for p in box))  # fmt: skip
    if not ok:
        raise DataError(f"{where}: must be {q} [lo, hi] pairs of finite numbers, got {box!r}"[:300])


def result_kind(d, where) -> str:
    """``"synthesis"`` or ``"pareto"`` for a loaded JSON value, else DataError naming ``where``."""
    if not isinstance(d, dict):
        raise DataError(f"{where}: expected a JSON object (a saved result), got a {type(d).__name__}")
    if "groups" in d and "disturbances" in d:
        return "synthesis"
    if "front" in d:
        return "pareto"
    raise DataError(f"{where}: not a synthesis or Pareto-front result (keys {sorted(d)[:6]})")


def check_synthesis_dict(d, where) -> dict:
    """Check a :meth:`SynthesisResult.to_dict` value read from a file (DataError naming ``where``)."""
    names = _check_names(d, where)
    groups = d.get("groups")
    if not isinstance(groups, dict) or not groups:
        raise DataError(f"{where}: 'groups' must be a non-empty object of boxes, got {groups!r}"[:300])
    for g, box in groups.items():
        _check_box(box, len(names), f"{where}: groups[{g!r}]")
    return d


def check_front_dict(d, where) -> dict:
    """Check a :meth:`ParetoFront.to_dict` value read from a file (DataError naming ``where``)."""
    names = _check_names(d, where)
    _check_box(d.get("start"), len(names), f"{where}: 'start'")
    front = d.get("front")
    if not isinstance(front, list):
        raise DataError(f"{where}: 'front' must be a list of boxes, got {front!r}"[:300])
    for k, entry in enumerate(front):
        if not isinstance(entry, dict):
            raise DataError(f"{where}: front[{k}] must be an object with 'box' and 'order'")
        _check_box(entry.get("box"), len(names), f"{where}: front[{k}].box")
    if not isinstance(d.get("check", ""), str):
        raise DataError(f"{where}: 'check' must be a string")
    return d


def plot_synthesis_dict(d):
    """``W_RC,Mnvr`` per group (one panel per disturbance) from :meth:`SynthesisResult.to_dict`; the figure."""
    import matplotlib.pyplot as plt

    names = d["disturbances"]
    fig, axes = plt.subplots(1, len(names), figsize=(2.2 * len(names), 3), squeeze=False)
    for j, name in enumerate(names):
        ax = axes[0, j]
        for i, (g, box) in enumerate(d["groups"].items()):
            ax.plot([i, i], box[j], lw=6, solid_capstyle="butt", label=g)
        ax.set_title(name)
        ax.set_xticks(range(len(d["groups"])), list(d["groups"]), rotation=45, fontsize=7)
    fig.suptitle("W_RC per group")
    fig.tight_layout()
    return fig
