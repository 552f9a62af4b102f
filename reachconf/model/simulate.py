"""Simulation of a :class:`~reachconf.Model` with piecewise-constant inputs and disturbances.

:func:`simulate` is the one entry point of the compiled fixed-step RK4
(:func:`reachconf_kernels.integrate.rk4_trace`): for users (validated
arguments), for the library's own loops (``check=False``) and with an estimate
of the integration error (``error_estimate=True``, the IVP of Alg. 1 and 2).
:func:`simulate_ivp` is the adaptive reference (scipy's DOP853).
"""

from __future__ import annotations

import numpy as np
from scipy.integrate import solve_ivp

from reachconf.errors import DataError, ModelError
from reachconf_kernels.integrate import rk4_trace

__all__ = ["simulate", "simulate_ivp", "signal_table"]


def _prepare(model, x0, times, inputs, disturbances):
    times = np.array(times, dtype=float).reshape(-1)
    if times.size < 2 or not np.all(np.isfinite(times)) or np.any(np.diff(times) <= 0):
        raise DataError("times must be finite, strictly increasing, with at least two entries")
    K = times.size
    x0 = np.array(x0, dtype=float).reshape(-1)
    if x0.shape != (model.n,) or not np.all(np.isfinite(x0)):
        raise DataError(f"x0 must be {model.n} finite values ({model.state_names}), got {np.shape(x0)}")

    return x0, times, signal_table(inputs, K, model.m, "inputs"), signal_table(disturbances, K, model.q, "disturbances")


def signal_table(value, K: int, width: int, name: str) -> np.ndarray:
    """``value`` as a ``(K, width)`` table of one row per sample time (a writeable C-ordered copy).

    ``None`` is zeros; a single row of ``width`` values is held; ``K - 1`` rows (one per interval) get the last
    row repeated.  :class:`DataError` naming ``name`` for another shape or NaN/inf.
    """
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


def simulate(model, x0, times, inputs=None, disturbances=None, substeps: int = 10, *, error_estimate: bool = False,
             check: bool = True):  # fmt: skip
    """States at ``times`` (fixed-step RK4, compiled); inputs/disturbances row k act on ``[t_k, t_k+1)``.

    Parameters
    ----------
    model : reachconf.Model
    x0 : array_like (n,)
        Initial state.
    times : array_like (K,)
        Strictly increasing sample times.
    inputs, disturbances : array_like (K, m) / (K, q) or (K-1, ...), optional
        Held constant over each sample interval; default zeros.  A single
        row is repeated.
    substeps : int, default 10
        RK4 steps per sample interval.
    error_estimate : bool, default False
        Also estimate the integration error by step doubling: the trace is
        integrated with ``substeps`` and ``2 substeps`` steps, the finer one is
        returned with ``|X_2 - X_1| 16/15 + 1e-12 (1 + |X_2|)`` (Richardson).
    check : bool, default True
        Validate and copy the arguments.  ``False`` is for the library's own
        loops: the arrays are taken as they are (float64; the disturbances
        with ``K-1`` rows are padded), and NaN/inf propagate into the result
        instead of raising.

    Returns
    -------
    X : ndarray (K, n)
        And with ``error_estimate``: ``err`` (K, n).

    Raises
    ------
    DataError
        On bad times, shapes or non-finite values (with ``check``).
    ModelError
        When a state becomes NaN or inf (with ``check``): the model is undefined along the trajectory or
        escapes to infinity.
    """
    if check:
        if isinstance(substeps, bool) or not isinstance(substeps, (int, np.integer)) or substeps < 1:
            raise DataError(f"substeps must be a positive integer (RK4 steps per sample interval), got {substeps!r}")
        x0, times, U, Wt = _prepare(model, x0, times, inputs, disturbances)
    else:
        U, Wt = inputs, disturbances
        if Wt.shape[0] == 0:
            Wt = np.zeros((times.size, 0))
        elif Wt.shape[0] == times.size - 1:
            Wt = np.vstack([Wt, Wt[-1:]])
        Wt = np.ascontiguousarray(Wt)
    f, p = model.compiled().f, model.param_vector
    if not error_estimate:
        return _finite(model, rk4_trace(f, x0, U, Wt, times, p, int(substeps)), times, check)
    X1 = rk4_trace(f, x0, U, Wt, times, p, int(substeps))
    X2 = _finite(model, rk4_trace(f, x0, U, Wt, times, p, int(2 * substeps)), times, check)
    err = np.abs(X2 - X1) * (16.0 / 15.0) + 1e-12 * (1 + np.abs(X2))
    return X2, err


def _finite(model, X, times, check: bool):
    """``X``, or (with ``check``) a :class:`ModelError` at the first sample where a state is NaN or inf."""
    if check and not np.all(np.isfinite(X)):
        k, i = (int(v[0]) for v in np.nonzero(~np.isfinite(X)))
        raise ModelError(f"model {model.name!r}: the simulation is not finite from t = {times[k]:.6g} on (state "
                         f"{model.state_names[i]!r} = {X[k, i]}): f is undefined there (a root or log of a negative "
                         f"number, a division by zero) or the state escapes to infinity; check the model, x0 and "
                         f"the inputs")  # fmt: skip
    return X


def simulate_ivp(model, x0, times, inputs=None, disturbances=None, rtol=1e-10, atol=1e-12, dense=None):
    """Reference simulation with ``scipy.integrate.solve_ivp`` (DOP853), interval by interval.

    Parameters
    ----------
    dense : int, optional
        If given, also return ``dense`` evenly spaced samples inside every
        sample interval (times and states), for checking time-interval sets.

    Returns
    -------
    X : ndarray (K, n)
        And if ``dense``: ``t_dense`` (K-1, dense), ``X_dense`` (K-1, dense, n).

    Raises
    ------
    DataError
        On bad arguments or when the integrator fails.
    """
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
