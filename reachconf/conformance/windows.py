"""Trace conformance in windows: any length in bounded memory and linear time (Alg. 1 and Alg. 2).

A case is cut into windows of ``TraceOptions.window`` samples.  DISTURBANCETRACE
runs window by window from the state the previous window ended in (the state
estimate is carried across windows): the per-step fit of section 3.2.1, or
Alg. 2 on the window plus ``overlap`` samples of look-ahead, of which only the
first part is kept (the look-ahead makes sure the kept part ends in a state
from which the measurements can still be followed).  ``method="auto"`` takes
the per-step fit where its simulated trace stays within ``W`` and ``V`` on the
window and look-ahead, Alg. 2 where it does not.

The verdict (Alg. 1, lines 3–5) simulates the whole disturbance trace window
by window, carrying the end states of both integrations (``substeps`` and
``2 substeps``, whose difference is the integration-error estimate) — the same
numbers as one simulation of the whole case, so the guarantee is unchanged:
"conformant" only if the one simulated trace satisfies eqs. 22–24 with margin.

Memory: the windows' working arrays, plus what the result keeps per sample:
the disturbance trace (the certificate, with ``x0``), and the state and
measurement-error traces at every ``trace_step``-th sample (at most
``TraceOptions.keep_samples`` rows each).  Margins, their times and the
interval hulls of W and V are over every sample.
"""

from __future__ import annotations

import math

import numpy as np

from reachconf.budget import progress_bar
from reachconf.conformance.optctrl import NO_TRACE, fine_grid, optctrl_trace
from reachconf.errors import ConformanceError
from reachconf.model.outputs import affine_output, evaluate_outputs, output_index_of_states, state_guess
from reachconf_kernels.integrate import rk4_trace
from reachconf_kernels.tracefit import perstep_fit

__all__ = ["window_plan", "WindowVerdict", "verdict_in_windows", "disturbance_trace_in_windows", "perstep_weights",
           "describe_violation", "keep_step", "summarize_windows"]


def window_plan(K: int, window: int, overlap: int):
    """Windows over samples ``0..K-1``: list of ``(a, c, b)`` — solve ``a..b-1``, keep intervals ``a..c-1``.

    Consecutive windows share the sample ``c`` (the next ``a``); the last has
    ``c = b = K - 1`` (its last sample is the case's).  Windows are at least
    two samples long; ``overlap`` is clipped to half a window.
    """
    window = max(2, int(window))
    overlap = min(max(0, int(overlap)), window // 2)
    if K <= window + overlap:
        return [(0, K - 1, K)]
    plan = []
    a = 0
    step = window
    while a < K - 1:
        c = min(a + step, K - 1)
        b = min(c + overlap + 1, K)
        if K - 1 - c < max(2, step // 4):  # a short tail joins this window
            c, b = K - 1, K
        plan.append((a, c, b))
        a = c
    return plan


class WindowVerdict:
    """What the streamed verdict keeps: margins (with times), hulls, kept traces, integration error."""

    def __init__(self, model, K, keep_every):
        self.model = model
        self.step = int(keep_every)
        self.X = []
        self.V = []
        self.t_kept = []
        self.margin = {}
        self.margin_time = {}
        self.v_lo = np.full(model.p, np.inf)
        self.v_hi = np.full(model.p, -np.inf)
        self.yerr = np.zeros(model.p)
        self.finite = True

    def _update(self, name, values, times):
        if values.size == 0:
            return
        i = int(np.argmin(values))
        if name not in self.margin or values[i] < self.margin[name]:
            self.margin[name] = float(values[i])
            self.margin_time[name] = float(times[i])


def verdict_in_windows(model, t, U, Y, x0, Wt, W_lo, W_hi, V_lo, V_hi, substeps, r=1, window=20_000,
                       keep_every=1, progress=None, desc="verdict") -> WindowVerdict:  # fmt: skip
    """Alg. 1 lines 3–5 over the whole case in windows (see the module docstring).

    ``Wt`` has ``(K-1) r`` rows (``r`` disturbances per sample interval).
    Margins: disturbance channel ``w`` -> smallest ``min(w - lo, hi - w)``;
    output ``y`` -> smallest distance of ``v = y - h(x)`` to V's bounds minus
    the integration-error estimate mapped to the outputs (by ``|C|`` for an
    affine ``h``, else by twice ``|dh/dx|`` at the sample).
    """
    K = t.size
    comp = model.compiled()
    pv = model.param_vector
    n, q, p = model.n, model.q, model.p
    aff = affine_output(model)
    absC = np.abs(aff[0]) if aff is not None else None
    out = WindowVerdict(model, K, keep_every)
    names_w = list(model.disturbance_names)
    names_v = [nm if nm not in names_w else f"v:{nm}" for nm in model.output_names]
    x1 = np.array(x0, dtype=float)
    x2 = np.array(x0, dtype=float)
    bar = progress_bar(progress, K, desc, "sample", 49_999)
    a = 0
    try:
        while True:
            b = min(K - 1, a + max(1, int(window)))
            tf, Uf, idx = fine_grid(t[a : b + 1], U[a : b + 1], r)
            if q:
                Wf = Wt[a * r : b * r]
                Wf = np.ascontiguousarray(np.vstack([Wf, Wf[-1:]]))
            else:
                Wf = np.zeros((tf.size, 0))
            X1 = rk4_trace(comp.f, x1, Uf, Wf, tf, pv, int(substeps))
            X2 = rk4_trace(comp.f, x2, Uf, Wf, tf, pv, int(2 * substeps))
            x1, x2 = X1[-1].copy(), X2[-1].copy()
            first = 0 if a == 0 else 1  # sample a was checked by the previous window
            Xs = X2[idx][first:]
            err = (np.abs(X2[idx] - X1[idx]) * (16.0 / 15.0) + 1e-12 * (1 + np.abs(X2[idx])))[first:]
            ts = t[a + first : b + 1]
            if absC is not None:
                Vt = Y[a + first : b + 1] - evaluate_outputs(model, Xs, U[a + first : b + 1])
                yerr = err @ absC.T
            else:  # the state error through |dh/dx| (twice: the Jacobian changes along the error's segment);
                # it was 10 x the largest state error, whatever the output's gain (1e4: wrongly "conformant")
                Yh, J = evaluate_outputs(model, Xs, U[a + first : b + 1], jacobian=True)
                Vt = Y[a + first : b + 1] - Yh
                yerr = 2.0 * np.einsum("kpn,kn->kp", np.abs(J), err)
            if not np.all(np.isfinite(Xs)):
                out.finite = False
            for i, nm in enumerate(names_v):
                m = np.minimum(Vt[:, i] - yerr[:, i] - V_lo[i], V_hi[i] - Vt[:, i] - yerr[:, i])
                out._update(nm, np.where(np.isfinite(m), m, -np.inf), ts)
            if Vt.size:
                out.v_lo = np.minimum(out.v_lo, Vt.min(axis=0))
                out.v_hi = np.maximum(out.v_hi, Vt.max(axis=0))
                out.yerr = np.maximum(out.yerr, yerr.max(axis=0))
            if q:
                Wk = Wt[a * r : b * r]
                tw = np.repeat(t[a:b], r)
                for i, nm in enumerate(names_w):
                    out._update(nm, np.minimum(Wk[:, i] - W_lo[i], W_hi[i] - Wk[:, i]), tw)
            sel = np.arange(a + first, b + 1)
            keep = sel % out.step == 0
            if keep.any():
                out.X.append(Xs[keep])
                out.V.append(Vt[keep])
                out.t_kept.append(ts[keep])
            if bar is not None:
                bar.update(b + 1 - a - (1 - first))
            if b >= K - 1:
                break
            a = b
    finally:
        if bar is not None:
            bar.close()
    for nm in names_w:
        out.margin.setdefault(nm, 0.0)
    out.X = np.concatenate(out.X) if out.X else np.zeros((0, n))
    out.V = np.concatenate(out.V) if out.V else np.zeros((0, p))
    out.t_kept = np.concatenate(out.t_kept) if out.t_kept else np.zeros(0)
    return out


def disturbance_trace_in_windows(model, t, U, Y, Yx, W_lo, W_hi, V_lo, V_hi, options, method, progress=None,
                                 x0=None, budget=None):  # fmt: skip
    """DISTURBANCETRACE window by window; returns ``(x0, W, info)``.

    ``Yx``: state estimates at the samples (measured states), or None when
    the states cannot be read from the outputs (then only Alg. 2 applies).
    ``method``: "perstep", "optctrl" or "auto".  ``info`` has per-window
    records ``(a, c, method, reason)`` and messages of Alg. 2.
    """
    K = t.size
    q = model.q
    r = int(options.subdivision) if method != "perstep" else 1
    if method == "auto" and r != 1:
        r = 1  # the per-step fit has one disturbance per sample interval; auto keeps that grid
    plan = window_plan(K, options.window, options.overlap)
    if x0 is None:
        x0 = Yx[0].copy() if Yx is not None else state_guess(model, U[0], Y[0])
    W = np.zeros(((K - 1) * r, q))
    records, messages = [], []
    starts = [np.array(x0, dtype=float)]  # the state at the start of each window
    x0_out = starts[0].copy()
    bar = progress_bar(progress, K, f"DISTURBANCETRACE ({method})", "sample", 49_999)
    anchor = None
    merged = 0  # windows joined to the failed one so far (at most MAX_BACKTRACK)
    j = 0
    try:
        while j < len(plan):
            a, c, b = plan[j]
            x_start = starts[j]
            used, reason, Ww = method, "", None
            if method in ("perstep", "auto") and Yx is not None and not merged:
                Ww, anchor = _perstep_window(model, t[a:b], U[a:b], Yx[a:b], x_start, V_lo, V_hi, options)
                used = "perstep"
                if method == "auto":
                    ok, where = _window_ok(model, t[a:b], U[a:b], Y[a:b], x_start, Ww, W_lo, W_hi, V_lo, V_hi,
                                           options.substeps)  # fmt: skip
                    used, reason = ("perstep", "per-step trace within W and V") if ok else ("optctrl", f"per-step trace {where}")
            elif method == "auto":
                used = "optctrl"
                reason = "joined to the next window" if merged else "the states cannot be read from the outputs"
            if used == "optctrl":
                xs, Ww, msg, ok = _alg2_window(model, t, U, Y, W, plan, j, x_start, Ww, W_lo, W_hi, V_lo, V_hi,
                                               options, r)  # fmt: skip
                if not ok and j > 0 and merged < MAX_BACKTRACK:
                    # no trace from the carried state: solve again together with the previous window, whose
                    # start state is still free to move the junction (bounded: at most MAX_BACKTRACK windows)
                    messages.append(f"samples {a}-{b - 1}: {msg}; solved again from sample {plan[j - 1][0]}")
                    plan[j - 1] = (plan[j - 1][0], c, b)
                    del plan[j]
                    records.pop()
                    starts.pop()
                    j -= 1
                    merged += 1
                    continue
                messages.append(f"samples {a}-{b - 1}: {msg}")
                if j == 0:
                    x0_out = xs.copy()
                    starts[0] = xs.copy()
                    x_start = starts[0]
            # keep intervals a..c-1 and move to sample c
            W[a * r : c * r] = Ww[: (c - a) * r]
            if b > c + 1 and q:  # remember the look-ahead as the next window's start
                W[c * r : (b - 1) * r] = Ww[(c - a) * r :]
            starts.append(_advance(model, t[a : c + 1], U[a : c + 1], x_start, W[a * r : c * r], r, options.substeps))
            records.append((int(a), int(c), used, reason))
            merged = 0
            if bar is not None:
                bar.n = c + (1 if c == K - 1 else 0)
                bar.refresh()
            if budget is not None and c < K - 1:
                budget.check(c, K)
            j += 1
    finally:
        if bar is not None:
            bar.close()
    return x0_out, W, {"windows": records, "messages": messages, "anchor": anchor, "subdivision": r}


#: how many earlier windows a window whose carried start state admits no trace may be joined with
MAX_BACKTRACK = 3


def _alg2_window(model, t, U, Y, W, plan, j, x_start, Ww, W_lo, W_hi, V_lo, V_hi, options, r):
    """Alg. 2 on window ``j`` from ``x_start`` (free in the first window); ``(x0, W, message, ok)``."""
    a, c, b = plan[j]
    q = model.q
    start = np.zeros(((b - a - 1) * r, q))
    if Ww is not None and q:
        start = np.repeat(Ww, r, axis=0) if r > 1 else Ww.copy()
    if j > 0 and q:  # what the earlier windows left for these samples (their look-ahead) as the start
        known = min(plan[j - 1][2] - 1, b - 1) - a
        if known > 0:
            start[: known * r] = W[a * r : (a + known) * r]
    start = np.clip(start, W_lo, W_hi) if q else start
    scale = _robust_scale(Ww, q)
    x0, Wt, message, ok = optctrl_trace(model, t[a:b], U[a:b], Y[a:b], W_lo, W_hi, V_lo, V_hi, x_start.copy(), start,
                                        options, x0_fixed=j > 0, scale=scale)  # fmt: skip
    for reserve in ALG2_RESERVES:
        if ok or NO_TRACE in message:
            break
        # not converged: the linearisation error (coarse samples) exceeds the 0.1 % of V kept in reserve; solve
        # again from the last trace keeping more of V for it (the verdict simulates the result anyway)
        x0, Wt, again, ok = optctrl_trace(model, t[a:b], U[a:b], Y[a:b], W_lo, W_hi, V_lo, V_hi,
                                          x0.copy() if j == 0 else x_start.copy(), Wt, options, x0_fixed=j > 0,
                                          reserve=reserve, scale=scale)  # fmt: skip
        message += f"; again with {100 * (1 - reserve):g} % of V in reserve: {again}"
    return x0, Wt, message, ok


#: V's share Alg. 2 keeps for the QP (1 - reserve) when it does not converge with 0.1 %
ALG2_RESERVES = (0.98, 0.9)


def _robust_scale(Ww, q):
    """Per-channel scale of eq. 36's weights from a per-step trace (1.4826 MAD; 1 without one)."""
    if Ww is None or not q or Ww.shape[0] == 0:
        return None
    mad = 1.4826 * np.median(np.abs(Ww - np.median(Ww, axis=0)), axis=0)
    return np.where(mad > 0, mad, 1.0)


def perstep_weights(model, Yx, V_lo, V_hi, objective):
    """Weights of the per-step residual components (per step, per state): ``1 / scale^2``.

    The scale is V's radius where a state is measured directly and V is not
    zero there, else the state's spread; ``objective="relative"``: eq. 27's
    ``1 / y_{k+1}^2``.
    """
    K, n = Yx.shape
    if objective == "relative":
        if np.any(Yx[1:] == 0):
            raise ConformanceError("objective='relative' (eq. 27) needs measurements that are never zero")
        return 1.0 / Yx[1:] ** 2
    direct = output_index_of_states(model)
    scale = np.ptp(Yx, axis=0)
    if direct is not None:
        vrad = 0.5 * (V_hi - V_lo)[direct]
        scale = np.where(vrad > 0, vrad, scale)
    scale = np.where(scale > 0, scale, 1.0)
    return np.tile(1.0 / scale**2, (K - 1, 1))


def _perstep_window(model, t, U, Yx, x_start, V_lo, V_hi, options):
    anchor = options.anchor
    if anchor == "auto":
        anchor = "measured" if model.q >= model.n else "simulated"
    if model.q == 0:
        return np.zeros((t.size - 1, 0)), anchor
    S = np.array(Yx, dtype=float)
    S[0] = x_start
    weights = np.ascontiguousarray(perstep_weights(model, Yx, V_lo, V_hi, options.objective))
    W0 = np.zeros((t.size - 1, model.q))
    try:
        Wt, _ = perstep_fit(model.compiled().f, S, np.ascontiguousarray(Yx), np.ascontiguousarray(U[:-1]), np.diff(t),
                            model.param_vector, weights, W0, int(options.substeps), int(options.gauss_newton_iterations),
                            anchor == "simulated")  # fmt: skip
    except np.linalg.LinAlgError:  # a step's Gauss-Newton system went non-finite (e.g. a glitch of 1e4 in a sample)
        Wt = np.full((t.size - 1, model.q), np.nan)  # no per-step trace: its simulation is "diverged (NaN/inf)"
    return Wt, anchor


def _window_ok(model, t, U, Y, x_start, Ww, W_lo, W_hi, V_lo, V_hi, substeps):
    """Does the simulated window trace stay within W and V?  ``(ok, where-text)``."""
    v = verdict_in_windows(model, t, U, Y, x_start, Ww, W_lo, W_hi, V_lo, V_hi, substeps, 1, window=t.size,
                           keep_every=max(1, t.size), progress=False)  # fmt: skip
    worst = min(v.margin, key=v.margin.get) if v.margin else None
    if worst is None or (v.finite and v.margin[worst] >= 0):
        return True, ""
    if not v.finite:
        return False, "diverged (NaN/inf)"
    return False, describe_violation(model, worst, v.margin[worst], v.margin_time[worst], W_lo, W_hi, V_lo, V_hi)


def describe_violation(model, channel, margin, when, W_lo, W_hi, V_lo, V_hi) -> str:
    """``"leaves V on output vy at t = 3.2 s by 0.012 (12 % of V's half-width)"``."""
    names_w = list(model.disturbance_names)
    if channel in names_w:
        i = names_w.index(channel)
        rad = 0.5 * (W_hi[i] - W_lo[i])
        what = f"leaves W on disturbance {channel}"
    else:
        name = channel[2:] if channel.startswith("v:") else channel
        i = list(model.output_names).index(name)
        rad = 0.5 * (V_hi[i] - V_lo[i])
        what = f"leaves V on output {name}"
    rel = f" ({-100 * margin / rad:.3g} % of its half-width)" if np.isfinite(rad) and rad > 0 else ""
    return f"{what} at t = {when:.4g} s by {-margin:.3g}{rel}"


def _advance(model, t, U, x, Wk, r, substeps):
    """The state at ``t[-1]`` simulated from ``x`` at ``t[0]`` (the carried state estimate)."""
    if t.size < 2:
        return np.array(x, dtype=float)
    tf, Uf, _ = fine_grid(t, U, r)
    Wf = np.ascontiguousarray(np.vstack([Wk, Wk[-1:]])) if Wk.shape[1] else np.zeros((tf.size, 0))
    return rk4_trace(model.compiled().f, np.array(x, dtype=float), Uf, Wf, tf, model.param_vector,
                     int(substeps))[-1].copy()  # fmt: skip


def keep_step(K: int, keep_samples: int) -> int:
    """Every how many samples the state/error traces are kept so that at most ``keep_samples`` remain."""
    return max(1, math.ceil(K / max(1, int(keep_samples))))


#: why a per-step trace that misses a bound is "undecided" (eqs. 26/27 fit w to the noisy measured states)
PERSTEP_NO_PROOF = ("; undecided: the per-step fit (eqs. 26/27) uses the measurements as states, so its trace missing "
                    "a bound is no proof; method='auto' or 'optctrl' searches within V")


def summarize_windows(info, method):
    """``(method label, reason, message, search failed)`` of :func:`disturbance_trace_in_windows`'s ``info``.

    ``search failed``: Alg. 2's QP found no trace in a window that was not
    solved again (the trace verdict is then undecided, see ``optctrl.NO_TRACE``).
    """
    windows = info["windows"]
    used = sorted({w[2] for w in windows})
    if len(used) == 1:
        label = used[0]
        if label == "perstep" and info.get("anchor"):
            label = f"perstep ({info['anchor']})"
    else:
        counts = {m_: sum(w[2] == m_ for w in windows) for m_ in used}
        label = "auto: " + ", ".join(f"{m_} in {c} windows" for m_, c in counts.items())
    if method != "auto":
        reason = f"method={method!r} was asked for"
    elif len(windows) == 1:
        reason = windows[0][3]
    else:
        reason = "; ".join(f"samples {a}-{c}: {why}" for a, c, _, why in windows[:5] if why)
    msgs = info["messages"]
    trouble = [m_ for m_ in msgs if "converged" not in m_ and "within V" not in m_]
    if len(msgs) <= 3:
        message = "; ".join(msgs)
    else:  # the windows where Alg. 2 had trouble first, then a count of the others
        message = "; ".join(trouble[:5]) + ("; " if trouble else "")
        message += f"Alg. 2 converged in {len(msgs) - len(trouble)} of {len(msgs)} windows"
    failed = any(NO_TRACE in m_ and "solved again" not in m_ for m_ in msgs)
    return label, reason, message, failed

