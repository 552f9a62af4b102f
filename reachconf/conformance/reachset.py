"""Reachset conformance of a model with one measured test case (section 3.3, eqs. 42/43, 67)."""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace

import numpy as np
from scipy.optimize import linprog

from reachconf.checks import check_options
from reachconf.budget import TimeBudget, check_memory, check_time_limit, tube_bytes_per_step
from reachconf.errors import ConformanceError, OptionsError, ReachError, SetError
from reachconf.io.cases import case_arrays
from reachconf.io.results import JsonResult
from reachconf.plot import plot_measured
from reachconf.model.core import require_model
from reachconf.model.outputs import (affine_output, output_enclosure, output_index_of_states, outputs_of_states,
                                     state_estimate, unmeasured_bounds)
from reachconf.reach import ReachStopped, integration_steps, reach_run
from reachconf.reach_options import AdaptiveReach, ReachOptions
from reachconf.reach_stream import streamed_bytes_per_step
from reachconf.sets.containment import contains_points_lp
from reachconf.sets.convert import as_box, as_zonotope
from reachconf.sets.core import Interval, Zonotope
from reachconf.sets.union import SetUnion
from reachconf.tube import ReachTube
from reachconf.verdict import Verdict
from reachconf_kernels.containment import contains_mapped_sequence
from reachconf_kernels.zonotope import from_interval

__all__ = ["ReachsetResult", "reachset_conformance", "initial_set", "StreamChecker", "reach_plan",
           "reach_bytes_per_step", "reach_step_count"]


@dataclass
class ReachsetResult(JsonResult):
    """Outcome of the reachset-conformance check of one test case (eq. 42/43).

    Attributes
    ----------
    case : str
    conformant : bool
        Every measurement lies in ``h(R(t_i)) ⊕ V`` with ``R`` the *computed*
        (over-approximating) reachable set — the set a verification with these
        options would use (eq. 43), not a proof about the exact one (trace
        conformance gives that); False also when the reachability analysis
        failed (then ``verdict`` is undecided).
    first_violation_time : float or None
        First sample outside its set; when undecided, the time the reach
        failed.
    max_violation : float
        Largest infinity-norm distance of a measurement from its set
        ``h(R(t_i)) ⊕ V`` (0 when conformant, ``inf`` when the reach failed,
        NaN when not computed: ``violation_distance=False``; ``null`` in JSON
        for both).
    inside : ndarray of bool (K,)
        Measurement inside its set (False also for samples not checked after
        a stop at the first violation).
    tube : ReachTube or None
        Not saved by :meth:`save` (save it with ``tube.save``).
    seconds : float
    message : str
        Why the reach failed (the :class:`ReachError` text), else empty.
    violations : dict
        Time -> distance of each violating measurement (with ``violation_distance``).
    t : ndarray (K,) or None
        Sample times of the case.
    Y : ndarray (K, p) or None
        The measurements.
    output_names : tuple of str
    verdict : Verdict
        ``CONFORMANT``, ``NOT_CONFORMANT`` (a measurement lies outside its
        set: the reachable set is an over-approximation, so this is
        certain), or ``UNDECIDED`` (the reach failed; ``message`` says why).
    """

    case: str
    conformant: bool
    first_violation_time: float | None
    max_violation: float
    inside: np.ndarray
    tube: object = None
    seconds: float = 0.0
    message: str = ""
    violations: dict = field(default_factory=dict)
    t: np.ndarray | None = None
    Y: np.ndarray | None = None
    output_names: tuple = ()
    verdict: Verdict | None = None

    def __post_init__(self):
        self.verdict = Verdict.of(self.conformant) if self.verdict is None else Verdict(self.verdict)
        if self.conformant and self.verdict is not Verdict.CONFORMANT:
            raise ConformanceError(f"case {self.case!r}: conformant=True with verdict {self.verdict.value}")

    def to_dict(self) -> dict:
        """Verdict, violations and measurements (the tube is not included; ``max_violation`` None if not finite)."""
        return {"case": self.case, "verdict": self.verdict.value, "conformant": self.verdict.json_conformant,
                "first_violation_time": self.first_violation_time, "max_violation": float(self.max_violation),
                "inside": np.asarray(self.inside, bool).tolist(), "seconds": float(self.seconds),
                "message": self.message, "violations": {repr(k): float(v) for k, v in self.violations.items()},
                "t": None if self.t is None else np.asarray(self.t).tolist(),
                "Y": None if self.Y is None else np.asarray(self.Y).tolist(),
                "output_names": list(self.output_names)}  # fmt: skip

    @classmethod
    def from_dict(cls, d: dict) -> "ReachsetResult":
        """The result from :meth:`to_dict` (without a tube)."""
        arr = (lambda v: None if v is None else np.asarray(v, dtype=float))  # noqa: E731
        verdict = Verdict(d.get("verdict", Verdict.of(bool(d["conformant"]))))
        worst = d["max_violation"]
        worst = (np.inf if verdict is Verdict.UNDECIDED else np.nan) if worst is None else float(worst)
        return cls(d["case"], verdict is Verdict.CONFORMANT, d["first_violation_time"], worst,
                   np.asarray(d["inside"], dtype=bool), None, float(d["seconds"]), d["message"],
                   {float(k): float(v) for k, v in d["violations"].items()}, arr(d.get("t")), arr(d.get("Y")),
                   tuple(d.get("output_names", ())), verdict)  # fmt: skip

    def plot(self, ax=None, dims=None, **style):
        """The reach tube (if kept) with the measurements; measurements outside their sets in red.

        Parameters
        ----------
        ax : matplotlib Axes, optional
        dims : pair of str, optional
            States drawn (default: the tube's first two); the measurements
            drawn are the outputs of the same names.
        **style
            Passed to :meth:`ReachTube.plot` (``color``, ``alpha``, ``outline``, ``label``).

        Returns
        -------
        matplotlib Axes
        """
        import matplotlib.pyplot as plt

        if self.tube is not None:
            dims = tuple(self.tube.state_names[:2]) if dims is None else tuple(dims)
            ax = self.tube.plot(ax=ax, dims=dims, **style)
        elif ax is None:
            _, ax = plt.subplots(figsize=(8, 5))
        names = list(self.output_names)
        if dims is None:
            dims = tuple(names[:2])
        unknown = [d for d in dims if d not in names]
        if self.tube is None and (unknown or len(dims) != 2):  # (with a tube, its states are checked by its plot)
            raise SetError(f"ReachsetResult.plot: dims must be two of the outputs {names}, got {tuple(dims)!r}")
        if self.Y is not None and not unknown:
            xy = np.asarray(self.Y)[:, [names.index(d) for d in dims]]
            inside = np.asarray(self.inside, bool)
            plot_measured(ax, [xy[inside]], dims)
            if (~inside).any():
                plot_measured(ax, [xy[~inside]], dims, label="outside its set", color="C3", ms=4)
            ax.set_xlabel(dims[0])
            ax.set_ylabel(dims[1])
        ax.set_title(f"{self.case}: {self.verdict.label}", fontsize=9)
        return ax


def initial_set(model, case, V, unmeasured=None) -> Interval | Zonotope:
    """Eq. 67: the states the first measurement allows, ``X(t_1) ⊕ (−V)`` in state space.

    A measurement is ``y = h(x) + v`` with ``v`` in V, so the state is ``y − v``: if every state is
    an output, the measured first sample minus V (the report writes ``⊕ V`` for its symmetric V; for an
    asymmetric V, ``[0, 0.2]`` say, the states lie below the measurement, not above it).  If ``h``
    is affine with full column rank ``C``, the preimage ``C^+ (y_1 - D u_1 - e - V)``.  Otherwise pass
    ``X0`` explicitly, or ``unmeasured``.

    Parameters
    ----------
    model : Model
    case : TestCase
    V : Interval or array-like of (lo, hi)
    unmeasured : mapping of state name to (lo, hi), optional
        Bounds of the states that are not outputs (e.g. a box around the start
        of the case's disturbance trace, ``TraceResult.x0``); the states that
        are outputs take eq. 67's first sample minus V.  Every state that is not
        an output must be given, and only those.

    Returns
    -------
    Interval or Zonotope
    """
    t, U, Y = case_arrays(model, case)
    Vb = as_box(V, model.p, "V")
    V_lo, V_hi = Vb.lo, Vb.hi
    if unmeasured is not None:
        return _partly_measured(model, Y[0], V_lo, V_hi, unmeasured)
    direct = output_index_of_states(model)
    if direct is not None:
        x1 = Y[0, direct]
        return Interval(x1 - V_hi[direct], x1 - V_lo[direct])
    aff = affine_output(model)
    if aff is not None and np.linalg.matrix_rank(aff[0]) == model.n:
        C, D, e = aff
        Cp = np.linalg.pinv(C)
        x1 = state_estimate(model, case)[0]
        Vc, Vr = 0.5 * (V_lo + V_hi), 0.5 * (V_hi - V_lo)
        return Zonotope(x1 - Cp @ Vc, -Cp * Vr)
    raise ConformanceError(
        f"model {model.name!r}: eq. 67 needs the states from the outputs (h not invertible); give the initial set "
        f"X0 (reachset_conformance(X0=...), SynthesisOptions(X0=...), or [sets] X0 in a run file), or the bounds of "
        f"the unmeasured states (initial_set(..., unmeasured={{name: (lo, hi)}}))"
    )


def _partly_measured(model, y1, V_lo, V_hi, unmeasured) -> Interval:
    """Eq. 67 for the states that are outputs (the measurement minus V), the given bounds for the others."""
    bounds = unmeasured_bounds(model, unmeasured)
    lo, hi = np.empty(model.n), np.empty(model.n)
    for j, i in outputs_of_states(model).items():
        lo[j], hi[j] = y1[i] - V_hi[i], y1[i] - V_lo[i]
    for j, (lo_j, hi_j) in bounds.items():
        lo[j], hi[j] = lo_j, hi_j
    return Interval(lo, hi)


def _distance(S, y: np.ndarray) -> float:
    """Infinity-norm distance from ``y`` to the zonotope (an LP); to the nearest piece of a union."""
    if isinstance(S, SetUnion):
        return min(_distance(piece, y) for piece in S)
    c, G = S.center, S.generators
    n, m = G.shape
    # min s  s.t. |G b - (y - c)| <= s, |b| <= 1
    cost = np.zeros(m + 1)
    cost[-1] = 1.0
    A = np.vstack([np.hstack([G, -np.ones((n, 1))]), np.hstack([-G, -np.ones((n, 1))])])
    d = y - c
    res = linprog(cost, A_ub=A, b_ub=np.concatenate([d, -d]), bounds=[(-1, 1)] * m + [(0, None)], method="highs")
    if res.status != 0:
        return float(np.max(np.abs(d)))
    return float(res.x[-1])


def reachset_conformance(model, case, W, V, X0=None, options=None, keep_tube: bool = True,
                         violation_distance: bool = True, stop_at_first_violation: bool = False,
                         progress: bool | None = None, max_distance_samples: int = 2000,
                         time_limit: float | None = None) -> ReachsetResult:  # fmt: skip
    """Eq. 43: is every measurement ``Y(t_i)`` in ``h(REACH(X0, u, t_i)) ⊕ V``?

    Parameters
    ----------
    model : Model
    case : TestCase
    W : Interval or Zonotope
        Disturbance set (disturbances vary in time within it).
    V : Interval or Zonotope
        Additive measurement-error set.
    X0 : Interval or Zonotope, optional
        Initial set; default eq. 67, ``X(t_1) ⊕ (−V)`` (:func:`initial_set`).
    options : ReachOptions, optional
        Default ``ReachOptions()`` (``"adaptive"``: its steps end at every
        sample time).
    keep_tube : bool
        Keep the reach tube in the result.  False streams the reach: the sets
        are checked chunk by chunk as they are computed and dropped, with the
        state set carried from chunk to chunk, so memory does not grow with
        the length of the case (a few bytes per sample: the verdicts).
    violation_distance : bool
        Compute ``max_violation`` (one LP per violating sample; when
        streaming, for the first ``max_distance_samples`` of them).
    stop_at_first_violation : bool
        Stop the reachability analysis at the first measurement outside its
        set (only the verdict and ``first_violation_time`` are wanted: the
        α-search of eq. 68); ignored with ``keep_tube`` or ``violation_distance``
        and once the set has been split.
    progress : bool or None
        Progress bar of the reach (default: long reaches on a terminal).
    time_limit : float or None
        Seconds (streamed reach only): stop with ResourceError once the
        projected duration, measured on the first 2 % of the steps, exceeds it.

    Returns
    -------
    ReachsetResult
        A reach that fails (the set explodes) gives ``verdict=UNDECIDED``
        (``conformant=False``) with the reason in ``message``: a failed reach
        never counts as conformant, nor as a violation.

    Raises
    ------
    ResourceError
        Before any work, when ``keep_tube`` would need more memory than is
        available (pass ``keep_tube=False``).
    """
    t0 = time.perf_counter()
    require_model(model, "reachset_conformance")
    options = check_options(options, ReachOptions, "reachset_conformance")
    check_time_limit(time_limit)
    if isinstance(max_distance_samples, bool) or not isinstance(max_distance_samples, (int, np.integer)) \
            or max_distance_samples < 0:  # fmt: skip
        raise OptionsError(f"reachset_conformance: max_distance_samples must be a non-negative integer, "
                           f"got {max_distance_samples!r}")  # fmt: skip
    if progress is not None and not isinstance(progress, bool):
        raise OptionsError(f"reachset_conformance: progress must be True, False or None, got {progress!r}")
    t, U, Y = case_arrays(model, case)
    name = getattr(case, "name", "case")
    if X0 is None:
        X0 = initial_set(model, case, V)
    X0 = as_zonotope(X0, model.n, "X0")  # a wrong size is an error before any work, never a verdict
    if progress is not None:
        options = replace(options, progress=progress)
    Vb = as_box(V, model.p, "V")
    V_lo, V_hi = Vb.lo, Vb.hi
    Vset = Interval(V_lo, V_hi)
    inputs = U if model.m else None
    per_step, fixed = reach_bytes_per_step(model, options, keep_tube)
    steps = reach_step_count(t, options)
    check_memory(f"reachset conformance of case {name!r}", steps, per_step, fixed,
                 hint="pass keep_tube=False (the CLI does) to stream the reach" if keep_tube else "")  # fmt: skip
    if not keep_tube:
        checker = StreamChecker(model, U if model.m else np.zeros((t.size, 0)), Y, V_lo, V_hi,
                                stop_at_first_violation and not violation_distance, violation_distance,
                                max_distance_samples)  # fmt: skip
        try:
            if checker.check_first(X0):
                raise ReachStopped(0)
            budget = TimeBudget(f"reachset conformance of case {name!r}", time_limit, min_fraction=0.02)
            # progress in steps ("lin"/"poly") or in sample intervals ("adaptive": k0, k1 are samples)
            total = t.size - 1 if isinstance(options.alg, AdaptiveReach) else steps
            reach_run(model, X0, t - t[0], inputs=inputs, W=W, options=options, monitor=checker,
                      stream=lambda k0, k1, *_: budget.check(k1, total))  # fmt: skip
        except ReachError as exc:
            return ReachsetResult(name, False, float(t[0] + (exc.time or 0.0)), float("inf"), checker.inside,
                                  None, time.perf_counter() - t0, str(exc), {}, t, Y, model.output_names,
                                  Verdict.UNDECIDED)  # fmt: skip
        except ReachStopped:
            first = int(np.nonzero(checker.status == 0)[0][0])
            return ReachsetResult(name, False, float(t[first]), float("nan"), checker.inside, None,
                                  time.perf_counter() - t0, "", {}, t, Y, model.output_names)  # fmt: skip
        inside = checker.inside
        bad = np.nonzero(~inside)[0]
        violations = {float(t[k]): d for k, d in checker.distances.items() if not inside[k]}
        worst = max(violations.values()) if violations else (float("nan") if bad.size else 0.0)
        message = ""
        if bad.size and violation_distance and bad.size > len(violations):
            message = f"distances computed for the first {len(violations)} of {bad.size} violating samples"
        return ReachsetResult(name, not bad.size, float(t[bad[0]]) if bad.size else None, worst, inside, None,
                              time.perf_counter() - t0, message, violations, t, Y, model.output_names)  # fmt: skip
    checker = StreamChecker(model, U if model.m else np.zeros((t.size, 0)), Y, V_lo, V_hi, False)
    checker.check_first(X0)
    try:
        run = reach_run(model, X0, t - t[0], inputs=inputs, W=W, options=options, monitor=checker)
    except ReachError as exc:
        return ReachsetResult(name, False, float(t[0] + (exc.time or 0.0)), float("inf"), np.zeros(t.size, bool),
                              None, time.perf_counter() - t0, str(exc), {}, t, Y, model.output_names,
                              Verdict.UNDECIDED)  # fmt: skip
    tube = ReachTube.from_run(run, model)
    if run.monitored:  # every sample was checked as the sets were computed (no split)
        inside = checker.inside
    else:
        inside = tube.contains(t - t[0], Y, V=Vset, output=True, inputs=inputs).inside
    bad = np.nonzero(~inside)[0]
    worst = float("nan") if bad.size and not violation_distance else 0.0
    violations = {}
    if bad.size and violation_distance:
        for k in bad:
            S = output_enclosure(model, tube.at(t[k] - t[0]), U[k] if model.m else None) + Vset.to_zonotope()
            dist = _distance(S, Y[k])
            violations[float(t[k])] = dist
            worst = max(worst, dist)
    first = float(t[bad[0]]) if bad.size else None
    return ReachsetResult(name, not bad.size, first, worst, inside, tube, time.perf_counter() - t0, "",
                          violations, t, Y, model.output_names)  # fmt: skip


def reach_step_count(t, options) -> int:
    """Integration steps of a reach over the sample times ``t`` (as :func:`reachconf.reach.reach` makes them)."""
    return integration_steps(np.asarray(t, dtype=float) - float(t[0]), options)


def reach_bytes_per_step(model, options, keep_tube) -> tuple[float, float]:
    """Memory estimate of a reach: ``(bytes per integration step, fixed bytes)``.

    Kept tube: two zonotopes per step (time point and time interval) of at
    most ``n (order + 1) + 1`` generators, in the kernel's arrays and again as
    set objects.  Streamed: the per-sample verdicts and inputs; fixed: one
    chunk of 500 steps.
    """
    per_tube, fixed = tube_bytes_per_step(model.n, model.m, options.zonotope_order)
    if keep_tube:
        return per_tube, fixed
    per_set = per_tube / 4  # one zonotope
    return 8.0 * (model.m + 3) + 2, 501 * 2 * per_set + fixed


def reach_plan(model, options, case, stream_bytes: float) -> bool:
    """Pre-flight of a reach over ``case``: True if its tube must be streamed (it needs more than ``stream_bytes``).

    Raises :class:`~reachconf.errors.ResourceError` (before any work) if even
    the chosen way needs more memory than is available.
    """
    steps = reach_step_count(case.t, options)
    per, fixed = reach_bytes_per_step(model, options, True)
    stream = steps * per + fixed > stream_bytes
    if stream:
        check_memory(f"reach of case {case.name!r}", steps, streamed_bytes_per_step(model), 256e6)
    else:
        check_memory(f"reach of case {case.name!r}", steps, per, fixed)
    return stream


class StreamChecker:
    """Monitor of a streamed reach: eq. 43 sample by sample as the sets are computed (union-aware).

    A sample is inside when some piece of the (possibly split) reachable set
    at its time, enlarged by V, contains its measurement.  Affine output
    maps use the compiled sequence kernel; others the mean-value enclosure of
    :func:`reachconf.model.outputs.output_enclosure` per sample.
    """

    def __init__(self, model, U, Y, V_lo, V_hi, stop, distances=False, max_distances=2000):
        self.model = model
        self.aff = affine_output(model)
        self.U = U
        self.Y = np.ascontiguousarray(Y, dtype=float)
        self.V = Interval(V_lo, V_hi)
        self.stop = stop
        self.want_distances = distances
        self.max_distances = int(max_distances)
        self.status = np.full(Y.shape[0], -2, dtype=np.int8)  # -2 unchecked, 0 outside (so far), 1 inside
        self.distances = {}
        self.seq = _SequenceChecker(self.aff, U, Y, V_lo, V_hi) if self.aff is not None else None

    @property
    def inside(self):
        """Per sample: inside some piece of its set (False for samples not checked)."""
        return self.status == 1

    def _piece_status(self, js, c, G, ng):
        if self.seq is not None:
            return self.seq.decide(js, c, G, ng)
        st = np.zeros(js.size, dtype=np.int64)
        for i, k in enumerate(js):
            Z = Zonotope(c[i], G[i][:, : ng[i]])
            S = output_enclosure(self.model, Z, self.U[k] if self.model.m else None) + self.V.to_zonotope()
            st[i] = int(bool(S.contains(self.Y[k])))
        return st

    def _distance(self, k, c, G, ng):
        Z = Zonotope(c, G[:, :ng])
        S = output_enclosure(self.model, Z, self.U[k] if self.model.m else None) + self.V.to_zonotope()
        return _distance(S, self.Y[k])

    def check_first(self, X0):
        """Check the first sample against the initial set; True if a stop was asked for and it is outside."""
        Z = X0.to_zonotope()
        G = np.asarray(Z.generators, dtype=float)
        return self(np.array([0]), np.asarray(Z.center, dtype=float)[None, :], G[None, :, :],
                    np.array([G.shape[1]], dtype=np.int64), False)  # fmt: skip

    def __call__(self, js, c, G, ng, split=False):
        st = self._piece_status(js, c, G, ng)
        now_in = st == 1
        prev = self.status[js]
        self.status[js] = np.where(now_in | (prev == 1), 1, 0)
        if self.want_distances:
            for i in np.nonzero(~now_in & (prev != 1))[0]:
                k = int(js[i])
                if k in self.distances or len(self.distances) < self.max_distances:
                    d = self._distance(k, c[i], G[i], ng[i])
                    self.distances[k] = min(d, self.distances.get(k, np.inf))
        return bool(self.stop and not split and np.any(~now_in))


class _SequenceChecker:
    """Eq. 43 for a chunk of time-point sets with an affine output map (one compiled kernel call)."""

    def __init__(self, aff, U, Y, V_lo, V_hi):
        C, D, e = aff
        cv, Gv = from_interval(np.ascontiguousarray(V_lo, dtype=float), np.ascontiguousarray(V_hi, dtype=float))
        self.C = np.ascontiguousarray(C, dtype=float)
        self.off = np.ascontiguousarray(U @ D.T + e + cv)
        self.v_rad = np.ascontiguousarray(np.sum(np.abs(Gv), axis=1))
        self.Y = np.ascontiguousarray(Y, dtype=float)

    def decide(self, js, c, G, ng):
        """Per sample ``js[i]``: 1 if its measurement is in ``C Z_i + off ⊕ V``, else 0 (compiled, LP fallback)."""
        st = contains_mapped_sequence(np.ascontiguousarray(c), np.ascontiguousarray(G), np.ascontiguousarray(ng),
                                      self.C, self.off[js], self.v_rad, self.Y[js], 1e-9, False)  # fmt: skip
        for i in np.nonzero(st == -1)[0]:  # no certificate: the reference LP
            Gi = np.hstack([self.C @ G[i][:, : ng[i]], np.diag(self.v_rad)[:, self.v_rad > 0]])
            ci = self.C @ c[i] + self.off[js[i]]
            st[i] = int(contains_points_lp(ci, Gi, self.Y[js[i]][None, :], 1e-9)[0])
        return st
