"""Reachset conformance of a model with one measured test case (section 3.3, eqs. 42/43, 67)."""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from reachconf.conformance.trace import _as_box, _output_states, case_arrays, state_estimate
from reachconf.errors import ConformanceError, ReachError
from reachconf.sets import Interval, Zonotope

__all__ = ["ReachsetResult", "reachset_conformance", "initial_set"]


@dataclass
class ReachsetResult:
    """Outcome of the reachset-conformance check of one test case (eq. 42/43).

    Attributes
    ----------
    case : str
    conformant : bool
        Every measurement lies in ``h(R(t_i)) ⊕ V``; False also when the
        reachability analysis failed (see ``message``).
    first_violation_time : float or None
    max_violation : float
        Largest infinity-norm distance of a measurement from its set
        ``h(R(t_i)) ⊕ V`` (0 when conformant, ``inf`` when the reach failed).
    inside : ndarray of bool (K,)
    tube : ReachTube or None
    seconds : float
    message : str
        Why the reach failed (the :class:`ReachError` text), else empty.
    """

    case: str
    conformant: bool
    first_violation_time: float | None
    max_violation: float
    inside: np.ndarray
    tube: object = None
    seconds: float = 0.0
    message: str = ""
    violations: dict = field(default_factory=dict)


def initial_set(model, case, V) -> Interval | Zonotope:
    """Eq. 67: ``X(t_1) ⊕ V`` in state space.

    If every state is an output, the measured first sample plus V.  If ``h``
    is affine with full column rank ``C``, the preimage
    ``C^+ (y_1 - D u_1 - e - V)``.  Otherwise pass ``X0`` explicitly.
    """
    t, U, Y = case_arrays(model, case)
    V_lo, V_hi = _as_box(V, model.p, "V")
    direct = _output_states(model)
    if direct is not None:
        x1 = Y[0, direct]
        return Interval(x1 + V_lo[direct], x1 + V_hi[direct])
    from reachconf.output_map import affine_output

    aff = affine_output(model)
    if aff is not None and np.linalg.matrix_rank(aff[0]) == model.n:
        C, D, e = aff
        Cp = np.linalg.pinv(C)
        x1 = state_estimate(model, case)[0]
        Vc, Vr = 0.5 * (V_lo + V_hi), 0.5 * (V_hi - V_lo)
        return Zonotope(x1 - Cp @ Vc, -Cp * Vr)
    raise ConformanceError(
        f"model {model.name!r}: eq. 67 needs the states from the outputs (h not invertible); pass X0 explicitly"
    )


def _distance(S: Zonotope, y: np.ndarray) -> float:
    """Infinity-norm distance from ``y`` to the zonotope (an LP)."""
    from scipy.optimize import linprog

    c, G = S.center, S.generators
    n, m = G.shape
    # min s  s.t. |G b - (y - c)| <= s, |b| <= 1
    cost = np.zeros(m + 1)
    cost[-1] = 1.0
    A = np.vstack([np.hstack([G, -np.ones((n, 1))]), np.hstack([-G, -np.ones((n, 1))])])
    d = y - c
    res = linprog(cost, A_ub=A, b_ub=np.concatenate([d, -d]), bounds=[(-1, 1)] * m + [(0, None)], method="highs")
    if res.status != 0:
        return float(np.max(np.abs(d)))
    return float(res.x[-1])


def reachset_conformance(model, case, W, V, X0=None, options=None, keep_tube: bool = True,
                         violation_distance: bool = True) -> ReachsetResult:  # fmt: skip
    """Eq. 43: is every measurement ``Y(t_i)`` in ``h(REACH(X0, u, t_i)) ⊕ V``?

    Parameters
    ----------
    model : Model
    case : TestCase
    W : Interval or Zonotope
        Disturbance set (disturbances vary in time within it).
    V : Interval or Zonotope
        Additive measurement-error set.
    X0 : Interval or Zonotope, optional
        Initial set; default eq. 67, ``X(t_1) ⊕ V`` (:func:`initial_set`).
    options : ReachOptions, optional
        Default: time step = sample spacing.
    keep_tube : bool
        Keep the reach tube in the result (set False to save memory).
    violation_distance : bool
        Compute ``max_violation`` (one LP per violating sample).

    Returns
    -------
    ReachsetResult
        A reach that fails (the set explodes) gives ``conformant=False`` with
        the reason in ``message``: a failed reach never counts as conformant.
    """
    from reachconf.reach import ReachOptions, reach

    t0 = time.perf_counter()
    t, U, Y = case_arrays(model, case)
    name = getattr(case, "name", "case")
    if X0 is None:
        X0 = initial_set(model, case, V)
    options = options or ReachOptions()
    V_lo, V_hi = _as_box(V, model.p, "V")
    Vset = Interval(V_lo, V_hi)
    Wset = W if W is not None else None
    try:
        tube = reach(model, X0, t - t[0], inputs=U if model.m else None, W=Wset, options=options)
    except ReachError as exc:
        return ReachsetResult(name, False, float(t[0] + (exc.time or 0.0)), float("inf"), np.zeros(t.size, bool),
                              None, time.perf_counter() - t0, str(exc))  # fmt: skip
    cont = tube.contains(t - t[0], Y, V=Vset, output=True, inputs=U if model.m else None)
    worst = 0.0
    violations = {}
    if not cont.conformant and violation_distance:
        from reachconf.output_map import output_enclosure

        for k in np.nonzero(~cont.inside)[0]:
            S = output_enclosure(model, tube.at(t[k] - t[0]), U[k] if model.m else None) + Vset.to_zonotope()
            dist = _distance(S, Y[k])
            violations[float(t[k])] = dist
            worst = max(worst, dist)
    first = None if cont.first_violation is None else float(t[cont.first_violation])
    return ReachsetResult(name, cont.conformant, first, worst, cont.inside, tube if keep_tube else None,
                          time.perf_counter() - t0, "", violations)  # fmt: skip
