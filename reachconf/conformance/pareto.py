"""Pareto front of conformant disturbance boxes (beyond the report, section 4.3.2's outlook).

A single α (eq. 68) scales every channel of the box together, giving one
point of the Pareto front of conformant models.  Shrinking one channel at a
time while the others stay fixed, in different channel orders, gives
further boxes that are each conformant and none of which is wider than
another in every channel: a sampled Pareto front.
"""

from __future__ import annotations

import math
import threading
from dataclasses import dataclass, field

import numpy as np

from reachconf.checks import check_options, check_workers
from reachconf.conformance.alpha import check_initial_sets, reachset_check
from reachconf.conformance.synthesis import SynthesisOptions
from reachconf.conformance.trace import trace_conformance
from reachconf.errors import ConformanceError, OptionsError
from reachconf.io.cases import suite_cases
from reachconf.io.results import JsonResult
from reachconf.model.core import require_model
from reachconf.model.shipping import prepare_model
from reachconf.reach_options import ReachOptions
from reachconf.runner.pool import progress_bar, use_pool
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
    log : list of str
        Events of the workers during the run (lost workers, restarts).
    """

    boxes: list
    orders: list
    start: Interval
    disturbance_names: tuple
    check: str
    log: list = field(default_factory=list)

    @property
    def widths(self) -> np.ndarray:
        """(number of boxes, q) channel widths."""
        return np.array([b.hi - b.lo for b in self.boxes])

    def to_dict(self):
        """Channel names, the start box and the front (each box with its channel order)."""
        return {"disturbances": list(self.disturbance_names), "check": self.check, "start": self.start.to_list(),
                "front": [{"box": b.to_list(), "order": list(o)} for b, o in zip(self.boxes, self.orders)],
                "log": list(self.log)}  # fmt: skip

    @classmethod
    def from_dict(cls, d: dict) -> "ParetoFront":
        """The front from :meth:`to_dict`."""
        return cls([Interval.from_list(e["box"]) for e in d["front"]], [tuple(e["order"]) for e in d["front"]],
                   Interval.from_list(d["start"]), tuple(d["disturbances"]), d["check"],
                   list(d.get("log", [])))  # fmt: skip

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
                 options: SynthesisOptions | None = None, workers=None, scheduler=None, pool=None,
                 progress=None) -> ParetoFront:  # fmt: skip
    """Sample the Pareto front of conformant boxes by per-channel shrinking.

    Parameters
    ----------
    W_start : Interval
        A box conformant for every case (e.g. ``SynthesisResult.groups[g]``).  Each channel's
        half-width is bisected about its centre, which every box of the front keeps: start from a
        synthesized box for a front near the minimal boxes (``reachconf pareto`` does when the run file
        has no ``[sets] W``); a wide box centred elsewhere gives boxes the synthesis's dominate.
    check : {"reachset", "trace"}
        Conformance notion (eq. 43 with eq. 67, or Alg. 1 with Alg. 2).
    iterations : int
        Bisection steps per channel.
    orders : list of sequences of int, optional
        Channel orders to try; default: the q rotations of ``0..q-1``.
    workers, scheduler : see :func:`reachconf.runner.run_cases`
        Used when no ``pool`` is given: a pool for this call only.
    pool : reachconf.runner.Pool, optional
        The run's pool: every check of every case is one of its tasks (the
        orders are searched at once when it is parallel; a check stops at
        the first case that fails it).
    progress : bool, optional
        Progress bar of the checks.

    Returns
    -------
    ParetoFront
        The non-dominated boxes found (each verified conformant), with the
        pool's events of the run in ``log``.
    """
    require_model(model, "pareto_front")
    options = check_options(options, SynthesisOptions, "pareto_front")
    workers = check_workers(workers, "pareto_front: workers")
    if check not in ("reachset", "trace"):
        raise OptionsError(f"check must be 'reachset' or 'trace', got {check!r}")
    if isinstance(iterations, bool) or not isinstance(iterations, (int, np.integer)) or iterations < 1:
        raise OptionsError(f"pareto_front: iterations must be a positive integer, got {iterations!r}")
    Vb = as_box(V, model.p, "V", exact=check == "trace")
    Vbox = Interval(Vb.lo, Vb.hi)
    Wb = as_box(W_start, model.q, "W_start")
    W_start = Interval(Wb.lo, Wb.hi)
    cases = suite_cases(suite, "pareto_front")
    check_initial_sets(options.X0, cases, model.n, "pareto_front")
    q = model.q
    if q == 0:
        raise OptionsError(f"pareto_front: model {model.name!r} has no disturbance inputs w: there is no front of W")
    if orders is None:
        orders = [tuple((k + i) % q for i in range(q)) for k in range(q)]
    orders = _channel_orders(orders, q)
    with use_pool(pool, workers, scheduler) as p:
        return _front(model, cases, Vbox, W_start, check, int(iterations), orders, options, p, progress)


def _channel_orders(orders, q: int) -> list:
    """``orders`` checked: each a sequence of distinct channel indices ``0..q-1`` (a channel repeated would be
    shrunk twice and another never)."""
    bad = OptionsError(f"pareto_front: orders must be a list of sequences of distinct channels 0..{q - 1}, got "
                       f"{orders!r}")  # fmt: skip
    if isinstance(orders, (str, bytes)) or not hasattr(orders, "__iter__"):
        raise bad
    out = []
    for o in orders:
        if isinstance(o, (str, bytes)) or not hasattr(o, "__iter__"):
            raise bad
        chans = list(o)
        if any(isinstance(ch, bool) or not isinstance(ch, (int, np.integer)) for ch in chans):
            raise bad
        chans = [int(ch) for ch in chans]
        if not chans or any(not 0 <= ch < q for ch in chans) or len(set(chans)) != len(chans):
            raise bad
        out.append(tuple(chans))
    if not out:
        raise bad
    return out


def _front(model, cases, Vbox, W_start, check, iterations, orders, options, pool, progress):
    mark = len(pool.log)
    if check == "reachset":
        prepare_model(pool, model, (options.reach or ReachOptions(), options.reach_fallback))
    job_fn = _reachset_job if check == "reachset" else _trace_job
    bar = progress_bar(1 + iterations * sum(len(o) for o in orders), "pareto", progress, unit="check")
    lock = threading.Lock()
    active = [len(orders)]
    failing = list(range(len(cases)))  # cases that failed a check come first next time (shared by the orders)

    def ok(W, stop=None):
        with lock:
            order = list(failing)
            batch = max(1, math.ceil(pool.size / max(active[0], 1)))
        bad = pool.first_failures(job_fn, [(model, cases[i], W, Vbox, options) for i in order], batch=batch, stop=stop)
        with lock:
            bar.update()
            if bad:
                first = [order[i] for i, _ in bad]
                failing[:] = first + [j for j in failing if j not in first]
        return not bad

    def search(order, stop):
        try:
            c, r = W_start.center, W_start.radius.copy()
            for ch in order:
                lo, hi = 0.0, 1.0
                for _ in range(iterations):
                    mid = 0.5 * (lo + hi)
                    trial = r.copy()
                    trial[ch] = r[ch] * mid
                    if ok(Interval(c - trial, c + trial), stop):
                        hi = mid
                    else:
                        lo = mid
                r[ch] = r[ch] * hi
            return Interval(c - r, c + r)
        finally:
            with lock:
                active[0] -= 1

    try:
        if not ok(W_start):
            raise ConformanceError(f"W_start {W_start} is not {check} conformant for every case; start from a "
                                   f"conformant box (a synthesized one: reachconf pareto without [sets] W)")  # fmt: skip
        boxes = pool.each(search, orders)
    finally:
        bar.close()
    widths = [b.hi - b.lo for b in boxes]
    keep = []
    for i, w in enumerate(widths):
        others = [widths[j] for j in range(len(widths)) if j != i]
        if _dominated(w, others):
            continue
        if any(np.allclose(w, widths[j]) for j in keep):
            continue
        keep.append(i)
    return ParetoFront([boxes[i] for i in keep], [orders[i] for i in keep], W_start, tuple(model.disturbance_names),
                       check, pool.log_since(mark))  # fmt: skip
