"""Alg. 2 and the box SCP as sparse, banded QPs solved directly (no modelling layer).

Both problems — Alg. 2's disturbance trace (eqs. 29–41, cost eq. 36) and
synthesis step 2's smallest box — are, around a consistent trace (simulated
states ``X`` for disturbances ``W``), convex problems on the linearised dynamics::

    dx[j+1] = Ad[j] dx[j] + Bd[j] dw[j] + d[j]            (eqs. 30–32)
    lo_W <= w[j] + dw[j] <= hi_W                           (eqs. 37/38)
    V_lo <= y_k - h(x_k) - C_k dx_k <= V_hi                (eqs. 39/40)
    |dx| <= trust region

whose constraint matrix is block-banded in time: every row touches one or
two consecutive steps (plus the ``2 q`` box variables).  Unlike eq. 34 we keep
``dx`` and ``dw`` both as variables with the dynamics as equality
constraints, so no r-step controllability (pseudo-inverse of ``B~``) is
needed; ``subdivision = r`` still splits each sample interval into ``r``
disturbance steps.  This module writes the matrix once per iteration as one
scipy CSC matrix (vectorised index arithmetic, no loop over time steps) and
hands it to Clarabel's interior-point solver, whose sparse LDLᵀ factorisation
of the KKT system costs time and memory linear in the number of steps.
Variables are scaled (states by the measurement-error radius, disturbances
by the box radius) so that one tolerance fits all channels.

The solved trace is re-simulated (Alg. 2, line 7) until the simulated outputs agree with the linear
prediction (line 8, in units of V's radius).  A first QP with no W in its bounds takes one step with W
unbounded.  Vehicle suites at 100 Hz (9,000 variables): 0.2–0.5 s per QP (cvxpy: 1–2 s), 2–3 iterations.

* :func:`optctrl_trace` — Alg. 2 with a fixed box ``W`` and eq. 36's cost;
* :func:`reachconf.conformance.bounds.box_scp` — the same constraints with the
  box itself a variable (synthesis step 2), on :class:`TraceQP` too.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sps

from reachconf.errors import SolverError
from reachconf.model.outputs import affine_output, evaluate_outputs, output_index_of_states
from reachconf_kernels.integrate import eval_outputs, rk4_one_step_each, rk4_trace
from reachconf_kernels.ocp_ipm import ocp_qp
from reachconf_kernels.tracefit import discrete_linearization

__all__ = ["TraceQP", "fine_grid", "solve_sparse_qp", "optctrl_trace", "disturbance_scale", "NO_TRACE"]

#: in the message of :func:`optctrl_trace` when its QP failed (the trace verdict is then undecided)
NO_TRACE = "no disturbance trace found"


def fine_grid(t, U, r):
    """Time grid with ``r`` sub-steps per sample interval; inputs repeated; sample indices on it."""
    if r == 1:  # writeable copies: the compiled kernels take mutable arrays
        return np.array(t, dtype=float), np.array(U, dtype=float, order="C"), np.arange(np.size(t))
    K = t.size
    frac = np.arange(r) / r
    tf = np.concatenate([(t[:-1, None] + frac[None, :] * np.diff(t)[:, None]).ravel(), t[-1:]])
    Uf = np.vstack([np.repeat(U[:-1], r, axis=0), U[-1:]])
    return tf, np.ascontiguousarray(Uf), np.arange(K) * r


def _settings(tol, refine, presolve=True, extra=None):
    import clarabel

    s = clarabel.DefaultSettings()
    s.verbose = False
    s.max_iter = 60
    s.tol_feas = s.tol_gap_abs = s.tol_gap_rel = tol
    s.iterative_refinement_enable = refine
    s.presolve_enable = presolve
    for k, v in (extra or {}).items():
        setattr(s, k, v)
    return s


def _same_pattern(a, b) -> bool:
    return a.shape == b.shape and np.array_equal(a.indptr, b.indptr) and np.array_equal(a.indices, b.indices)


def _solve_reused(reuse, Pu, c, A, b, n_eq, cones):
    """Solve through the solver kept in ``reuse`` when the sparsity pattern is the one it was set up for.

    An SCP solves QPs of one pattern again and again: updating the data of the
    solver skips its setup (KKT ordering and factorisation structure), about
    40 % of a solve of the vehicle's 100 Hz box QPs, with the same optimum.
    """
    import clarabel

    kept = reuse.get("solver")
    if kept is not None and reuse["n_eq"] == n_eq and _same_pattern(reuse["P"], Pu) and _same_pattern(reuse["A"], A):
        kept.update(P=Pu, q=c, A=A, b=b)
        return kept.solve()
    solver = clarabel.DefaultSolver(Pu, c, A, b, cones, _settings(1e-7, False, presolve=False))
    if solver.is_data_update_allowed():
        reuse.update(solver=solver, n_eq=n_eq, P=Pu, A=A)
    return solver.solve()


def solve_sparse_qp(P, c, A, b, n_eq, settings=None, reuse=None):
    """``min 1/2 z'Pz + c'z`` s.t. ``A[:n_eq] z = b[:n_eq]``, ``A[n_eq:] z <= b[n_eq:]`` (Clarabel).

    ``reuse``: a dict kept between calls with QPs of one sparsity pattern
    (e.g. the iterations of an SCP): the solver set up for the first is
    updated with the data of the next (finite ``b`` and no ``settings`` only;
    a solve that fails that way is done again from scratch).

    Returns ``(status, z)`` with status ``"optimal"``, ``"infeasible"`` or the
    solver's own word; ``z`` is None unless solved.
    """
    import clarabel

    cones = [clarabel.ZeroConeT(int(n_eq)), clarabel.NonnegativeConeT(int(A.shape[0] - n_eq))]
    Pu, A, c, b = sps.triu(P, format="csc"), A.tocsc(), np.asarray(c, float), np.asarray(b, float)
    status = "not solved"
    attempts = ((1e-7, False), (1e-7, True), (1e-6, True))
    if reuse is not None and not settings and np.all(np.isfinite(b)):
        try:
            sol = _solve_reused(reuse, Pu, c, A, b, int(n_eq), cones)
        except Exception:  # noqa: BLE001 - the fresh solves below report a real failure
            reuse.clear()
            sol = None
        if sol is not None:
            if str(sol.status) in ("Solved", "AlmostSolved"):
                return "optimal", np.asarray(sol.x)
            attempts = attempts[1:]  # the unrefined solve at 1e-7 was this one: go on with refined KKT solves
    # the scaled problems need no more than 1e-7 (a ten-millionth of V; every trace is simulated and checked
    # again): Clarabel's default 1e-8 sometimes stalls at a residual floor of 2e-10 and then diverges
    # first without iterative refinement of the KKT solves (measured on the vehicle's 100 Hz box QPs: the same
    # iterations and optimum, 40 % less solve time); if that does not solve, with it
    for tol, refine in attempts:
        try:
            sol = clarabel.DefaultSolver(Pu, c, A, b, cones, _settings(tol, refine, extra=settings)).solve()
        except Exception as exc:  # pragma: no cover - Clarabel raises on malformed data only
            raise SolverError(f"the QP solver (Clarabel) failed: {exc}") from None
        status = str(sol.status)
        if status in ("Solved", "AlmostSolved"):
            return "optimal", np.asarray(sol.x)
        if "Infeasible" in status and refine:  # an infeasibility is confirmed with refined KKT solves
            return "infeasible", None
    return status, None


class TraceQP:
    """One case (or window) on the grid of Alg. 2, with the scales of its QPs.

    Parameters
    ----------
    model : Model
    t, U, Y : sample times, inputs, measurements (model order)
    V_lo, V_hi : measurement-error box
    r : int
        Disturbances per sample interval (Alg. 2's subdivision).
    substeps : int
        RK4 steps per grid interval of the simulations.
    state_scale : ndarray (n,), optional
        Scale of the state corrections (default: V's radius where a state is
        measured directly, else the spread of the measurements/states).
    """

    def __init__(self, model, t, U, Y, V_lo, V_hi, r=1, substeps=10, state_scale=None, trust=None):
        self.model = model
        self.t, self.U, self.Y = t, U, Y
        self.r = int(r)
        self.tf, self.Uf, self.idx = fine_grid(t, U, self.r)
        self.n, self.q, self.p = model.n, model.q, model.p
        self.J = self.tf.size - 1
        self.substeps = int(substeps)
        self.V_lo, self.V_hi = np.asarray(V_lo, float), np.asarray(V_hi, float)
        vrad = 0.5 * (self.V_hi - self.V_lo)
        self.spread_y = np.maximum(np.ptp(Y, axis=0), np.max(np.abs(Y), axis=0))
        sv = np.where(np.isfinite(vrad) & (vrad > 0), vrad, np.where(self.spread_y > 0, 1e-3 * self.spread_y, 1.0))
        self.aff = affine_output(model)
        self.direct = output_index_of_states(model)
        self.partial = {i: j for i, s in enumerate(model.z_symbols[: model.n]) for j, e in enumerate(model.h_expr)
                        if e == s}  # state -> the output that is that state  # fmt: skip
        self.set_scales(sv, state_scale, trust)
        self._qp_solver = {}  # the QP solver kept between the SCP's solves (solve_sparse_qp's ``reuse``)

    def __getstate__(self):
        state = dict(self.__dict__)
        state["_qp_solver"] = {}  # a solver does not travel between processes
        return state

    def set_scales(self, sv, state_scale=None, trust=None):
        """Units of the output rows (``sv``) and of the state corrections (``sx``), and the trust region."""
        self.sv = np.asarray(sv, float)
        direct = self.direct
        if state_scale is None:
            sx = np.ones(self.n)
            spread = np.ones(self.n)
            if direct is not None:
                sx = self.sv[direct].copy()
                spread = np.maximum(self.spread_y[direct], sx)
            for i, j in self.partial.items() if direct is None else ():  # measured states: their outputs' units
                sx[i], spread[i] = self.sv[j], max(self.spread_y[j], self.sv[j])
            state_scale = sx
            trust = spread if trust is None else trust
        self.sx = np.asarray(state_scale, float)
        self.trust = np.asarray(trust if trust is not None else 1e3 * self.sx, float)

    # ------------------------------------------------------------------ pieces
    def simulate(self, x0, W):
        """States on the grid from ``x0`` with the disturbance trace ``W`` (RK4, ``substeps`` per interval)."""
        Wf = np.ascontiguousarray(np.vstack([W, W[-1:]])) if W.shape[0] else np.zeros((self.tf.size, 0))
        x0 = np.array(x0, dtype=float)  # a writable copy: the kernel's signature takes no read-only array
        return rk4_trace(self.model.compiled().f, x0, self.Uf, Wf, self.tf,
                         self.model.param_vector, self.substeps)  # fmt: skip

    def outputs(self, X):
        """``h(x, u)`` at the sample stages of the grid."""
        return evaluate_outputs(self.model, X[self.idx], self.Uf[self.idx])

    def output_jacobians(self, X):
        """``(resid, Jh)``: ``Y - h(X)`` at the samples and ``dh/dx`` there ((K, p, n), or (p, n) if affine)."""
        if self.aff is not None:
            return self.Y - self.outputs(X), self.aff[0]
        comp = self.model.compiled()
        Yh, Jz = eval_outputs(comp.h, comp.jac_h, np.ascontiguousarray(X[self.idx]),
                              np.ascontiguousarray(self.Uf[self.idx]), self.model.param_vector, self.p, self.q)  # fmt: skip
        return self.Y - Yh, np.ascontiguousarray(Jz[:, :, : self.n])

    def linearisation(self, X, W):
        """``(Ad, Bd, defect)`` of eqs. 30–32 around the trace ``(X, W)`` (unscaled)."""
        comp, pv, dts = self.model.compiled(), self.model.param_vector, np.diff(self.tf)
        Xs = np.ascontiguousarray(X[:-1])
        Us = np.ascontiguousarray(self.Uf[:-1])
        Ws = np.ascontiguousarray(W) if self.q else np.zeros((self.J, 0))
        Ad, Bd = discrete_linearization(comp.jac, Xs, Us, Ws, dts, pv)
        Phi = rk4_one_step_each(comp.f, Xs, Us, Ws, dts, pv, self.substeps)
        with np.errstate(invalid="ignore", over="ignore"):  # a diverging trace: the QP reports it, numpy need not
            return Ad, Bd, Phi - X[1:]

    def dynamics(self, X, W):
        """Scaled equality rows (CSC pieces) of the linearised dynamics around the trace ``(X, W)``."""
        n, q, J = self.n, self.q, self.J
        Ad, Bd, defect = self.linearisation(X, W)
        sx = self.sx
        nx = (J + 1) * n
        jj = np.arange(J)[:, None, None]
        aa = np.arange(n)[None, :, None]
        bb = np.arange(n)[None, None, :]
        rows_A = np.broadcast_to(jj * n + aa, (J, n, n)).ravel()
        cols_A = np.broadcast_to(jj * n + bb, (J, n, n)).ravel()
        vals_A = (-Ad * sx[None, None, :] / sx[None, :, None]).ravel()
        rows_I = np.arange(J * n)
        cols_I = n + np.arange(J * n)
        parts_r, parts_c, parts_v = [rows_I, rows_A], [cols_I, cols_A], [np.ones(J * n), vals_A]
        if q:
            cc = np.arange(q)[None, None, :]
            rows_B = np.broadcast_to(jj * n + aa, (J, n, q)).ravel()
            cols_B = np.broadcast_to(nx + jj * q + cc, (J, n, q)).ravel()
            parts_r.append(rows_B)
            parts_c.append(cols_B)
            parts_v.append((-Bd * self.sw[None, None, :] / sx[None, :, None]).ravel())
        rows, cols, vals = np.concatenate(parts_r), np.concatenate(parts_c), np.concatenate(parts_v)
        keep = vals != 0
        rhs = (defect / sx[None, :]).ravel()
        return rows[keep], cols[keep], vals[keep], rhs

    def output_rows(self, X):
        """``(rows, cols, vals, resid)`` of ``C_k dx_k`` in scaled units (rows k p + i)."""
        resid, Jh = self.output_jacobians(X)
        K, n, p = self.idx.size, self.n, self.p
        kk = np.arange(K)[:, None, None]
        ii = np.arange(p)[None, :, None]
        bb = np.arange(n)[None, None, :]
        rows = np.broadcast_to(kk * p + ii, (K, p, n)).ravel()
        cols = np.broadcast_to(self.idx[:, None, None] * n + bb, (K, p, n)).ravel()
        Jfull = np.broadcast_to(Jh, (K, p, n)) if Jh.ndim == 2 else Jh
        vals = (Jfull * self.sx[None, None, :] / self.sv[None, :, None]).ravel()
        keep = vals != 0
        return rows[keep], cols[keep], vals[keep], resid

    # ------------------------------------------------------------------ QP
    def build(self, X, W, mode, W_lo=None, W_hi=None, V_lo=None, V_hi=None, x0_fixed=False, weights=None,
              reg=1e-6):  # fmt: skip
        """Assemble the scaled QP.

        mode : "alg2" (eq. 36 cost, W in the fixed box), "box" (box of W is a
        variable, linear cost ``weights`` on its scaled widths), "vbox" (box of
        V is a variable, W fixed to ``[W_lo, W_hi]``).
        Returns ``(P, c, A, b, n_eq, layout)``.
        """
        n, q, p, J = self.n, self.q, self.p, self.J
        nx, nw = (J + 1) * n, J * q
        nb = 2 * q if mode == "box" else (2 * p if mode == "vbox" else 0)
        nz = nx + nw + nb
        er, ec, ev, eb = self.dynamics(X, W)
        eq_r, eq_c, eq_v, eq_b = [er], [ec], [ev], [eb]
        n_eq = J * n
        if x0_fixed:
            eq_r.append(n_eq + np.arange(n))
            eq_c.append(np.arange(n))
            eq_v.append(np.ones(n))
            eq_b.append(np.zeros(n))
            n_eq += n
        ineq_r, ineq_c, ineq_v, ineq_b = [], [], [], []
        row = [0]

        def add(r_, c_, v_, b_):
            ineq_r.append(r_ + row[0])
            ineq_c.append(c_)
            ineq_v.append(v_)
            ineq_b.append(b_)
            row[0] += b_.size

        # trust region on the scaled state corrections; not needed where every state is measured and V
        # bounds it (a third fewer rows, the QP is that much faster)
        if self.direct is None or mode == "vbox" or not np.all(np.isfinite(np.asarray(V_hi, float)[self.direct])):
            tr = np.tile(self.trust / self.sx, J + 1)
            ar = np.arange(nx)
            add(ar, ar, np.ones(nx), tr)
            add(ar, ar, -np.ones(nx), tr)
        # outputs within V (eqs. 39/40), or within the variable box of V
        orr, oc, ov, resid = self.output_rows(X)
        K = self.idx.size
        rs = (resid / self.sv[None, :]).ravel()
        if mode == "vbox":
            a_cols = nx + nw + np.tile(np.arange(p), K)
            b_cols = a_cols + p
            ones = np.ones(K * p)
            # resid - C dx >= sv a  <=>  C~ xi + a <= resid/sv ;  resid - C dx <= sv b  <=>  -C~ xi - b <= -resid/sv
            add(np.concatenate([orr, np.arange(K * p)]), np.concatenate([oc, a_cols]), np.concatenate([ov, ones]), rs)
            add(np.concatenate([orr, np.arange(K * p)]), np.concatenate([oc, b_cols]), np.concatenate([-ov, -ones]), -rs)
            rp = np.arange(p)
            add(np.concatenate([rp, rp]), np.concatenate([nx + nw + rp, nx + nw + p + rp]),
                np.concatenate([np.ones(p), -np.ones(p)]), np.zeros(p))  # a <= b  # fmt: skip
        else:
            vlo = (np.asarray(V_lo, float) / self.sv)
            vhi = (np.asarray(V_hi, float) / self.sv)
            up = (rs.reshape(K, p) - vlo[None, :]).ravel()
            dn = (vhi[None, :] - rs.reshape(K, p)).ravel()
            add(orr, oc, ov, up)
            add(orr, oc, -ov, dn)
        # disturbances
        Ws = (W / self.sw[None, :]).ravel() if q else np.zeros(0)
        aw = nx + np.arange(nw)
        if mode in ("alg2", "vbox") and q:
            lo = np.tile(np.asarray(W_lo, float) / self.sw, J) - Ws
            hi = np.tile(np.asarray(W_hi, float) / self.sw, J) - Ws
            f = np.isfinite(hi)
            add(np.arange(f.sum()), aw[f], np.ones(f.sum()), hi[f])
            f = np.isfinite(lo)
            add(np.arange(f.sum()), aw[f], -np.ones(f.sum()), -lo[f])
        elif mode == "box" and q:
            lam = nx + nw + np.tile(np.arange(q), J)
            mu = lam + q
            # lam - eta <= W/sw ;  eta - mu <= -W/sw ;  lam - mu <= 0
            r_ = np.arange(nw)
            add(np.concatenate([r_, r_]), np.concatenate([lam, aw]), np.concatenate([np.ones(nw), -np.ones(nw)]), Ws)
            add(np.concatenate([r_, r_]), np.concatenate([aw, mu]), np.concatenate([np.ones(nw), -np.ones(nw)]), -Ws)
            rq = np.arange(q)
            add(np.concatenate([rq, rq]), np.concatenate([nx + nw + rq, nx + nw + q + rq]),
                np.concatenate([np.ones(q), -np.ones(q)]), np.zeros(q))  # fmt: skip
        A_eq = sps.csr_matrix((np.concatenate(eq_v), (np.concatenate(eq_r), np.concatenate(eq_c))), shape=(n_eq, nz))
        A_in = sps.csr_matrix((np.concatenate(ineq_v), (np.concatenate(ineq_r), np.concatenate(ineq_c))),
                              shape=(row[0], nz))  # fmt: skip
        A = sps.vstack([A_eq, A_in], format="csc")
        b = np.concatenate([np.concatenate(eq_b), np.concatenate(ineq_b)])
        # objective
        pdiag = np.zeros(nz)
        c = np.zeros(nz)
        pdiag[:nx] = 2.0 * reg
        if mode == "alg2" and q:
            pdiag[nx : nx + nw] = 2.0
            c[nx : nx + nw] = 2.0 * Ws
        elif mode == "box" and q:
            c[nx + nw : nx + nw + q] = -weights
            c[nx + nw + q :] = weights
            pdiag[nx : nx + nw] = 2.0 * reg  # keeps the disturbance trace unique where the box does not bind
        elif mode == "vbox":
            c[nx + nw : nx + nw + p] = -weights
            c[nx + nw + p :] = weights
            if q:
                pdiag[nx : nx + nw] = 2.0 * reg
        P = sps.diags(pdiag, format="csc")
        return P, c, A, b, n_eq, (nx, nw, nb)

    def solve(self, X, W, mode, **kw):
        """Build (:meth:`build`) and solve the QP with Clarabel; ``(status, DX, DW, box)`` in the model's units."""
        P, c, A, b, n_eq, (nx, nw, nb) = self.build(X, W, mode, **kw)
        status, z = solve_sparse_qp(P, c, A, b, n_eq, reuse=self._qp_solver)
        if z is None:
            return status, None, None, None
        n, q, J = self.n, self.q, self.J
        DX = (z[:nx].reshape(J + 1, n)) * self.sx[None, :]
        DW = (z[nx : nx + nw].reshape(J, q)) * self.sw[None, :] if q else np.zeros((J, 0))
        extra = z[nx + nw :]
        if mode == "box":
            extra = np.concatenate([extra[:q] * self.sw, extra[q:] * self.sw])
        elif mode == "vbox":
            extra = np.concatenate([extra[: self.p] * self.sv, extra[self.p :] * self.sv])
        return status, DX, DW, extra

    def solve_alg2(self, X, W, W_lo, W_hi, V_lo, V_hi, x0_fixed=False, reg=1e-6):
        """Alg. 2's QP (eq. 36 cost): the Riccati interior-point kernel, Clarabel where it does not converge.

        The kernel (:func:`reachconf_kernels.ocp_ipm.ocp_qp`) exploits the
        stage structure (about three times faster than Clarabel on the vehicle
        windows); it needs no trust region, i.e. every state measured
        directly.  Anything else — or a problem the kernel does not solve
        (it cannot certify infeasibility) — goes to :meth:`solve`.
        """
        kw = dict(W_lo=W_lo, W_hi=W_hi, V_lo=V_lo, V_hi=V_hi, x0_fixed=x0_fixed)
        if self.direct is None or not self.q or not np.all(np.isfinite(np.asarray(V_hi, float)[self.direct])):
            return self.solve(X, W, "alg2", **kw)
        n, q, p, J = self.n, self.q, self.p, self.J
        sx, sw, sv = self.sx, self.sw, self.sv
        Ad, Bd, defect = self.linearisation(X, W)
        At = np.ascontiguousarray(Ad * sx[None, None, :] / sx[None, :, None])
        Bt = np.ascontiguousarray(Bd * sw[None, None, :] / sx[None, :, None])
        f = np.ascontiguousarray(defect / sx[None, :])
        resid, Jh = self.output_jacobians(X)
        C = np.zeros((J + 1, p, n))
        ylo = np.full((J + 1, p), -np.inf)
        yhi = np.full((J + 1, p), np.inf)
        C[self.idx] = Jh * sx[None, :] / sv[:, None] if Jh.ndim == 2 else Jh * sx[None, None, :] / sv[None, :, None]
        ylo[self.idx] = (resid - np.asarray(V_hi, float)) / sv
        yhi[self.idx] = (resid - np.asarray(V_lo, float)) / sv
        Ws = W / sw[None, :]
        wlo = np.ascontiguousarray(np.asarray(W_lo, float)[None, :] / sw[None, :] - Ws)
        whi = np.ascontiguousarray(np.asarray(W_hi, float)[None, :] / sw[None, :] - Ws)
        status, xs, ws, _ = ocp_qp(At, Bt, f, np.full(n, 2.0 * reg), np.full(q, 2.0), np.ascontiguousarray(2.0 * Ws),
                                   C, ylo, yhi, wlo, whi, not x0_fixed, 1e-8, 60)  # fmt: skip
        if status != 0:
            return self.solve(X, W, "alg2", **kw)
        return "optimal", xs * sx[None, :], ws * sw[None, :], None

    def linearisation_error(self, X, X_tilde):
        """Largest output difference between the re-simulated and the QP's trace, in units of V's radius."""
        d = self.outputs(X) - self.outputs(X_tilde)
        return float(np.max(np.abs(d) / self.sv[None, :])) if d.size else 0.0


def disturbance_scale(W_lo, W_hi, W, q, scale=None):
    """Units of the disturbance variables (and eq. 36's weights): W's radius, else ``scale``, else W's spread."""
    rad = 0.5 * (np.asarray(W_hi, float) - np.asarray(W_lo, float))
    if scale is not None:
        fallback = np.asarray(scale, float)
    else:
        spread = np.ptp(W, axis=0) if W.size else np.zeros(q)
        mag = np.max(np.abs(W), axis=0) if W.size else np.zeros(q)
        fallback = np.where(spread > 0, 0.5 * spread, np.where(mag > 0, mag, 1.0))
    return np.where(np.isfinite(rad) & (rad > 0), rad, fallback)


def optctrl_trace(model, t, U, Y, W_lo, W_hi, V_lo, V_hi, x0, W, options, x0_fixed=False, reserve=0.999,
                scale=None):  # fmt: skip
    """Alg. 2 (eqs. 29–41, cost eq. 36) on the sparse QP; returns ``(x0, W, message, ok)``.

    ``W`` is the start trace on the grid of ``options.subdivision``; with
    ``x0_fixed`` the initial state stays ``x0`` (a window continuing a trace).
    ``reserve`` shrinks V around its centre for the QP (room for the
    integration error the verdict subtracts).  ``scale``: per-channel weights
    ``S`` of eq. 36 where W is unbounded (default: 1).  ``ok``: the loop
    converged or its simulated trace is within V (the verdict decides anyway).
    """
    r = int(options.subdivision)
    prob = TraceQP(model, t, U, Y, V_lo, V_hi, r=r, substeps=options.substeps)
    W_lo = np.asarray(W_lo, float)
    W_hi = np.asarray(W_hi, float)
    W = np.clip(W, W_lo, W_hi) if W.size else W
    prob.sw = disturbance_scale(W_lo, W_hi, W, model.q, np.ones(model.q) if scale is None else scale)
    prob.trust = prob.trust * options.trust_region
    vc, vr = 0.5 * (prob.V_lo + prob.V_hi), 0.5 * (prob.V_hi - prob.V_lo)
    Vq_lo, Vq_hi = vc - reserve * vr, vc + reserve * vr
    X = prob.simulate(x0, W)
    if not np.all(np.isfinite(X)):  # nothing to linearise around
        return x0, W, f"Alg. 2: the trace simulated from the start state diverged (NaN/inf): {NO_TRACE}", False
    message, ok = "", False
    relaxed = not (W.size and np.any(np.isfinite(W_lo) | np.isfinite(W_hi)))
    for it in range(1, options.max_iterations + 1):
        status, DX, DW, _ = prob.solve_alg2(X, W, W_lo, W_hi, Vq_lo, Vq_hi, x0_fixed=x0_fixed)
        if status != "optimal" and not relaxed:  # far from the data no W within bounds may fit the linearisation:
            relaxed, inf = True, np.full(model.q, np.inf)  # one step with W unbounded (clipped below); verdict checks
            status, DX, DW, _ = prob.solve_alg2(X, W, -inf, inf, Vq_lo, Vq_hi, x0_fixed=x0_fixed)
        if status != "optimal":
            what = status if status in ("infeasible", "unbounded") else f"not solved (solver status {status})"
            message = f"Alg. 2: the linearised QP is {what} in iteration {it}: {NO_TRACE}"
            break
        X_tilde = X + DX
        W = np.clip(W + DW, W_lo, W_hi) if W.size else W
        x0 = x0 if x0_fixed else X_tilde[0]
        X = prob.simulate(x0, W)
        if not np.all(np.isfinite(X)):
            message = f"Alg. 2: the simulated trace diverged in iteration {it}"
            break
        e = prob.linearisation_error(X, X_tilde)
        if e <= max(options.epsilon, 1e-12) or (e <= 1e-3 and (not DW.size or np.max(np.abs(DW) / prob.sw) <= 1e-6)):
            message = f"Alg. 2 converged in {it} iterations"
            ok = True
            break
        if e <= 0.5 * (1.0 - reserve):
            # the QP kept (1 - reserve) of V in reserve and the simulated outputs moved less than half of that
            # from the QP's: the simulated trace satisfies eqs. 22-24 (the verdict checks it again)
            message = f"Alg. 2: simulated trace within V after {it} iterations (linearisation error {e:.1e} of V)"
            ok = True
            break
    else:
        message = f"Alg. 2 stopped after {options.max_iterations} iterations (last output change {e:.2e} of V)"
    return x0, W, message, ok
