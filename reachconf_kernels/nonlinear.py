"""Nonlinear reachability by conservative linearisation / polynomialisation.

The whole time loop runs here, in compiled code.  The model's generated
functions arrive as first-class function arguments with the fixed signatures
of :mod:`reachconf_kernels.signatures`, so this module is compiled (and cached
on disk) once for every model.

Per step (Althoff's conservative linearisation, CORA's ``linReach``; see
``../shared/research/cora.md`` sections 2–3):

1. linearisation point ``p = (c + dt/2 f(c, u, w_c), u, w_c)``;
2. linear reach of the deviation system ``x' = A x + f(p) + B (w - w_c)``
   (:mod:`reachconf_kernels.linsys`);
3. the abstraction error (Lagrange remainder) is bounded over the
   time-interval set by an iteration: assume ``|L| <= 1.1 e``, enlarge the
   time-interval set by that error's particular solution, bound the
   remainder over the result, repeat until the bound is self-consistent;
   ``tensor_order = 2``: the model's ``lagrange_iv`` bound of
   ``1/2 H(xi)[d, d]`` over the box; ``tensor_order = 3``: ``1/2 quad_map(Z,
   H(p))`` plus its bound of ``1/6 T(xi)[d, d, d]`` (interval Taylor mode,
   :mod:`reachconf_kernels.taylor`, or the interval tensors,
   :mod:`reachconf_kernels.remainder`); the
   ``poly`` algorithm (polynomialisation) splits the quadratic term into a
   static part over the start set and a dynamic part over the increment;
4. the error enters as a time-varying input; sets are reduced.

A failure (a domain error in the interval evaluation, non-finite values, an
error bound that does not converge or exceeds ``max_error``) stops the loop
and is reported with the step, the state and the error term, so the caller
can split the set or raise a helpful error.
"""

from __future__ import annotations

import numpy as np
from numba import njit, types

from reachconf_kernels import quadmap as QM
from reachconf_kernels import zonotope as Z
from reachconf_kernels.reduce_adaptive import reduce_adaptive
from reachconf_kernels.small_linalg import mat_mat, mat_vec
from reachconf_kernels.signatures import (
    FN_IV_REMAINDER,
    FN_POINT_MAT,
    FN_POINT_T3,
    FN_POINT_VEC,
    f8_1,
    f8_2,
    f8_3,
)
from reachconf_kernels.linsys import (
    interval_matrix_times_vector,
    interval_matrix_times_zonotope,
    linear_step_matrices,
    particular_constant,
    particular_varying,
)

# status codes
OK = 0
DOMAIN_ERROR = 1  # guarded interval operation failed (division by 0-interval, log of <= 0, ...)
NOT_FINITE = 2  # NaN/inf in a set or an error bound
NO_CONVERGENCE = 3  # the abstraction-error iteration did not become self-consistent
MAX_ERROR = 4  # the abstraction error exceeded max_error

# error terms (for messages)
TERM_LAGRANGE2 = 0  # second-order Lagrange remainder (lagrange_iv, order 2)
TERM_QUADRATIC = 1  # quadratic term at the linearisation point (quad_map)
TERM_LAGRANGE3 = 2  # third-order Lagrange remainder (lagrange_iv, order 3)
TERM_STATIC = 3  # static (start-set) quadratic term of 'poly'

REDUCE_GIRARD = 0
REDUCE_PCA = 1


@njit(cache=True)
def _reduce(c, G, order, method):
    if method == REDUCE_PCA:
        return Z.reduce_pca(c, G, order)
    return Z.reduce_girard(c, G, order)


@njit(cache=True)
def _reduce_tol(c, G, order, method, tol, keep=0):
    """Fixed-order reduction (``tol <= 0``) or error-bounded reduction capped at ``order`` (first ``keep`` kept)."""
    if tol > 0.0:
        return reduce_adaptive(c, G, tol, order, keep)
    return _reduce(c, G, order, method)


@njit(cache=True)
def _add_box(c, G, rad):
    """Zonotope plus the box ``[-rad, rad]`` (zero radii add no generator)."""
    n = c.shape[0]
    k = 0
    for i in range(n):
        if rad[i] > 0.0:
            k += 1
    out = np.empty((n, G.shape[1] + k))
    out[:, : G.shape[1]] = G
    j = G.shape[1]
    for i in range(n):
        if rad[i] > 0.0:
            for r in range(n):
                out[r, j] = 0.0
            out[i, j] = rad[i]
            j += 1
    return c.copy(), out


@njit(cache=True)
def abs_bound(c, G):
    """Per-axis bound of ``|x|`` over the zonotope (no rounding)."""
    out = np.abs(c).copy()
    for j in range(G.shape[1]):
        for i in range(c.shape[0]):
            out[i] += abs(G[i, j])
    return out


@njit(cache=True)
def row_radius(G):
    """Per-row sum of ``|G|`` (the interval-hull radius of a zonotope with generators ``G``)."""
    out = np.zeros(G.shape[0])
    for j in range(G.shape[1]):
        for i in range(G.shape[0]):
            out[i] += abs(G[i, j])
    return out


@njit(cache=True)
def _hcat(A, B):
    out = np.empty((A.shape[0], A.shape[1] + B.shape[1]))
    out[:, : A.shape[1]] = A
    out[:, A.shape[1] :] = B
    return out


@njit(cache=True)
def _all_finite(a):
    for v in a.ravel():
        if not np.isfinite(v):
            return False
    return True


@njit(cache=True)
def _half_hessian(Hp, n, idx):
    """``1/2 H(p)`` of the ``n`` states restricted to the coordinates ``idx`` of z (states and disturbances)."""
    k = idx.shape[0]
    Q = np.empty((n, k, k))
    for i in range(n):
        for a in range(k):
            for b in range(k):
                Q[i, a, b] = 0.5 * Hp[i, idx[a], idx[b]]
    return Q


@njit(cache=True)
def quadratic_error(cz, Gz, Hp, n, idx):
    """``1/2 quad_map(Z, H(p))`` restricted to the coordinates ``idx`` of z, and the radius of its rounding."""
    Q = _half_hessian(Hp, n, idx)
    qc, qG = QM.quad_map(cz, Gz, Q)
    return qc, qG, QM.quad_map_rounding(cz, Gz, cz, Gz, Q)


@njit(cache=True)
def _quad_maps_poly(cs, Gs, cd, Gd, Hp, n, idx):
    """Dynamic quadratic error of 'poly': ``1/2 [q(s, d) + q(d, s) + q(d, d)]``.

    ``s`` ranges over the start set (deviation coordinates, disturbance part
    zero) and ``d`` over the increment set (with the disturbance part).  Returns the centre, the generators
    and the radius of their rounding (the three maps' bounds, and a quarter more for summing them).
    """
    Q = _half_hessian(Hp, n, idx)
    c1, G1 = QM.quad_map_mixed(cs, Gs, cd, Gd, Q)
    c2, G2 = QM.quad_map_mixed(cd, Gd, cs, Gs, Q)
    c3, G3 = QM.quad_map(cd, Gd, Q)
    rnd = QM.quad_map_rounding(cs, Gs, cd, Gd, Q) + QM.quad_map_rounding(cd, Gd, cs, Gs, Q)
    rnd = 1.25 * (rnd + QM.quad_map_rounding(cd, Gd, cd, Gd, Q))
    return c1 + c2 + c3, _hcat(_hcat(G1, G2), G3), rnd


@njit(cache=True)
def extend_with_disturbance(c, G, WG, n, q, with_w):
    """Embed a state zonotope into (x, w) coordinates (w part = W - wc or 0)."""
    gw = WG.shape[1] if with_w else 0
    cz = np.zeros(n + q)
    cz[:n] = c
    Gz = np.zeros((n + q, G.shape[1] + gw))
    Gz[:n, : G.shape[1]] = G
    if with_w:
        Gz[n:, G.shape[1] :] = WG
    return cz, Gz


@njit(cache=True)
def _term_of(i, tensor_order, term_q, cubic):
    if tensor_order == 2:
        return TERM_LAGRANGE2
    return TERM_QUADRATIC if term_q[i] >= cubic[i] else TERM_LAGRANGE3


@njit(cache=True)
def nonlinear_step(
    c, G, u, wc, WG, p, dt, r,
    f, jac, hess, lagrange_iv,
    algorithm, tensor_order, zono_order, inter_order, err_order, reduce_method,
    max_iter, max_error, err_init, rel_round, red_tol, keep, info,
):  # fmt: skip
    """One step from the time-point set ``Z(c, G)`` over ``[t, t + dt]``.

    Parameters
    ----------
    c, G : start set; u : known input (constant in the step);
    wc, WG : disturbance zonotope (centre, generators); p : parameters;
    algorithm : 0 = 'lin', 1 = 'poly' (needs tensor_order 3);
    err_init : (n,) warm start of the abstraction error.
    red_tol, keep : ``red_tol > 0``: the time-point (time-interval) set is reduced error-bounded
        (``reduce_adaptive``, tolerance ``red_tol`` (x5), at most ``zono_order``, first ``keep`` kept).
    info : int64 (4,) out: error iterations, generators into ``quad_map``, of the tp and ti sets.

    Returns
    -------
    ctp, Gtp, cti, Gti, err, status, bad_state, bad_term
    """
    n = c.shape[0]
    m = u.shape[0]
    q = wc.shape[0]
    nz = n + m + q
    empty = np.zeros((n, 0))
    # -- linearisation point and Jacobians
    z = np.empty(nz)
    z[:n] = c
    z[n : n + m] = u
    z[n + m :] = wc
    fc = np.empty(n)
    f(z, p, fc)
    px = c + 0.5 * dt * fc
    z[:n] = px
    f0 = np.empty(n)
    f(z, p, f0)
    J = np.zeros((n, nz))
    jac(z, p, J)
    if not (_all_finite(f0) and _all_finite(J) and _all_finite(px)):
        return c, empty, c, empty, err_init, NOT_FINITE, -1, -1
    A = np.ascontiguousarray(J[:, :n])
    B = np.ascontiguousarray(J[:, n + m :])
    eAt, E, T, F_c, F_r, G_c, G_r = linear_step_matrices(A, dt, r)
    # -- linear part in deviation coordinates (around px)
    cd = c - px
    Pu_c, Pu_rad = particular_constant(T, E, dt, f0)
    H_c, H_G, H_rad = interval_matrix_times_zonotope(eAt, E, cd, G)
    ctp_lin, Gtp_lin = _add_box(H_c + Pu_c, H_G, H_rad + Pu_rad)
    ce, Ge = Z.enclose(cd, G, ctp_lin, Gtp_lin)
    Cs_c, Cs_G, Cs_rad = interval_matrix_times_zonotope(F_c, F_r, cd, G)
    Ci_c, Ci_rad = interval_matrix_times_vector(G_c, G_r, f0)
    cti_lin, Gti_lin = _add_box(ce + Cs_c + Ci_c, _hcat(Ge, Cs_G), Cs_rad + Ci_rad)
    PU_c, PU_G, PU_rad = particular_varying(T, E, dt, np.zeros(n), mat_mat(B, WG))
    PU_c, PU_G = _add_box(PU_c, PU_G, PU_rad)
    ctp_lin = ctp_lin + PU_c
    Gtp_lin = _hcat(Gtp_lin, PU_G)
    cti_lin, Gti_lin = _reduce(cti_lin + PU_c, _hcat(Gti_lin, PU_G), inter_order, reduce_method)
    ti_lo, ti_hi = Z.interval_hull(cti_lin, Gti_lin)
    # hull radius of the particular solution of a unit box input
    Tabs = E * dt
    for i in range(T.shape[0]):
        Tabs = Tabs + np.abs(T[i])
    Tabs = Tabs * (1.0 + 1e-12)
    # -- 'poly': start set, static error and the increment set
    cs = np.zeros(n + q)
    Gs = np.zeros((n + q, 0))
    stat_c = np.zeros(n)
    stat_G = np.zeros((n, 0))
    stat_abs = np.zeros(n)
    stat_rnd = np.zeros(n)  # rounding radius of the static quadratic term
    cdiff = np.zeros(n)
    Gdiff = np.zeros((n, 0))
    idx = np.empty(n + q, dtype=np.int64)
    for i in range(n):
        idx[i] = i
    for i in range(q):
        idx[n + i] = n + m + i
    Hp = np.zeros((n, nz, nz))
    if tensor_order >= 3:
        hess(z, p, Hp)
    if algorithm == 1:
        c_s, G_s = _reduce(cd, G, err_order, reduce_method)
        cs, Gs = extend_with_disturbance(c_s, G_s, WG, n, q, False)
        stat_c, stat_G, stat_rnd = quadratic_error(cs, Gs, Hp, n, idx)
        stat_c, stat_G = _reduce(stat_c, stat_G, inter_order, reduce_method)
        stat_abs = abs_bound(stat_c, stat_G) + stat_rnd
        # increments x(t) - x(t_k) of the linear part
        D_c, D_G, D_rad = interval_matrix_times_zonotope(eAt - np.eye(n), E, cd, G)
        D_c, D_G = _add_box(D_c + Pu_c, D_G, D_rad + Pu_rad)
        e_c, e_G = Z.enclose(np.zeros(n), np.zeros((n, 0)), D_c, D_G)
        cdiff, Gdiff = _add_box(e_c + Cs_c + Ci_c + PU_c, _hcat(_hcat(e_G, Cs_G), PU_G), Cs_rad + Ci_rad)
        cdiff, Gdiff = _reduce(cdiff, Gdiff, inter_order, reduce_method)
    s_lo, s_hi = Z.interval_hull(cd, G)
    d_lo, d_hi = Z.interval_hull(cdiff, Gdiff)
    # -- box of z around p for the Lagrange remainders
    w_rad = row_radius(WG)
    zlo = np.empty(nz)
    zhi = np.empty(nz)
    zlo[n : n + m] = u
    zhi[n : n + m] = u
    zlo[n + m :] = wc - w_rad
    zhi[n + m :] = wc + w_rad
    dlo = np.zeros(nz)  # direction box z - (px, u, wc): the u part is fixed
    dhi = np.zeros(nz)
    dlo[n + m :] = -w_rad
    dhi[n + m :] = w_rad
    # the same directions as a zonotope (keeps the set's correlations for the remainder's affine parts):
    # the time-interval set (lin) or start set + increments (poly), the error box (columns set per
    # iteration) and W - wc
    if algorithm == 1:
        dx_c = cd + cdiff
        dx_G = _hcat(G, Gdiff)
    else:
        dx_c = cti_lin
        dx_G = Gti_lin
    gx = dx_G.shape[1]
    dc = np.zeros(nz)
    dc[:n] = dx_c
    dG = np.zeros((nz, gx + n + WG.shape[1]))
    dG[:n, :gx] = dx_G
    dG[n + m :, gx + n :] = WG
    # -- abstraction-error iteration
    err = err_init.copy()
    err_c = np.zeros(n)
    err_G = np.zeros((n, 0))
    term_q = np.zeros(n)
    q_rnd = np.zeros(n)  # rounding radius of the quadratic term
    cubic = np.zeros(n)
    true_err = np.zeros(n)
    status = NO_CONVERGENCE
    bad_state = -1
    bad_term = TERM_LAGRANGE2
    info[0] = 0
    info[1] = 0
    for it in range(max_iter):
        info[0] = it + 1
        applied = err * 1.1
        rad_v = mat_vec(Tabs, applied)
        if algorithm == 1:
            xlo = s_lo + d_lo - rad_v
            xhi = s_hi + d_hi + rad_v
        else:
            xlo = ti_lo - rad_v
            xhi = ti_hi + rad_v
        for i in range(n):
            # the remainder's points lie on segments from px: the box must hold px too
            zlo[i] = min(xlo[i], 0.0) + px[i]
            zhi[i] = max(xhi[i], 0.0) + px[i]
            dlo[i] = xlo[i]
            dhi[i] = xhi[i]
            dG[i, gx + i] = rad_v[i]
        if tensor_order == 2:
            true_err = np.empty(n)
            st = lagrange_iv(zlo, zhi, dlo, dhi, z, dc, dG, p, 2, true_err)
            if st != 0:
                return c, empty, c, empty, err, DOMAIN_ERROR, st, TERM_LAGRANGE2
            cubic = true_err
        else:
            cubic = np.empty(n)
            st = lagrange_iv(zlo, zhi, dlo, dhi, z, dc, dG, p, 3, cubic)
            if st != 0:
                return c, empty, c, empty, err, DOMAIN_ERROR, st, TERM_LAGRANGE3
            if algorithm == 1:
                c_d, G_d = _add_box(cdiff, Gdiff, rad_v)
                c_d, G_d = _reduce(c_d, G_d, err_order, reduce_method)
                czd, Gzd = extend_with_disturbance(c_d, G_d, WG, n, q, True)
                qc, qG, q_rnd = _quad_maps_poly(cs, Gs, czd, Gzd, Hp, n, idx)
            else:
                c_r, G_r = _add_box(cti_lin, Gti_lin, rad_v)
                c_r, G_r = _reduce(c_r, G_r, err_order, reduce_method)
                info[1] = G_r.shape[1]
                czr, Gzr = extend_with_disturbance(c_r, G_r, WG, n, q, True)
                qc, qG, q_rnd = quadratic_error(czr, Gzr, Hp, n, idx)
            err_c, err_G = _reduce(qc, qG, inter_order, reduce_method)
            term_q = abs_bound(err_c, err_G) + q_rnd
            true_err = term_q + cubic + stat_abs
        if not _all_finite(true_err):
            status = NOT_FINITE
            break
        converged = True
        worst = 0.0
        for i in range(n):
            if true_err[i] > max_error[i]:
                status = MAX_ERROR
                bad_state = i
                bad_term = _term_of(i, tensor_order, term_q, cubic)
                break
            if true_err[i] > applied[i]:
                converged = False
                ratio = true_err[i] / applied[i] if applied[i] > 0.0 else np.inf
                if ratio > worst:
                    worst = ratio
                    bad_state = i
                    bad_term = _term_of(i, tensor_order, term_q, cubic)
        if status == MAX_ERROR:
            break
        if converged:
            status = OK
            break
        err = true_err
    if status != OK:
        return c, empty, c, empty, true_err, status, bad_state, bad_term
    # -- final sets: linear part + px + particular solution of the error set
    if tensor_order == 2:
        ec, eG = _add_box(np.zeros(n), np.zeros((n, 0)), true_err)
    else:
        ec, eG = _add_box(err_c + stat_c, _hcat(err_G, stat_G), cubic + q_rnd + stat_rnd)
    # adaptive (red_tol > 0): the generators of the error's particular solution beyond the first Taylor term are boxed
    # at once (with tensor order 3 the error set has up to intermediate_order * n generators, so each term adds as many; the
    # higher terms' images are O(dt^2) and the error-bounded reduction below would box them anyway, after sorting them)
    Pc, PG, Prad = particular_varying(T, E, dt, ec, eG, 1 if red_tol > 0.0 else -1)
    Pc, PG = _add_box(Pc, PG, Prad)
    ctp = ctp_lin + px + Pc
    Gtp = _hcat(Gtp_lin, PG)
    cti = cti_lin + px + Pc
    Gti = _hcat(Gti_lin, PG)
    # rounding allowance of the float zonotope arithmetic
    ctp, Gtp = _add_box(ctp, Gtp, rel_round * (abs_bound(ctp, Gtp) + 1e-300))
    cti, Gti = _add_box(cti, Gti, rel_round * (abs_bound(cti, Gti) + 1e-300))
    ctp, Gtp = _reduce_tol(ctp, Gtp, zono_order, reduce_method, red_tol, keep)
    cti, Gti = _reduce_tol(cti, Gti, zono_order, reduce_method, 5.0 * red_tol, keep)
    info[2] = Gtp.shape[1]
    info[3] = Gti.shape[1]
    if not (_all_finite(ctp) and _all_finite(Gtp) and _all_finite(cti) and _all_finite(Gti)):
        return c, empty, c, empty, true_err, NOT_FINITE, -1, -1
    return ctp, Gtp, cti, Gti, true_err, OK, -1, -1


_i8 = types.int64
_f8 = types.float64
REACH_LOOP_ARGS = (
    f8_1, f8_2, f8_2, f8_1, f8_1, f8_2, f8_1, _i8,  # c0, G0, U, dts, wc, WG, p, r
    FN_POINT_VEC, FN_POINT_MAT, FN_POINT_T3, FN_IV_REMAINDER,  # f, jac, hess, lagrange_iv
    _i8, _i8, _f8, _f8, _f8, _i8,  # algorithm, tensor_order, orders, reduce_method
    _i8, f8_1, _f8, _i8, _i8,  # max_iter, max_error, rel_round, start, stop
    f8_2, f8_3, f8_2, f8_3, types.int64[::1], types.int64[::1], f8_2,  # stores, err_trace
)


@njit(REACH_LOOP_ARGS, cache=True)
def reach_loop(
    c0, G0, U, dts, wc, WG, p, r,
    f, jac, hess, lagrange_iv,
    algorithm, tensor_order, zono_order, inter_order, err_order, reduce_method,
    max_iter, max_error, rel_round, start, stop,
    store_tp_c, store_tp_G, store_ti_c, store_ti_G, store_ng_tp, store_ng_ti, err_trace,
):  # fmt: skip
    """Run the steps from ``start`` to ``stop - 1`` from ``Z(c0, G0)``, until ``stop`` or a failure.

    Step ``k`` uses input ``U[k]`` and length ``dts[k]``.  Sets are written to
    the preallocated stores (time-point set at the end of step k and the
    time-interval set of step k, both at index k), padded with zero generators;
    ``err_trace[k]`` is the abstraction-error bound of step k.

    Returns
    -------
    (status, step, bad_state, bad_term, c, G)
        ``step`` is the step that failed (or ``stop``), ``c, G`` the set at its start.
    """
    n = c0.shape[0]
    c = c0.copy()
    G = np.ascontiguousarray(G0).copy()
    err = np.zeros(n)
    if start > 0:
        err = err_trace[start - 1].copy()
    info = np.zeros(4, dtype=np.int64)
    for k in range(start, stop):
        ctp, Gtp, cti, Gti, e, st, bs, bt = nonlinear_step(
            c, G, U[k], wc, WG, p, dts[k], r, f, jac, hess, lagrange_iv,
            algorithm, tensor_order, zono_order, inter_order, err_order, reduce_method,
            max_iter, max_error, err, rel_round, 0.0, np.int64(0), info,  # (not a literal: the adaptive run's compile)
        )  # fmt: skip
        if st != OK:
            err_trace[k] = e
            return st, k, bs, bt, c, G
        g1 = Gtp.shape[1]
        g2 = Gti.shape[1]
        if g1 > store_tp_G.shape[2] or g2 > store_ti_G.shape[2]:
            return NOT_FINITE, k, -1, -1, c, G
        store_tp_c[k] = ctp
        store_ti_c[k] = cti
        store_tp_G[k, :, :g1] = Gtp
        store_tp_G[k, :, g1:] = 0.0
        store_ti_G[k, :, :g2] = Gti
        store_ti_G[k, :, g2:] = 0.0
        store_ng_tp[k] = g1
        store_ng_ti[k] = g2
        err_trace[k] = e
        c = ctp
        G = np.ascontiguousarray(Gtp)
        err = e
    return OK, stop, -1, -1, c, G
