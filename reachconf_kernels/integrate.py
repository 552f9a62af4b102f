"""Fixed-step Runge–Kutta integration of generated models (compiled, cached once).

Inputs and disturbances are piecewise constant over the sample intervals.
Used for simulation, the IVP step of trace conformance (Alg. 1, line 3) and
many short per-step problems; ``scipy.integrate.solve_ivp`` with tight
tolerances is the reference in tests.
"""

from __future__ import annotations

import numpy as np
from numba import njit, types

from reachconf_kernels.signatures import FN_POINT_MAT, FN_POINT_VEC, f8_1, f8_2


@njit(cache=True)
def rk4_step(f, x, zbuf, n, p, h, k1, k2, k3, k4, tmp):
    """One classical RK4 step of ``x' = f(z, p)`` in place; ``zbuf`` holds ``(x, u, w)`` with ``u, w`` set.

    ``k1..k4, tmp`` are work arrays of length ``n``.
    """
    zbuf[:n] = x
    f(zbuf, p, k1)
    for i in range(n):
        tmp[i] = x[i] + 0.5 * h * k1[i]
    zbuf[:n] = tmp
    f(zbuf, p, k2)
    for i in range(n):
        tmp[i] = x[i] + 0.5 * h * k2[i]
    zbuf[:n] = tmp
    f(zbuf, p, k3)
    for i in range(n):
        tmp[i] = x[i] + h * k3[i]
    zbuf[:n] = tmp
    f(zbuf, p, k4)
    for i in range(n):
        x[i] = x[i] + h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i])


@njit((FN_POINT_VEC, f8_1, f8_2, f8_2, f8_1, f8_1, types.int64), cache=True)
def rk4_trace(f, x0, U, Wt, times, p, substeps):
    """States at ``times`` from ``x0``, inputs ``U[k]`` and disturbances ``Wt[k]`` on ``[t_k, t_k+1)``.

    ``substeps`` RK4 steps per sample interval.  Returns ``X`` of shape (K, n).
    """
    K = times.shape[0]
    n = x0.shape[0]
    m = U.shape[1]
    q = Wt.shape[1]
    X = np.empty((K, n))
    x = x0.copy()
    X[0] = x
    z = np.zeros(n + m + q)
    k1 = np.empty(n)
    k2 = np.empty(n)
    k3 = np.empty(n)
    k4 = np.empty(n)
    tmp = np.empty(n)
    for k in range(K - 1):
        z[n : n + m] = U[k]
        z[n + m :] = Wt[k]
        h = (times[k + 1] - times[k]) / substeps
        for s in range(substeps):
            rk4_step(f, x, z, n, p, h, k1, k2, k3, k4, tmp)
        X[k + 1] = x
    return X


@njit((FN_POINT_VEC, f8_2, f8_2, f8_2, f8_1, f8_1, types.int64), cache=True)
def rk4_one_step_each(f, X0, U, Wt, dts, p, substeps):
    """Integrate every sample interval separately: ``X0[k]`` over ``dts[k]`` with ``U[k]``, ``Wt[k]``.

    Returns the end states, shape (K, n): the building block of the per-step
    disturbance fit (eq. 25/26), vectorised over all steps.
    """
    K = X0.shape[0]
    n = X0.shape[1]
    m = U.shape[1]
    q = Wt.shape[1]
    out = np.empty((K, n))
    z = np.zeros(n + m + q)
    k1 = np.empty(n)
    k2 = np.empty(n)
    k3 = np.empty(n)
    k4 = np.empty(n)
    tmp = np.empty(n)
    for k in range(K):
        x = X0[k].copy()
        z[n : n + m] = U[k]
        z[n + m :] = Wt[k]
        h = dts[k] / substeps
        for s in range(substeps):
            rk4_step(f, x, z, n, p, h, k1, k2, k3, k4, tmp)
        out[k] = x
    return out


@njit(
    types.Tuple((f8_2, types.float64[:, :, ::1]))(FN_POINT_VEC, FN_POINT_MAT, f8_2, f8_2, f8_1, types.int64,
                                                  types.int64),
    cache=True,
)  # fmt: skip
def eval_outputs(h, jac_h, X, U, p, n_out, q):
    """``h(X[k], U[k])`` and ``dh/dz`` at every sample: shapes (K, p) and (K, p, nz)."""
    K = X.shape[0]
    n = X.shape[1]
    m = U.shape[1]
    nz = n + m + q
    Y = np.empty((K, n_out))
    J = np.zeros((K, n_out, nz))
    z = np.zeros(nz)
    out = np.empty(n_out)
    Jk = np.zeros((n_out, nz))
    for k in range(K):
        z[:n] = X[k]
        z[n : n + m] = U[k]
        h(z, p, out)
        Y[k] = out
        Jk[:, :] = 0.0
        jac_h(z, p, Jk)
        J[k] = Jk
    return Y, J


@njit(
    (FN_POINT_VEC, f8_2, types.int64[:], f8_2, f8_1, f8_1, types.int64, types.int64, types.int64, types.boolean),
    cache=True,
)
def rk4_windows(f, X0, starts, U, times, p, q, length, substeps, per_substep):
    """Multi-step predictions: from ``X0[j]`` at sample ``starts[j]`` over ``length`` sample intervals.

    Inputs ``U[k]`` act on ``[t_k, t_k+1)``; with ``per_substep``, ``U[k * substeps + s]`` acts on RK4 substep ``s``
    of that interval (``U`` then has ``substeps`` rows per sample interval, e.g. a lag's output held over each
    substep instead of over the whole interval).  The ``q`` disturbances are zero.  Returns the predicted states at
    samples ``starts[j] + 1 ... starts[j] + length``, shape (J, length, n); every window must end inside ``times``.
    """
    J = X0.shape[0]
    n = X0.shape[1]
    m = U.shape[1]
    out = np.empty((J, length, n))
    z = np.zeros(n + m + q)
    k1 = np.empty(n)
    k2 = np.empty(n)
    k3 = np.empty(n)
    k4 = np.empty(n)
    tmp = np.empty(n)
    x = np.empty(n)
    for j in range(J):
        x[:] = X0[j]
        k0 = starts[j]
        for i in range(length):
            k = k0 + i
            if not per_substep:
                z[n : n + m] = U[k]
            h = (times[k + 1] - times[k]) / substeps
            for s in range(substeps):
                if per_substep:
                    z[n : n + m] = U[k * substeps + s]
                rk4_step(f, x, z, n, p, h, k1, k2, k3, k4, tmp)
            out[j, i] = x
    return out
