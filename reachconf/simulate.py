"""Simulation of a :class:`~reachconf.Model` with piecewise-constant inputs and disturbances."""

from __future__ import annotations

import numpy as np

from reachconf.errors import DataError

__all__ = ["simulate", "simulate_ivp"]


def _prepare(model, x0, times, inputs, disturbances):
    times = np.array(times, dtype=float).reshape(-1)
    if times.size < 2 or not np.all(np.isfinite(times)) or np.any(np.diff(times) <= 0):
        raise DataError("times must be finite, strictly increasing, with at least two entries")
    K = times.size
    x0 = np.array(x0, dtype=float).reshape(-1)
    if x0.shape != (model.n,) or not np.all(np.isfinite(x0)):
        raise DataError(f"x0 must be {model.n} finite values ({model.state_names}), got {np.shape(x0)}")

    def table(value, width, name):
        if width == 0:
            return np.zeros((K, 0))
        if value is None:
            return np.zeros((K, width))
        arr = np.asarray(value, dtype=float)
        if arr.ndim == 1 and arr.size == width:
            arr = np.tile(arr, (K, 1))
        if arr.ndim != 2 or arr.shape[1] != width or arr.shape[0] not in (K, K - 1):
            raise DataError(f"{name} must have shape ({K}, {width}) or ({K - 1}, {width}), got {arr.shape}")
        if not np.all(np.isfinite(arr)):
            raise DataError(f"{name} contains NaN or inf")
        if arr.shape[0] == K - 1:
            arr = np.vstack([arr, arr[-1:]])
        return np.array(arr, order="C")  # writeable copy for the compiled kernels

    return x0, times, table(inputs, model.m, "inputs"), table(disturbances, model.q, "disturbances")


def simulate(model, x0, times, inputs=None, disturbances=None, substeps: int = 10) -> np.ndarray:
    """States at ``times`` (fixed-step RK4, compiled); inputs/disturbances row k act on ``[t_k, t_k+1)``.

    Returns
    -------
    ndarray (K, n)
    """
    from reachconf_kernels.integrate import rk4_trace

    x0, times, U, Wt = _prepare(model, x0, times, inputs, disturbances)
    comp = model.compiled()
    return rk4_trace(comp.f, x0, U, Wt, times, model.param_vector, int(substeps))


def simulate_ivp(model, x0, times, inputs=None, disturbances=None, rtol=1e-10, atol=1e-12, dense=None):
    """Reference simulation with ``scipy.integrate.solve_ivp`` (DOP853), interval by interval.

    Parameters
    ----------
    dense : int, optional
        If given, also return ``dense`` evenly spaced samples inside every
        sample interval (times and states), for checking time-interval sets.

    Returns
    -------
    X : ndarray (K, n), and if ``dense``: (t_dense (K-1, dense), X_dense (K-1, dense, n))
    """
    from scipy.integrate import solve_ivp

    x0, times, U, Wt = _prepare(model, x0, times, inputs, disturbances)
    comp = model.compiled()
    p = model.param_vector
    n, m = model.n, model.m
    X = np.empty((times.size, n))
    X[0] = x0
    td = np.empty((times.size - 1, dense or 0))
    Xd = np.empty((times.size - 1, dense or 0, n))
    z = np.zeros(model.nz)
    out = np.empty(n)

    def rhs(t, x):
        z[:n] = x
        comp.f(z, p, out)
        return out.copy()

    x = x0
    for k in range(times.size - 1):
        z[n : n + m] = U[k]
        z[n + m :] = Wt[k]
        t_eval = None
        if dense:
            t_eval = np.linspace(times[k], times[k + 1], dense + 2)[1:-1]
        sol = solve_ivp(rhs, (times[k], times[k + 1]), x, method="DOP853", rtol=rtol, atol=atol,
                        dense_output=bool(dense))  # fmt: skip
        if not sol.success:
            raise DataError(f"simulation failed in interval {k}: {sol.message}")
        x = sol.y[:, -1]
        X[k + 1] = x
        if dense:
            td[k] = t_eval
            Xd[k] = sol.sol(t_eval).T
    return (X, td, Xd) if dense else X
