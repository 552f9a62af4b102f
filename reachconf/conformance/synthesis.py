"""Three-step synthesis of a minimal reachset-conformant disturbance box (section 4.3.2).

Per test case:

1. ``W_TC``: the interval hull of the per-step disturbance trace (eqs. 62–66);
2. ``W_opt``: the smallest-volume box keeping the case trace conformant under
   V (sequential convex programming on the linearised dynamics, cvxpy);
3. ``W_RC``: the binary α-search of eq. 68, ``c + α g`` with the centre ``c``
   and radius ``g`` of ``W_opt``, for the smallest α in [0, 1] that is reachset
   conformant (eq. 43 with the initial set of eq. 67).

Per group (maneuver): the hull of its cases' ``W_RC`` and the α-search again
over all of its cases, giving ``W_RC,Mnvr`` (Table 6).
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

from reachconf.checks import check_field_types, check_options, check_workers
from reachconf.conformance.alpha import alpha_search, check_initial_sets, reachset_check
from reachconf.conformance.bounds import minimize_box, step1_trace
from reachconf.conformance.merge import merge_groups
from reachconf.conformance.trace import TraceOptions
from reachconf.errors import ConformanceError, OptionsError
from reachconf.io.cases import suite_cases
from reachconf.io.results import JsonResult
from reachconf.model.core import require_model
from reachconf.model.shipping import prepare_model
from reachconf.reach_options import ReachOptions
from reachconf.runner.pool import Interrupted, WorkersLost, use_pool
from reachconf.sets.convert import as_box
from reachconf.sets.core import Interval, Zonotope
from reachconf.verdict import Verdict, overall_verdict

__all__ = ["SynthesisOptions", "CaseSynthesis", "SynthesisResult", "synthesize_W", "alpha_search",
           "reachset_check"]  # fmt: skip


@dataclass(frozen=True)
class SynthesisOptions:
    """Options of :func:`synthesize_W`.

    Parameters
    ----------
    alpha_iterations : int, default 10
        Bisection steps of the α-search (eq. 68); the result is within
        ``2**-alpha_iterations`` of the smallest conformant α.
    merge_iterations : int or None, default None
        Bisection steps of the merge's α-search (``None``: ``alpha_iterations``).
    alpha_max : float, default 4.0
        Largest α tried when α = 1 is not reachset conformant.  Eq. 68
        searches α in [0, 1] because ``W_opt`` is trace conformant; here it is
        so on the samples steps 1–2 saw (``step2_decimate``) and from the
        trace's own initial state, not from the initial set of eq. 67, so α = 1
        can fail.  Then α is doubled up to ``alpha_max`` and the search bisects
        between the last failing and the first conformant α.  Every returned
        box is verified by reachability whatever α is; ``1.0`` gives eq. 68
        exactly.
    alpha_below_failed_reach : bool, default True
        When the reach fails (undecided) at a tried α before any α passed —
        at α = 1, or while α is doubled — bisect below it for an α that
        passes (:func:`~reachconf.conformance.alpha.alpha_search`): a smaller
        box keeps the reach from exploding, and reachset conformance (eq. 43)
        holds for the computed over-approximation, which can contain every
        measurement where ``W_opt`` itself could not be reached (eq. 68
        searches α in [0, 1]).  The merge then also tries, when the hull of
        all its cases' boxes fails, the hull of those conformant alone.
        Every box returned is still verified on every case.  False: the
        search stops at the failed reach (as until 3 Dec 2026).
    optimize : bool, default True
        Run step 2; if False, step 3 starts from ``W_TC``.
    step2_decimate : int, default 1
        Run steps 1–2 on every k-th sample only (the SCP cost grows with the
        number of samples); step 3 always checks every sample.
    merge : bool, default True
        Compute the per-group ``W_RC,Mnvr``.
    reach : ReachOptions or None
        Options of the reachability analysis (default: ``ReachOptions()``).
    reach_fallback : ReachOptions or None
        More precise (slower) options, tried when a reach with ``reach``
        fails (the set explodes or leaves the model's domain), never when it
        merely misses a measurement: e.g. ``tensor_order=2`` first and 3 only
        where the larger boxes of the merge need it.  Both are sound, so a
        box verified by either is reachset conformant.
    trace : TraceOptions or None
        Options of the trace-conformance steps.
    step1_method : {"auto", "perstep", "optctrl"}, default "auto"
        DISTURBANCETRACE of step 1: the per-step fit of eqs. 62–66 (no
        measurement errors), Alg. 2 (the trace within V of least eq. 36 cost,
        W unbounded), or "auto": the per-step trace where it stays within V,
        else Alg. 2's (noisy measurements at a high rate make the per-step
        trace drift out of V; step 2 then starts from a trace within V).
        A model whose states cannot be read from its outputs goes to Alg. 2 at once.
    X0 : Interval, Zonotope, mapping or None
        Initial set of every case's reach in the α-searches (step 3, the
        merge, the Pareto checks); a mapping ``{case name: Interval or
        Zonotope}`` gives each case its own (every case of the suite must have
        one: a model with an unmeasured state whose start differs per run);
        None: eq. 67, the states read from each case's first measurement and
        V — which needs outputs from which the states can be read: give X0
        for a model with an unmeasured state (``[sets] X0`` of a run file).
    """

    alpha_iterations: int = 10
    merge_iterations: int | None = None
    alpha_max: float = 4.0
    alpha_below_failed_reach: bool = True
    optimize: bool = True
    step2_decimate: int = 1
    merge: bool = True
    reach: object = None
    reach_fallback: object = None
    trace: TraceOptions | None = None
    step1_method: str = "auto"
    X0: object = None

    def __post_init__(self):
        check_field_types(self)
        if isinstance(self.X0, Mapping):
            for name, X in self.X0.items():
                if not isinstance(name, str) or not isinstance(X, (Interval, Zonotope)):
                    raise OptionsError(f"X0 as a mapping takes case names to an Interval or a Zonotope, got "
                                       f"{name!r}: {type(X).__name__}")  # fmt: skip
            object.__setattr__(self, "X0", dict(self.X0))  # a copy: later changes to the caller's dict do not leak in
        elif self.X0 is not None and not isinstance(self.X0, (Interval, Zonotope)):
            raise OptionsError(f"X0 must be an Interval, a Zonotope, a mapping of case names to them or None, got "
                               f"{type(self.X0).__name__}")  # fmt: skip
        if self.step1_method not in ("auto", "perstep", "optctrl"):
            raise OptionsError(f"step1_method must be 'auto', 'perstep' or 'optctrl', got {self.step1_method!r}")
        if int(self.alpha_iterations) != self.alpha_iterations or self.alpha_iterations < 1:
            raise OptionsError(f"alpha_iterations must be a positive integer, got {self.alpha_iterations!r}")
        mi = self.merge_iterations
        if mi is not None and (int(mi) != mi or mi < 1):
            raise OptionsError(f"merge_iterations must be a positive integer or None, got {mi!r}")
        if self.step2_decimate < 1:
            raise OptionsError(f"step2_decimate must be an integer >= 1, got {self.step2_decimate!r}")
        if not (np.isfinite(self.alpha_max) and self.alpha_max >= 1.0):
            raise OptionsError(f"alpha_max must be a finite number >= 1, got {self.alpha_max!r}")
        for name in ("reach", "reach_fallback"):
            value = getattr(self, name)
            if value is not None and not isinstance(value, ReachOptions):
                raise OptionsError(f"{name} must be a ReachOptions or None, got {type(value).__name__}")


@dataclass
class CaseSynthesis:
    """Per-case result: the three boxes, α, timings and verdicts.

    Attributes
    ----------
    name, group : str
    W_TC, W_opt, W_RC : Interval
        Steps 1, 2 and 3 (eqs. 62–66, the SCP box, the α-search of eq. 68).
    alpha : float
    conformant : bool
        ``W_RC`` is reachset conformant (verified).
    seconds : float
    step_seconds : dict
        ``step1``, ``step2``, ``step3`` -> seconds.
    trace_conformant : bool
        ``W_opt`` is trace conformant.
    message : str
    alpha_trials : list of (alpha, conformant)
    verdict : Verdict
        Of ``W_RC``: ``CONFORMANT`` (verified by reachability),
        ``NOT_CONFORMANT`` (at the largest α tried a measurement lies outside
        its reachable set) or ``UNDECIDED`` (the reach failed at the largest α
        tried; ``message`` says why).
    """

    name: str
    group: str
    W_TC: Interval
    W_opt: Interval
    W_RC: Interval
    alpha: float
    conformant: bool
    seconds: float
    step_seconds: dict = field(default_factory=dict)
    trace_conformant: bool = False
    message: str = ""
    alpha_trials: list = field(default_factory=list)
    step1_method: str = ""
    step1_reason: str = ""
    verdict: Verdict | None = None

    def __post_init__(self):
        self.verdict = Verdict.of(self.conformant) if self.verdict is None else Verdict(self.verdict)

    def to_dict(self):
        """The case result as JSON values."""
        return {"name": self.name, "group": self.group, "W_TC": self.W_TC.to_list(), "W_opt": self.W_opt.to_list(),
                "W_RC": self.W_RC.to_list(), "alpha": self.alpha, "verdict": self.verdict.value,
                "conformant": self.verdict.json_conformant,
                "trace_conformant": self.trace_conformant, "seconds": self.seconds,
                "step_seconds": self.step_seconds, "message": self.message,
                "alpha_trials": self.alpha_trials, "step1_method": self.step1_method,
                "step1_reason": self.step1_reason}  # fmt: skip

    @classmethod
    def from_dict(cls, d: dict) -> "CaseSynthesis":
        """The case result from :meth:`to_dict`."""
        box = Interval.from_list
        return cls(d["name"], d["group"], box(d["W_TC"]), box(d["W_opt"]), box(d["W_RC"]), float(d["alpha"]),
                   bool(d["conformant"]), float(d["seconds"]), dict(d.get("step_seconds", {})),
                   bool(d.get("trace_conformant", False)), d.get("message", ""),
                   [tuple(x) if isinstance(x, list) else x for x in d.get("alpha_trials", [])],
                   d.get("step1_method", ""), d.get("step1_reason", ""),
                   Verdict(d.get("verdict", Verdict.of(bool(d["conformant"])))))  # fmt: skip


@dataclass
class SynthesisResult(JsonResult):
    """Outcome of :func:`synthesize_W`.

    Attributes
    ----------
    cases : dict name -> CaseSynthesis
    groups : dict group -> Interval
        ``W_RC,Mnvr`` per group (Table 6).
    group_alpha : dict group -> float
    group_conformant : dict group -> bool
        ``W_RC,Mnvr`` verified conformant for every case of the group.
    V : Interval
    disturbance_names : tuple of str
    seconds : float
    group_seconds : dict group -> float
    group_verdict : dict group -> Verdict
        As ``group_conformant``, with ``UNDECIDED`` where the merge failed
        because a reach failed (not because a measurement left its set).
    log : list of str
        Events of the workers during the run (lost workers, restarts); empty
        when nothing happened.
    merge_seconds : float
        Wall time of the merge (all groups; they run at once on a parallel pool).
    """

    cases: dict
    groups: dict
    group_alpha: dict
    group_conformant: dict
    V: Interval
    disturbance_names: tuple
    seconds: float
    group_seconds: dict = field(default_factory=dict)
    group_verdict: dict = field(default_factory=dict)
    log: list = field(default_factory=list)
    merge_seconds: float = 0.0

    def __post_init__(self):
        for g, ok in self.group_conformant.items():
            self.group_verdict.setdefault(g, Verdict.of(bool(ok)))
        self.group_verdict = {g: Verdict(v) for g, v in self.group_verdict.items()}

    @property
    def verdict(self) -> Verdict:
        """Undecided if any case or group is, else not conformant if any is, else conformant."""
        return overall_verdict([c.verdict for c in self.cases.values()] + list(self.group_verdict.values()))

    def to_dict(self):
        """The result as JSON values (boxes as ``[lo, hi]`` pairs; ``conformant`` values None where undecided)."""
        return {
            "verdict": self.verdict.value,
            "disturbances": list(self.disturbance_names),
            "V": self.V.to_list(),
            "cases": {k: c.to_dict() for k, c in self.cases.items()},
            "groups": {g: W.to_list() for g, W in self.groups.items()},
            "group_alpha": self.group_alpha,
            "group_conformant": {g: v.json_conformant for g, v in self.group_verdict.items()},
            "group_verdict": {g: v.value for g, v in self.group_verdict.items()},
            "group_seconds": self.group_seconds,
            "seconds": self.seconds,
            "merge_seconds": self.merge_seconds,
            "log": list(self.log),
        }

    @classmethod
    def from_dict(cls, d: dict) -> "SynthesisResult":
        """The result from :meth:`to_dict`."""
        return cls({k: CaseSynthesis.from_dict(c) for k, c in d["cases"].items()},
                   {g: Interval.from_list(W) for g, W in d["groups"].items()}, dict(d["group_alpha"]),
                   {g: bool(ok) for g, ok in d["group_conformant"].items()}, Interval.from_list(d["V"]),
                   tuple(d["disturbances"]), float(d["seconds"]), dict(d.get("group_seconds", {})),
                   dict(d.get("group_verdict", {})), list(d.get("log", [])),
                   float(d.get("merge_seconds", 0.0)))  # fmt: skip

    def plot(self, ax=None):
        """``W_RC,Mnvr`` per group: one axes per disturbance channel, a bar per group; returns the axes.

        Parameters
        ----------
        ax : sequence of matplotlib Axes, optional
            One per disturbance; a new figure if None.
        """
        import matplotlib.pyplot as plt

        names = list(self.disturbance_names)
        if ax is None:
            fig, ax = plt.subplots(1, len(names), figsize=(2.2 * len(names), 3), squeeze=False)
            ax = ax[0]
            fig.suptitle("W_RC per group")
        axes = np.atleast_1d(ax)
        for j, name in enumerate(names):
            for i, (g, box) in enumerate(self.groups.items()):
                ok = self.group_verdict.get(g, Verdict.of(self.group_conformant.get(g))) is Verdict.CONFORMANT
                # a marker too: a box of (nearly) zero width is a point; a group without a verified box is hollow
                axes[j].plot([i, i], [box.lo[j], box.hi[j]], lw=6, solid_capstyle="butt", label=g, marker="_",
                             markersize=10, alpha=1.0 if ok else 0.3)  # fmt: skip
            axes[j].set_title(name)
            axes[j].set_xlim(-0.5, len(self.groups) - 0.5)
            axes[j].set_xticks(range(len(self.groups)), list(self.groups), rotation=45, fontsize=7)
        axes[0].figure.tight_layout()
        return axes

    def table(self, digits: int = 4) -> str:
        """Table 6 style: one row per group, one ``[lo, hi]`` column per disturbance.

        A group that is not conformant has no verified box: its cells are "—" (the last box tried is in
        ``groups`` and the JSON).
        """
        if isinstance(digits, bool) or not isinstance(digits, (int, np.integer)) or not 1 <= digits <= 17:
            raise OptionsError(f"SynthesisResult.table: digits must be an integer from 1 to 17, got {digits!r}")
        names = list(self.disturbance_names)
        head = "| group | " + " | ".join(names) + " | α | conformant |"
        rows = [head, "|" + "---|" * (len(names) + 3)]
        for g, W in self.groups.items():
            verdict = self.group_verdict.get(g, Verdict.of(self.group_conformant[g]))
            if verdict is Verdict.CONFORMANT:
                cells = [f"[{lo:.{digits}g}, {hi:.{digits}g}]" for lo, hi in zip(W.lo, W.hi)]
                alpha = f"{self.group_alpha[g]:.4g}"
            else:
                cells, alpha = ["—"] * len(names), "—"
            rows.append(f"| {g} | " + " | ".join(cells) + f" | {alpha} | {verdict.label} |")
        return "\n".join(rows)

    def __str__(self):
        return self.table()


def _synth_case(job) -> CaseSynthesis:
    model, case, V, options = job
    topts = options.trace or TraceOptions()
    t_start = time.perf_counter()
    steps = {}
    t0 = time.perf_counter()
    case12 = case.decimate(options.step2_decimate)
    start, step1_reason = step1_trace(model, case12, V, options.step1_method, topts)
    if not np.all(np.isfinite(start.W_trace)):
        raise ConformanceError(f"case {case.name!r}: synthesis step 1 found no disturbance trace: "
                               f"{step1_reason or start.message}")  # fmt: skip
    W_TC = start.disturbance_box()
    steps["step1"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    trace_ok = False
    W_opt = W_TC
    if options.optimize:
        W_opt, res = minimize_box(model, case12, V, W_TC, start, options=topts)
        trace_ok = bool(res.conformant)
    steps["step2"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    message = ""
    at_one = {}  # the check of α = 1 (W_opt itself), for the message if nothing passes; and the last check

    def check(W, scale_of=None):
        res = reachset_check(model, case, W, V, options)
        if scale_of is not None and np.allclose(W.lo, scale_of.lo) and np.allclose(W.hi, scale_of.hi):
            at_one.setdefault("res", res)
        at_one["last"] = res
        if res.verdict is Verdict.UNDECIDED:
            at_one.setdefault("undecided", res)
        return res.verdict

    below = options.alpha_below_failed_reach
    alpha, W_RC, ok, trials = alpha_search(lambda W: check(W, W_opt), W_opt, options.alpha_iterations,
                                           options.alpha_max, below)  # fmt: skip
    if ok and alpha > 1.0:
        message = f"W_opt was not reachset conformant; enlarged by alpha = {alpha:.4g}"
    elif ok and "undecided" in at_one:
        message = f"the reach failed at a larger alpha; conformant below it, at alpha = {alpha:.4g}"
    if not ok and options.optimize and W_opt is not W_TC:
        # W_opt is only trace conformant on the samples step 2 saw (and the initial set of eq. 67 differs
        # from the trace's x0): fall back to the search on the hull of step 1's and step 2's boxes
        hull = Interval(np.minimum(W_TC.lo, W_opt.lo), np.maximum(W_TC.hi, W_opt.hi))
        alpha2, W2, ok2, trials2 = alpha_search(check, hull, options.alpha_iterations, options.alpha_max, below)
        trials += [("W_TC hull", True)] + trials2
        if ok2:
            alpha, W_RC, ok = alpha2, W2, True
            message = "W_opt was not reachset conformant; alpha scales the hull of W_TC and W_opt"
    # a failed search that met a failed reach is undecided, even if its last (smaller) α missed a measurement
    failed_reach = at_one.get("undecided")
    verdict = Verdict.CONFORMANT if ok else (Verdict.UNDECIDED if failed_reach is not None else at_one["last"].verdict)
    if not ok and verdict is Verdict.UNDECIDED:
        message = f"undecided: the reach failed at the largest α tried ({alpha:g}): {failed_reach.message}"
        smallest = min(a for a, _ in trials if not isinstance(a, str))
        if smallest < alpha:
            message += f"; no smaller α passed (down to {smallest:.3g}: failed reaches or measurements outside)"
    elif not ok:
        res = at_one["res"]
        message = res.message or (f"not reachset conformant up to α = {options.alpha_max:g} (at α = 1 first "
                                  f"violation at t = {res.first_violation_time})")  # fmt: skip
    steps["step3"] = time.perf_counter() - t0
    return CaseSynthesis(case.name, case.group, W_TC, W_opt, W_RC, alpha, ok, time.perf_counter() - t_start, steps,
                         trace_ok, message, trials, start.method, step1_reason, verdict)  # fmt: skip


def synthesize_W(model, suite, V, options: SynthesisOptions | None = None, workers=None, scheduler=None,
                 progress=None, executor=None, pool=None) -> SynthesisResult:  # fmt: skip
    """Minimal reachset-conformant disturbance boxes per case and per group (section 4.3.2).

    Parameters
    ----------
    model : Model
    suite : TestSuite
    V : Interval
        Measurement-error box.
    options : SynthesisOptions
    workers, scheduler : see :func:`reachconf.runner.run_cases`
        Used when no ``pool`` is given: a pool for this call only.
    pool : reachconf.runner.Pool, optional
        The run's pool: the cases and every α-check of the merge are its
        tasks (``executor`` is the older name).
    progress : bool, optional
        Progress bars of the cases and of the merge.

    Returns
    -------
    SynthesisResult
        With ``log``: lost workers and other events of the pool during the run.

    Raises
    ------
    Interrupted, WorkersLost
        On Ctrl-C, or when no worker is left: ``.partial`` holds the finished
        cases' :class:`CaseSynthesis` (``None`` for the others), in suite order.
    """
    require_model(model, "synthesize_W")
    options = check_options(options, SynthesisOptions, "synthesize_W")
    workers = check_workers(workers, "synthesize_W: workers")
    cases = suite_cases(suite, "synthesize_W")
    check_initial_sets(options.X0, cases, model.n, "synthesize_W")
    if model.q == 0:
        raise OptionsError(f"synthesize_W: model {model.name!r} has no disturbance inputs w, so there is no W to "
                           f"synthesize (check it with reachset_conformance or trace_conformance)")  # fmt: skip
    t_all = time.perf_counter()
    Vb = as_box(V, model.p, "V", exact=True)
    Vbox = Interval(Vb.lo, Vb.hi)
    if workers is not None and pool is None and executor is None:
        workers = min(int(workers), max(len(cases), 1))
    with use_pool(pool if pool is not None else executor, workers, scheduler, preload=PRELOAD) as p:
        return _synthesize(model, cases, Vbox, options, p, progress, t_all)


#: modules the local worker processes load once (their server imports them before forking the workers)
PRELOAD = ("reachconf.conformance.synthesis", "reachconf.conformance.pareto")


def _synthesize(model, cases, Vbox, options, pool, progress, t_all):
    mark = len(pool.log)
    prepare_model(pool, model, (options.reach or ReachOptions(), options.reach_fallback))
    # longest cases first: fewer idle workers at the end
    longest = sorted(range(len(cases)), key=lambda i: -np.size(cases[i].t))
    jobs = [(model, cases[i], Vbox, options) for i in longest]
    per_case = [None] * len(cases)
    try:
        done = pool.map(_synth_case, jobs, desc="synthesis", progress=progress)
    except (Interrupted, WorkersLost) as exc:
        for i, cs in zip(longest, exc.partial or []):
            per_case[i] = cs
        exc.partial = per_case
        raise
    for i, cs in zip(longest, done):
        per_case[i] = cs
    result_cases = {c.name: c for c in per_case}
    groups, galpha, gok, gsec, gver = {}, {}, {}, {}, {}
    t_merge = time.perf_counter()
    if options.merge:
        try:
            groups, galpha, gok, gsec, gver = merge_groups(model, cases, per_case, Vbox, options, pool, progress)
        except KeyboardInterrupt:  # the cases are finished: keep them
            raise Interrupted(per_case) from None
        except WorkersLost as exc:
            exc.partial = per_case
            raise
    t_merge = time.perf_counter() - t_merge
    return SynthesisResult(result_cases, groups, galpha, gok, Vbox, tuple(model.disturbance_names),
                           time.perf_counter() - t_all, gsec, gver, pool.log_since(mark), t_merge)  # fmt: skip
