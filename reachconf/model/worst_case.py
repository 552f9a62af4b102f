"""The worst case of a model over a box of starts and a box of disturbances: an inner bound of its reachable set.

A reach tube is an outer bound; how tight it is can only be judged against what
the model can really reach.  Random trajectories understate that (the
disturbance that drives a state furthest is a particular signal, not a random
one).  :func:`worst_case` searches for it: for a box ``W`` of piecewise-constant
disturbances, Pontryagin's maximum principle makes the maximiser of a function
of the state at one time *bang-bang*, ``w(t) = c + r sign(B(t)^T lam(t))`` with
``lam`` the adjoint of the trajectory (and the start at a corner of ``X0`` by
the sign of ``lam(0)``).  From the centres of the boxes it alternates an adjoint
sweep along the current trajectory (:func:`reachconf_kernels.adjoint.adjoint_sweep`)
with a step towards the bang-bang signal that is kept only when the simulated
value grows.  Every result is that of a simulated trajectory, so it is a point
of the reachable set: a sound *inner* bound, and a local optimum (exact for
linear systems).

Used by ``examples/vehicle/dlc4.py`` (how much of the reach's width at DLC_4 is
real) and by the soundness tests of the reach algorithms, whose trajectories
then reach the edge of the reachable set.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from reachconf.checks import value_has_type
from reachconf.errors import DataError, OptionsError
from reachconf.model.core import require_model
from reachconf.model.simulate import signal_table, simulate
from reachconf.sets import as_box

__all__ = ["WorstCase", "worst_case"]


@dataclass(frozen=True)
class WorstCase:
    """A trajectory found by :func:`worst_case`.

    Attributes
    ----------
    value : float
        The function's value at ``times[at]`` on this trajectory.
    x0 : ndarray (n,)
        Its start (in ``X0``).
    disturbances : ndarray (k, q)
        Its disturbance on each sample interval before ``times[at]`` (in ``W``).
    states : ndarray (k + 1, n)
        Its states at ``times[: at + 1]`` (fixed-step RK4 with ``substeps``).
    iterations : int
        Adjoint sweeps done.
    """

    value: float
    x0: np.ndarray
    disturbances: np.ndarray
    states: np.ndarray
    iterations: int


def worst_case(model, X0, times, value, *, inputs=None, W=None, at: int = -1, iterations: int = 25,
               substeps: int = 4) -> WorstCase:  # fmt: skip
    """The largest ``value(x(times[at]), u)`` found over starts in ``X0`` and disturbances in ``W``.

    Parameters
    ----------
    model : reachconf.Model
    X0 : Interval or Zonotope
        Initial states (its interval hull is searched).
    times : array_like (K,)
        Sample times; the disturbance is constant on each interval between them.
    value : callable, array_like (n,) or str
        ``value(x, u) -> float`` of the state and the input at ``times[at]``, weights ``c`` for ``c . x``,
        or a state's name (``"-name"``: its smallest value, negated).
        Its gradient is taken by finite differences.
    inputs : array_like (K, m) or (K - 1, m), optional
        Known inputs (as for :func:`reachconf.simulate`).
    W : Interval or Zonotope, optional
        Disturbances (interval hull); ``None``: zero.
    at : int
        Index of the sample time (negative counts from the end); at least 1.
    iterations : int
        At most this many adjoint sweeps.
    substeps : int
        RK4 steps per sample interval.

    Returns
    -------
    WorstCase
        The best trajectory found; for the smallest value, negate ``value``.
    """
    from reachconf_kernels.adjoint import adjoint_sweep  # compiled on first use, not when reachconf.model is imported

    model = require_model(model, "worst_case")
    times = np.array(times, dtype=float).reshape(-1)
    if times.size < 2 or not np.all(np.isfinite(times)) or np.any(np.diff(times) <= 0):
        raise DataError("worst_case: times must be finite, strictly increasing, with at least two entries")
    for name, v in (("at", at), ("iterations", iterations), ("substeps", substeps)):
        if not value_has_type(v, int):
            raise OptionsError(f"worst_case: {name} must be an integer, got {v!r}")
    k_at = at % times.size if -times.size <= at < times.size else -1
    if k_at < 1:
        raise OptionsError(f"worst_case: at = {at} must name a sample time after the first of {times.size}")
    if iterations < 1 or substeps < 1:
        raise OptionsError(f"worst_case: iterations and substeps must be positive, got {iterations}, {substeps}")
    n, m, q = model.n, model.m, model.q
    box0 = as_box(X0, n, "X0")
    Wb = as_box(W, q, "W")
    if isinstance(value, str):  # a state by name ("-name": its smallest value)
        name = value[1:] if value.startswith("-") else value
        if name not in model.state_names:
            raise DataError(f"worst_case: value {value!r} is not a state of model {model.name!r}; states are "
                            f"{list(model.state_names)} (or pass a callable or {n} weights)")  # fmt: skip
        value = np.eye(n)[list(model.state_names).index(name)] * (-1.0 if value.startswith("-") else 1.0)
    if callable(value):
        fn = value
    else:
        try:
            weights = np.asarray(value, dtype=float).reshape(-1)
        except (TypeError, ValueError):
            raise DataError(f"worst_case: value must be a callable, {n} weights or a state's name, got "
                            f"{value!r}"[:200]) from None  # fmt: skip
        if weights.size != n or not np.all(np.isfinite(weights)):
            raise DataError(f"worst_case: value must be a callable or {n} finite weights, got {np.shape(value)}")
        fn = lambda x, u: weights @ x  # noqa: E731
    t = times[: k_at + 1]
    U = signal_table(inputs, times.size, m, "worst_case: inputs")[: k_at + 1]
    dts = np.diff(t)
    c, r = Wb.center, Wb.radius
    xc, xr = box0.center, box0.radius
    jac, p = model.compiled().jac, np.ascontiguousarray(model.param_vector, dtype=float)

    def evaluate(x, u):
        try:
            got = fn(x, u)
        except (TypeError, ValueError) as exc:  # its own error, e.g. a callable of one argument
            raise DataError(f"worst_case: value(x, u) failed: {type(exc).__name__}: {exc}"[:300]) from None
        try:
            return float(np.asarray(got, dtype=float).reshape(()))
        except (TypeError, ValueError):
            raise DataError(f"worst_case: value(x, u) must return one number, got {got!r}"[:200]) from None

    def run(x0, w):
        X = simulate(model, x0, t, inputs=U, disturbances=w, substeps=substeps, check=False)
        return X, (evaluate(X[-1], U[-1]) if np.all(np.isfinite(X)) else -np.inf)

    def gradient(x, u):
        v0 = evaluate(x, u)
        h = 1e-6 * np.maximum(1.0, np.abs(x))
        return np.array([(evaluate(x + h[i] * e, u) - v0) / h[i] for i, e in enumerate(np.eye(n))])

    w, x0 = np.tile(c, (k_at, 1)), xc.copy()
    X, best = run(x0, w)
    if not np.isfinite(best):
        raise DataError("worst_case: the simulation from the centres of X0 and W is not finite")
    gw = np.empty((k_at, q))
    done = 0
    for done in range(1, iterations + 1):
        lam = gradient(X[-1], U[-1])
        adjoint_sweep(np.ascontiguousarray(X), U, np.ascontiguousarray(w), dts, p, jac, substeps, lam, gw)
        target_w, target_x0 = c + r * np.sign(gw), xc + xr * np.sign(lam)
        for step in (1.0, 0.5, 0.25, 0.1, 0.03):
            wn, xn = w + step * (target_w - w), x0 + step * (target_x0 - x0)
            Xn, v = run(xn, wn)
            if v > best + 1e-12 * max(1.0, abs(best)):
                X, best, w, x0 = Xn, v, wn, xn
                break
        else:
            break
    return WorstCase(best, x0, w, X, done)
