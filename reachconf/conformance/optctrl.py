"""Optimal-control disturbance traces (Alg. 2, eqs. 29–41) and box minimisation by SCP.

Both solve, around a consistent trace (simulated states ``X`` for the
disturbances ``W``), the convex problem on the linearised dynamics::

    dx[j+1] = Ad[j] dx[j] + Bd[j] dw[j] + d[j]            (eqs. 30–32)
    lo_W <= w[j] + dw[j] <= hi_W                           (eqs. 37/38)
    V_lo <= y_k - h(x_k) - C_k dx_k <= V_hi                (eqs. 39/40)
    |dx| <= trust region

with ``d[j]`` the defect of the current trace, then re-simulate (the IVP of
Alg. 2, line 7) and repeat until the simulated and the optimised states agree
(line 8).  Unlike eq. 34 we keep ``dx`` and ``dw`` both as variables with the
dynamics as equality constraints, so no r-step controllability (pseudo-inverse
of ``B~``) is needed; ``subdivision = r`` still splits each sample interval
into ``r`` disturbance steps.

* :func:`optctrl_trace` — Alg. 2 with the fixed box ``W`` and the quadratic
  cost of eq. 36 (smallest average disturbances).
* :func:`box_scp` — the same constraints with the box itself a variable:
  minimise its volume (synthesis step 2; the concave log-volume is majorised by
  its tangent each iteration) or the sum of its normalised widths
  (:func:`reachconf.minimal_trace_bounds`).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sps

from reachconf.errors import SolverError
from reachconf.model.outputs import evaluate_outputs, output_index_of_states, state_estimate
from reachconf.model.simulate import simulate
from reachconf_kernels.integrate import rk4_one_step_each
from reachconf_kernels.tracefit import discrete_linearization

__all__ = ["optctrl_trace", "box_scp", "fine_grid", "NO_TRACE"]

#: in the message of :func:`optctrl_trace` when its QP failed (the trace verdict is then undecided)
NO_TRACE = "no disturbance trace found"


def fine_grid(t, U, r):
    """Time grid with ``r`` sub-steps per sample interval; inputs repeated; sample indices."""
    if r == 1:
        return t, U, np.arange(t.size)
    K = t.size
    tf = np.concatenate([np.linspace(t[k], t[k + 1], r, endpoint=False) for k in range(K - 1)] + [t[-1:]])
    Uf = np.vstack([np.repeat(U[:-1], r, axis=0), U[-1:]])
    return tf, np.ascontiguousarray(Uf), np.arange(K) * r


class _Linearised:
    """Sparse pieces of the linearised problem around ``(X, W)`` on the grid ``tf``."""

    def __init__(self, model, tf, Uf, X, W):
        comp = model.compiled()
        pv = model.param_vector
        n, q = model.n, model.q
        J = tf.size - 1
        dts = np.diff(tf)
        Ad, Bd = discrete_linearization(comp.jac, X[:-1].copy(), Uf[:-1].copy(), W, dts, pv)
        Phi = rk4_one_step_each(comp.f, X[:-1].copy(), Uf[:-1].copy(), W, dts, pv, 10)
        self.defect = Phi - X[1:]
        nx, nw = (J + 1) * n, J * q
        # rows j*n + a:  dx[j+1, a] - sum_b Ad[j, a, b] dx[j, b] - sum_c Bd[j, a, c] dw[j, c] = defect[j, a]
        jj, aa, bb = np.meshgrid(np.arange(J), np.arange(n), np.arange(n), indexing="ij")
        rows_A = (jj * n + aa).ravel()
        cols_A = (jj * n + bb).ravel()
        ident_rows = np.arange(J * n)
        ident_cols = n + np.arange(J * n)
        jw, aw, cw = np.meshgrid(np.arange(J), np.arange(n), np.arange(q), indexing="ij")
        rows = np.concatenate([ident_rows, rows_A, (jw * n + aw).ravel()])
        cols = np.concatenate([ident_cols, cols_A, nx + (jw * q + cw).ravel()])
        vals = np.concatenate([np.ones(J * n), -Ad.ravel(), -Bd.ravel()])
        self.Aeq = sps.csr_matrix((vals, (rows, cols)), shape=(J * n, nx + nw))
        self.beq = self.defect.ravel()
        self.nx, self.nw = nx, nw


def _output_rows(model, X, Uf, idx, Y):
    """Sparse map dx -> C_k dx_k at the sample indices, and the current residual ``Y - h(X)``."""
    Yh, Jh = evaluate_outputs(model, X[idx], Uf[idx], jacobian=True)
    K, p, n = Jh.shape
    kk, ii, bb = np.meshgrid(np.arange(K), np.arange(p), np.arange(n), indexing="ij")
    rows = (kk * p + ii).ravel()
    cols = (idx[kk] * n + bb).ravel()
    C = sps.csr_matrix((Jh.ravel(), (rows, cols)), shape=(K * p, X.shape[0] * n))
    return C, (Y - Yh)


def _solve(problem, solver):
    import cvxpy as cp  # imported when a problem is solved: its import takes about a second

    tried = [solver] if solver else ["CLARABEL", "OSQP"]
    last = None
    for name in tried:
        try:
            problem.solve(solver=name)
            last = problem.status
            if problem.status in (cp.OPTIMAL, cp.OPTIMAL_INACCURATE):
                return problem.status
            if problem.status in (cp.INFEASIBLE, cp.INFEASIBLE_INACCURATE):
                return problem.status
        except cp.error.SolverError as exc:  # try the next solver
            last = str(exc)
    raise SolverError(f"the QP solver failed ({last})")


def _scales(model, Y, X):
    """State scales for the trust region: the spread of the simulated and of the measured states.

    The first simulation (from the initial estimate with zero disturbance) may
    barely move, so the measured states are taken into account too.
    """
    sx = np.maximum(np.ptp(X, axis=0), np.max(np.abs(X), axis=0))
    direct = output_index_of_states(model)
    if direct is not None:
        Ys = Y[:, direct]
        sx = np.maximum(sx, np.maximum(np.ptp(Ys, axis=0), np.max(np.abs(Ys), axis=0)))
    return np.where(sx > 0, sx, 1.0)


def optctrl_trace(model, t, U, Y, W_lo, W_hi, V_lo, V_hi, options, case, start=None):
    """Alg. 2: a disturbance trace in ``[W_lo, W_hi]`` keeping the outputs within ``V`` (eqs. 29–41).

    Returns ``(x0, W_trace, message)``; ``W_trace`` has ``(K-1) r`` rows.
    """
    import cvxpy as cp

    r = int(options.subdivision)
    tf, Uf, idx = fine_grid(t, U, r)
    n, q = model.n, model.q
    J = tf.size - 1
    if start is not None:
        x0 = start.x0.copy()
        W = np.repeat(start.W_trace, r, axis=0) if start.W_trace.shape[0] == t.size - 1 else start.W_trace.copy()
    else:
        try:
            x0 = state_estimate(model, case)[0]
        except Exception:  # partial outputs: start from the outputs' least-squares state
            x0 = np.zeros(n)
        W = np.zeros((J, q))
    W = np.clip(W, np.where(np.isfinite(W_lo), W_lo, -np.inf), np.where(np.isfinite(W_hi), W_hi, np.inf))
    X = simulate(model, x0, tf, Uf, W, substeps=10, check=False)
    sx = _scales(model, Y, X)
    wrad = 0.5 * (W_hi - W_lo)
    sw = np.where(np.isfinite(wrad) & (wrad > 0), wrad, 1.0)
    # keep a little of V for the QP tolerance and the integration error
    vc, vr = 0.5 * (V_lo + V_hi), 0.5 * (V_hi - V_lo)
    V_lo, V_hi = vc - 0.999 * vr, vc + 0.999 * vr
    message = ""
    for it in range(options.max_iterations):
        lin = _Linearised(model, tf, Uf, X, W)
        C, resid = _output_rows(model, X, Uf, idx, Y)
        z = cp.Variable(lin.nx + lin.nw)
        dx, dw = z[: lin.nx], z[lin.nx :]
        cons = [lin.Aeq @ z == lin.beq, cp.abs(dx) <= np.tile(options.trust_region * sx, J + 1)]
        lo = np.tile(W_lo, J) - W.ravel()
        hi = np.tile(W_hi, J) - W.ravel()
        fin = np.isfinite(lo)
        if fin.any():
            cons.append(dw[np.nonzero(fin)[0]] >= lo[fin])
        fin = np.isfinite(hi)
        if fin.any():
            cons.append(dw[np.nonzero(fin)[0]] <= hi[fin])
        # V_lo <= resid - C dx <= V_hi
        cons += [C @ dx <= (resid - V_lo).ravel(), C @ dx >= (resid - V_hi).ravel()]
        weights = np.tile(1.0 / sw, J)
        objective = cp.sum_squares(cp.multiply(weights, W.ravel() + dw)) + 1e-6 * cp.sum_squares(
            cp.multiply(np.tile(1.0 / sx, J + 1), dx))  # fmt: skip
        status = _solve(cp.Problem(cp.Minimize(objective), cons), options.solver)
        if status not in ("optimal", "optimal_inaccurate"):
            message = f"Alg. 2: the linearised QP is {status} in iteration {it + 1}: {NO_TRACE}"
            break
        DX = np.asarray(dx.value).reshape(J + 1, n)
        X_tilde = X + DX
        W = W + np.asarray(dw.value).reshape(J, q)
        W = np.clip(W, np.where(np.isfinite(W_lo), W_lo, -np.inf), np.where(np.isfinite(W_hi), W_hi, np.inf))
        x0 = X_tilde[0]
        X = simulate(model, x0, tf, Uf, W, substeps=10, check=False)
        e = np.max(np.abs(X - X_tilde) / sx)
        if e <= options.epsilon:
            message = f"Alg. 2 converged in {it + 1} iterations"
            break
    else:
        message = f"Alg. 2 stopped after {options.max_iterations} iterations (last change {e:.2e})"
    return x0, W, message


def box_scp(model, t, U, Y, V_lo, V_hi, x0, W, options, objective="volume", W_fixed=None, V_free=False,
            iterations=None, scale=None):  # fmt: skip
    """Sequential convex programming for the smallest box (W, or V with ``V_free``).

    Parameters
    ----------
    x0, W : start trace (W on the grid of ``options.subdivision``)
    objective : {"volume", "sum"}
        Minimise the box volume (tangent majorisation of the log-volume) or
        the sum of normalised widths.
    W_fixed : (lo, hi) or None
        Keep the disturbances inside this fixed box (e.g. ``{0}`` when
        solving for V) instead of a variable one.
    V_free : bool
        Make the measurement-error box the variable (``V_lo, V_hi`` are ignored).

    Returns
    -------
    (lo, hi, x0, W)
    """
    import cvxpy as cp

    r = int(options.subdivision)
    tf, Uf, idx = fine_grid(t, U, r)
    n, q, p = model.n, model.q, model.p
    J = tf.size - 1
    if r > 1 and W.shape[0] == t.size - 1:  # a start trace on the sample grid: hold it over the sub-steps
        W = np.repeat(W, r, axis=0)
    X = simulate(model, x0, tf, Uf, W, substeps=10, check=False)
    sx = _scales(model, Y, X)
    dim = p if V_free else q
    if V_free:
        Yh_res = _output_rows(model, X, Uf, idx, Y)[1]
        lo_prev, hi_prev = Yh_res.min(axis=0), Yh_res.max(axis=0)
    else:
        lo_prev, hi_prev = (W.min(axis=0), W.max(axis=0)) if W.size else (np.zeros(q), np.zeros(q))
    width0 = np.maximum(hi_prev - lo_prev, 1e-12)
    norm = scale if scale is not None else width0
    for it in range(iterations or options.max_iterations):
        lin = _Linearised(model, tf, Uf, X, W)
        C, resid = _output_rows(model, X, Uf, idx, Y)
        z = cp.Variable(lin.nx + lin.nw)
        lo, hi = cp.Variable(dim), cp.Variable(dim)
        dx, dw = z[: lin.nx], z[lin.nx :]
        cons = [lin.Aeq @ z == lin.beq, cp.abs(dx) <= np.tile(options.trust_region * sx, J + 1), lo <= hi]
        if q:
            Wn = W.ravel() + dw
            if V_free or W_fixed is not None:
                wlo, whi = W_fixed if W_fixed is not None else (np.full(q, -np.inf), np.full(q, np.inf))
                fl, fh = np.isfinite(np.tile(wlo, J)), np.isfinite(np.tile(whi, J))
                if fl.any():
                    cons.append(Wn[np.nonzero(fl)[0]] >= np.tile(wlo, J)[fl])
                if fh.any():
                    cons.append(Wn[np.nonzero(fh)[0]] <= np.tile(whi, J)[fh])
            else:
                Wmat = cp.reshape(Wn, (J, q), order="C")
                ones = np.ones((J, 1))
                cons += [Wmat >= ones @ cp.reshape(lo, (1, q), order="C"),
                         Wmat <= ones @ cp.reshape(hi, (1, q), order="C")]  # fmt: skip
        Cdx = cp.reshape(C @ dx, (idx.size, p), order="C")
        R = resid
        if V_free:
            cons += [R - Cdx >= np.ones((idx.size, 1)) @ cp.reshape(lo, (1, p), order="C"),
                     R - Cdx <= np.ones((idx.size, 1)) @ cp.reshape(hi, (1, p), order="C")]  # fmt: skip
        else:
            cons += [C @ dx <= (R - V_lo).ravel(), C @ dx >= (R - V_hi).ravel()]
        width = hi - lo
        if objective == "volume":
            obj = cp.sum(cp.multiply(1.0 / (np.maximum(hi_prev - lo_prev, 0) + 1e-3 * width0), width))
        else:
            obj = cp.sum(cp.multiply(1.0 / norm, width))
        obj = obj + 1e-6 * cp.sum_squares(cp.multiply(np.tile(1.0 / sx, J + 1), dx))
        status = _solve(cp.Problem(cp.Minimize(obj), cons), options.solver)
        if status not in ("optimal", "optimal_inaccurate"):
            break
        DX = np.asarray(dx.value).reshape(J + 1, n)
        X_tilde = X + DX
        if q:
            W = W + np.asarray(dw.value).reshape(J, q)
        x0 = X_tilde[0]
        X = simulate(model, x0, tf, Uf, W, substeps=10, check=False)
        new_lo, new_hi = np.asarray(lo.value), np.asarray(hi.value)
        change = np.max(np.abs(new_hi - new_lo - (hi_prev - lo_prev)) / width0)
        lo_prev, hi_prev = new_lo, new_hi
        e = np.max(np.abs(X - X_tilde) / sx)
        if e <= max(options.epsilon, 1e-9) and change < 1e-3:
            break
        if it >= 2 and e <= 1e-3 and change < 2e-2:  # the box has settled to 2 %: verified below anyway
            break
    if V_free:
        res = _output_rows(model, X, Uf, idx, Y)[1]
        return res.min(axis=0), res.max(axis=0), x0, W
    if q:
        return W.min(axis=0), W.max(axis=0), x0, W
    return np.zeros(0), np.zeros(0), x0, W
