"""What the adaptive reachability algorithm chose: steps, orders and splits over time."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

__all__ = ["ReachLog"]

_STEP_FIELDS = ("branch", "t0", "dt", "tensor_order", "zonotope_order", "quad_order", "error_rate",
                "error_floor", "tries", "taylor_terms", "iterations")  # fmt: skip
_SPLIT_FIELDS = ("split_time", "split_start", "split_parent", "split_children")


@dataclass
class ReachLog:
    """Per-step choices of ``algorithm="adaptive"`` (attached to the tube as ``tube.log``).

    One entry per accepted step of every branch (a branch is a piece of the
    set after splitting; branch 0 starts from ``X0``).

    Attributes
    ----------
    branch : ndarray of int (N,)
    t0, dt : ndarray (N,)
        Start and length of the step.
    tensor_order : ndarray of int (N,)
        2 (interval Hessian) or 3 (Hessian at the point plus third-order remainder).
    zonotope_order : ndarray (N,)
        Generators of the time-point set divided by the dimension (after the
        error-bounded reduction).
    quad_order : ndarray (N,)
        Order of the set that entered ``quad_map`` (0 with tensor order 2).
    error_rate : ndarray (N,)
        ``max_i L_i / rad_i``: abstraction-error rate relative to the set (1/s).
    error_floor : ndarray (N,)
        The same over the start set (``dt -> 0``), or NaN where not computed.
    tries : ndarray of int (N,)
        Step computations until the step was accepted.
    taylor_terms, iterations : ndarray of int (N,)
        Taylor terms of the matrix exponential; abstraction-error iterations.
    split_time : ndarray (M,)
        When each split was decided (the error floor was over budget there).
    split_start : ndarray (M,)
        Where the halves start: ``split_time`` (the set was split there) or
        the start of the branch (its start set was halved and the branch run
        again, so that the error it had accumulated halves too).
    split_parent : ndarray of int (M,)
        The branch that was split (a restarted branch keeps no steps).
    split_children : ndarray of int (M, 2)
    budget : float
        Error budget ``beta`` (1/s) the steps were held to.
    smallest_step : float
        Smallest step tried (also rejected ones).
    budgets_tried : ndarray
        The ``AdaptiveReach.error_budget`` of every run, the last one the run
        kept: a run whose error could not be bounded is repeated from the
        start with half the budget (``budget_retries``); the last budget
        appears twice when its ordinary run failed too and the run that
        held the step over budget was kept.
    """

    branch: np.ndarray
    t0: np.ndarray
    dt: np.ndarray
    tensor_order: np.ndarray
    zonotope_order: np.ndarray
    quad_order: np.ndarray
    error_rate: np.ndarray
    error_floor: np.ndarray
    tries: np.ndarray
    taylor_terms: np.ndarray
    iterations: np.ndarray
    split_time: np.ndarray = field(default_factory=lambda: np.zeros(0))
    split_start: np.ndarray = field(default_factory=lambda: np.zeros(0))
    split_parent: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    split_children: np.ndarray = field(default_factory=lambda: np.zeros((0, 2), dtype=np.int64))
    budget: float = float("nan")
    smallest_step: float = float("nan")
    budgets_tried: np.ndarray = field(default_factory=lambda: np.zeros(0))

    @property
    def steps(self) -> int:
        """Accepted steps over all branches."""
        return int(self.dt.size)

    @property
    def splits(self) -> int:
        """Number of splits (and restarts from a halved start set)."""
        return int(self.split_time.size)

    def summary(self) -> str:
        """A few lines: step sizes, orders and splits over time."""
        if self.steps == 0:
            return "adaptive reach: no steps"
        dt = self.dt
        span = float(np.sum(dt))
        share3 = float(np.sum(dt[self.tensor_order == 3]) / span) if span > 0 else 0.0
        zo = self.zonotope_order
        lines = [
            f"adaptive reach: {self.steps} steps in {int(self.branch.max()) + 1} branch(es), "
            f"budget {self.budget:.3g}/s",
            f"  time step {dt.min():.3g} .. {dt.max():.3g} s (median {np.median(dt):.3g}, smallest tried "
            f"{self.smallest_step:.3g}), {int(np.sum(self.tries > 1))} steps retried",
            f"  tensor order 3 on {100 * share3:.0f} % of the integrated time, 2 on the rest",
            f"  zonotope order {zo.min():.3g} .. {zo.max():.3g} (median {np.median(zo):.3g}), "
            f"Taylor terms {int(self.taylor_terms.min())} .. {int(self.taylor_terms.max())}",
        ]
        if self.splits:
            pairs = [f"{t:.3g}" if s == t else f"{t:.3g}->{s:.3g}" for t, s in zip(self.split_time, self.split_start)]
            ts = ", ".join(pairs[:12]) + (" ..." if self.splits > 12 else "")
            restarted = int(np.sum(self.split_start < self.split_time))
            lines.append(f"  {self.splits} split(s) decided at t = {ts} ({restarted} restarted the branch from "
                         "its start, halved)")
        else:
            lines.append("  no splits")
        b = np.asarray(self.budgets_tried, dtype=float)
        if b.size > 1:
            held = bool(b[-1] == b[-2])  # the last budget run again, holding the step over budget
            tried = ", ".join(f"{v:g}" for v in b[:-1])
            lines.append(f"  error_budget {b[-1]:g} after the error could not be bounded with {tried}"
                         + ("; held over budget where smaller steps could not lower the error rate" if held else ""))
        return "\n".join(lines)

    def __repr__(self):
        if self.steps == 0:
            return "ReachLog(no steps)"
        return (f"ReachLog({self.steps} steps, dt {self.dt.min():.3g}..{self.dt.max():.3g} s, "
                f"tensor order {sorted(set(int(k) for k in self.tensor_order))}, "
                f"zonotope order {self.zonotope_order.min():.3g}..{self.zonotope_order.max():.3g}, "
                f"{self.splits} splits)")  # fmt: skip

    def to_arrays(self) -> dict:
        """Arrays for ``np.savez`` (keys prefixed ``log_``)."""
        out = {f"log_{k}": np.asarray(getattr(self, k)) for k in _STEP_FIELDS + _SPLIT_FIELDS}
        out["log_scalars"] = np.array([self.budget, self.smallest_step])
        out["log_budgets_tried"] = np.asarray(self.budgets_tried, dtype=float)
        return out

    @classmethod
    def from_arrays(cls, data) -> "ReachLog | None":
        """Inverse of :meth:`to_arrays` (None if ``data`` holds no log)."""
        if "log_dt" not in data:
            return None
        kw = {k: np.asarray(data[f"log_{k}"]) for k in _STEP_FIELDS + _SPLIT_FIELDS}
        budget, smallest = (float(v) for v in np.asarray(data["log_scalars"]).reshape(-1)[:2])
        tried = np.asarray(data["log_budgets_tried"], dtype=float) if "log_budgets_tried" in data else np.zeros(0)
        return cls(**kw, budget=budget, smallest_step=smallest, budgets_tried=tried)

    @classmethod
    def concat(cls, logs) -> "ReachLog":
        """One log of several runs (the chunks of a streamed adaptive reach, in time order).

        Branch numbers are made unique by offsetting each run's by the
        branches before it; ``budgets_tried`` is that of the run that tried
        the most budgets (a run is retried from its start with half the budget).
        """
        logs = list(logs)
        if len(logs) == 1:
            return logs[0]
        offsets = np.cumsum([0] + [_branch_count(lg) for lg in logs[:-1]])
        cat = {k: np.concatenate([np.asarray(getattr(lg, k)) for lg in logs]) for k in _STEP_FIELDS[1:]}
        cat["branch"] = np.concatenate([lg.branch + o for lg, o in zip(logs, offsets)]).astype(np.int64)
        for k in ("split_time", "split_start"):
            cat[k] = np.concatenate([np.asarray(getattr(lg, k), dtype=float) for lg in logs])
        cat["split_parent"] = np.concatenate([lg.split_parent + o for lg, o in zip(logs, offsets)]).astype(np.int64)
        cat["split_children"] = np.concatenate([lg.split_children.reshape(-1, 2) + o
                                                for lg, o in zip(logs, offsets)]).astype(np.int64)  # fmt: skip
        tried = max((np.asarray(lg.budgets_tried, dtype=float) for lg in logs), key=np.size)
        return cls(**cat, budget=logs[0].budget, smallest_step=float(min(lg.smallest_step for lg in logs)),
                   budgets_tried=tried)  # fmt: skip

    @classmethod
    def from_records(cls, rec, branches, split_log, budget, smallest, n) -> "ReachLog":
        """The log of an adaptive run from the kernel's per-step records.

        ``rec`` (N, N_REC) as :mod:`reachconf_kernels.adaptive` writes it,
        ``branches`` with ``index``, ``rec_lo``, ``rec_hi``, ``split_log`` rows
        ``(time decided, time applied, parent, child a, child b)``.
        """
        from reachconf_kernels import adaptive as ak

        branch = np.zeros(rec.shape[0], dtype=np.int64)
        for br in branches:
            if br.rec_hi > br.rec_lo >= 0:
                branch[br.rec_lo : br.rec_hi] = br.index
        floor = rec[:, ak.REC_RHO0].copy()
        floor[floor < 0] = np.nan
        splits = np.array(split_log, dtype=float).reshape(-1, 5)
        return cls(
            branch=branch,
            t0=rec[:, ak.REC_T0].copy(),
            dt=rec[:, ak.REC_DT].copy(),
            tensor_order=rec[:, ak.REC_KAPPA].astype(np.int64),
            zonotope_order=rec[:, ak.REC_NG_TP] / n,
            quad_order=rec[:, ak.REC_NG_QUAD] / n,
            error_rate=rec[:, ak.REC_RHO].copy(),
            error_floor=floor,
            tries=rec[:, ak.REC_TRIES].astype(np.int64),
            taylor_terms=rec[:, ak.REC_TAYLOR].astype(np.int64),
            iterations=rec[:, ak.REC_ITER].astype(np.int64),
            split_time=splits[:, 0].copy(),
            split_start=splits[:, 1].copy(),
            split_parent=splits[:, 2].astype(np.int64),
            split_children=splits[:, 3:5].astype(np.int64),
            budget=float(budget),
            smallest_step=float(smallest),
        )


def _branch_count(log) -> int:
    """Branches a run numbered (0 .. the largest index in its steps or splits)."""
    top = [int(log.branch.max()) if log.branch.size else 0]
    if np.size(log.split_children):
        top.append(int(np.max(log.split_children)))
    return max(top) + 1
