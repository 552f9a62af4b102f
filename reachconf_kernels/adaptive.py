"""Adaptive nonlinear reachability: time step, orders and tensor order per step.

The step itself is :func:`reachconf_kernels.nonlinear.nonlinear_step`
(conservative linearisation, tensor order 2 or 3).  This module chooses its
parameters step by step from the abstraction and reduction errors, after
Wetzlinger, Kochdumper, Bak, Althoff, "Adaptive parameter tuning for
reachability analysis of nonlinear systems", HSCC 2021 (CORA's
``lin-adaptive``), with a simpler controller and splitting:

* **error budget** ``beta`` (1/s): the abstraction error ``L`` enters the
  set as an input, so ``rho = mean_i L_i / (rad_i + dt L_i)`` (error rate relative to the
  radius of the time-point set, per state at least ``rtol |x_i| + atol``:
  :func:`rate_radius`) is the relative growth rate it causes.  A step is
  accepted when ``rho <= beta``.
* **time step**: ``rho(dt) ~ rho0 + s dt``, where ``rho0`` is the floor, the
  error over the start set itself (``dt -> 0``).  A rejected step is retried
  with the step this model predicts for ``0.9 beta``; accepted steps grow it.
* **tensor order**: 2 while its floor is within budget (cheaper), else 3
  if that lowers the floor; back to 2 when the floor of 2 fits again.
* **splitting**: when the floor exceeds ``split_fraction * beta``, meeting the
  budget by the step size would cost more than twice the steps (the floor
  halves with the set, the slope does not), so the caller splits the set.
* **linear part**: the excess of the step's input solution and of the
  exponential's remainder over the exact linear solution, which the
  abstraction error does not see, is held to a share of the budget too
  (:mod:`reachconf_kernels.adaptive_linear`; it caps the next step).
* **orders**: the time-point and time-interval sets are reduced
  error-bounded (:func:`~reachconf_kernels.reduce_adaptive.reduce_adaptive`)
  with a tolerance ``reduction_share * beta * dt`` per step (at most
  ``MAX_RED_TOL``), capped by the zonotope order; the images of the start
  set's generators are kept (splits halve them).  Intermediate sets use the
  fixed intermediate and error orders (error-bounded reduction of the large
  ``quad_map`` outputs cost twice Girard's and changed little).
* **last budget** (no retry with a smaller one left): the time-interval set
  keeps at least the start set's generators, and a step is not made
  smaller where that cannot lower its rate (``FUTILE_SHRINK``): the run
  goes on over budget instead of giving up at the smallest step.
* **stale floors**: a step about to be cut near its limit by a floor from
  an earlier set (reused) first measures it on its own set (``REMEASURE_NEAR``).
* **Taylor terms**: the first neglected term of ``e^{|A| dt}`` below 1 %
  (at least ``taylor_min``; the remainder is bounded either way); a step
  that needs more than ``MAX_TAYLOR_TERMS`` is halved (a stiff linear part).

One call runs one set (branch) over the sample grid from ``(t0, k0)`` and
returns when it is done, when a split is wanted, when the order-3 functions
are needed, when its output buffers are full, at the sample ``k_stop`` (for a
monitor), or when the error cannot be bounded.  The caller keeps the state
(``state``, ``err_warm``) between calls.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, types

from reachconf_kernels import zonotope as Z
from reachconf_kernels.zonotope import piece_hulls  # noqa: F401 (used from here by tube, reach_stream)
from reachconf_kernels.adaptive_linear import linear_step_cap, taylor_terms_for
from reachconf_kernels.nonlinear import (
    NO_CONVERGENCE,
    OK,
    abs_bound,
    extend_with_disturbance,
    nonlinear_step,
    quadratic_error,
    row_radius,
)
from reachconf_kernels.reduce_adaptive import reduce_adaptive
from reachconf_kernels.small_linalg import mat_mat
from reachconf_kernels.signatures import FN_IV_REMAINDER, FN_POINT_MAT, FN_POINT_T3, FN_POINT_VEC, f8_1, f8_2

_i8, _f8, _G = types.int64, types.float64, types.float64[:, :]  # one compiled floor for any layout of G and kappa

# return codes of adaptive_run (the step's own codes 1..4 come back in fail[0])
DONE = 0
CHUNK = 5  # reached the sample k_stop
FULL = 6  # output buffers full: grow them and call again
SPLIT = 7  # the error floor is over budget: split the set (c, G) at t and continue both halves
NEED_ORDER3 = 8  # tensor order 3 wanted: compile the third-order functions and call again
FAIL = 9  # the error could not be bounded even at the smallest step (details in state[S_FAIL_*])
#: ``state[S_FAIL_CODE]`` when no step failed but the error rate kept growing until the smallest step
RATE_GROWTH = -1

# columns of the per-step record
REC_T0, REC_DT, REC_KAPPA, REC_NG_TP, REC_NG_QUAD, REC_RHO, REC_RHO0, REC_TRIES, REC_TAYLOR, REC_ITER = range(10)
N_REC = 10

# fpar entries
(P_BUDGET, P_DT_MAX, P_DT_MIN, P_RED_SHARE, P_MAX_ORDER, P_ERR_ORDER, P_INTER_ORDER, P_ROUND, P_SPLIT_FRAC,
 P_SPLIT_AFTER, P_SLACK, P_T0, P_EXCESS, P_EXCESS_REL, P_LIN_GOAL, P_HORIZON,
 P_DIST_W, P_RTOL, P_ATOL) = range(19)
N_FPAR = 19
# ipar entries
I_KAPPA_MODE, I_HAVE3, I_TAYLOR_MIN, I_MAX_ITER, I_CAN_SPLIT, I_KEEP, I_LAST = range(7)
N_IPAR = 7
# state entries (carried between calls of one branch)
(S_DT, S_KAPPA, S_SINCE_CHECK, S_MIN_DT, S_MAX_KAPPA, S_FAIL_CODE, S_FAIL_STATE, S_FAIL_TERM, S_SPENT, S_FLOOR,
 S_FLOOR_AGE, S_FLOOR_KAPPA, S_FLOOR_RATE, S_FLOOR_LIM) = range(14)
N_STATE = 14
#: A computed error floor is reused for up to this many accepted-at-first-try steps while the error rate stays
#: within 10 % of the rate it was computed at (it changes slowly with the set); a rejected step recomputes it.
FLOOR_REUSE = 8
#: On the last error budget (``ipar[I_LAST]``: no retry with a smaller one is left, only giving up), a step is not
#: made smaller when its rate is within this factor of the floor's limit for ``dt -> 0`` (the floor's error over the
#: set's own radius, :func:`floor_rates`): smaller steps cannot lower the rate below that limit, and where the error
#: widens the set within a step as much as its radius they raise it (the set they divide by is smaller).  Without
#: it the step shrank to its limit, and the reach gave up, on sets whose floor is over budget.
FUTILE_SHRINK = 1.05
#: A step about to be made shorter than this many times the step limit, by an error floor measured on an earlier set
#: (reused, ``FLOOR_REUSE``) or at a step over ten times as long, first measures the floor on its own set at its own
#: step: the rate a step tends to grows as the step shrinks, and the stale floor's lower goal shrank the wide
#: rate-limited lane change (``tests/reach/test_reach_rate_limited.py``) past its limit near its end.
REMEASURE_NEAR = 10.0
#: Largest reduction tolerance per step (fraction of the hull diagonal).
MAX_RED_TOL = 1e-3


@njit(cache=True)
def relative_rate(err, rad, dt):
    """``mean_i err_i / (rad_i + dt err_i)`` (terms 0 where both vanish)."""
    rho = 0.0
    for i in range(err.shape[0]):
        den = rad[i] + dt * err[i]
        if den > 0.0:
            rho += err[i] / den
    return rho / err.shape[0]


@njit(cache=True)
def rate_radius(G, c, fpar):
    """Radius (n,) the error rates are measured against: the set's interval radius, but per state at least
    ``rtol |c_i| + atol`` (``fpar[P_RTOL]``, ``fpar[P_ATOL]``).

    Relative to the radius alone, any error is an infinite growth rate on a point or a very thin set: the steps
    shrank to their limit (a Lotka-Volterra system from a point failed at t = 5e-7 s) or, from a box of radius
    1e-9, took 89,000 steps for 5 s.  Below the floor the budget is absolute, as an ODE solver's tolerance."""
    rad = row_radius(G)
    for i in range(rad.shape[0]):
        rad[i] = max(rad[i], fpar[P_RTOL] * abs(c[i]) + fpar[P_ATOL])
    return rad


@njit((f8_1, _G, f8_1, f8_1, f8_2, f8_1, FN_POINT_T3, FN_IV_REMAINDER, _i8, _f8, _f8), cache=True)
def error_floor(c, G, u, wc, WG, p, hess, lagrange_iv, kappa, err_order, err_tol):
    """Abstraction-error bound over the set itself (the ``dt -> 0`` limit of a step).

    Linearisation point ``(c, u, wc)``; ``kappa = 2``: the second-order
    Lagrange remainder over the set (``lagrange_iv`` of order 2); ``kappa =
    3``: ``1/2 quad_map(Z, H(p))`` plus the third-order Lagrange remainder.
    Returns ``(err (n,), status)`` (status > 0: a domain error of the
    interval evaluation).
    """
    n = c.shape[0]
    m = u.shape[0]
    q = wc.shape[0]
    nz = n + m + q
    lo, hi = Z.interval_hull(c, G)
    w_rad = row_radius(WG)
    zlo = np.empty(nz)
    zhi = np.empty(nz)
    dlo = np.zeros(nz)
    dhi = np.zeros(nz)
    for i in range(n):
        zlo[i] = min(lo[i], c[i])
        zhi[i] = max(hi[i], c[i])
        dlo[i] = lo[i] - c[i]
        dhi[i] = hi[i] - c[i]
    zlo[n : n + m] = u
    zhi[n : n + m] = u
    for i in range(q):
        zlo[n + m + i] = wc[i] - w_rad[i]
        zhi[n + m + i] = wc[i] + w_rad[i]
        dlo[n + m + i] = -w_rad[i]
        dhi[n + m + i] = w_rad[i]
    z = np.empty(nz)
    z[:n] = c
    z[n : n + m] = u
    z[n + m :] = wc
    # the directions as a zonotope: the set's generators and W - wc
    dc = np.zeros(nz)
    dG = np.zeros((nz, G.shape[1] + WG.shape[1]))
    dG[:n, : G.shape[1]] = G
    dG[n + m :, G.shape[1] :] = WG
    out = np.empty(n)
    if kappa == 2:
        st = lagrange_iv(zlo, zhi, dlo, dhi, z, dc, dG, p, 2, out)
        if st != 0:
            return np.full(n, np.inf), st
        return out, 0
    st = lagrange_iv(zlo, zhi, dlo, dhi, z, dc, dG, p, 3, out)
    if st != 0:
        return np.full(n, np.inf), st
    Hp = np.zeros((n, nz, nz))
    hess(z, p, Hp)
    idx = np.empty(n + q, dtype=np.int64)
    for i in range(n):
        idx[i] = i
    for i in range(q):
        idx[n + i] = n + m + i
    cr, Gr = reduce_adaptive(np.zeros(n), np.ascontiguousarray(G), err_tol, err_order, np.int64(0))  # (one compile)
    cz, Gz = extend_with_disturbance(cr, Gr, WG, n, q, True)
    qc, qG, _rnd = quadratic_error(cz, Gz, Hp, n, idx)  # an estimate for the step control: no rounding box
    return abs_bound(qc, qG) + out, 0


@njit((f8_1, _G, f8_1, f8_1, f8_2, f8_1, FN_POINT_T3, FN_IV_REMAINDER, _i8, f8_1, _f8), cache=True)
def floor_rates(c, G, u, wc, WG, p, hess, lagrange_iv, kappa, fpar, dt):
    """The error floor as a rate (``relative_rate`` of :func:`error_floor`) at the step ``dt``, and its limit for
    ``dt -> 0`` (the floor over the set's own radius: what a step's rate tends to as the step shrinks)."""
    err_tol = math.sqrt(min(MAX_RED_TOL, max(fpar[P_RED_SHARE] * fpar[P_BUDGET] * dt, 0.0)))
    e0, st = error_floor(c, G, u, wc, WG, p, hess, lagrange_iv, kappa, fpar[P_ERR_ORDER], err_tol)
    if st != 0:
        return np.inf, np.inf
    rad = rate_radius(G, c, fpar)
    return relative_rate(e0, rad, dt), relative_rate(e0, rad, 0.0)


@njit((f8_1, _G, f8_1, f8_1, f8_2, f8_1, FN_POINT_T3, FN_IV_REMAINDER, _i8, f8_1, _f8), cache=True)
def floor_rate(c, G, u, wc, WG, p, hess, lagrange_iv, kappa, fpar, dt):
    """The error floor as a rate at the step ``dt`` (the first of :func:`floor_rates`)."""
    return floor_rates(c, G, u, wc, WG, p, hess, lagrange_iv, kappa, fpar, dt)[0]


_i8_1 = types.int64[::1]
ADAPTIVE_ARGS = (
    f8_1, f8_2, f8_1, _i8, _f8, f8_2, f8_1, f8_2, f8_1,  # c0, G0, samples, k0, t0, U, wc, WG, p
    FN_POINT_VEC, FN_POINT_MAT, FN_POINT_T3, FN_IV_REMAINDER,  # f, jac, hess, lagrange_iv
    f8_1, _i8_1, f8_1, f8_1, _i8,  # fpar, ipar, state, err_warm, k_stop
    f8_2, f8_2, f8_2, f8_2, _i8_1, _i8_1, _i8_1,  # tp_c, tp_G, ti_c, ti_G, ng_tp, ng_ti, sample_step
    f8_2, f8_2, _i8_1,  # rec, rec_err, pos = (next record, next tp column, next ti column)
)


@njit(ADAPTIVE_ARGS, cache=True)
def adaptive_run(
    c0, G0, samples, k0, t0, U, wc, WG, p,
    f, jac, hess, lagrange_iv,
    fpar, ipar, state, err_warm, k_stop,
    tp_c, tp_G, ti_c, ti_G, ng_tp, ng_ti, sample_step,
    rec, rec_err, pos,
):  # fmt: skip
    """Run one set from ``(t0, k0)`` (``samples[k0] <= t0 < samples[k0+1]``) with adaptive parameters.

    Accepted steps are appended at ``pos``: centres to ``tp_c``/``ti_c`` rows
    ``pos[0]``, generators to the columns of ``tp_G``/``ti_G`` from
    ``pos[1]``/``pos[2]`` (counts in ``ng_tp``/``ng_ti``), the record to
    ``rec``/``rec_err``; ``sample_step[k]`` gets the record index of the step
    ending at sample ``k``.  ``pos`` is advanced.

    Returns
    -------
    (code, t, k, c, G)
        ``code``: DONE, CHUNK, FULL, SPLIT, NEED_ORDER3 or FAIL; ``(t, k)``
        where the run stopped and ``Z(c, G)`` the set there.  On FAIL,
        ``state[S_FAIL_*]`` holds the step's status, state and error term.
    """
    n = c0.shape[0]
    K = samples.shape[0]
    cap = tp_c.shape[0]
    gcap = tp_G.shape[1]
    beta = fpar[P_BUDGET]
    dt_max = fpar[P_DT_MAX]
    dt_min = fpar[P_DT_MIN]
    split_frac = fpar[P_SPLIT_FRAC]
    kmode = ipar[I_KAPPA_MODE]
    have3 = ipar[I_HAVE3] != 0
    last = ipar[I_LAST] != 0
    inf_err = np.full(n, np.inf)
    info = np.zeros(4, dtype=np.int64)
    gneed = int(n * fpar[P_MAX_ORDER]) + 2 * n + 2
    c = c0.copy()
    G = np.ascontiguousarray(G0).copy()
    t = t0
    k = k0
    kappa = int(state[S_KAPPA])
    if kappa == 0:  # first step: order 2 if its floor fits the budget, else 3 if that is lower
        kappa = 2 if kmode == 0 else kmode
        if kmode == 0 and k < K - 1:
            dt0 = min(state[S_DT], dt_max, samples[k + 1] - t)
            rho2 = floor_rate(c, G, U[k], wc, WG, p, hess, lagrange_iv, 2, fpar, dt0)
            if rho2 > 0.3 * beta:
                if not have3:
                    return NEED_ORDER3, t, k, c, G
                rho3 = floor_rate(c, G, U[k], wc, WG, p, hess, lagrange_iv, 3, fpar, dt0)
                if rho3 < 0.9 * rho2:
                    kappa = 3
        state[S_KAPPA] = kappa
    if kappa == 3 and not have3:
        return NEED_ORDER3, t, k, c, G
    zq = np.zeros(n + U.shape[1] + wc.shape[0])
    while k < K - 1:
        if k >= k_stop:
            return CHUNK, t, k, c, G
        if pos[0] >= cap or pos[1] + gneed > gcap or pos[2] + gneed > gcap:
            return FULL, t, k, c, G
        t_s = samples[k + 1]
        rem = t_s - t
        dt_prop = min(state[S_DT], dt_max)
        nsub = max(1, int(math.ceil(rem / dt_prop - 1e-9)))
        dt = rem / nsub
        u = U[k]
        # Jacobian at the centre for the Taylor-term choice
        zq[:n] = c
        zq[n : n + u.shape[0]] = u
        zq[n + u.shape[0] :] = wc
        J = np.zeros((n, zq.shape[0]))
        jac(zq, p, J)
        A = np.ascontiguousarray(J[:, :n])
        BW, fz = mat_mat(J[:, n + u.shape[0] :], WG), np.empty(n)
        f(zq, p, fz)
        w_rate = relative_rate(np.abs(BW).sum(axis=1), rate_radius(G, c, fpar), 0.0)  # the disturbance's growth rate
        rho0 = -1.0
        rho_lim = -1.0
        floor_dt = -1.0  # the step at which rho0 was measured on this set (-1: reused from an earlier set)
        futile = False  # last budget and the rate within FUTILE_SHRINK of the floor's dt -> 0 limit
        tries = 0
        state[S_FAIL_CODE] = 0.0
        last_e = np.zeros(n)
        last_rad = np.zeros(n)
        while True:
            tries += 1
            if dt < rem:  # the step the recorded times span: t + dt is rounded (by 1.2e-7 s at Unix time stamps)
                dt = (t + dt) - t
            if dt < dt_min and dt < rem:  # (a sample interval shorter than dt_min is one step, not a failure)
                state[S_MIN_DT] = min(state[S_MIN_DT], dt)
                if state[S_FAIL_CODE] == 0.0:  # no step failed: the error rate kept growing (explosion)
                    state[S_FAIL_CODE] = RATE_GROWTH
                    worst, ib = -1.0, -1
                    for i in range(n):
                        if last_e[i] > 0.0 and last_e[i] / max(last_rad[i], 1e-300) > worst:
                            worst, ib = last_e[i] / max(last_rad[i], 1e-300), i
                    state[S_FAIL_STATE] = ib
                    state[S_FAIL_TERM] = -kappa  # -2 / -3: the abstraction error of that tensor order
                return FAIL, t, k, c, G
            state[S_MIN_DT] = min(state[S_MIN_DT], dt)
            state[S_MAX_KAPPA] = max(state[S_MAX_KAPPA], kappa)
            r, fits = taylor_terms_for(A, dt, ipar[I_TAYLOR_MIN])
            if not fits and dt > 4.0 * dt_min:
                # a stiff linear part: with |A| dt of 15 (a 60-state heat equation, 0.1-s steps) the series' remainder
                # took the set's radius from 0.01 to 5,700 in one step
                dt *= 0.5
                continue
            red_tol = min(MAX_RED_TOL, fpar[P_RED_SHARE] * beta * dt)
            # on the last budget the time-interval set keeps at least as many generators as the start set: reduced
            # below it, it loses the correlations that bound the remainder's affine parts, and the step's error stays
            # above the floor however small the step (measured: 1.3-3.5 times the floor on the rate-limited steering)
            inter = max(fpar[P_INTER_ORDER], (G.shape[1] + n) / n) if last else fpar[P_INTER_ORDER]
            ctp, Gtp, cti, Gti, e, st, bs, bt = nonlinear_step(
                c, G, u, wc, WG, p, dt, r, f, jac, hess, lagrange_iv,
                np.int64(0), kappa, fpar[P_MAX_ORDER], inter, fpar[P_ERR_ORDER], np.int64(0),  # (not literal)
                ipar[I_MAX_ITER], inf_err, err_warm, fpar[P_ROUND], red_tol, ipar[I_KEEP], info,
            )  # fmt: skip
            if st != OK:
                state[S_FAIL_CODE] = st
                state[S_FAIL_STATE] = bs
                state[S_FAIL_TERM] = bt
                if kappa == 2 and kmode == 0 and st == NO_CONVERGENCE and dt < 0.26 * dt_prop:
                    # halving twice did not help: the quadratic term may need order 3
                    if not have3:
                        state[S_DT] = dt
                        return NEED_ORDER3, t, k, c, G
                    kappa = 3
                    err_warm[:] = 0.0
                    continue
                dt *= 0.5
                err_warm[:] = 0.0
                continue
            last_e = e
            last_rad = rate_radius(Gtp, ctp, fpar)
            rho = relative_rate(e, last_rad, dt)
            if rho <= beta:
                break
            if rho0 < 0.0:
                if (tries == 1 and state[S_FLOOR_AGE] < FLOOR_REUSE and state[S_FLOOR] >= 0.0
                        and kappa == state[S_FLOOR_KAPPA]
                        and abs(rho - state[S_FLOOR_RATE]) <= 0.1 * state[S_FLOOR_RATE]):  # fmt: skip
                    rho0 = state[S_FLOOR]
                    rho_lim = state[S_FLOOR_LIM]
                else:
                    rho0, rho_lim = floor_rates(c, G, u, wc, WG, p, hess, lagrange_iv, kappa, fpar, dt)
                    floor_dt = dt
                    state[S_FLOOR] = rho0
                    state[S_FLOOR_AGE] = 0.0
                    state[S_FLOOR_KAPPA] = kappa
                    state[S_FLOOR_RATE] = rho
                    state[S_FLOOR_LIM] = rho_lim
            # the floor is over budget: order 3 if it lowers the floor (asked when the floor was computed, not reused)
            dist = w_rate > fpar[P_DIST_W] * rho  # the set grows mostly by the disturbance
            if rho0 > split_frac * beta and kappa == 2 and kmode == 0 and (state[S_FLOOR_AGE] == 0.0 or not dist):
                if not have3:
                    state[S_DT] = dt
                    return NEED_ORDER3, t, k, c, G
                rho3, lim3 = floor_rates(c, G, u, wc, WG, p, hess, lagrange_iv, 3, fpar, dt)
                if rho3 < 0.9 * rho0:
                    kappa = 3
                    rho0 = rho3
                    rho_lim = lim3
                    floor_dt = dt
                    state[S_FLOOR] = rho3
                    state[S_FLOOR_LIM] = lim3
                    state[S_FLOOR_AGE] = 0.0
                    state[S_FLOOR_KAPPA] = 3
                    state[S_FLOOR_RATE] = np.inf  # recomputed at the next step
                    continue
            # goal: the rate at the budget, or, where the floor alone is near it, the floor plus a share of it
            goal = max(beta, rho0 + max(fpar[P_EXCESS] * beta, fpar[P_EXCESS_REL] * rho0))
            futile = last and rho <= FUTILE_SHRINK * rho_lim
            shrink = min(0.9, max(0.1, 0.9 * (goal - rho0) / max(rho - rho0, 1e-300)))
            if (rho > 1.05 * goal and dt > 4.0 * dt_min and not futile and dt * shrink < REMEASURE_NEAR * dt_min
                    and (floor_dt < 0.0 or dt < 0.1 * floor_dt)):  # fmt: skip
                rho0 = -1.0  # near the step limit by a floor from an earlier set or a longer step: measure it here
                continue
            if rho > 1.05 * goal and dt > 4.0 * dt_min and not futile:
                dt *= shrink
                continue
            if rho0 <= split_frac * beta:
                break
            # over budget: fine while the error spent stays under the budget line (+ slack), else split
            line = beta * (t + dt - fpar[P_T0]) + fpar[P_SLACK]
            if (state[S_SPENT] + rho * dt > line and ipar[I_CAN_SPLIT] != 0 and G.shape[1] > 0
                    and t >= fpar[P_SPLIT_AFTER]):  # fmt: skip
                state[S_DT] = dt
                state[S_KAPPA] = kappa
                return SPLIT, t, k, c, G
            break
        # -- accept the step
        s = pos[0]
        ng_tp[s] = Gtp.shape[1]
        ng_ti[s] = Gti.shape[1]
        tp_c[s] = ctp
        tp_G[:, pos[1] : pos[1] + Gtp.shape[1]] = Gtp
        ti_c[s] = cti
        ti_G[:, pos[2] : pos[2] + Gti.shape[1]] = Gti
        pos[1] += Gtp.shape[1]
        pos[2] += Gti.shape[1]
        rec[s, REC_T0] = t
        rec[s, REC_DT] = dt
        rec[s, REC_KAPPA] = kappa
        rec[s, REC_NG_TP] = Gtp.shape[1]
        rec[s, REC_NG_QUAD] = info[1]
        rec[s, REC_RHO] = rho
        rec[s, REC_RHO0] = rho0
        rec[s, REC_TRIES] = tries
        rec[s, REC_TAYLOR] = r
        rec[s, REC_ITER] = info[0]
        rec_err[s] = e
        pos[0] = s + 1
        state[S_SPENT] += rho * dt
        state[S_FLOOR_AGE] += 1.0
        if dt >= rem * (1.0 - 1e-12):
            t = t_s
            k += 1
            sample_step[k] = s
        else:
            t = t + dt
        # -- next step size: from the floor model where the floor is known, else grow while under budget
        base = max(dt, dt_prop) if dt >= rem * (1.0 - 1e-12) and tries == 1 else dt
        if rho0 >= 0.0:
            goal = max(beta, rho0 + max(fpar[P_EXCESS] * beta, fpar[P_EXCESS_REL] * rho0))
            if futile and rho > goal:
                state[S_DT] = base  # smaller steps cannot lower the rate (FUTILE_SHRINK): hold the step
            elif rho > rho0:
                state[S_DT] = base * min(2.0, max(0.5, 0.9 * (goal - rho0) / (rho - rho0)))
            else:
                state[S_DT] = 2.0 * base
        elif rho < 0.25 * beta:
            state[S_DT] = 2.0 * base
        elif rho < 0.5 * beta:
            state[S_DT] = 1.5 * base
        elif rho < 0.8 * beta:
            state[S_DT] = 1.1 * base
        else:
            state[S_DT] = base
        # -- the linear part's errors (input solution, exponential remainder): their share of the budget over the time
        # since the start (they pile up about in proportion to it, so the share holds whatever the horizon), at most over
        # the span the budget is spread over (P_HORIZON: the horizon, at most AdaptiveReach.budget_horizon)
        goal = fpar[P_LIN_GOAL] * beta * fpar[P_HORIZON] / min(t - fpar[P_T0], fpar[P_HORIZON])
        lin = linear_step_cap(A, BW, fz, last_rad, dt, r, goal, 10.0 * dt_min, fpar[P_HORIZON])
        state[S_DT] = min(state[S_DT], lin)
        # -- back to order 2 when its floor fits the budget again, or, where the floor is over budget and the set grows
        # mostly by the disturbance, when order 3 no longer lowers the floor by 10 % (order 2 steps cost about 2/3)
        if kappa == 3 and kmode == 0:
            state[S_SINCE_CHECK] += 1
            over = state[S_FLOOR] > split_frac * beta and w_rate > fpar[P_DIST_W] * rho
            if state[S_SINCE_CHECK] >= 10 and (rho < 0.5 * beta or over):
                state[S_SINCE_CHECK] = 0
                rho2 = floor_rate(ctp, Gtp, u, wc, WG, p, hess, lagrange_iv, 2, fpar, dt)
                if rho2 <= 0.3 * beta or (over and rho2 * 0.9 <= floor_rate(
                        ctp, Gtp, u, wc, WG, p, hess, lagrange_iv, 3, fpar, dt)):  # fmt: skip
                    kappa = 2
        state[S_KAPPA] = kappa
        err_warm[:] = e
        c = ctp
        G = np.ascontiguousarray(Gtp)
    return DONE, t, k, c, G
