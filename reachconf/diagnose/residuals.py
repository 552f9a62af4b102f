"""Multi-step prediction residuals of a candidate model on prepared cases (the diagnosis's loss).

Every prediction window starts from the measured (smoothed) state and runs the
model over the case's inputs as the candidate's input effects transform them;
input effects with memory (a lag) start each case where it fits best
(:func:`case_starts`).
"""

from __future__ import annotations

import numpy as np

from reachconf.errors import OptionsError
from reachconf.io.cases import TestCase
from reachconf.model.outputs import (
    evaluate_outputs,
    output_index_of_states,
    state_estimate,
    state_index_of_outputs,
)
from reachconf_kernels.integrate import rk4_windows

__all__ = ["case_starts", "received_inputs", "window_residuals"]

#: a lag's start counts as decayed below this fraction: windows that begin later are not simulated again
START_DECAYED = 1e-5


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


def _received(model, inputs, d, theta_eff, starts):
    return received_inputs(model, inputs, d.t, d.U, theta_eff, starts)


def _start_states(model, outputs, theta_eff, d, U, K, direct):
    """States at the starts of the case's first ``K`` windows, from the (corrected) smoothed measurement."""
    Y0 = d.Ys[d.starts[:K]]
    if outputs:  # the start state from the corrected measurement
        Y0 = Y0.copy()
        for e, tgt in outputs:
            i = model.output_names.index(tgt)
            Y0[:, i] = e.inverse(Y0[:, i], theta_eff[(e.name, tgt)])
    return np.ascontiguousarray(_states(model, Y0, U[d.starts[:K]], direct))


def _residuals_of(model, outputs, theta_eff, d, U, P, K, plain, sigma):
    """Normalised residuals of the predictions ``P`` of the case's first ``K`` windows (in measurement units)."""
    idx = d.idx[: K * d.offsets.size]
    Xp = P[:, d.offsets - 1, :].reshape(-1, model.n)
    Yp = Xp[:, plain] if plain is not None else evaluate_outputs(model, Xp, U[idx])
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
    for length in {d.length for d, _, _ in items}:
        group = [i for i, (d, _, _) in enumerate(items) if d.length == length]
        X0s, starts, Us, ts, shift = [], [], [], [], 0
        for i in group:
            d, U, K = items[i]
            stop = int(d.starts[K - 1]) + length + 1
            X0s.append(_start_states(model, outputs, theta_eff, d, U, K, direct))
            starts.append(d.starts[:K] + shift)
            Us.append(U[:stop])
            ts.append(d.t[:stop])
            shift += stop
        P = rk4_windows(comp.f, np.ascontiguousarray(np.vstack(X0s)), np.concatenate(starts).astype(np.int64),
                        np.ascontiguousarray(np.vstack(Us)), np.ascontiguousarray(np.concatenate(ts)), pv, model.q,
                        length, int(substeps))  # fmt: skip
        row = 0
        for i in group:
            d, U, K = items[i]
            out[i] = _residuals_of(model, outputs, theta_eff, d, U, P[row : row + K], K, plain, sigma)
            row += K
    return out


def _fit_starts(model, comp, pv, direct, plain, inputs, outputs, theta_eff, data, received, residuals, targets, sigma,
                substeps):  # fmt: skip
    """:func:`case_starts` for every case at once (the re-simulated windows batched); returns the residuals."""
    free = [(e.name, tgt) for e, tgt in inputs if e.start is not None]
    cols = [model.input_names.index(tgt) for _, tgt in free]
    heads = []  # (case number, windows to simulate again, [moved U], [steps])
    for c, (d, U0) in enumerate(zip(data, received)):
        moved, steps = [], []
        for key, j in zip(free, cols):
            steps.append(1e-3 * (float(np.max(np.abs(d.U[: d.length, j]))) + 1e-9))
            moved.append(_received(model, inputs, d, theta_eff, {key: steps[-1]}))
        # a start decays: only the windows that begin before it has (to START_DECAYED) are simulated again
        change = np.max([np.abs(Uk[:, j] - U0[:, j]) / h for Uk, h, j in zip(moved, steps, cols)], axis=0)
        seen = np.nonzero(change > START_DECAYED)[0]
        K = int(np.searchsorted(d.starts, seen[-1], side="right")) if seen.size else 0
        if K > 0:
            heads.append((c, K, moved, steps))
    if not heads:
        return residuals, [{} for _ in data]
    args = (model, comp, pv, direct, plain, outputs, theta_eff)
    sens = [_batch_residuals(*args, [(data[c], moved[k], K) for c, K, moved, _ in heads], sigma, substeps)
            for k in range(len(free))]  # fmt: skip
    found = [{} for _ in data]
    trial = []
    for h, (c, K, _, steps) in enumerate(heads):
        n = sens[0][h].size
        r0 = residuals[c][:n]
        S = np.column_stack([(sens[k][h] - r0) / steps[k] for k in range(len(free))])
        r0 = r0 - targets[c][:n]  # the start explains what the fit is to explain
        if not np.all(np.isfinite(S)) or not np.any(S):
            continue
        if S.shape[1] == 1:
            ss = float(S[:, 0] @ S[:, 0])
            coef = np.array([-float(S[:, 0] @ r0) / ss if ss > 0 else 0.0])
        else:
            coef = np.linalg.lstsq(S, -r0, rcond=None)[0]
        gain = float(r0 @ r0) - float(np.sum((r0 + S @ coef) ** 2))  # predicted by the sensitivities
        if np.all(np.isfinite(coef)) and gain > 0.0:
            found[c] = dict(zip(free, map(float, coef)))
            trial.append((c, K))
    if trial:
        again = _batch_residuals(*args, [(data[c], _received(model, inputs, data[c], theta_eff, found[c]), K)
                                         for c, K in trial], sigma, substeps)  # fmt: skip
        for (c, _), r_head in zip(trial, again):
            t = targets[c][: r_head.size]
            r0 = residuals[c][: r_head.size]
            if float((r_head - t) @ (r_head - t)) < float((r0 - t) @ (r0 - t)):  # kept only when it fits better
                residuals[c] = np.concatenate([r_head, residuals[c][r_head.size :]])
            else:
                found[c] = {}
    return residuals, found


def case_starts(model, cand, theta_eff: dict, d, sigma, substeps):
    """The start offsets of the candidate's input effects with memory (``Effect.start``) that fit the case best.

    A case cut from a longer run starts with the actuator in motion, so a
    lag's state at ``t_0`` is unknown: it is a nuisance parameter of each case
    (like the measured start state of every prediction window).  Its effect on
    the residuals is linear up to the model's curvature: one sensitivity per
    effect by a small step of the start (only the windows that begin before
    the start has decayed), then least squares; kept only when it lowers the
    case's loss.  Returns ``({(effect, target): offset}, residuals)``.
    """
    found, r = _starts_and_residuals(model, cand, theta_eff, [d], sigma, substeps)
    return found[0], r[0]


def _starts_and_residuals(model, cand, theta_eff, data, sigma, substeps, fixed=None, target=None):
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
    received = [_received(model, inputs, d, theta_eff, st) for d, st in zip(data, given)]
    res = _batch_residuals(*args, outputs, theta_eff, [(d, U, d.starts.size) for d, U in zip(data, received)], sigma,
                           substeps)  # fmt: skip
    if fixed is not None or not any(e.start is not None for e, _ in inputs):
        return [{} for _ in data], res
    sizes = np.cumsum([0] + [r.size for r in res])
    if target is not None and np.size(target) != sizes[-1]:
        raise OptionsError(f"target: {sizes[-1]} values expected (laid out as the residuals), got {np.size(target)}")
    targets = [np.zeros(r.size) for r in res] if target is None else [
        np.asarray(target, dtype=float)[a:b] for a, b in zip(sizes[:-1], sizes[1:])]  # fmt: skip
    res, found = _fit_starts(*args, inputs, outputs, theta_eff, data, received, res, targets, sigma, substeps)
    return found, res


def window_residuals(model, cand, theta_eff: dict, data, sigma, substeps, starts=None, target=None):
    """Normalised multi-step prediction residuals of all windows of all cases (one flat array).

    Window after window (each ``length x p`` values), case after case.  An
    output effect corrects the measured start state (its inverse) and passes
    the prediction through itself: the residual stays in measurement units,
    so that an output scale cannot lower the loss by shrinking the residuals
    (``y / k - y_pred`` would, by ``1/k``).  An input effect with memory (a
    lag) starts each case where it fits best (:func:`case_starts`), or
    where ``starts`` (one dict per case, as :func:`case_starts` gives) says;
    with ``target`` (laid out as the result), the start that brings the
    residuals nearest to it (a fit that explains the change from a reference).
    """
    return np.concatenate(_starts_and_residuals(model, cand, theta_eff, data, sigma, substeps, starts, target)[1])
