"""``algorithm="adaptive"``: reachability without hand-tuned parameters.

After Wetzlinger, Kochdumper, Bak, Althoff, "Adaptive parameter tuning for
reachability analysis of nonlinear systems", HSCC 2021 (CORA's
``lin-adaptive``): the time step, the zonotope order, the tensor order and
the Taylor terms are chosen step by step from the abstraction and reduction
errors against an error budget (the compiled kernel
:mod:`reachconf_kernels.adaptive` runs the steps of one set; its docstring
has the control law).  Unlike CORA's, it also splits.

Splitting.  Each branch (a piece of the set) keeps account of the error it
has spent, ``integral of rho dt``.  When that exceeds the budget's pro-rata
share plus a slack while the error floor (the error over the set itself) is
over budget — smaller steps cannot help — the kernel returns the set, and
this module decides:

* if halving the image of one of the branch's start generators lowers the
  floor, the branch is discarded and run again from its start as two halves
  (a restart: the error it accumulated halves too, unlike a split where the
  set is);
* else, if halving another generator lowers the floor enough, the set is
  split where it is;
* else the branch goes on over budget for a while.

No split is made when the disturbance widens the set faster than the error
does (the halves would be re-inflated), and a lineage stops restarting when
its restarts did not lower the error rate where the parents asked for them:
each restart is judged by ``rate of the half / rate of the parent`` at the
time the parent asked, and the lineage stops when the geometric mean of these
ratios over its restarts exceeds :data:`RESTART_FEEDBACK`.  The mean, not the
last ratio: restarts of a lineage lower the rate less and less as its pieces
shrink (Van der Pol mu = 2: 0.33, 0.55, 0.74, 0.84, 0.86 down one lineage),
and a lineage whose restarts have paid off on the whole goes on splitting where the error floor is.

The module also grows the kernel's output buffers, compiles the third-order
functions only when a step asks for them, feeds the monitor and turns a
failure into a :class:`~reachconf.errors.ReachError` that says what was tried
(smallest step, highest order, splits) and where it failed (time, state,
error term).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace

import numpy as np

from reachconf.budget import available_memory, format_bytes
from reachconf.errors import ReachError
from reachconf.reach_errors import adaptive_failure
from reachconf.reach_log import ReachLog

__all__ = ["AdaptiveRun", "run_adaptive", "DT_MIN_FRACTION", "MEMORY_SHARE"]

#: Smallest time step, as a fraction of the horizon: below it the analysis gives up.
DT_MIN_FRACTION = 1e-7
#: The kept sets of an adaptive run may use at most this share of the available memory
#: (:func:`reachconf.budget.available_memory`); beyond it the run stops with a ReachError.
MEMORY_SHARE = 0.4
#: Share of the budget given to the order reduction.
REDUCTION_SHARE = 0.5
#: Share of the budget for the linear part's errors (:mod:`reachconf_kernels.adaptive_linear`; chosen on a 3-d system).
LINEAR_SHARE = 0.1
#: A floor above this fraction of the budget makes a split cheaper than smaller steps.
SPLIT_FRACTION = 0.6
#: The part of the error rate that smaller steps remove (rate minus floor) is held to this share of the budget ...
FLOOR_EXCESS = 0.25
#: ... or to this fraction of the floor, if that is larger.
FLOOR_EXCESS_REL = 0.1
#: A branch is split when the error it spent exceeds the budget's pro-rata share plus this fraction of it.
SPLIT_SLACK = 0.1
#: Generators tried as split directions (besides the images of the start set's generators).
SPLIT_CANDIDATES = 3
#: A split is made only if the halves' error floor is at most this fraction of the set's.
SPLIT_GAIN = 0.8
#: The same for restarting the branch with its start set halved: the floor is estimated by halving the image of the
#: start generator in the current set, which misses that the error accumulated since the start shrinks too.
RESTART_GAIN = 0.95
#: A split needs the disturbance's growth rate of the set (relative, 1/s) to be at most this fraction of the error
#: rate: else the set grows mostly by the disturbance, which re-inflates any halves.
RESTART_W = 0.5
#: A lineage's restarts must lower the error rate, where their parents asked for the split, to this fraction of the
#: parents' rate or less (geometric mean over the lineage's restarts); else no branch of that lineage restarts again
#: (its restarts only postponed the problem).  Measured running means at the judged restarts: Van der Pol mu = 1
#: 0.42-0.65, mu = 2 0.33-0.67; coupled Van der Pol 1.06 (budget 0.7), 0.64-0.78 (budget 0.35); Laub-Loomis
#: W = 0.05 0.88, W = 0.1 0.82.
RESTART_FEEDBACK = 0.8
#: Window (fraction of the horizon) over which error rates are averaged for that comparison.
RESTART_WINDOW = 0.01
#: A retry with half the error budget may split this fraction of the times the failed run could: the tighter budget
#: keeps the set small by itself, and spent on every piece it would split far more (coupled Van der Pol, budget
#: 0.35: 239 splits, 48 s CPU with 256 allowed; 63 splits, 10 s with 64; both verified).
RETRY_SPLITS = 0.25
#: After a split that would not help, no split is tried for this fraction of the horizon.
NO_SPLIT_SPAN = 0.05


@dataclass
class _Branch:
    index: int
    t_begin: float
    rec_lo: int
    rec_hi: int = -1
    t_end: float = float("nan")
    sample_step: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))


@dataclass
class AdaptiveRun:
    """Raw result of :func:`run_adaptive`: the sets of every branch as arrays, and the log.

    ``ReachTube.from_run(run, model)`` builds the tube.

    Attributes
    ----------
    samples : ndarray (K,)
    scalar : bool
        The horizon was a number (time-point sets at every step end).
    X0, W : Zonotope
    options : ReachOptions
    tp_c, ti_c : ndarray (P, n)
        Centres of the time-point / time-interval set of every accepted step.
    tp_G, ti_G : ndarray (n, sum of ng)
        Their generators, back to back (``ng_tp``, ``ng_ti`` columns each).
    rec : ndarray (P, N_REC)
        Per-step record (:mod:`reachconf_kernels.adaptive` ``REC_*`` columns).
    branches : list
        Per branch: ``index``, ``t_begin``, ``t_end``, ``rec_lo``, ``rec_hi``
        (its steps) and ``sample_step`` (its step ending at each sample).
    log : ReachLog
    splits : int
    seconds : float
    monitored : bool
        Every sample after the first was passed to the monitor.
    """

    samples: np.ndarray
    scalar: bool
    X0: object
    W: object
    options: object
    tp_c: np.ndarray
    tp_G: np.ndarray
    ti_c: np.ndarray
    ti_G: np.ndarray
    ng_tp: np.ndarray
    ng_ti: np.ndarray
    rec: np.ndarray
    branches: list
    log: ReachLog
    splits: int
    seconds: float
    monitored: bool


class _Buffers:
    """Growable output arrays of the kernel (rows = accepted steps, columns = generators)."""

    def __init__(self, n, steps, gens):
        from reachconf_kernels.adaptive import N_REC

        self.n = n
        self.tp_c = np.zeros((steps, n))
        self.ti_c = np.zeros((steps, n))
        self.tp_G = np.zeros((n, gens))
        self.ti_G = np.zeros((n, gens))
        self.ng_tp = np.zeros(steps, dtype=np.int64)
        self.ng_ti = np.zeros(steps, dtype=np.int64)
        self.rec = np.zeros((steps, N_REC))
        self.rec_err = np.zeros((steps, n))
        self.pos = np.zeros(3, dtype=np.int64)

    def nbytes(self):
        return sum(getattr(self, a).nbytes for a in ("tp_c", "ti_c", "tp_G", "ti_G", "ng_tp", "ng_ti", "rec",
                                                     "rec_err"))  # fmt: skip

    def grown_bytes(self, need_gens):
        """Bytes after :meth:`grow` (for the memory check before it allocates)."""
        s = self.tp_c.shape[0]
        rows = 2 * s if self.pos[0] >= s else s
        g = self.tp_G.shape[1]
        cols = 2 * g + need_gens if max(self.pos[1], self.pos[2]) + need_gens > g else g
        return 8.0 * rows * (4 * self.n + 2 + self.rec.shape[1]) + 2 * 8.0 * self.n * cols

    def grow(self, need_gens):
        s = self.tp_c.shape[0]
        if self.pos[0] >= s:
            for name in ("tp_c", "ti_c", "ng_tp", "ng_ti", "rec", "rec_err"):
                a = getattr(self, name)
                b = np.zeros((2 * s,) + a.shape[1:], dtype=a.dtype)
                b[:s] = a
                setattr(self, name, b)
        g = self.tp_G.shape[1]
        if max(self.pos[1], self.pos[2]) + need_gens > g:
            for name in ("tp_G", "ti_G"):
                a = getattr(self, name)
                b = np.zeros((self.n, 2 * g + need_gens))
                b[:, :g] = a
                setattr(self, name, b)

    def trimmed(self):
        s, g1, g2 = (int(v) for v in self.pos)
        return (self.tp_c[:s], self.tp_G[:, :g1], self.ti_c[:s], self.ti_G[:, :g2], self.ng_tp[:s],
                self.ng_ti[:s], self.rec[:s], self.rec_err[:s])  # fmt: skip


def _halve(c, G, j):
    g = G[:, j].copy()
    Gh = G.copy()
    Gh[:, j] = g / 2
    return (np.ascontiguousarray(c - g / 2), np.ascontiguousarray(Gh)), (
        np.ascontiguousarray(c + g / 2),
        np.ascontiguousarray(Gh.copy()),
    )


@dataclass
class _Task:
    """A branch to run: where it is now, its split budget, and where it began (splits can go back there)."""

    branch: int
    t: float
    k: int
    c: np.ndarray
    G: np.ndarray
    state: np.ndarray
    err: np.ndarray
    share: float
    start: tuple  # (t, k, c, G, state) of the branch's first set
    keep: int  # leading generators that are the images of the start set's generators
    split_after: float = -np.inf  # a split did not help before this time
    parent_trigger: float = np.nan  # when the parent of a restarted branch asked for the split ...
    parent_rate: float = np.nan  # ... and its error rate then
    no_restart: bool = False  # the restarts of this lineage did not lower the error rate enough
    gain_log: float = 0.0  # sum of log(rate of the half / rate of the parent) over the lineage's judged restarts ...
    gain_n: int = 0  # ... and their number
    judged: bool = False  # the restart that made this branch has been judged


def run_adaptive(model, Z0, Wz, samples, U, options, scalar, horizon, monitor=None, progress=None,
                 stopped=StopIteration) -> AdaptiveRun:  # fmt: skip
    """Adaptive reach of ``model`` from ``Z0`` over the sample grid ``samples`` (see :func:`_run_once`).

    When the abstraction error cannot be bounded (the set explodes), the whole reach runs again with half the error
    budget and a quarter of the splits (:data:`RETRY_SPLITS`), up to ``AdaptiveReach.budget_retries`` times; when
    the last budget fails too, once more holding the step where a smaller one cannot lower the error rate
    (:data:`reachconf_kernels.adaptive.FUTILE_SHRINK`), over budget rather than giving up (the ordinary run first:
    a 40-state chain of cubic springs fails held and is verified ordinarily on the same budget).  Every finished run
    is sound; the budgets tried are in ``log.budgets_tried``.  Domain and step/memory failures are not retried.
    """
    alg, tried, held = options.alg, [], False
    while True:
        try:
            run = _run_once(model, Z0, Wz, samples, U, options, scalar, horizon, monitor=monitor, progress=progress,
                            stopped=stopped, last=held)  # fmt: skip
        except ReachError as exc:
            retryable = exc.term not in ("domain", "steps/memory")
            tried.append(options.alg.error_budget)
            if not retryable or held:
                if len(tried) > 1:  # (the held run repeats the last budget)
                    text = ", ".join(f"{b:g}" for b in tried[:-1]) + (", and " if held else ", ") + f"{tried[-1]:g}"
                    text += " again holding the step over budget" if held else ""
                    exc.args = (f"{exc.args[0]} (error budgets tried, each from the start: {text})",)
                    exc.tried = {**(exc.tried or {}), "error_budgets": tried}
                raise
            if len(tried) > alg.budget_retries:  # the last budget failed: once more, held over budget
                held = True
            else:
                options = replace(options, algorithm=replace(options.alg, error_budget=0.5 * options.alg.error_budget),
                    max_splits=max(min(1, options.effective_max_splits),
                                int(RETRY_SPLITS * options.effective_max_splits)))  # fmt: skip
            if progress is not None and hasattr(progress, "reset"):
                progress.reset()
            continue
        run.log.budgets_tried = np.array([*tried, options.alg.error_budget], dtype=float)
        return run


def _run_once(model, Z0, Wz, samples, U, options, scalar, horizon, monitor=None, progress=None,
              stopped=StopIteration, last=False) -> AdaptiveRun:  # fmt: skip
    """Adaptive reach of ``model`` from ``Z0`` over the sample grid ``samples``, with one error budget.

    ``U`` has one row per sample interval; steps end exactly at every sample
    time.  ``monitor(js, c, G, ng)`` is called with the time-point sets of the
    samples reached while nothing was split (a True return raises
    ``stopped(sample)``, :class:`reachconf.reach.ReachStopped` from ``reach_run``).

    Splitting: when a branch's error floor is over budget, the kernel returns
    its set.  If halving one of the images of the branch's start generators
    lowers the floor enough, the branch is discarded and restarted as two
    halves of its start set (the accumulated error halves too); else, if
    halving another generator helps, the set is split where it is; else the
    branch goes on over budget.
    """
    from reachconf_kernels import adaptive as ak
    from reachconf_kernels.adaptive_split import split_choice

    n = model.n
    K = samples.size
    opts = options
    horizon = min(float(horizon), float(opts.alg.budget_horizon))  # the span the budget (and fractions) spread over
    remainder = opts.remainder
    kappa_mode = 0 if opts.tensor_order is None else int(opts.tensor_order)
    # a "taylor" build serves both tensor orders; "tensor" builds the third-order functions when asked
    have3 = remainder == "taylor" or kappa_mode == 3
    comp = model.compiled(order=3 if have3 else 2, remainder=remainder)
    dt_max = float(opts.time_step) if opts.time_step is not None else horizon / 10.0
    budget = float(opts.alg.error_budget) / horizon
    fpar = np.zeros(ak.N_FPAR)
    fpar[ak.P_BUDGET] = budget
    fpar[ak.P_DT_MAX] = dt_max
    fpar[ak.P_DT_MIN] = DT_MIN_FRACTION * horizon
    fpar[ak.P_RED_SHARE] = REDUCTION_SHARE
    fpar[ak.P_MAX_ORDER] = float(opts.alg.max_order)
    fpar[ak.P_ERR_ORDER] = float(opts.error_order)
    fpar[ak.P_INTER_ORDER] = float(opts.intermediate_order)
    fpar[ak.P_ROUND] = float(opts.rounding)
    fpar[ak.P_SPLIT_FRAC], fpar[ak.P_SLACK] = SPLIT_FRACTION, SPLIT_SLACK * float(opts.alg.error_budget)
    fpar[ak.P_T0] = float(samples[0])
    fpar[ak.P_EXCESS], fpar[ak.P_EXCESS_REL] = FLOOR_EXCESS, FLOOR_EXCESS_REL
    fpar[ak.P_LIN_GOAL] = LINEAR_SHARE
    fpar[ak.P_HORIZON] = horizon
    fpar[ak.P_DIST_W] = RESTART_W
    fpar[ak.P_RTOL], fpar[ak.P_ATOL] = float(opts.alg.rtol), float(opts.alg.atol)  # the rates' radius floor
    ipar = np.zeros(ak.N_IPAR, dtype=np.int64)
    ipar[ak.I_KAPPA_MODE] = kappa_mode
    ipar[ak.I_TAYLOR_MIN] = int(opts.taylor_terms)
    ipar[ak.I_MAX_ITER] = int(opts.max_error_iterations)
    ipar[ak.I_LAST] = int(last)  # no smaller budget left: hold the step where smaller ones cannot lower the error rate
    max_splits = opts.effective_max_splits
    max_steps = int(opts.alg.max_steps)
    mem_limit = MEMORY_SHARE * available_memory()
    wc = np.array(Wz.center, dtype=float)
    WG = np.array(Wz.generators, dtype=float)
    params = model.param_vector
    U = np.array(U, dtype=float, order="C")
    gneed = int(n * opts.alg.max_order) + 2 * n + 2
    est_steps = max(64, min(20000, max_steps, 4 * (K - 1) + 200))
    buf = _Buffers(n, est_steps, est_steps * min(gneed, 4 * n + 4))
    state0 = np.zeros(ak.N_STATE)
    state0[ak.S_DT] = min(dt_max, horizon / 100.0)
    state0[ak.S_MIN_DT] = np.inf
    state0[ak.S_FLOOR] = -1.0
    c0, G0 = np.array(Z0.center, dtype=float), np.array(Z0.generators, dtype=float)
    keep0 = min(G0.shape[1], 2 * n)
    branches = [_Branch(0, float(samples[0]), 0, sample_step=np.full(K, -1, dtype=np.int64))]
    pending = [_Task(0, float(samples[0]), 0, c0, G0, state0, np.zeros(n), float(max_splits),
                     (float(samples[0]), 0, c0, G0, state0.copy()), keep0)]  # fmt: skip
    split_log = []  # (time decided, time applied, parent, child a, child b)
    chunk = max(50, (K - 1) // 50) if monitor is not None else K
    smallest, highest = np.inf, 2
    k_fed = 0  # last sample given to the monitor
    t_start = time.perf_counter()
    while pending:
        task = pending.pop()
        br = branches[task.branch]
        br.rec_lo = int(buf.pos[0])
        at_start = buf.pos.copy()
        t, k, c, G, state = task.t, task.k, task.c, task.G, task.state
        while True:
            ipar[ak.I_HAVE3] = int(have3)
            ipar[ak.I_KEEP] = task.keep
            can_split = task.share >= 1.0 and len(split_log) < max_splits
            ipar[ak.I_CAN_SPLIT] = int(can_split)
            fpar[ak.P_SPLIT_AFTER] = task.split_after
            k_stop = min(K - 1, k + chunk) if (monitor is not None and not split_log) else K
            code, t, k, c, G = ak.adaptive_run(
                np.ascontiguousarray(c), np.ascontiguousarray(G), samples, k, t, U, wc, WG, params,
                comp.f, comp.jac, comp.hess, comp.lagrange_iv, fpar, ipar, state, task.err, k_stop,
                buf.tp_c, buf.tp_G, buf.ti_c, buf.ti_G, buf.ng_tp, buf.ng_ti, br.sample_step,
                buf.rec, buf.rec_err, buf.pos,
            )  # fmt: skip
            smallest = min(smallest, state[ak.S_MIN_DT])
            highest = max(highest, int(state[ak.S_MAX_KAPPA]))
            if progress is not None and k > progress.n:
                progress.update(k - progress.n)
            if monitor is not None and not split_log and code in (ak.DONE, ak.CHUNK) and k > k_fed:
                js = np.arange(k_fed + 1, k + 1)
                k_fed = k
                if monitor(js, *_tp_sets(buf, br.sample_step[js])):
                    raise stopped(int(js[0]))
            if code == ak.DONE:
                br.t_end = float(t)
                br.rec_hi = int(buf.pos[0])
                break
            if code == ak.FULL:
                limit = _check_room(buf, gneed, max_steps, mem_limit)
                if limit:
                    raise adaptive_failure(model, opts, state, t, c, G, smallest, highest, len(split_log), max_splits,
                                           DT_MIN_FRACTION * horizon, limit=limit, steps=int(buf.pos[0]))  # fmt: skip
                buf.grow(gneed)
                continue
            if code == ak.NEED_ORDER3:
                comp, have3 = model.compiled(order=3, remainder=remainder), True
                continue
            if code == ak.CHUNK:
                continue
            if code in (ak.SPLIT, ak.FAIL) and can_split and G.shape[1] > 0:
                rate, jk, rk, jo, ro = split_choice(
                    np.ascontiguousarray(c), np.ascontiguousarray(G), U[min(k, K - 2)], wc, WG, params, comp.hess,
                    comp.lagrange_iv, int(max(state[ak.S_KAPPA], 2)), fpar, float(state[ak.S_DT]), task.keep,
                    SPLIT_CANDIDATES)  # fmt: skip
                w_rate = _disturbance_rate(comp, c, G, U[min(k, K - 2)], wc, WG, params)
                useful = w_rate <= RESTART_W * rate  # else the disturbance re-inflates any halves
                if not task.no_restart and not task.judged and np.isfinite(task.parent_trigger):
                    # did the restarts of this lineage lower the error rate where the parents got stuck?
                    task.judged = True
                    got = _rate_near(buf, br.rec_lo, task.parent_trigger, RESTART_WINDOW * horizon)
                    if got is not None and 0.0 < task.parent_rate < np.inf:
                        task.gain_log += float(np.log(max(got, 1e-300) / task.parent_rate))
                        task.gain_n += 1
                        task.no_restart = bool(np.exp(task.gain_log / task.gain_n) > RESTART_FEEDBACK)
                restart_ok = useful and jk >= 0 and not task.no_restart and rk <= RESTART_GAIN * rate
                half_share = (task.share - 1.0) / 2.0
                ia, ib = len(branches), len(branches) + 1
                trigger = (np.nan, np.nan)
                if restart_ok:  # restart from the branch's start, halved
                    t_b, k_b, c_b, G_b, state_b = task.start
                    trigger = (float(t), _rate_near(buf, br.rec_lo, float(t), RESTART_WINDOW * horizon) or np.inf)
                    buf.pos[:] = at_start
                    br.rec_hi = br.rec_lo
                    halves = _halve(c_b, G_b, jk)
                    at = (t_b, k_b)
                    st = state_b
                elif useful and jo >= 0 and ro <= SPLIT_GAIN * rate:  # split here
                    br.t_end = float(t)
                    br.rec_hi = int(buf.pos[0])
                    halves = _halve(c, G, jo)
                    at = (float(t), k)
                    st = state
                else:  # halving does not lower the floor: go on over budget for a while
                    if code == ak.FAIL:
                        raise adaptive_failure(model, opts, state, t, c, G, smallest, highest, len(split_log),
                                               max_splits, DT_MIN_FRACTION * horizon, steps=int(buf.pos[0]), t0=samples[0])
                    task.split_after = float(t) + NO_SPLIT_SPAN * horizon
                    continue
                for idx in (ia, ib):
                    branches.append(_Branch(idx, float(at[0]), -1, sample_step=np.full(K, -1, dtype=np.int64)))
                split_log.append((float(t), float(at[0]), task.branch, ia, ib))
                for idx, (hc, hG) in ((ib, halves[1]), (ia, halves[0])):
                    s2 = st.copy()
                    s2[ak.S_SINCE_CHECK] = 0
                    pending.append(_Task(idx, at[0], at[1], hc, hG, s2, np.zeros(n), half_share,
                                         (at[0], at[1], hc, hG, s2.copy()), task.keep, -np.inf, *trigger,
                                         task.no_restart, task.gain_log, task.gain_n))  # fmt: skip
                break
            raise adaptive_failure(model, opts, state, t, c, G, smallest, highest, len(split_log), max_splits,
                                   DT_MIN_FRACTION * horizon, steps=int(buf.pos[0]), t0=samples[0])
    seconds = time.perf_counter() - t_start
    tp_c, tp_G, ti_c, ti_G, ng_tp, ng_ti, rec, rec_err = buf.trimmed()
    log = ReachLog.from_records(rec, branches, split_log, budget, smallest, n)
    return AdaptiveRun(samples, scalar, Z0, Wz, options, tp_c, tp_G, ti_c, ti_G, ng_tp, ng_ti, rec, branches, log,
                       len(split_log), seconds, monitor is not None and not split_log)  # fmt: skip


def _check_room(buf, gneed, max_steps, mem_limit):
    """Why the buffers may not grow (``max_steps`` reached, or the memory share), or ``""``."""
    if buf.pos[0] >= max_steps:
        return f"it took more than max_steps = {max_steps} steps"
    need = buf.grown_bytes(gneed)
    if need > mem_limit:
        return (f"its sets would need {format_bytes(need)}, more than {MEMORY_SHARE:.0%} of the available memory "
                f"({format_bytes(mem_limit / MEMORY_SHARE)})")  # fmt: skip
    return ""


def _disturbance_rate(comp, c, G, u, wc, WG, params):
    """``mean_i (|B| rad(W))_i / rad_i``: how fast the disturbance alone widens the set, relative to its size (1/s)."""
    n = c.size
    if WG.shape[1] == 0:
        return 0.0
    z = np.concatenate([c, u, wc])
    J = np.zeros((n, z.size))
    comp.jac(z, params, J)
    wrad = np.abs(J[:, n + u.size :]) @ np.abs(WG).sum(axis=1)
    rad = np.abs(G).sum(axis=1)
    ok = rad > 0
    return float(np.mean(wrad[ok] / rad[ok])) if np.any(ok) else np.inf


def _rate_near(buf, rec_lo, t, window):
    """Mean error rate of the steps of the current branch (records ``rec_lo..pos``) within ``window`` before ``t``."""
    from reachconf_kernels import adaptive as ak

    rec = buf.rec[rec_lo : int(buf.pos[0])]
    if rec.shape[0] == 0 or rec[-1, ak.REC_T0] + rec[-1, ak.REC_DT] < t - 1e-12:
        return None
    sel = (rec[:, ak.REC_T0] + rec[:, ak.REC_DT] >= t - window) & (rec[:, ak.REC_T0] <= t)
    return float(np.mean(rec[sel, ak.REC_RHO])) if np.any(sel) else None


def _tp_sets(buf, recs):
    """Time-point sets of the records ``recs`` as padded arrays ``(c (J, n), G (J, n, g), ng (J,))``."""
    off = np.concatenate([[0], np.cumsum(buf.ng_tp[: int(buf.pos[0])])])
    ng = buf.ng_tp[recs].copy()
    G = np.zeros((recs.size, buf.n, max(1, int(ng.max(initial=0)))))
    for i, r in enumerate(recs):
        G[i, :, : ng[i]] = buf.tp_G[:, off[r] : off[r] + ng[i]]
    return buf.tp_c[recs].copy(), G, ng
