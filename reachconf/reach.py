"""Reachability analysis: ``reach(model, X0, times, inputs, W, options) -> ReachTube``.

Linear and nonlinear systems share one engine (:mod:`reachconf_kernels.nonlinear`):
a linear model has a zero Hessian, so its abstraction error is exactly zero
and each step is the linear-system step with uncertain inputs (Taylor series
of the exponential with remainder and the time-interval correction terms).
Nonlinear models use conservative linearisation (``algorithm="lin"``,
tensor order 2 or 3) or conservative polynomialisation (``"poly"``, tensor
order 3), with CORA's iterative abstraction-error bound.  When the error
cannot be bounded the set is split (up to ``max_splits`` times); after that a
:class:`~reachconf.ReachError` says when, in which state, through which error
term the set exploded and what to try.

All sets are sound enclosures: no trajectory of ``x' = f(x, u, w)`` with
``x(t0) in X0`` and any (measurable) ``w(t) in W`` leaves them.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, replace

import numpy as np

from reachconf.budget import check_memory, progress_bar, tube_bytes_per_step
from reachconf.checks import check_options
from reachconf.errors import OptionsError, ReachError
from reachconf.model.core import require_model
from reachconf.reach_adaptive import run_adaptive
from reachconf.reach_adaptive_stream import run_adaptive_streamed, streamed_grid
from reachconf.reach_errors import fixed_step_failure, float_failure
from reachconf.reach_options import AdaptiveReach, ReachOptions
from reachconf.sets.convert import as_zonotope
from reachconf.sets.core import Zonotope
from reachconf.timestamps import steps_per_interval
from reachconf.tube import ReachTube

__all__ = ["ReachOptions", "reach", "reach_run", "ReachRun", "ReachStopped"]


# ---------------------------------------------------------------------------
# argument handling
# ---------------------------------------------------------------------------
def sample_times(times) -> np.ndarray:
    """The sample times of ``times`` (a final time ``T``: ``[0, T]``), checked (:class:`ReachError` if bad)."""
    if np.iscomplexobj(times):
        raise ReachError(f"times must be real numbers, got {times!r}")
    if isinstance(times, (str, bytes)) or (isinstance(times, np.ndarray) and times.dtype.kind in "USO"):
        raise ReachError(f"times must be a final time or an array of sample times, got {times!r} "
                         f"(numbers, not text)"[:200])  # fmt: skip
    try:  # a writeable copy: the compiled kernels take no read-only arrays (TestCase.t is one)
        arr = np.array(times, dtype=float)
    except (TypeError, ValueError):
        raise ReachError(f"times must be a final time or an array of sample times, got {times!r}") from None
    if arr.ndim == 0:
        if not (math.isfinite(float(arr)) and float(arr) > 0):
            raise ReachError(f"times: the final time must be a positive number, got {times!r}")
        return np.array([0.0, float(arr)])
    if arr.ndim > 1:
        raise ReachError(f"times must be a final time or a 1-D array of sample times, got shape {arr.shape}")
    if arr.size < 2:
        raise ReachError("times must hold at least two sample times (or be a final time)")
    if not np.all(np.isfinite(arr)):
        raise ReachError("times contains NaN or inf")
    bad = np.nonzero(np.diff(arr) <= 0)[0]
    if bad.size:
        raise ReachError(f"times must be strictly increasing; times[{bad[0] + 1}] = {arr[bad[0] + 1]} "
                         f"<= times[{bad[0]}] = {arr[bad[0]]}")
    return arr


def _step_grid(samples: np.ndarray, time_step: float | None, scalar_horizon: bool):
    """Sub-steps of every sample interval: (dts, t_start, sample_of_step, step_of_sample)."""
    counts = _step_counts(samples, time_step, scalar_horizon)
    k = np.repeat(np.arange(samples.size - 1), counts)  # the sample interval of each step
    offsets = np.concatenate([[0], np.cumsum(counts)])
    t_start = samples[k] + (np.arange(k.size) - offsets[k]) * (np.diff(samples) / counts)[k]
    dts = np.diff(np.append(t_start, samples[-1]))  # the stamps' differences (exact for neighbours): steps cover them
    return dts, t_start, k, offsets


def _step_counts(samples: np.ndarray, time_step: float | None, scalar_horizon: bool) -> np.ndarray:
    horizon = samples[-1] - samples[0]
    if time_step is None:
        time_step = horizon / 100.0 if scalar_horizon else min(horizon / 100.0, float(np.min(np.diff(samples))))
    return steps_per_interval(samples, time_step)


def integration_steps(times, options=None) -> int:
    """How many integration steps :func:`reach` takes over ``times`` with ``options`` (for memory estimates).

    Counted without building the step grid (a tiny ``time_step`` is caught before it allocates); ``"adaptive"``
    without ``time_step``: one per sample interval and per hundredth of the horizon (not per shortest interval).
    """
    samples, options = sample_times(times), options or ReachOptions()
    step = options.time_step  # adaptive without one: a hundredth of the horizon (a 1e-8-s interval counted 2e8 steps)
    step = float(samples[-1] - samples[0]) / 100.0 if step is None and isinstance(options.alg, AdaptiveReach) else step
    return int(_step_counts(samples, step, np.ndim(times) == 0).sum(dtype=np.float64))  # (no int64 overflow)


def _input_table(model, inputs, samples, t_start, sample_of_step, per_step: bool) -> np.ndarray:
    """Known input of every step, shape (S, m)."""
    m = model.m
    S = t_start.size
    if m == 0:
        if inputs is not None and not callable(inputs) and np.size(inputs) != 0:
            raise ReachError(f"model {model.name!r} has no inputs, but inputs were given")
        return np.zeros((S, 0))
    if inputs is None:
        raise ReachError(f"model {model.name!r} needs inputs {model.input_names}; pass inputs=")
    if callable(inputs):
        at = t_start if per_step else samples[sample_of_step]
        try:
            U = np.array([np.asarray(inputs(float(t)), dtype=float).reshape(-1) for t in at])
        except (TypeError, ValueError) as exc:
            raise ReachError(f"inputs(t) failed: {exc}") from None
        if U.shape != (S, m):
            raise ReachError(f"inputs(t) must return {m} values ({model.input_names}), got shape {U.shape[1:]}")
    else:
        U = np.asarray(inputs, dtype=float)
        if U.ndim == 1 and U.size == m:
            U = np.tile(U, (samples.size, 1))
        elif U.ndim == 1 and m == 1:
            U = U[:, None]
        if U.ndim != 2 or U.shape[1] != m or U.shape[0] not in (samples.size, samples.size - 1):
            raise ReachError(
                f"inputs must have shape ({samples.size}, {m}) (one row per sample time, columns "
                f"{model.input_names}), got {np.shape(inputs)}"
            )
        U = U[sample_of_step]
    if not np.all(np.isfinite(U)):
        row = int(np.nonzero(~np.all(np.isfinite(U), axis=1))[0][0])
        raise ReachError(f"inputs contain NaN or inf (step {row})")
    return np.array(U, order="C")  # writeable copy


# ---------------------------------------------------------------------------
# splitting
# ---------------------------------------------------------------------------
def _split(c: np.ndarray, G: np.ndarray, method: str):
    """Two zonotopes whose union contains Z(c, G)."""
    from reachconf_kernels import zonotope as zk

    if method == "box" or G.shape[1] == 0:
        lo, hi = zk.interval_hull(c, G)
        width = hi - lo
        scale = np.where(width > 0, width, 1.0)
        axis = int(np.argmax(width / scale.max())) if method == "box" else int(np.argmax(width))
        cc, GG = zk.from_interval(lo, hi)
        # generator along the chosen axis
        j = int(np.argmax(np.abs(GG[axis])))
        g = GG[:, j].copy()
    else:
        lo, hi = zk.interval_hull(c, G)
        width = np.where(hi - lo > 0, hi - lo, 1.0)
        normalised = np.abs(G) / width[:, None]
        j = int(np.argmax(normalised.sum(axis=0)))
        cc, GG, g = c, G, G[:, j].copy()
    G_half = GG.copy()
    G_half[:, j] = g / 2
    a, b, G_half = np.ascontiguousarray(cc - g / 2), np.ascontiguousarray(cc + g / 2), np.ascontiguousarray(G_half)
    return (a, G_half), (b, G_half)


def _push_halves(pending, options, splits, status, step, c_fail, G_fail, depth) -> bool:
    """Split a set that failed at ``step`` into two pending branches, if allowed (returns whether it was)."""
    if not (splits < options.effective_max_splits and status in (3, 4, 2) and G_fail.shape[1] > 0):
        return False
    half_a, half_b = _split(np.asarray(c_fail), np.asarray(G_fail), options.split_method)
    pending.append((step, *half_a, depth + 1))
    pending.append((step, *half_b, depth + 1))
    return True


# ---------------------------------------------------------------------------
# main entry point
# ---------------------------------------------------------------------------
def reach(model, X0, times, inputs=None, W=None, options: ReachOptions | None = None):
    """Reachable sets of ``x' = f(x, u, w)`` from ``X0`` (source report eq. 11).

    Parameters
    ----------
    model : reachconf.Model
    X0 : Interval or Zonotope
        Initial set, dimension ``model.n``.
    times : float or array_like
        Final time (sets every ``time_step``) or strictly increasing sample
        times; time-point sets are returned at these times.
    inputs : array_like (K, m) or callable, optional
        Known inputs, piecewise constant between sample times: row ``k`` acts
        on ``[t_k, t_{k+1})``; a callable ``u(t)`` is evaluated at ``t_k``.
    W : Interval or Zonotope, optional
        Disturbance set; the disturbance may vary arbitrarily in time within it.
        Default: ``{0}``.
    options : ReachOptions, optional

    Returns
    -------
    ReachTube

    Raises
    ------
    SetError, ReachError, OptionsError
    ResourceError
        Before any work, if the tube would need more memory than is available
        (:func:`reachconf.reach_stream.reach_streamed` keeps it bounded).
    """
    require_model(model, "reach")
    options = check_options(options, ReachOptions, "reach")
    per, fixed = tube_bytes_per_step(model.n, model.m, options.zonotope_order)
    check_memory(f"reach of model {model.name!r}", integration_steps(times, options), per, fixed,
                 hint="reachconf.reach_stream.reach_streamed computes it in bounded memory")  # fmt: skip
    with float_failure(model):
        return ReachTube.from_run(reach_run(model, X0, times, inputs, W, options), model)


class ReachStopped(Exception):
    """Raised by :func:`reach_run` when its ``monitor`` asks to stop (not a user error).

    Attributes
    ----------
    sample : int
        Index of the sample time at which the monitor stopped the reach.
    """

    def __init__(self, sample: int):
        super().__init__(f"stopped by the monitor at sample {sample}")
        self.sample = int(sample)


@dataclass
class ReachRun:
    """The raw result of :func:`reach_run`: the sets as kernel arrays, per branch of the splits.

    ``ReachTube.from_run(run, model)`` turns it into a :class:`~reachconf.ReachTube`.

    Attributes
    ----------
    samples : ndarray (K,)
        Sample times.
    step_offsets : ndarray (K,)
        Number of integration steps up to each sample time.
    t_start, dts : ndarray (S,)
        Start and length of each integration step.
    X0, W : Zonotope
        The initial and disturbance sets used.
    branches : list of (first_step, stop_step, store)
        Arrays of the sets of each branch (one without splits).
    splits : int
    seconds : float
    options : ReachOptions
    monitored : bool
        Every sample after the first was passed to the monitor (no split happened).
    """

    samples: np.ndarray
    step_offsets: np.ndarray
    t_start: np.ndarray
    dts: np.ndarray
    X0: Zonotope
    W: Zonotope
    branches: list
    splits: int
    seconds: float
    options: ReachOptions
    monitored: bool  # every sample after the first was passed to the monitor (no split happened)


def reach_run(model, X0, times, inputs=None, W=None, options=None, monitor=None, stream=None,
              chunk_steps=None) -> ReachRun:  # fmt: skip
    """The computation behind :func:`reach`, on raw arrays, optionally watched by a monitor.

    Arguments as :func:`reach`, plus ``monitor``, ``stream`` and ``chunk_steps``.

    ``monitor(samples, c, G, ng)``, if given, is called after every computed
    chunk of the unsplit reach with the indices of the sample times the chunk
    reached and their time-point sets (``c`` (J, n), ``G`` (J, n, gmax), ``ng``
    (J,) generators in use); a True return raises :class:`ReachStopped`.  After
    a split the monitor is no longer called (``monitored`` is then False).

    Streaming (``stream`` given): the sets are not kept — memory does not
    grow with the horizon.  After every computed chunk of every branch (also
    after splits) ``stream(k0, k1, store, base)`` receives the sets of steps
    ``k0 .. k1-1`` (at store index ``step - base``; ``chunk_steps`` steps per
    chunk, default 500), and the monitor is called for every branch with a
    fifth argument ``split`` (True once the set has been split: the sets are
    then pieces of a union, and a measurement outside one piece is no
    violation by itself).  ``branches`` is empty.  With ``algorithm="adaptive"``
    the chunks are of ``chunk_steps`` sample intervals (default
    :data:`~reachconf.reach_adaptive_stream.CHUNK_SAMPLES`), the state set is
    carried across them as a union of pieces, and ``stream(k0, k1, run)``
    receives, per piece, the adaptive run over the samples ``k0 .. k1``
    (:func:`reachconf.reach_adaptive_stream.run_adaptive_streamed`).

    Returns
    -------
    ReachRun, AdaptiveRun or StreamedAdaptiveRun
        (:class:`reachconf.reach_adaptive.AdaptiveRun` with ``algorithm="adaptive"``,
        :class:`reachconf.reach_adaptive_stream.StreamedAdaptiveRun` if also streamed)

    Raises
    ------
    SetError, ReachError, OptionsError
        As :func:`reach`; :class:`ReachStopped` when the monitor stops the run.
    """
    from reachconf_kernels import nonlinear as nl

    options = options or ReachOptions()
    if not isinstance(options, ReachOptions):
        raise OptionsError(f"options must be a ReachOptions, got {type(options).__name__}")
    n, q = model.n, model.q
    Z0 = as_zonotope(X0, n, "X0")
    if W is None:
        W = Zonotope(np.zeros(q), np.zeros((q, 0)))
    Wz = as_zonotope(W, q, "W")
    scalar = np.ndim(times) == 0
    samples = sample_times(times)
    if isinstance(options.alg, AdaptiveReach):
        return _adaptive(model, Z0, Wz, samples, scalar, inputs, options, monitor, stream, chunk_steps)
    dts, t_start, sample_of_step, step_offsets = _step_grid(samples, options.time_step, scalar)
    U = _input_table(model, inputs, samples, t_start, sample_of_step, per_step=scalar)
    if scalar:  # every step end is a sample time
        samples = np.concatenate([[samples[0]], t_start + dts])
        step_offsets = np.arange(samples.size)

    order = options.effective_tensor_order
    comp = model.compiled(order=3 if order == 3 else 2, remainder=options.remainder)
    S = dts.size
    gmax = int(n * max(options.zonotope_order, 1.0)) + n + 1
    me = np.atleast_1d(np.asarray(options.max_error, dtype=float))
    if me.size not in (1, n):
        raise OptionsError(f"ReachOptions.max_error has {me.size} entries, model {model.name!r} has {n} states")
    me = np.broadcast_to(me, (n,)).copy()
    params = model.param_vector
    algorithm = options.alg.kernel_code
    reduce_method = options.reduction_method.kernel_code

    def new_store(size=S):
        return dict(
            tp_c=np.zeros((size, n)),
            tp_G=np.zeros((size, n, gmax)),
            ti_c=np.zeros((size, n)),
            ti_G=np.zeros((size, n, gmax)),
            ng_tp=np.zeros(size, dtype=np.int64),
            ng_ti=np.zeros(size, dtype=np.int64),
            err=np.zeros((size, n)),
        )

    if stream is not None:
        return _reach_streamed(model, options, Z0, Wz, samples, step_offsets, t_start, dts, U, comp, gmax,
                               me, params, algorithm, order, reduce_method, new_store, monitor, stream,
                               chunk_steps)  # fmt: skip

    sample_step = np.asarray(step_offsets, dtype=np.int64) - 1  # step ending at each sample (-1: sample 0)
    t0 = time.perf_counter()
    branches = []  # (first_step, stop_step, store)
    pending = [(0, np.array(Z0.center), np.array(Z0.generators), 0)]  # writeable copies
    splits = 0
    chunk = max(50, S // 50)
    bar = progress_bar(options.progress, S, f"reach {model.name}", "step", 2000, terminal_only=True)
    try:
        while pending:
            start, c, G, depth = pending.pop()
            store = new_store()
            k = start
            failed = None
            while k < S:
                stop = min(S, k + chunk)
                status, step, bad_state, bad_term, c_fail, G_fail = nl.reach_loop(
                    c, G, U, dts, np.array(Wz.center), np.array(Wz.generators), params,
                    int(options.taylor_terms), comp.f, comp.jac, comp.hess, comp.lagrange_iv,
                    algorithm, order, float(options.zonotope_order), float(options.intermediate_order),
                    float(options.error_order), reduce_method, int(options.max_error_iterations), me,
                    float(options.rounding), k, stop,
                    store["tp_c"], store["tp_G"], store["ti_c"], store["ti_G"],
                    store["ng_tp"], store["ng_ti"], store["err"],
                )  # fmt: skip
                if bar is not None and depth == 0:
                    bar.update(step - k)
                if status != 0:
                    failed = (status, step, bad_state, bad_term, c_fail, G_fail)
                    break
                if monitor is not None and splits == 0:
                    js = np.nonzero((sample_step >= k) & (sample_step < stop))[0]
                    if js.size:
                        st = sample_step[js]
                        if monitor(js, store["tp_c"][st], store["tp_G"][st], store["ng_tp"][st]):
                            raise ReachStopped(int(js[0]))
                c, G, k = np.ascontiguousarray(c_fail), np.ascontiguousarray(G_fail), stop
            if failed is None:
                branches.append((start, S, store))
                continue
            status, step, bad_state, bad_term, c_fail, G_fail = failed
            branches.append((start, step, store))
            if _push_halves(pending, options, splits, status, step, c_fail, G_fail, depth):
                splits += 1
                continue
            raise fixed_step_failure(model, options, status, step, bad_state, bad_term, t_start, dts, store["err"][step],
                               comp, splits)  # fmt: skip
    except KeyboardInterrupt:
        raise
    finally:
        if bar is not None:
            bar.close()
    seconds = time.perf_counter() - t0
    return ReachRun(samples, step_offsets, t_start, dts, Z0, Wz, branches, splits, seconds, options,
                     monitor is not None and splits == 0)  # fmt: skip


def _reach_streamed(model, options, Z0, Wz, samples, step_offsets, t_start, dts, U, comp, gmax, me, params,
                    algorithm, order, reduce_method, new_store, monitor, stream, chunk_steps) -> ReachRun:  # fmt: skip
    """:func:`reach_run` without keeping the sets: chunks of ``chunk_steps`` steps, handed to ``stream``."""
    from reachconf_kernels import nonlinear as nl

    S = dts.size
    chunk = int(chunk_steps or 500)
    sample_step = np.asarray(step_offsets, dtype=np.int64) - 1
    store = new_store(chunk + 1)  # slot 0: the step before the chunk (its error bound seeds the next step)
    t0 = time.perf_counter()
    pending = [(0, np.array(Z0.center), np.array(Z0.generators), 0)]
    splits = 0
    bar = progress_bar(options.progress, S, f"reach {model.name}", "step", 2000, terminal_only=True)
    wc, WG = np.array(Wz.center), np.array(Wz.generators)
    try:
        while pending:
            start, c, G, depth = pending.pop()
            k = start
            store["err"][0] = 0.0
            while k < S:
                stop = min(S, k + chunk)
                base = k - 1 if k > 0 else 0
                status, step, bad_state, bad_term, c_fail, G_fail = nl.reach_loop(
                    c, G, U[base:stop], dts[base:stop], wc, WG, params,
                    int(options.taylor_terms), comp.f, comp.jac, comp.hess, comp.lagrange_iv,
                    algorithm, order, float(options.zonotope_order), float(options.intermediate_order),
                    float(options.error_order), reduce_method, int(options.max_error_iterations), me,
                    float(options.rounding), k - base, stop - base,
                    store["tp_c"], store["tp_G"], store["ti_c"], store["ti_G"],
                    store["ng_tp"], store["ng_ti"], store["err"],
                )  # fmt: skip
                end = step + base
                if bar is not None and depth == 0:
                    bar.update(end - k)
                if end > k:
                    stream(k, end, store, base)
                    if monitor is not None:
                        js = np.nonzero((sample_step >= k) & (sample_step < end))[0]
                        if js.size:
                            st = sample_step[js] - base
                            if monitor(js, store["tp_c"][st], store["tp_G"][st], store["ng_tp"][st], splits > 0):
                                raise ReachStopped(int(js[0]))
                if status != 0:
                    if _push_halves(pending, options, splits, status, end, c_fail, G_fail, depth):
                        splits += 1
                        break
                    raise fixed_step_failure(model, options, status, end, bad_state, bad_term, t_start, dts,
                                       store["err"][step], comp, splits)  # fmt: skip
                # the last step's error bound seeds the next chunk (slot 0)
                store["err"][0] = store["err"][stop - 1 - base]
                c, G, k = np.ascontiguousarray(c_fail), np.ascontiguousarray(G_fail), stop
    finally:
        if bar is not None:
            bar.close()
    return ReachRun(samples, step_offsets, t_start, dts, Z0, Wz, [], splits, time.perf_counter() - t0, options,
                     monitor is not None)  # fmt: skip


def _adaptive(model, Z0, Wz, samples, scalar, inputs, options, monitor, stream=None, chunk=None):
    """``algorithm="adaptive"``: inputs per sample interval, then :func:`reachconf.reach_adaptive.run_adaptive`.

    Streamed (``stream`` given): :func:`reachconf.reach_adaptive_stream.run_adaptive_streamed`, chunks of
    ``chunk`` sample intervals, on :func:`~reachconf.reach_adaptive_stream.streamed_grid` for a final time.
    """
    horizon = float(samples[-1] - samples[0])
    mag = float(np.max(np.abs(Z0.center) + np.sum(np.abs(Z0.generators), axis=1), initial=0.0))
    options = replace(options, algorithm=options.alg.for_initial_set(mag))  # atol in the problem's units
    U = None
    if scalar and stream is not None:  # a grid to stream on; inputs given as rows act on all of it
        if not callable(inputs):
            U = _input_table(model, inputs, samples, samples[:-1], np.arange(samples.size - 1), per_step=False)
        samples = streamed_grid(samples, scalar, options.time_step)
        U = None if U is None else np.repeat(U[:1], samples.size - 1, axis=0)
    elif scalar and model.m and callable(inputs):  # a callable input is sampled on the default grid
        grid = options.time_step if options.time_step is not None else horizon / 100.0
        samples = np.linspace(samples[0], samples[-1], max(1, int(np.ceil(horizon / grid - 1e-9))) + 1)
    samples = np.ascontiguousarray(samples, dtype=float)
    K = samples.size
    if U is None:
        U = _input_table(model, inputs, samples, samples[:-1], np.arange(K - 1), per_step=False)
    bar = progress_bar(options.progress, K - 1, f"reach {model.name}", "sample", 2000, terminal_only=True)
    try:
        if stream is not None:
            return run_adaptive_streamed(model, Z0, Wz, samples, U, options, horizon, stream=stream, monitor=monitor,
                                         chunk=chunk, progress=bar, stopped=ReachStopped)  # fmt: skip
        return run_adaptive(model, Z0, Wz, samples, U, options, scalar, horizon, monitor=monitor, progress=bar,
                            stopped=ReachStopped)  # fmt: skip
    finally:
        if bar is not None:
            bar.close()
