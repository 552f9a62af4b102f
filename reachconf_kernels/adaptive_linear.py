"""Step control of the adaptive algorithm for the errors of the linear part of a step.

The abstraction error, which :mod:`reachconf_kernels.adaptive` controls,
vanishes for a linear system, yet the step size still drives two errors that
accumulate in the time-point sets (after the linear-adaptive part of
Wetzlinger, Kochdumper, Bak, Althoff, HSCC 2021, and CORA's ``adaptive``
linear algorithm, which hold the *total* error, incl. these, to the budget):

* the **input solution** of the disturbance: the step encloses
  ``int_0^dt e^{A s} B w(s) ds`` by the Minkowski sum
  ``(+)_k T_k B W (+) [-E dt, E dt] B W`` (``T_k = A^k dt^(k+1)/(k+1)!``).
  The constant-input solution ``(sum_k T_k) B W`` lies inside the exact set,
  so the sum exceeds the exact set by at most
  ``2 sum_{k>=1} |T_k B W| + E dt |B W|`` (per state, interval radii) — a
  relative excess of about ``|A| dt`` per step, whatever the error budget;
* the **remainder** ``E`` of the truncated exponential on the set,
  ``E (|c - p_x| + rad)``.

:func:`linear_step_cap` turns their sum into a relative growth rate (like the
abstraction error's: per unit time, relative to the set's radius, here in
the 2-norm over the states, as the excess is not axis-aligned) and returns
the step that holds it to a goal.  The caller's goal is a share of the error
budget spread over the time since the start (``share * error_budget / (t -
t0)``), not over the horizon: these errors pile up about in proportion to the
elapsed time, like the set they are measured against, so the share holds
over recordings of any length.  It only shapes the step size: every step is
sound whatever its size.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from reachconf_kernels.linsys import exp_remainder, taylor_powers
from reachconf_kernels.small_linalg import abs_row_sums_of_product, mat_vec

#: Most Taylor terms of the exponential per step; a step that needs more is shortened (:func:`taylor_terms_for`).
MAX_TAYLOR_TERMS = 20


@njit(cache=True)
def linear_excess(A, BW, fc, rad, dt, r):
    """Bound (n,) of how far one step's time-point set exceeds the exact one by its linear part.

    Parameters
    ----------
    A : ndarray (n, n)
        Jacobian of the dynamics in the state.
    BW : ndarray (n, q)
        Generators of the disturbance set mapped into the state (``B`` times
        the generators of ``W``).
    fc : ndarray (n,)
        The dynamics at the centre (the step's expansion point is
        ``c + dt/2 fc``).
    rad : ndarray (n,)
        Interval radius of the set.
    dt : float
        Step size.
    r : int
        Taylor terms of the exponential.

    Returns
    -------
    ndarray (n,)
        ``2 sum_{k>=1} |T_k B W| + E dt |B W| + E (dt/2 |fc| + rad)``.
    """
    P = taylor_powers(A, dt, r)  # P[k] = (A dt)^k / k!
    E = exp_remainder(A, dt, r)
    e = mat_vec(E, 0.5 * dt * np.abs(fc) + rad)
    if BW.shape[1] > 0:
        e += mat_vec(E * dt, np.abs(BW).sum(axis=1))
        for k in range(1, r + 1):
            e += (2.0 * dt / (k + 1)) * abs_row_sums_of_product(P[k], BW)
    return e


@njit(cache=True)
def linear_step_cap(A, BW, fc, rad, dt, r, goal, dt_floor, horizon):
    """Step for the next step that holds the linear excess's rate to ``goal`` (1/s), at least ``dt_floor``.

    The rate is ``|w linear_excess| / (dt |rad|)`` (2-norms) and grows about
    linearly with the step (the input solution's term; the remainder's grows
    faster but is kept small by the Taylor terms).  ``w_i = 1 / max(1,
    lambda_i horizon)`` with ``lambda_i = -A_ii`` where positive: an excess in
    a state that decays at the rate ``lambda_i`` does not pile up over the
    horizon but over ``1 / lambda_i``.  Returns ``inf`` when the rate vanishes
    (no disturbance, exact exponential).
    """
    e = linear_excess(A, BW, fc, rad, dt, r)
    for i in range(e.shape[0]):
        e[i] /= max(1.0, -A[i, i] * horizon)
    num = math.sqrt(np.sum(e * e))
    den = dt * math.sqrt(np.sum(rad * rad))
    if num <= 0.0 or not (goal > 0.0):
        return np.inf
    if den <= 0.0:
        return dt_floor
    return max(dt_floor, dt * 0.9 * goal * den / num)


@njit(cache=True)
def taylor_terms_for(A, dt, r_min):
    """Smallest ``r >= r_min`` with ``(|A|_inf dt)^(r+1)/(r+1)! <= 1e-2``, at most :data:`MAX_TAYLOR_TERMS`.

    Returns ``(r, fits)``: ``fits`` is False when even that many terms leave a larger first neglected term
    (``|A|_inf dt`` above about 6): the step is too long for the exponential's series, whose remainder
    (bounded through ``|A|``, sound) would then swamp the set, and the caller shortens it.
    """
    a = 0.0
    for i in range(A.shape[0]):
        s = 0.0
        for j in range(A.shape[1]):
            s += abs(A[i, j])
        a = max(a, s)
    x = a * dt
    r = r_min
    term = 1.0
    for i in range(1, r + 2):
        term *= x / i
    while term > 1e-2 and r < MAX_TAYLOR_TERMS:
        r += 1
        term *= x / (r + 1)
    return r, term <= 1e-2
