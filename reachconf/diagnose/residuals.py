"""Multi-step prediction residuals of a candidate model on prepared cases (the diagnosis's loss).

Every prediction window starts from the measured (smoothed) state and runs the
model over the case's inputs as the candidate's input effects transform them;
input effects with memory (a lag) start each case where it fits best
(:func:`case_starts`, chosen on the samples before its first window).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from reachconf.conformance.optctrl import fine_grid
from reachconf.errors import OptionsError
from reachconf.io.cases import TestCase
from reachconf.model.outputs import (
    evaluate_outputs,
    output_index_of_states,
    state_estimate,
    state_index_of_outputs,
)
from reachconf_kernels.integrate import rk4_windows

__all__ = ["case_starts", "ramp_grid", "residuals_and_prefix", "received_inputs", "steps_per_sample", "window_residuals"]

#: a lag's start counts as decayed below this fraction: windows that begin later are not simulated again
START_DECAYED = 1e-5
#: longest RK4 step (s) of the predictions when ``DiagnoseOptions.substeps`` is None (one step per sample at >= 100 Hz)
MAX_STEP = 0.01


def steps_per_sample(substeps, d) -> int:
    """RK4 steps per sample interval of the prepared case ``d``: ``substeps``, or for None enough that none is longer
    than :data:`MAX_STEP` (by the case's median sampling interval, ``d.dt`` when :func:`~reachconf.diagnose.fit.prepare`
    set it)."""
    if substeps is not None:
        return int(substeps)
    dt = getattr(d, "dt", None)
    if dt is None:
        dt = float(np.median(np.diff(d.t))) if np.size(d.t) > 1 else MAX_STEP
    return max(1, int(np.ceil(dt / MAX_STEP - 1e-9)))


def _states(model, Ys, U, direct):
    if direct is not None:
        return np.ascontiguousarray(Ys[:, direct])
    t = np.arange(Ys.shape[0], dtype=float)
    return state_estimate(model, TestCase("windows", "default", t, U, Ys, model.input_names, model.output_names))


def received_inputs(model, inputs, t, U, theta_eff: dict, starts=None):
    """What the system really received: ``U`` with the input effects ``inputs`` (``(effect, target)`` pairs, in
    their composition order) applied, each with memory started at ``starts[(effect, target)]`` (default 0)."""
    if not inputs:
        return U
    U = U.copy()
    for e, tgt in inputs:
        j = model.input_names.index(tgt)
        key = (e.name, tgt)
        U[:, j] = e.apply_signal(t, U[:, j], theta_eff[key], (starts or {}).get(key, 0.0))
    return U


def _received(model, inputs, d, theta_eff, starts, substeps=1):
    """The received inputs of a prepared case: per sample, or per RK4 substep when the case has more than one
    (:func:`steps_per_sample`) and there are input effects (a lag's or a dead time's output moves within a sample
    interval; held over the whole interval as its mean, a 0.6-sample lag came out 5 % short at 20 Hz)."""
    m = steps_per_sample(substeps, d)
    if d.hold == "linear":  # per RK4 step (one per sample too): the ramp's mean over the step
        t_sub, U_sub = ramp_grid(d.t, d.U, m)
        return received_inputs(model, inputs, t_sub, U_sub, theta_eff, starts)
    if m > 1 and inputs:  # the substeps' times and the commands held on them (row k m + s: substep s of interval k)
        t_sub, U_sub, _ = fine_grid(d.t, d.U, m)
        return received_inputs(model, inputs, t_sub, U_sub, theta_eff, starts)
    return received_inputs(model, inputs, d.t, d.U, theta_eff, starts)


def ramp_grid(t, U, r):
    """Inputs that move linearly between their samples (a first-order hold), as :func:`fine_grid`'s ``r`` steps
    per sample interval, each holding the ramp's mean over it (its value at the step's midpoint); the last row is the
    last sample.  Returns the steps' start times and the inputs, ``(K - 1) r + 1`` rows each."""
    U = np.asarray(U, dtype=float)
    tf = fine_grid(t, U, r)[0]
    mid = U[:-1, None, :] + ((np.arange(r) + 0.5) / r)[None, :, None] * np.diff(U, axis=0)[:, None, :]
    return tf, np.ascontiguousarray(np.vstack([mid.reshape(-1, U.shape[1]), U[-1:]]))


def _per(d, U) -> int:
    """Input rows per sample interval of ``U`` for the case ``d`` (1: per sample; else per substep)."""
    return 1 if U.shape[0] == d.t.size else (U.shape[0] - 1) // (d.t.size - 1)


def _start_states(model, outputs, theta_eff, d, U, K, direct):
    """States at the starts of the case's first ``K`` windows, from the (corrected) smoothed measurement."""
    Y0 = d.Ys[d.starts[:K]]
    per = _per(d, U)
    if outputs:  # the start state from the corrected measurement
        Y0 = Y0.copy()
        for e, tgt in outputs:
            i = model.output_names.index(tgt)
            Y0[:, i] = e.inverse(Y0[:, i], theta_eff[(e.name, tgt)])
    return np.ascontiguousarray(_states(model, Y0, U[d.starts[:K] * per], direct))


def _residuals_of(model, outputs, theta_eff, d, U, P, K, plain, sigma):
    """Normalised residuals of the predictions ``P`` of the case's first ``K`` windows (in measurement units)."""
    idx = d.idx[: K * d.offsets.size]
    Xp = P[:, d.offsets - 1, :].reshape(-1, model.n)
    Yp = Xp[:, plain] if plain is not None else evaluate_outputs(model, Xp, U[idx * _per(d, U)])
    if outputs:
        Yp = Yp.copy()
        for e, tgt in outputs:
            i = model.output_names.index(tgt)
            Yp[:, i] = e.apply_signal(d.t[idx], Yp[:, i], theta_eff[(e.name, tgt)])
    if not np.all(np.isfinite(Yp)):
        Yp = np.where(np.isfinite(Yp), Yp, 1e6)
    return ((Yp - d.Y[idx]) * (d.weight / sigma)).reshape(-1)


def _batch_residuals(model, comp, pv, direct, plain, outputs, theta_eff, items, sigma, substeps):
    """Residuals of the first ``K`` windows of several cases, ``items = [(d, U, K), ...]``, with one compiled
    simulation per window length (the cases' arrays side by side)."""
    out = [None] * len(items)
    keys = [(d.length, _per(d, U), steps_per_sample(substeps, d)) for d, U, _ in items]
    for length, per, steps in set(keys):
        group = [i for i, key in enumerate(keys) if key == (length, per, steps)]
        X0s, starts, Us, ts, shift = [], [], [], [], 0
        for i in group:
            d, U, K = items[i]
            stop = int(d.starts[K - 1]) + length + 1
            X0s.append(_start_states(model, outputs, theta_eff, d, U, K, direct))
            starts.append(d.starts[:K] + shift)
            if per == 1:
                Us.append(U[:stop])
            else:  # the case's substeps up to its sample `stop`, padded so that the next case's rows line up
                head = U[: (stop - 1) * per + 1]
                Us.append(np.concatenate([head, np.repeat(head[-1:], per - 1, axis=0)]))
            ts.append(d.t[:stop])
            shift += stop
        args = (comp.f, np.ascontiguousarray(np.vstack(X0s)), np.concatenate(starts).astype(np.int64),
                np.ascontiguousarray(np.vstack(Us)), np.ascontiguousarray(np.concatenate(ts)), pv, model.q, length)
        P = rk4_windows(*args, steps, False) if per == 1 else rk4_windows(*args, per, True)
        row = 0
        for i in group:
            d, U, K = items[i]
            out[i] = _residuals_of(model, outputs, theta_eff, d, U, P[row : row + K], K, plain, sigma)
            row += K
    return out


def _prefix(d):
    """The case's samples before its first prediction window as one window from ``t_0`` (never scored), or None."""
    first = int(d.starts[0]) if d.starts.size else 0
    if first < 2:
        return None
    every = int(d.offsets[1] - d.offsets[0]) if d.offsets.size > 1 else 1
    offs = np.arange(first, 0, -every, dtype=np.int64)[::-1]
    Y = d.Y
    if d.prefix_Y is not None:  # the case's Y holds only its windows' compared samples (pseudo-measurements)
        Y = np.zeros((first + 1, np.shape(d.prefix_Y)[1]))
        Y[offs] = d.prefix_Y
    return replace(d, Y=Y, starts=np.zeros(1, dtype=np.int64), length=first, offsets=offs, idx=offs.copy(),
                   prefix_Y=None)


def residuals_and_prefix(model, cand, theta_eff: dict, data, sigma, substeps) -> tuple:
    """:func:`window_residuals` and, per case, the candidate's predictions of the compared samples before its first
    window (from ``t_0``, the lag started as :func:`case_starts` chooses; measurement units; None without such
    samples) — from one choice of the starts."""
    found, res = _starts_and_residuals(model, cand, theta_eff, data, sigma, substeps)
    inputs = cand.inputs
    outputs = [(e, tgt) for e, tgt in cand.parts if e.kind == "output"]
    items, where = [], []
    for c, (d, st) in enumerate(zip(data, found)):
        pre = _prefix(d)
        if pre is not None:
            items.append((pre, _received(model, inputs, d, theta_eff, st, substeps), 1))
            where.append(c)
    out = [None] * len(data)
    if items:
        pres = _batch_residuals(model, model.compiled(), model.param_vector, output_index_of_states(model),
                                state_index_of_outputs(model), outputs, theta_eff, items, sigma, substeps)  # fmt: skip
        for c, (pre, _, _), r in zip(where, items, pres):
            Ym = np.asarray(pre.Y, dtype=float)[pre.idx]
            out[c] = Ym + r.reshape(Ym.shape) * sigma / data[c].weight
    return np.concatenate(res), out


def _fit_starts(model, comp, pv, direct, plain, inputs, outputs, theta_eff, data, received, residuals, sigma,
                substeps, every_case=True):  # fmt: skip
    """:func:`case_starts` from each case's samples before its first window (prequential: the scored windows do not
    choose their own start); returns the residuals and the starts.  ``every_case=False``: only the cases whose
    windows a start reaches (the others' residuals do not depend on it; their starts are not reported)."""
    free = [(e.name, tgt) for e, tgt in inputs if e.start is not None]
    cols = [model.input_names.index(tgt) for _, tgt in free]
    heads = []  # (case number, prefix, windows to simulate again, [moved U], [steps])
    for c, (d, U0) in enumerate(zip(data, received)):
        pre = _prefix(d)
        if pre is None:
            continue
        moved, steps = [], []
        for key, j in zip(free, cols):
            steps.append(1e-3 * (float(np.max(np.abs(d.U[: d.length, j]))) + 1e-9))
            moved.append(_received(model, inputs, d, theta_eff, {key: steps[-1]}, substeps))
        change = np.max([np.abs(Uk[:, j] - U0[:, j]) / h for Uk, h, j in zip(moved, steps, cols)], axis=0)
        seen = np.nonzero(change > START_DECAYED)[0] // _per(d, U0)
        K = int(np.searchsorted(d.starts, seen[-1], side="right")) if seen.size else 0
        if K > 0 or every_case:
            heads.append((c, pre, K, moved, steps))
    found = [{} for _ in data]
    if not heads:
        return residuals, found
    args = (model, comp, pv, direct, plain, outputs, theta_eff)
    r0s = _batch_residuals(*args, [(pre, received[c], 1) for c, pre, _, _, _ in heads], sigma, substeps)
    sens = [_batch_residuals(*args, [(pre, moved[k], 1) for _, pre, _, moved, _ in heads], sigma, substeps)
            for k in range(len(free))]  # fmt: skip
    trial = []
    for h, (c, pre, K, _, steps) in enumerate(heads):
        r0 = r0s[h]
        S = np.column_stack([(sens[k][h] - r0) / steps[k] for k in range(len(free))])
        if not np.all(np.isfinite(S)) or not np.any(S):
            continue
        coef = np.linalg.lstsq(S, -r0, rcond=None)[0]
        if np.all(np.isfinite(coef)) and float(r0 @ r0) - float(np.sum((r0 + S @ coef) ** 2)) > 0.0:
            found[c] = dict(zip(free, map(float, coef)))
            trial.append(h)
    if not trial:
        return residuals, found
    moved_U = {heads[h][0]: _received(model, inputs, data[heads[h][0]], theta_eff, found[heads[h][0]], substeps)
               for h in trial}  # fmt: skip
    again = _batch_residuals(*args, [(heads[h][1], moved_U[heads[h][0]], 1) for h in trial], sigma, substeps)
    redo = []
    for h, r_pre in zip(trial, again):
        c = heads[h][0]
        if float(r_pre @ r_pre) < float(r0s[h] @ r0s[h]):  # kept only when it fits the prefix better
            if heads[h][2] > 0:
                redo.append((c, heads[h][2]))
        else:
            found[c] = {}
    if redo:
        new = _batch_residuals(*args, [(data[c], moved_U[c], K) for c, K in redo], sigma, substeps)
        for (c, _), r_head in zip(redo, new):
            residuals[c] = np.concatenate([r_head, residuals[c][r_head.size :]])
    return residuals, found


def case_starts(model, cand, theta_eff: dict, d, sigma, substeps):
    """The start offsets of the candidate's input effects with memory (``Effect.start``) that fit the case best.

    A case cut from a longer run starts with the actuator in motion, so a
    lag's state at ``t_0`` is unknown: it is a nuisance parameter of each case
    (like the measured start state of every prediction window).  It is chosen
    on the case's samples *before* its first prediction window (the past that
    :attr:`~reachconf.diagnose.options.DiagnoseOptions.start_state` ``"past"``
    estimates the first start state from), predicted from ``t_0`` as one
    window that is never scored — prequentially, so that a held-out score
    never fits a nuisance to the windows it scores.  (Fitted on the scored
    windows, where a short lag's start is seen only through
    ``exp(-t_first / tau)``, the start of a 0.05-s lag came out tens of times
    the steering range and absorbed the noise of those windows' start states,
    a freedom a dead time does not have.)  Its effect on the prefix is linear
    up to the model's curvature: one sensitivity per effect by a small step
    of the start, then least squares; kept only when it lowers the prefix's
    loss.  A case without samples before its first window (``start_state =
    "centered"``) keeps the lag at rest.  Returns ``({(effect, target):
    offset}, residuals)``; the residuals of the windows that begin before the
    start has decayed (to ``START_DECAYED``) are simulated with it.
    """
    found, r = _starts_and_residuals(model, cand, theta_eff, [d], sigma, substeps)
    return found[0], r[0]


def _starts_and_residuals(model, cand, theta_eff, data, sigma, substeps, fixed=None, every_case=True):
    comp = model.compiled()
    pv = model.param_vector
    direct = output_index_of_states(model)
    plain = state_index_of_outputs(model)
    inputs = cand.inputs
    outputs = [(e, tgt) for e, tgt in cand.parts if e.kind == "output"]
    args = (model, comp, pv, direct, plain)
    if fixed is not None and len(fixed) != len(data):
        raise OptionsError(f"starts: one dict per case expected ({len(data)}), got {len(fixed)}")
    given = fixed if fixed is not None else [{}] * len(data)
    received = [_received(model, inputs, d, theta_eff, st, substeps) for d, st in zip(data, given)]
    res = _batch_residuals(*args, outputs, theta_eff, [(d, U, d.starts.size) for d, U in zip(data, received)], sigma,
                           substeps)  # fmt: skip
    if fixed is not None or not any(e.start is not None for e, _ in inputs):
        return [{} for _ in data], res
    return _fit_starts(*args, inputs, outputs, theta_eff, data, received, res, sigma, substeps, every_case)[::-1]


def window_residuals(model, cand, theta_eff: dict, data, sigma, substeps, starts=None):
    """Normalised multi-step prediction residuals of all windows of all cases (one flat array).

    Window after window (each ``length x p`` values), case after case.  An
    output effect corrects the measured start state (its inverse) and passes
    the prediction through itself: the residual stays in measurement units,
    so that an output scale cannot lower the loss by shrinking the residuals
    (``y / k - y_pred`` would, by ``1/k``).  An input effect with memory (a
    lag) starts each case where its samples before the first window say
    (:func:`case_starts`), or where ``starts`` (one dict per case, as
    :func:`case_starts` gives) says.
    """
    # (the starts of cases whose windows a start does not reach are not needed here: not chosen)
    return np.concatenate(_starts_and_residuals(model, cand, theta_eff, data, sigma, substeps, starts,
                                                every_case=False)[1])
