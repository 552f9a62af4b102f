"""Signal transformations of the gap diagnosis (compiled): actuator lag and transport delay of a sampled input.

Inputs are piecewise constant on the sample intervals ``[t_k, t_k+1)`` (zero-order
hold, as everywhere in reachconf); the transformed signal is returned in the
same form, as the *mean* of the continuous-time result over each interval, so
that a model driven by it integrates the exact input integral.
"""

from __future__ import annotations

import numpy as np
from numba import njit, types

from reachconf_kernels.signatures import f8_1


@njit((f8_1, f8_1, types.float64, types.float64), cache=True)
def first_order_lag_from(t, u, tau, y0):
    """Interval means of ``y' = (u - y) / tau``, ``y(t_0) = y0``, for the zero-order-hold input ``u``.

    Exact for piecewise-constant ``u``: on ``[t_k, t_k+1)`` with ``a = exp(-dt/tau)``
    the mean is ``u_k + (y_k - u_k) tau (1 - a) / dt``.
    """
    K = t.shape[0]
    out = np.empty(K)
    y = y0
    for k in range(K - 1):
        dt = t[k + 1] - t[k]
        r = dt / tau
        a = np.exp(-r)
        out[k] = u[k] + (y - u[k]) * (-np.expm1(-r)) / r
        y = u[k] + (y - u[k]) * a
    out[K - 1] = y
    return out


@njit((f8_1, f8_1, types.float64), cache=True)
def first_order_lag(t, u, tau):
    """:func:`first_order_lag_from` at rest: ``y(t_0) = u_0``."""
    return first_order_lag_from(t, u, tau, u[0])


@njit(cache=True)
def _locate(t, s):
    # last k with t[k] <= s (0 if s < t[0])
    lo, hi = 0, t.shape[0] - 1
    if s <= t[0]:
        return 0
    if s >= t[hi]:
        return hi
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if t[mid] <= s:
            lo = mid
        else:
            hi = mid
    return lo


@njit(cache=True)
def _cumulative(t, u, C, s):
    if s <= t[0]:
        return u[0] * (s - t[0])
    k = _locate(t, s)
    return C[k] + u[k] * (s - t[k])


@njit(cache=True)
def _value(t, u, s):
    return u[_locate(t, s)]


@njit((f8_1, f8_1, types.float64), cache=True)
def transport_delay(t, u, delay):
    """Interval means of ``u(t - delay)`` for the zero-order-hold input ``u`` (``u_0`` before ``t_0``).

    Smooth in ``delay`` (the mean over a shifted interval varies continuously), so
    a delay can be fitted by gradient-based least squares.
    """
    K = t.shape[0]
    # cumulative integral of the ZOH signal at the sample times
    C = np.empty(K)
    C[0] = 0.0
    for k in range(K - 1):
        C[k + 1] = C[k] + u[k] * (t[k + 1] - t[k])
    out = np.empty(K)
    for k in range(K):
        a = t[k] - delay
        b = (t[k + 1] - delay) if k < K - 1 else a
        # integral from t_0 - inf (value u_0) to s, evaluated at a and b
        ia = _cumulative(t, u, C, a)
        ib = _cumulative(t, u, C, b)
        out[k] = (ib - ia) / (b - a) if b > a else _value(t, u, a)
    return out
