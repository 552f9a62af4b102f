"""Reachability of long horizons in bounded memory: :func:`reach_streamed`.

:func:`reachconf.reach` keeps every reachable set (two zonotopes per step:
about 12 KB per step for six states at zonotope order 20).  For recordings of
hours that is more than a machine has.  :func:`reach_streamed` runs the same
sound analysis chunk by chunk, carrying the state set from chunk to chunk, and
keeps

* the interval hull of every time-interval set (``ReachTube.bounds()``,
  ``2 n`` numbers per step), and
* the sets themselves of every ``keep_every``-th step and sample only (at
  most ``max_sets`` of each), enough for pictures.

The returned :class:`~reachconf.ReachTube` says so (``tube.keep_every``); its
``contains``/``at`` refuse times whose sets were not kept.
"""

from __future__ import annotations

import json
import math

import numpy as np

from reachconf.budget import TimeBudget, check_time_limit
from reachconf.checks import check_options
from reachconf.errors import OptionsError
from reachconf.model.core import require_model
from reachconf.reach import sample_times, integration_steps, reach_run
from reachconf.reach_adaptive_stream import streamed_grid
from reachconf.reach_options import AdaptiveReach, ReachOptions
from reachconf.sets.core import Zonotope
from reachconf.sets.union import SetUnion
from reachconf.tube import ReachTube

__all__ = ["reach_streamed", "streamed_bytes_per_step"]


def streamed_bytes_per_step(model) -> float:
    """Memory per integration step of :func:`reach_streamed`: the bounds, the step grid and the inputs."""
    return 8.0 * (2 * model.n + 4 + 2 * model.m)


def reach_streamed(model, X0, times, inputs=None, W=None, options=None, max_sets: int = 2000, monitor=None,
                   time_limit: float | None = None):  # fmt: skip
    """:func:`reachconf.reach` in bounded memory (see the module docstring).

    Parameters
    ----------
    model, X0, times, inputs, W, options
        As :func:`reachconf.reach`.
    max_sets : int
        At most this many time-point and time-interval sets are kept.
    monitor : callable, optional
        ``monitor(samples, c, G, ng, split)`` for every chunk (see
        :func:`reachconf.reach.reach_run`).
    time_limit : float, optional
        Seconds; stops with :class:`~reachconf.errors.ResourceError` once the
        projected duration (from the first 2 % of the steps) exceeds it.

    Returns
    -------
    ReachTube
        With every step's interval hull and every ``tube.keep_every``-th set.
        With ``algorithm="adaptive"`` (:mod:`reachconf.reach_adaptive_stream`)
        the "steps" of the bounds and of ``keep_every`` are the sample
        intervals (a final time is cut into a hundred, or into ``time_step``
        pieces); a kept time-interval set is the union of the sets of all
        adaptive steps in its sample interval, and ``tube.log`` holds the
        choices of every chunk.
    """
    require_model(model, "reach_streamed")
    options = check_options(options, ReachOptions, "reach_streamed")
    check_time_limit(time_limit)
    if not (isinstance(max_sets, int) and not isinstance(max_sets, bool) and max_sets >= 2):
        raise OptionsError(f"reach_streamed: max_sets must be an integer >= 2, got {max_sets!r}")
    if isinstance(options.alg, AdaptiveReach):
        return _streamed_adaptive(model, X0, times, inputs, W, options, max_sets, monitor, time_limit)
    S = integration_steps(times, options)
    keep_every, bounds, ti_kept, tp_kept, budget = _accumulators(model, S, max_sets, time_limit)

    def collect(k0, k1, store, base):
        sl = slice(k0 - base, k1 - base)
        rad = np.abs(store["ti_G"][sl]).sum(axis=2)  # generators beyond ng are zero
        lo, hi = store["ti_c"][sl] - rad, store["ti_c"][sl] + rad
        bounds[k0:k1, 0] = np.minimum(bounds[k0:k1, 0], lo)
        bounds[k0:k1, 1] = np.maximum(bounds[k0:k1, 1], hi)
        first = k0 + (-k0) % keep_every
        for k in range(first, k1, keep_every):  # at most max_sets steps in all
            i = k - base
            ti_kept.setdefault(k, []).append(_set(store["ti_c"][i], store["ti_G"][i], store["ng_ti"][i]))
            tp_kept.setdefault(k, []).append(_set(store["tp_c"][i], store["tp_G"][i], store["ng_tp"][i]))
        budget.check(k1, S)

    run = reach_run(model, X0, times, inputs, W, options, monitor=monitor, stream=collect)
    steps = np.array(sorted(ti_kept), dtype=np.int64)
    # the kept time-point sets are those at sample times whose step was kept
    sample_step = np.asarray(run.step_offsets, dtype=np.int64) - 1
    kept_samples = [0] + [j for j in range(1, run.samples.size) if int(sample_step[j]) in tp_kept]
    tp_sets = [run.X0] + [_one(tp_kept[int(sample_step[j])]) for j in kept_samples[1:]]
    intervals = np.column_stack([run.t_start[steps], run.t_start[steps] + run.dts[steps]]) if steps.size else np.zeros((0, 2))
    options_json = json.loads(json.dumps(run.options.__dict__, default=str))  # inf -> "inf", tuples -> lists
    meta = {"model": model.name, "options": options_json, "streamed": True, "steps": int(S)}
    return ReachTube(run.samples[kept_samples], tp_sets, intervals, [_one(ti_kept[int(k)]) for k in steps],
                     model.state_names, model=model, splits=run.splits, seconds=run.seconds, meta=meta,
                     keep_every=keep_every, step_bounds=bounds, all_times=run.samples)  # fmt: skip


def _streamed_adaptive(model, X0, times, inputs, W, options, max_sets, monitor, time_limit):
    """:func:`reach_streamed` with ``algorithm="adaptive"``: bounds and kept sets per sample interval."""
    from reachconf_kernels.adaptive import REC_T0, piece_hulls

    samples = streamed_grid(sample_times(times), np.ndim(times) == 0, options.time_step)
    S = samples.size - 1
    keep_every, bounds, ti_kept, tp_kept, budget = _accumulators(model, S, max_sets, time_limit)

    def collect(k0, k1, run):
        lo, hi = piece_hulls(run.ti_c, np.ascontiguousarray(run.ti_G), run.ng_ti)
        # every step lies within one sample interval (steps end at every sample time)
        j = k0 + np.clip(np.searchsorted(run.samples, run.rec[:, REC_T0], side="right") - 1, 0, k1 - k0 - 1)
        np.minimum.at(bounds[:, 0], j, lo)
        np.maximum.at(bounds[:, 1], j, hi)
        off_ti = np.concatenate([[0], np.cumsum(run.ng_ti)])
        for p in np.nonzero(j % keep_every == 0)[0]:
            ti_kept.setdefault(int(j[p]), []).append(_set(run.ti_c[p], run.ti_G[:, off_ti[p] :], run.ng_ti[p]))
        off_tp = np.concatenate([[0], np.cumsum(run.ng_tp)])
        for br in run.branches:
            if br.rec_hi <= br.rec_lo:
                continue
            for js in np.nonzero(br.sample_step >= 0)[0]:
                k = k0 + int(js)
                if js >= 1 and k % keep_every == 0:
                    r = int(br.sample_step[js])
                    tp_kept.setdefault(k, []).append(_set(run.tp_c[r], run.tp_G[:, off_tp[r] :], run.ng_tp[r]))
        budget.check(k1, S)

    run = reach_run(model, X0, times, inputs, W, options, monitor=monitor, stream=collect)  # on the same grid
    steps = np.array(sorted(ti_kept), dtype=np.int64)
    kept_samples = [0] + sorted(tp_kept)
    tp_sets = [run.X0] + [_one(tp_kept[k]) for k in kept_samples[1:]]
    intervals = np.column_stack([samples[steps], samples[steps + 1]]) if steps.size else np.zeros((0, 2))
    options_json = json.loads(json.dumps(run.options.__dict__, default=str))
    meta = {"model": model.name, "options": options_json, "streamed": True, "steps": int(run.log.steps),
            "chunks": run.chunks}  # fmt: skip
    return ReachTube(samples[kept_samples], tp_sets, intervals, [_one(ti_kept[int(k)]) for k in steps],
                     model.state_names, model=model, splits=run.splits, seconds=run.seconds, meta=meta,
                     keep_every=keep_every, step_bounds=bounds, all_times=samples, log=run.log)  # fmt: skip


def _accumulators(model, S: int, max_sets: int, time_limit):
    """What a streamed reach collects over ``S`` steps: ``keep_every``, the empty ``(S, 2, n)`` bounds, the kept
    time-interval and time-point sets (step -> pieces) and the time budget."""
    keep_every = max(1, math.ceil(S / max(1, int(max_sets))))
    bounds = np.empty((S, 2, model.n))
    bounds[:, 0] = np.inf
    bounds[:, 1] = -np.inf
    budget = TimeBudget(f"reach of model {model.name!r}", time_limit, min_fraction=0.02)
    return keep_every, bounds, {}, {}, budget


def _one(pieces):
    return pieces[0] if len(pieces) == 1 else SetUnion(pieces)


def _set(c, G, ng):
    return Zonotope.from_kernel(np.array(c, dtype=np.float64), np.ascontiguousarray(G[:, :ng], dtype=np.float64))
