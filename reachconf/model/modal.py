"""A linear model in real modal coordinates, where the reach's boxes do not grow.

The order reduction of every reach algorithm boxes part of the set in the
state axes each step; under ``e^{A dt}`` such a box grows at up to the
logarithmic norm ``mu_inf(A)``, which for a stiff, non-normal ``A`` can be
10^4 1/s although every eigenvalue is stable — the set explodes (the wrapping
effect; :func:`reachconf.reach_errors.wrapping_diagnosis` says so in the
ReachError).  In the real modal coordinates ``z = V^-1 x`` the matrix is
block diagonal (real eigenvalues on the diagonal, ``[[a, w], [-w, a]]`` for a
pair ``a +- i w``), its logarithmic norm is ``max(Re lambda + |Im lambda|)``,
and boxes shrink with the modes.

The new model keeps the inputs and disturbances, has the states ``z0, z1, ...``
and outputs ``h(V z, u)`` under the original output names (by default the
original states), so its tube's output sets are in the original coordinates.
Its coefficients are ``V^-1 A V`` etc. in floating point, with the couplings
between modes below the transform's rounding (``8 n eps |V^-1| |A| |V|``) set to
zero: it is the model that is reached, equal to the original up to rounding of
its coefficients.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import sympy as sp

from reachconf.errors import ModelError

__all__ = ["ModalForm", "modal_form", "affine_parts"]

#: largest condition number of the eigenvector basis accepted (beyond it ``A`` is (nearly) defective)
MAX_CONDITION = 1e8


@dataclass(frozen=True)
class ModalForm:
    """A linear model in real modal coordinates (see :func:`modal_form`).

    Attributes
    ----------
    model : Model
        ``z' = V^-1 f(V z, u, w)``, outputs ``h(V z, u)`` under the original output names.
    V, V_inv : ndarray (n, n)
        ``x = V z`` and ``z = V_inv x`` (``V_inv`` the floating-point inverse).
    eigenvalues : ndarray (n,) complex
        The eigenvalues of ``A``, in the order of the modal states (a complex pair takes two states).
    """

    model: object
    V: np.ndarray
    V_inv: np.ndarray
    eigenvalues: np.ndarray

    def to_modal(self, X):
        """The set (Interval or Zonotope) or point ``X`` of the original states in modal coordinates."""
        return _map(self.V_inv, X)

    def from_modal(self, Z):
        """The set or point ``Z`` of the modal states in the original coordinates."""
        return _map(self.V, Z)


def _map(M, X):
    if hasattr(X, "linear_map"):  # a set: its image (outward rounded)
        return X.linear_map(M)
    return M @ np.asarray(X, dtype=float)


def _real_basis(A: np.ndarray, name: str):
    lam, W = np.linalg.eig(A)
    cond = np.linalg.cond(W)
    if not np.isfinite(cond) or cond > MAX_CONDITION:
        raise ModelError(f"model {name!r}: its state matrix A is not diagonalisable (the condition number of its "
                         f"eigenvectors is {cond:.3g}); it has no modal form")  # fmt: skip
    cols, order = [], []
    done = np.zeros(len(lam), dtype=bool)
    for i in np.argsort(-lam.real, kind="stable"):
        if done[i]:
            continue
        done[i] = True
        if abs(lam[i].imag) <= 1e-12 * max(1.0, abs(lam[i])):
            v = W[:, i].real
            cols.append(v / np.linalg.norm(v))
            order.append(lam[i].real)
            continue
        # a + i w with w > 0: columns (p, q) of v = p + i q; A [p q] = [p q] [[a, w], [-w, a]]
        j = int(np.argmin(np.where(done, np.inf, np.abs(lam - np.conj(lam[i])))))
        done[j] = True
        v = W[:, i] if lam[i].imag > 0 else W[:, j]
        scale = np.linalg.norm(v)
        cols += [v.real / scale, v.imag / scale]
        a, w = lam[i].real, abs(lam[i].imag)
        order += [complex(a, w), complex(a, -w)]
    V = np.column_stack(cols)
    return V, np.linalg.inv(V), np.asarray(order, dtype=complex)


def affine_parts(model):
    """``(J, f0)`` of a linear model: ``f(z) = J z + f0`` with ``z = (x, u, w)``, parameters substituted."""
    F = sp.Matrix(model.f_expr).xreplace({s: float(model.params[s.name]) for s in model.p_symbols})
    J = np.array(F.jacobian(model.z_symbols).evalf(), dtype=float)  # constant: f is affine
    f0 = np.array(F.xreplace({s: 0 for s in model.z_symbols}).evalf(), dtype=float).ravel()
    return J, f0


def modal_form(model, state_prefix: str = "z", keep_outputs: bool = True) -> ModalForm:
    """The linear ``model`` in real modal coordinates ``z = V^-1 x`` (parameters substituted).

    Parameters
    ----------
    model : Model
        A model whose ``f`` is affine in ``(x, u, w)`` (:meth:`Model.is_linear`) and whose state
        matrix ``A`` is diagonalisable.
    state_prefix : str, default "z"
        The modal states are named ``z0, z1, ...``.
    keep_outputs : bool, default True
        Outputs ``h(V z, u)`` under the original names, so that output sets (and conformance
        checks) are in the original coordinates; each is a dense combination of the modal
        states, which code generation pays for (a 10-state heat equation: 21 s; 60 states: over 13 minutes).
        False: the modal states are the outputs (map sets back with :meth:`ModalForm.from_modal`).

    Returns
    -------
    ModalForm
        The new model, ``V``, ``V^-1`` and the eigenvalues; reach it from ``to_modal(X0)``.

    Raises
    ------
    ModelError
        If the model is not linear or ``A`` is (nearly) defective.
    """
    from reachconf.model.core import Model

    if not isinstance(model, Model):
        raise ModelError(f"modal_form needs a reachconf Model, got {type(model).__name__}")
    if not model.is_linear():
        raise ModelError(f"model {model.name!r} is not linear (f is not affine in x, u, w): it has no modal form")
    values = {s: float(model.params[s.name]) for s in model.p_symbols}
    n, z_old = model.n, model.z_symbols
    J, f0 = affine_parts(model)
    V, V_inv, lam = _real_basis(J[:, :n], model.name)
    names = [f"{state_prefix}{i}" for i in range(n)]
    taken = set(model.input_names + model.disturbance_names + (model.output_names if keep_outputs else ()))
    clash = sorted(taken & set(names))
    if clash:
        raise ModelError(f"modal_form: the state names {clash} are taken in model {model.name!r}; "
                         f"pass another state_prefix")  # fmt: skip
    # z' = V^-1 (A V z + B (u, w) + f0), built from the numbers (an expansion in sympy is quadratic in n and slow)
    M = np.hstack([V_inv @ J[:, :n] @ V, V_inv @ J[:, n:]])
    c = V_inv @ f0
    # the off-diagonal entries between modes are rounding noise (about eps |V^-1| |A| |V|): zero, as the
    # transform's rounding, so that the model stays sparse (a 60-state model compiles in seconds, not minutes)
    noise = 8.0 * n * np.finfo(float).eps * (np.abs(V_inv) @ np.abs(J[:, :n]) @ np.abs(V))
    block = np.abs(np.subtract.outer(np.arange(n), np.arange(n))) <= 1  # a complex pair's 2x2 block
    M[:, :n][(np.abs(M[:, :n]) <= noise) & ~block] = 0.0

    def dynamics(s):
        syms = [s[k] for k in names] + [s[old.name] for old in z_old[n:]]
        return [sp.Add(sp.Float(c[i]), *[sp.Float(M[i, j]) * syms[j] for j in range(len(syms)) if M[i, j] != 0.0])
                for i in range(n)]  # fmt: skip

    def outputs(s):
        sub = dict(values)
        sub.update({xi: sp.Add(*[sp.Float(V[i, j]) * s[names[j]] for j in range(n) if V[i, j] != 0.0])
                    for i, xi in enumerate(z_old[:n])})  # fmt: skip
        sub.update({old: s[old.name] for old in z_old[n:]})
        return {k: e.xreplace(sub) for k, e in zip(model.output_names, model.h_expr)}

    new = Model(states=names, dynamics=dynamics, outputs=outputs if keep_outputs else None, inputs=model.input_names,
                disturbances=model.disturbance_names, params={}, name=f"{model.name}_modal",
                description=f"{model.name} in real modal coordinates z = V^-1 x")  # fmt: skip
    return ModalForm(new, V, V_inv, lam)
