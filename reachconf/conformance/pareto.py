"""Pareto front of conformant disturbance boxes (beyond the report, section 4.3.2's outlook).

A single α (eq. 68) scales every channel of the box together, giving one
point of the Pareto front of conformant models.  Shrinking one channel at a
time while the others stay fixed, in different channel orders, gives
further boxes that are each conformant and none of which is wider than
another in every channel: a sampled Pareto front.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from reachconf.checks import check_options, check_workers
from reachconf.conformance.synthesis import SynthesisOptions, reachset_check
from reachconf.conformance.trace import trace_conformance
from reachconf.errors import ConformanceError, OptionsError
from reachconf.io.cases import suite_cases
from reachconf.io.results import JsonResult
from reachconf.model.core import require_model
from reachconf.runner import run_cases
from reachconf.sets.convert import as_box
from reachconf.sets.core import Interval

__all__ = ["ParetoFront", "pareto_front", "plot_front_dict"]


@dataclass
class ParetoFront(JsonResult):
    """Non-dominated conformant boxes.

    Attributes
    ----------
    boxes : list of Interval
        Each conformant for every case of the suite.
    orders : list of tuple of int
        Channel order of the search that produced each box.
    start : Interval
        The conformant box the searches started from.
    disturbance_names : tuple of str
    check : str
        "reachset" or "trace".
    """

    boxes: list
    orders: list
    start: Interval
    disturbance_names: tuple
    check: str

    @property
    def widths(self) -> np.ndarray:
        """(number of boxes, q) channel widths."""
        return np.array([b.hi - b.lo for b in self.boxes])

    def to_dict(self):
        """Channel names, the start box and the front (each box with its channel order)."""
        return {"disturbances": list(self.disturbance_names), "check": self.check, "start": self.start.to_list(),
                "front": [{"box": b.to_list(), "order": list(o)} for b, o in zip(self.boxes, self.orders)]}  # fmt: skip

    @classmethod
    def from_dict(cls, d: dict) -> "ParetoFront":
        """The front from :meth:`to_dict`."""
        return cls([Interval.from_list(e["box"]) for e in d["front"]], [tuple(e["order"]) for e in d["front"]],
                   Interval.from_list(d["start"]), tuple(d["disturbances"]), d["check"])  # fmt: skip

    def plot(self, ax=None):
        """Parallel coordinates: the channel widths of each box, normalised by the start box; returns the axes."""
        import matplotlib.pyplot as plt

        names = list(self.disturbance_names)
        start = np.array(self.start.to_list())
        ref = np.where(start[:, 1] > start[:, 0], start[:, 1] - start[:, 0], 1.0)
        if ax is None:
            _, ax = plt.subplots(figsize=(1.2 * len(names) + 3, 3.5))
        for box, order in zip(self.boxes, self.orders):
            ax.plot(range(len(names)), (box.hi - box.lo) / ref, "o-", label=f"order {list(order)}")
        ax.set_xticks(range(len(names)), names)
        ax.set_ylabel("width / start width")
        ax.set_title(f"Pareto front of {self.check}-conformant boxes")
        ax.legend(fontsize=6)
        ax.figure.tight_layout()
        return ax


def plot_front_dict(d, ax=None):
    """Plot a front given as :meth:`ParetoFront.to_dict`'s dict (see :meth:`ParetoFront.plot`); returns the figure."""
    return ParetoFront.from_dict(d).plot(ax).figure


def _reachset_job(job):
    model, case, W, V, options = job
    return reachset_check(model, case, W, V, options).conformant


def _trace_job(job):
    model, case, W, V, options = job
    return trace_conformance(model, case, W, V, method="optctrl", options=options.trace).conformant


def _dominated(w, others):
    return any(np.all(o <= w + 1e-12) and np.any(o < w - 1e-12) for o in others)


def pareto_front(model, suite, V, W_start, check: str = "reachset", iterations: int = 8, orders=None,
                 options: SynthesisOptions | None = None, workers=None, scheduler=None) -> ParetoFront:  # fmt: skip
    """Sample the Pareto front of conformant boxes by per-channel shrinking.

    Parameters
    ----------
    W_start : Interval
        A box conformant for every case (e.g. ``SynthesisResult.groups[g]``).
    check : {"reachset", "trace"}
        Conformance notion (eq. 43 with eq. 67, or Alg. 1 with Alg. 2).
    iterations : int
        Bisection steps per channel.
    orders : list of sequences of int, optional
        Channel orders to try; default: the q rotations of ``0..q-1``.

    Returns
    -------
    ParetoFront
        The non-dominated boxes found (each verified conformant).
    """
    require_model(model, "pareto_front")
    options = check_options(options, SynthesisOptions, "pareto_front")
    workers = check_workers(workers, "pareto_front: workers")
    if check not in ("reachset", "trace"):
        raise OptionsError(f"check must be 'reachset' or 'trace', got {check!r}")
    Vb = as_box(V, model.p, "V")
    Vbox = Interval(Vb.lo, Vb.hi)
    Wb = as_box(W_start, model.q, "W_start")
    W_start = Interval(Wb.lo, Wb.hi)
    cases = suite_cases(suite, "pareto_front")
    q = model.q
    job_fn = _reachset_job if check == "reachset" else _trace_job

    def ok(W):
        jobs = [(model, case, W, Vbox, options) for case in cases]
        return all(run_cases(job_fn, jobs, workers=workers, scheduler=scheduler, progress=False))

    if not ok(W_start):
        raise ConformanceError(f"W_start is not {check} conformant for every case; start from a conformant box")
    if orders is None:
        orders = [tuple((k + i) % q for i in range(q)) for k in range(q)]
    c = W_start.center
    boxes, used = [], []
    for order in orders:
        r = W_start.radius.copy()
        for ch in order:
            lo, hi = 0.0, 1.0
            for _ in range(iterations):
                mid = 0.5 * (lo + hi)
                trial = r.copy()
                trial[ch] = r[ch] * mid
                if ok(Interval(c - trial, c + trial)):
                    hi = mid
                else:
                    lo = mid
            r[ch] = r[ch] * hi
        boxes.append(Interval(c - r, c + r))
        used.append(tuple(order))
    widths = [b.hi - b.lo for b in boxes]
    keep = []
    for i, w in enumerate(widths):
        others = [widths[j] for j in range(len(widths)) if j != i]
        if _dominated(w, others):
            continue
        if any(np.allclose(w, widths[j]) for j in keep):
            continue
        keep.append(i)
    return ParetoFront([boxes[i] for i in keep], [used[i] for i in keep], W_start, tuple(model.disturbance_names), check)
