"""Enclosure of the output set ``h(R, u)`` of a reachable set ``R`` (eq. 42).

Affine output maps (the common ``y = x + v`` of eq. 52, selections, linear
combinations) are mapped exactly.  Nonlinear maps use the mean-value form
``h(R) ⊆ h(c) + [J_h(box(R))] (R - c)`` with the generated interval Jacobian.
"""

from __future__ import annotations

import numpy as np
import sympy as sp

from reachconf.errors import ReachError
from reachconf.sets import Zonotope

__all__ = ["output_enclosure", "affine_output"]


def affine_output(model):
    """``(C, D, e)`` with ``h(x, u) = C x + D u + e`` if ``h`` is affine, else None (cached per model)."""
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


def output_enclosure(model, S, u=None):
    """A zonotope (or union) enclosing ``{h(x, u) | x in S}``."""
    from reachconf.tube import SetUnion

    if isinstance(S, SetUnion):
        return SetUnion([output_enclosure(model, p, u) for p in S.pieces])
    u = np.zeros(model.m) if u is None else np.asarray(u, dtype=float).reshape(model.m)
    aff = affine_output(model)
    if aff is not None:
        C, D, e = aff
        return (C @ S) + (D @ u + e)
    comp = model.compiled()
    box = S.interval()
    zlo = np.concatenate([box.lo, u, np.zeros(model.q)])
    zhi = np.concatenate([box.hi, u, np.zeros(model.q)])
    Jlo = np.zeros((model.p, model.nz))
    Jhi = np.zeros((model.p, model.nz))
    st = comp.jac_h_iv(zlo, zhi, model.param_vector, Jlo, Jhi)
    if st != 0:
        raise ReachError(f"output map of model {model.name!r}: {comp.guards[st - 1]}")
    hc = np.empty(model.p)
    comp.h(np.concatenate([S.center, u, np.zeros(model.q)]), model.param_vector, hc)
    from reachconf_kernels.linsys import interval_matrix_times_zonotope

    Jc = 0.5 * (Jlo + Jhi)[:, : model.n]
    Jr = 0.5 * (Jhi - Jlo)[:, : model.n]
    c, G, rad = interval_matrix_times_zonotope(
        np.ascontiguousarray(Jc), np.ascontiguousarray(Jr), np.zeros(model.n), np.array(S.generators)
    )
    # h(c) itself is a float evaluation: allow its rounding
    rad = rad + 1e-14 * (np.abs(hc) + 1e-300)
    gens = np.hstack([G, np.diag(rad)])
    return Zonotope(hc + c, gens)
