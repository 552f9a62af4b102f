"""The model evaluated on data: the output map ``y = h(x, u) + v`` on traces and on sets.

* :func:`evaluate_outputs` — ``h`` at every sample of a state trace (and its
  state Jacobians), compiled;
* :func:`affine_output` — ``(C, D, e)`` when ``h`` is affine;
* :func:`output_enclosure` — a zonotope enclosing ``h(R, u)`` for a reachable
  set ``R`` (eq. 42): affine maps exactly, nonlinear ones by the mean-value
  form ``h(R) ⊆ h(c) + [J_h(box(R))] (R - c)`` with the generated interval
  Jacobian;
* :func:`state_estimate` — the states at the sample times of a test case from
  its measured outputs (``h`` inverted);
* :func:`output_index_of_states` / :func:`state_index_of_outputs` — which
  outputs measure which states directly (the common ``y = x + v`` of eq. 52).
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
import sympy as sp

from reachconf.errors import ConformanceError, DataError, OptionsError, ReachError
from reachconf.io.cases import case_arrays
from reachconf.sets.core import Interval, Zonotope
from reachconf.sets.union import SetUnion
from reachconf_kernels.integrate import eval_outputs
from reachconf_kernels.linsys import interval_matrix_times_zonotope

__all__ = ["output_enclosure", "affine_output", "output_uses_inputs", "evaluate_outputs", "state_estimate", "output_index_of_states",
           "outputs_of_states", "state_index_of_outputs", "state_guess"]  # fmt: skip


def affine_output(model):
    """``(C, D, e)`` with ``h(x, u) = C x + D u + e`` if ``h`` is affine, else None (cached per model).

    Parameters
    ----------
    model : reachconf.Model

    Returns
    -------
    tuple of ndarray ``(C (p, n), D (p, m), e (p,))`` or None
    """
    key = ("_affine_output", tuple(model.param_vector))
    cache = model.__dict__.setdefault("_affine_cache", {})
    if key in cache:
        return cache[key]
    z = model.z_symbols
    n, m = model.n, model.m
    rows_C, rows_D, e = [], [], []
    affine = True
    subs0 = {s: 0 for s in z}
    for expr in model.h_expr:
        grad = [sp.diff(expr, s) for s in z[: n + m]]
        if any(g.free_symbols & set(z) for g in grad):
            affine = False
            break
        params = dict(zip(model.p_symbols, model.param_vector))
        rows_C.append([float(g.subs(params)) for g in grad[:n]])
        rows_D.append([float(g.subs(params)) for g in grad[n:]])
        e.append(float(expr.subs(subs0).subs(params)))
    result = None
    if affine:
        result = (np.array(rows_C).reshape(model.p, n), np.array(rows_D).reshape(model.p, m), np.array(e))
    cache[key] = result  # keyed by the parameter values (with_params shares the dict)
    return result


def output_uses_inputs(model) -> list:
    """The inputs that ``h(x, u)`` depends on (names, in the model's order; cached per model)."""
    cache = model.__dict__.setdefault("_affine_cache", {})
    if "_output_inputs" not in cache:
        used = set().union(*(sp.sympify(e).free_symbols for e in model.h_expr)) if model.h_expr else set()
        z = model.z_symbols[model.n : model.n + model.m]
        cache["_output_inputs"] = [name for name, s in zip(model.input_names, z) if s in used]
    return cache["_output_inputs"]


def output_enclosure(model, S, u=None):
    """A zonotope (or union) enclosing ``{h(x, u) | x in S}`` (eq. 42, without V).

    Parameters
    ----------
    model : reachconf.Model
    S : Zonotope, Interval or SetUnion
        A set of states.
    u : array_like (m,), optional
        The known input; needed when ``h`` depends on an input (zeros would be a wrong answer), else
        ignored (zeros).

    Returns
    -------
    Zonotope or SetUnion

    Raises
    ------
    ReachError
        If the interval Jacobian of ``h`` is not defined over ``S``.
    DataError
        If ``h`` depends on an input and ``u`` is not given.
    """
    if u is None and model.m and output_uses_inputs(model):
        raise DataError(f"the outputs of model {model.name!r} depend on the inputs {output_uses_inputs(model)}: "
                        f"give the inputs at the sample times (inputs=), or check states (output=False)")  # fmt: skip
    if len(S.pieces) > 1:
        return SetUnion([output_enclosure(model, p, u) for p in S.pieces])
    u = np.zeros(model.m) if u is None else np.asarray(u, dtype=float).reshape(model.m)
    aff = affine_output(model)
    if aff is not None:
        C, D, e = aff
        # a box for the rounding of the float products and sums: C c + D u + e can cancel far below its terms (a
        # point set's exact output was outside its own output set)
        box = S.interval()
        mag = np.abs(C) @ np.maximum(np.abs(box.lo), np.abs(box.hi)) + np.abs(D) @ np.abs(u) + np.abs(e)
        rad = (model.n + model.m + 3) * np.finfo(float).eps * mag
        return (C @ S) + (D @ u + e) + Interval(-rad, rad)
    comp = model.compiled()
    box = S.interval()
    zlo = np.concatenate([box.lo, u, np.zeros(model.q)])
    zhi = np.concatenate([box.hi, u, np.zeros(model.q)])
    Jlo = np.zeros((model.p, model.nz))
    Jhi = np.zeros((model.p, model.nz))
    st = comp.jac_h_iv(zlo, zhi, model.param_vector, Jlo, Jhi)
    if st != 0:
        raise ReachError(f"output map of model {model.name!r}: {comp.guards[st - 1]}")
    # h at the centre as an interval: a float evaluation may lose far more than a few ulps of the result to
    # cancellation (x^2 - y^2 at x, y ~ 1e4 of 1e-12 apart: 1e-4 of it; the allowance was 1e-14 of the result)
    zc = np.concatenate([S.center, u, np.zeros(model.q)])
    hlo, hhi = np.empty(model.p), np.empty(model.p)
    st = comp.h_iv(zc, zc, model.param_vector, hlo, hhi)
    if st != 0:
        raise ReachError(f"output map of model {model.name!r}: {comp.guards[st - 1]}")
    hc = 0.5 * hlo + 0.5 * hhi
    Jc = 0.5 * (Jlo + Jhi)[:, : model.n]
    Jr = 0.5 * (Jhi - Jlo)[:, : model.n]
    c, G, rad = interval_matrix_times_zonotope(
        np.ascontiguousarray(Jc), np.ascontiguousarray(Jr), np.zeros(model.n), np.array(S.generators)
    )
    rad = rad + np.nextafter(np.maximum(hc - hlo, hhi - hc), np.inf) + 1e-14 * (np.abs(hc) + 1e-300)
    gens = np.hstack([G, np.diag(rad)])
    return Zonotope(hc + c, gens)


def evaluate_outputs(model, X, U, jacobian: bool = False):
    """``h(X[k], U[k])`` for all samples (and the state Jacobians ``dh/dx`` if asked).

    Parameters
    ----------
    model : reachconf.Model
    X : ndarray (K, n)
        States.
    U : ndarray (K, m)
        Known inputs.
    jacobian : bool
        Also return ``dh/dx`` at every sample.

    Returns
    -------
    Y : ndarray (K, p)
        And with ``jacobian``: ``J`` (K, p, n).
    """
    aff = affine_output(model)
    if aff is not None and not jacobian:
        C, D, e = aff
        return X @ C.T + U @ D.T + e
    comp = model.compiled()
    Yh, J = eval_outputs(comp.h, comp.jac_h, np.ascontiguousarray(X), np.ascontiguousarray(U), model.param_vector,
                         model.p, model.q)  # fmt: skip
    return (Yh, np.ascontiguousarray(J[:, :, : model.n])) if jacobian else Yh


def output_index_of_states(model):
    """Index of each state among the outputs if every state is an output directly (``y = x`` part), else None.

    Parameters
    ----------
    model : reachconf.Model

    Returns
    -------
    list of int (n,) or None
    """
    direct = outputs_of_states(model)
    return [direct[j] for j in range(model.n)] if len(direct) == model.n else None


def outputs_of_states(model) -> dict:
    """``{state index: output index}`` of the states that are an output directly (``y_i = x_j``; the first such)."""
    out = {}
    for j, s in enumerate(model.z_symbols[: model.n]):
        hit = [i for i, e in enumerate(model.h_expr) if isinstance(e, sp.Symbol) and e == s]
        if hit:
            out[j] = hit[0]
    return out


def unmeasured_bounds(model, unmeasured) -> dict:
    """Checked bounds of the states that are not outputs: ``{state index: (lo, hi)}``.

    Parameters
    ----------
    model : reachconf.Model
    unmeasured : mapping of state name to (lo, hi)
        Every state that is not an output directly (:func:`outputs_of_states`), and only those.

    Returns
    -------
    dict of int to (float, float)

    Raises
    ------
    OptionsError
        Not a mapping, unknown or measured state names, missing states, pairs that are not finite ``lo <= hi``.
    """
    if not isinstance(unmeasured, Mapping):
        raise OptionsError(f"unmeasured must map state names to (lo, hi), got {type(unmeasured).__name__}")
    measured = {model.state_names[j] for j in outputs_of_states(model)}
    unknown = sorted(set(unmeasured) - set(model.state_names))
    if unknown:
        raise OptionsError(f"unmeasured: {unknown} are not states of model {model.name!r} ({model.state_names})")
    wrong = sorted(set(unmeasured) & measured)
    missing = [x for x in model.state_names if x not in measured and x not in unmeasured]
    if wrong or missing:
        raise OptionsError(f"unmeasured must give exactly the states that are not outputs of model {model.name!r}: "
                           f"{'outputs given: ' + str(wrong) if wrong else 'missing: ' + str(missing)}")  # fmt: skip
    out = {}
    for name, pair in unmeasured.items():
        try:
            lo, hi = (float(v) for v in pair)
        except (TypeError, ValueError):
            raise OptionsError(f"unmeasured[{name!r}] must be a pair (lo, hi), got {pair!r}") from None
        if not (np.isfinite(lo) and np.isfinite(hi) and lo <= hi):
            raise OptionsError(f"unmeasured[{name!r}] must be finite with lo <= hi, got {pair!r}")
        out[model.state_names.index(name)] = (lo, hi)
    return out


def state_index_of_outputs(model):
    """State index of every output if each output is a state (``y = x`` part), else None (cached on the model).

    Parameters
    ----------
    model : reachconf.Model

    Returns
    -------
    ndarray of int (p,) or None
    """
    key = "_plain_outputs"
    if key not in model.__dict__:
        states = list(model.z_symbols[: model.n])
        idx = [states.index(e) if e in states else None for e in model.h_expr]
        model.__dict__[key] = None if any(i is None for i in idx) else np.array(idx)
    return model.__dict__[key]


def state_estimate(model, case) -> np.ndarray:
    """States at the sample times from the measured outputs (``h`` inverted), shape (K, n).

    If every state is an output, it is read off directly.  If ``h`` is affine
    with full column rank, by least squares.  Otherwise ``h(x, u) = y`` is
    solved for ``x`` at every sample by Gauss–Newton (all samples at once);
    this needs ``h`` to determine the state (at least ``n`` independent outputs).

    Parameters
    ----------
    model : reachconf.Model
    case : reachconf.TestCase

    Returns
    -------
    ndarray (K, n)

    Raises
    ------
    ConformanceError
        If the outputs do not determine the state.
    """
    t, U, Y = case_arrays(model, case)
    direct = output_index_of_states(model)
    if direct is not None:
        return np.ascontiguousarray(Y[:, direct])
    if model.p < model.n:
        raise ConformanceError(
            f"model {model.name!r} has {model.p} outputs for {model.n} states: the state cannot be read from the "
            f"measurements; use method='optctrl'"
        )
    aff = affine_output(model)
    if aff is not None and np.linalg.matrix_rank(aff[0]) == model.n:
        C, D, e = aff
        rhs = Y - U @ D.T - e
        return np.ascontiguousarray(np.linalg.lstsq(C, rhs.T, rcond=None)[0].T)
    # nonlinear h: Gauss-Newton on all samples at once
    K, n = t.size, model.n
    X = np.zeros((K, n))
    for _ in range(30):
        R, JJ = evaluate_outputs(model, X, U, jacobian=True)
        R = R - Y
        steps = np.stack([np.linalg.lstsq(JJ[k], -R[k], rcond=None)[0] for k in range(K)])
        X += steps
        if np.max(np.abs(steps)) <= 1e-12 * (1 + np.max(np.abs(X))):
            return X
    raise ConformanceError(f"model {model.name!r}: could not invert the output map h to estimate the states")


def state_guess(model, u, y, iterations: int = 30) -> np.ndarray:
    """A state consistent with one sample's measured outputs when they do not determine it: the start of Alg. 2.

    Least squares ``h(x, u) = y`` by Gauss–Newton from ``x = 0`` with minimum-norm steps: a state the outputs
    measure directly takes its measured value, a state they do not see stays 0 (a zero start put, e.g., a
    vehicle's unmeasured model at ``v_x = 0``, where its slip angles divide by zero).

    Parameters
    ----------
    model : reachconf.Model
    u : ndarray (m,)
        The inputs at the sample.
    y : ndarray (p,)
        The outputs measured at the sample.

    Returns
    -------
    ndarray (n,)
        Finite; 0 where an iteration would leave the finite numbers.
    """
    U = np.asarray(u, dtype=float).reshape(1, -1)
    y = np.asarray(y, dtype=float).reshape(-1)
    x = np.zeros((1, model.n))
    for _ in range(iterations):
        R, J = evaluate_outputs(model, x, U, jacobian=True)
        if not (np.all(np.isfinite(R)) and np.all(np.isfinite(J))):
            break
        step = np.linalg.lstsq(J[0], y - R[0], rcond=None)[0]
        if not np.all(np.isfinite(step)):
            break
        x = x + step
        if np.max(np.abs(step)) <= 1e-12 * (1 + np.max(np.abs(x))):
            break
    return np.where(np.isfinite(x[0]), x[0], 0.0)
