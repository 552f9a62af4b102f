"""``algorithm="adaptive"`` in bounded memory: the adaptive reach chunk by chunk.

A streamed reach (:func:`reachconf.reach_stream.reach_streamed`, and the
reachset-conformance check with ``keep_tube=False``) must not keep every set.
:func:`run_adaptive_streamed` cuts the sample grid into chunks of
:data:`CHUNK_SAMPLES` sample intervals and runs the adaptive algorithm
(:func:`reachconf.reach_adaptive.run_adaptive`) over one chunk at a time:

* **The state set is carried across chunk boundaries as a union of pieces.**
  The first chunk starts from ``X0``.  Every later chunk starts from the
  time-point sets, at its first sample, of all pieces (branches) that reached
  it; each piece is run on its own.  The reachable set of a union is the
  union of the reachable sets of its pieces, so the pieces' sets together
  enclose every trajectory (each piece's run is sound by itself).
* **Splits and restarts stay within a chunk**: a restart from a halved start
  set goes back at most to the chunk's first sample, and a retry with half the
  error budget (``AdaptiveReach.budget_retries``) repeats only that piece's
  chunk.  A chunk is handed on (to ``stream`` and the monitor) only when all
  its pieces are finished, so no discarded set is ever seen.
* **The error budget is that of the whole horizon** (per unit time), as in
  the unstreamed run; the smallest step, too, is a fraction of the whole
  horizon.  At most ``max_splits`` splits are made over all chunks (each
  piece of a chunk may make an equal share of those left).

What differs from the unstreamed run: at every chunk boundary each piece's
step-size controller and its account of the error spent start afresh, and a
restart cannot reach back beyond the boundary, so the sets can differ
(both enclose the reachable set).  The per-step log of every chunk is kept
(:meth:`reachconf.reach_log.ReachLog.concat`; about 90 bytes per step).

Recordings of hours: the budget per unit time is ``error_budget / horizon``
with the horizon capped at ``AdaptiveReach.budget_horizon`` (100 s; over the
whole span a 10,000-s recording of the closed-loop bicycle at 100 Hz was
undecided at t = 0.057 s), and in the reductions' tolerance a state counts
at most :data:`reachconf_kernels.reduce_adaptive.OUTLIER` median radii (else
the straight road's position, kilometres wide after an hour, set the
tolerance of the lateral states: undecided at t = 3,762 s).  With both the
10,000-s recording is conformant.
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass

import numpy as np

from reachconf.reach_adaptive import run_adaptive
from reachconf.reach_log import ReachLog
from reachconf.sets.core import Zonotope

__all__ = ["CHUNK_SAMPLES", "StreamedAdaptiveRun", "run_adaptive_streamed", "streamed_grid", "end_pieces"]

#: Sample intervals per chunk of a streamed adaptive reach.  A chunk's sets are kept until it is done (at zonotope
#: order up to 50 about 60 MB per 1,000 samples for six states): measured with ``reachconf conform --kind
#: reachset`` on the demo run file, 100,000 samples, peak 516 MB with 1,000, 382 MB with 200 (the fixed-step
#: "lin": 357 MB), CPU 31 s and 33 s.
CHUNK_SAMPLES = 200


@dataclass
class StreamedAdaptiveRun:
    """Result of :func:`run_adaptive_streamed` (the sets went to ``stream``; none is kept).

    Attributes
    ----------
    samples : ndarray (K,)
        The sample grid.
    X0, W : Zonotope
    options : ReachOptions
    log : ReachLog
        The per-step choices of all chunks (branch numbers unique over the chunks).
    splits : int
        Splits over all chunks.
    pieces : int
        Pieces of the set at the last sample.
    chunks : int
    seconds : float
    monitored : bool
        Every sample after the first was passed to the monitor.
    """

    samples: np.ndarray
    X0: Zonotope
    W: Zonotope
    options: object
    log: ReachLog
    splits: int
    pieces: int
    chunks: int
    seconds: float
    monitored: bool


def streamed_grid(samples: np.ndarray, scalar: bool, time_step: float | None) -> np.ndarray:
    """The sample grid of a streamed adaptive reach.

    Sample times as given; for a final time (``scalar``) a grid of spacing
    ``time_step`` (``None``: a hundredth of the horizon), so that there are
    chunks to stream and time-point sets to keep.
    """
    if not scalar:
        return samples
    horizon = float(samples[-1] - samples[0])
    grid = time_step if time_step is not None else horizon / 100.0
    return np.linspace(samples[0], samples[-1], max(1, int(np.ceil(horizon / grid - 1e-9))) + 1)


def end_pieces(run, tol: float = 1e-12) -> list:
    """``(c, G)`` of every piece of an :class:`~reachconf.reach_adaptive.AdaptiveRun` at its last sample."""
    off = np.concatenate([[0], np.cumsum(run.ng_tp)])
    t_end = float(run.samples[-1])
    out = []
    for br in run.branches:
        r = int(br.sample_step[-1])
        if br.rec_hi > br.rec_lo and r >= 0 and br.t_end >= t_end - tol * max(1.0, abs(t_end)):
            out.append((run.tp_c[r].copy(), np.ascontiguousarray(run.tp_G[:, off[r] : off[r] + run.ng_tp[r]])))
    return out


def _sample_sets(run, k0, monitor, split):
    """Pass the time-point sets of every finished piece at the chunk's samples 1.. to ``monitor``.

    Returns the first (global) sample index at which the monitor asked to stop, or None.
    """
    off = np.concatenate([[0], np.cumsum(run.ng_tp)])
    for br in run.branches:
        if br.rec_hi <= br.rec_lo:
            continue
        js = np.nonzero(br.sample_step >= 0)[0]
        js = js[js >= 1]
        if js.size == 0:
            continue
        recs = br.sample_step[js]
        ng = run.ng_tp[recs]
        G = np.zeros((js.size, run.tp_c.shape[1], max(1, int(ng.max()))))
        for i, r in enumerate(recs):
            G[i, :, : ng[i]] = run.tp_G[:, off[r] : off[r] + ng[i]]
        if monitor(js + k0, run.tp_c[recs].copy(), G, ng.copy(), split):
            return int(js[0] + k0)
    return None


def run_adaptive_streamed(model, Z0, Wz, samples, U, options, horizon, stream=None, monitor=None, chunk=None,
                          progress=None, stopped=StopIteration) -> StreamedAdaptiveRun:  # fmt: skip
    """Adaptive reach over ``samples`` chunk by chunk (see the module docstring).

    Parameters
    ----------
    model, Z0, Wz, samples, U, options, horizon
        As :func:`reachconf.reach_adaptive.run_adaptive` (``U``: one row per
        sample interval; ``horizon``: of the whole reach).
    stream : callable, optional
        ``stream(k0, k1, run)`` for every piece of every finished chunk:
        ``run`` is the :class:`~reachconf.reach_adaptive.AdaptiveRun` of that
        piece over the samples ``k0 .. k1`` (``run.samples`` is
        ``samples[k0 : k1 + 1]``; its records are the accepted steps of its
        branches, none discarded).
    monitor : callable, optional
        ``monitor(js, c, G, ng, split)`` with the time-point sets of every
        piece at the samples ``js`` (``split``: the set is in more than one
        piece, so a measurement outside one piece is no violation by itself);
        a True return raises ``stopped(sample)``.
    chunk : int, optional
        Sample intervals per chunk (default :data:`CHUNK_SAMPLES`).
    progress : tqdm bar, optional
        Advanced by the sample intervals done.

    Raises
    ------
    ReachError
        As :func:`~reachconf.reach_adaptive.run_adaptive`, with the time of the failure.
    """
    K = samples.size
    chunk = max(1, int(chunk or CHUNK_SAMPLES))
    pieces = [(np.array(Z0.center, dtype=float), np.array(Z0.generators, dtype=float))]
    max_splits = options.effective_max_splits
    splits, chunks, logs = 0, 0, []
    t0 = time.perf_counter()
    for k0 in range(0, K - 1, chunk):
        k1 = min(K - 1, k0 + chunk)
        sub = np.ascontiguousarray(samples[k0 : k1 + 1])
        Usub = np.ascontiguousarray(U[k0:k1])
        carried = []
        for i, (c, G) in enumerate(pieces):
            allowed = max(0, (max_splits - splits) // (len(pieces) - i))
            opts = dataclasses.replace(options, max_splits=allowed, progress=False)
            run = run_adaptive(model, Zonotope.from_kernel(c, G), Wz, sub, Usub, opts, False, horizon)
            splits += run.splits
            logs.append(run.log)
            if stream is not None:
                stream(k0, k1, run)
            if monitor is not None:
                hit = _sample_sets(run, k0, monitor, splits > 0 or len(pieces) > 1)
                if hit is not None:
                    raise stopped(hit)
            carried.extend(end_pieces(run))
        pieces = carried
        chunks += 1
        if progress is not None:
            progress.update(k1 - k0)
    log = ReachLog.concat(logs)
    return StreamedAdaptiveRun(samples, Z0, Wz, options, log, splits, len(pieces), chunks, time.perf_counter() - t0,
                               monitor is not None)  # fmt: skip
