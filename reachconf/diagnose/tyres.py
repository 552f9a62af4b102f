"""Tyre saturation as a candidate effect of the gap diagnosis: the Fiala brush model with a friction coefficient.

A linear tyre gives the lateral force ``F = c alpha`` at any slip angle; a real
tyre saturates at the friction limit ``mu F_z``.  The Fiala brush model (one
friction coefficient, a parabolic pressure distribution in the contact patch;
H. Pacejka, *Tire and Vehicle Dynamics*, 3rd ed., section 3.2.2; the tyre
model of Stanford's vehicle-dynamics group) is, with ``u = c alpha / (mu F_z)``::

    F / (mu F_z) = u - u |u| / 3 + u^3 / 27        for |u| <= 3   (adhesion and partial sliding)
                 = sign(u)                          for |u| >  3   (the whole patch slides)

It has the linear tyre's cornering stiffness ``c`` at zero slip, reaches the
limit ``mu F_z`` at ``|alpha| = 3 mu F_z / c`` with zero slope and zero
curvature there (so it is twice continuously differentiable), and is monotone.
For the code generator, which needs smooth expressions, ``|u|`` is
``sqrt(u^2 + 1e-8)`` and the cut at ``|u| = 3`` is a smooth clamp
``(u + 3 - sqrt((u - 3)^2 + 1e-4)) / 2`` on both sides; both change the force
by less than 0.1 % of ``mu F_z`` anywhere (the polynomial is flat to second
order at the cut) and the slope at zero slip by less than 1e-5.

The effect ``tire_fiala`` acts on models that follow the single-track
convention of :func:`reachconf.models.single_track`: parameters ``m, l_f,
l_r`` and axle cornering stiffnesses ``c_f, c_r``, states ``vx, vy, omega``,
input ``delta``, the dynamics linear in each stiffness with the axle's slip
angle (:func:`reachconf.models.single_track_cg.slip_angles`) as a factor of
its derivative.  The static axle loads are ``F_zf = m g l_r / (l_f + l_r)``
and ``F_zr = m g l_f / (l_f + l_r)``.  Targets: ``c_f`` or ``c_r`` (one axle
saturates, with its own friction coefficient) and ``axles`` (both, with one
friction coefficient).  Its parameter is ``mu``; with ``mu`` large the model is
the linear one.  An axle whose force is already non-linear in its stiffness (a
tyre effect applied before) is left as it is.
"""

from __future__ import annotations

import sympy as sp

from reachconf.diagnose.effects import Effect, register_effect
from reachconf.errors import ModelError
from reachconf.model.core import Model
from reachconf.models.single_track_cg import GRAVITY, SINGLE_TRACK_AXLES, slip_angles

__all__ = ["fiala_force", "tire_fiala_model", "TIRE_FIALA", "FIALA_TARGETS"]

#: targets of ``tire_fiala``: one axle (its stiffness parameter) or both with one friction coefficient
FIALA_TARGETS = ("c_f", "c_r", "axles")

_ABS_EPS2 = sp.Rational(1, 10**8)  # smooth |u| = sqrt(u^2 + 1e-8)
_CLAMP_EPS2 = sp.Rational(1, 10**4)  # smooth clamp to [-3, 3] with a knee of about 0.005


def _smooth_clamp3(u):
    """``u`` clamped to ``[-3, 3]`` by smooth minimum and maximum (square-root knees)."""
    upper = (u + 3 - sp.sqrt((u - 3) ** 2 + _CLAMP_EPS2)) / 2
    return (upper - 3 + sp.sqrt((upper + 3) ** 2 + _CLAMP_EPS2)) / 2


def fiala_force(c, alpha, f_max):
    """Lateral force of the Fiala brush model (smoothed, see the module docstring) as a sympy expression.

    Parameters
    ----------
    c : sympy.Expr
        Cornering stiffness [N/rad].
    alpha : sympy.Expr
        Slip angle [rad].
    f_max : sympy.Expr
        Friction limit ``mu F_z`` [N].

    Returns
    -------
    sympy.Expr
    """
    u = _smooth_clamp3(c * alpha / f_max)
    return f_max * (u - u * sp.sqrt(u**2 + _ABS_EPS2) / 3 + u**3 / 27)


def _is_single_track(model) -> bool:
    need_p = {"m", "l_f", "l_r", "c_f", "c_r"}
    return (need_p <= set(model.param_names) and {"vx", "vy", "omega"} <= set(model.state_names)
            and "delta" in model.input_names)  # fmt: skip


def _targets(model):
    return list(FIALA_TARGETS) if _is_single_track(model) else []


def _axle_force_factor(base, c_name, alpha):
    """``(f0, k)`` with ``f = f0 + k c alpha`` for every state equation (raises if ``f`` has another form).

    ``base`` needs ``symbols``, ``f_expr`` and ``state_names`` (a model, or :class:`_Exprs` after the other axle).
    """
    c = base.symbols[c_name]
    f0, k = [], []
    for i, e in enumerate(base.f_expr):
        d = sp.diff(e, c)
        if sp.diff(d, c) != 0:
            raise ModelError(f"tire_fiala: state equation {base.state_names[i]!r} is not linear in {c_name!r}")
        ki = sp.cancel(d / alpha) if d != 0 else sp.Integer(0)
        if d != 0 and (ki.has(sp.atan) or sp.simplify(ki * alpha - d) != 0):
            raise ModelError(f"tire_fiala: {c_name!r} does not multiply the slip angle {alpha} in the equation "
                             f"of {base.state_names[i]!r}")  # fmt: skip
        f0.append(e.subs(c, 0))
        k.append(ki)
    return f0, k


def tire_fiala_model(base, target: str, names) -> Model:
    """The base model with the Fiala tyre on one axle (``c_f``/``c_r``) or both (``axles``).

    Parameters
    ----------
    base : Model
        A model in the single-track convention (see the module docstring).
    target : {"c_f", "c_r", "axles"}
    names : tuple of str
        Model-parameter name of the friction coefficient (one name).

    Returns
    -------
    Model
        With the new parameter ``names[0]`` (default 1.0).

    Raises
    ------
    ModelError
        If the model does not follow the convention.
    """
    if not _is_single_track(base):
        raise ModelError(f"tire_fiala: model {base.name!r} does not follow the single-track convention "
                         "(parameters m, l_f, l_r, c_f, c_r; states vx, vy, omega; input delta)")  # fmt: skip
    if target not in FIALA_TARGETS:
        raise ModelError(f"tire_fiala: target must be one of {FIALA_TARGETS}, got {target!r}")
    s = base.symbols
    mu = sp.Symbol(names[0], real=True)
    alphas = dict(zip(("c_f", "c_r"), slip_angles(s)))
    axles = ("c_f", "c_r") if target == "axles" else (target,)
    f = list(base.f_expr)
    for c_name in axles:
        if any(sp.diff(e, s[c_name], 2) != 0 for e in f):
            # the axle saturates already (a tyre effect applied before, e.g. the pair axles + c_r of the
            # diagnosis): it stays as it is and this friction coefficient does not act on it
            continue
        _, lever = SINGLE_TRACK_AXLES[c_name]
        f_z = s.m * GRAVITY * s[lever] / (s.l_f + s.l_r)
        f0, k = _axle_force_factor(_Exprs(base, f), c_name, alphas[c_name])
        force = fiala_force(s[c_name], alphas[c_name], mu * f_z)
        f = [a + b * force for a, b in zip(f0, k)]
    params = dict(base.params)
    params[names[0]] = 1.0
    outputs = dict(zip(base.output_names, base.h_expr))
    return Model(states=base.state_names, dynamics=f, inputs=base.input_names, disturbances=base.disturbance_names,
                 params=params, outputs=outputs, name=f"{base.name}+tire_fiala({target})",
                 description=base.description)  # fmt: skip


class _Exprs:
    """The parts of a model :func:`_axle_force_factor` reads, with other state equations."""

    def __init__(self, base, f):
        self.symbols = base.symbols
        self.f_expr = tuple(f)
        self.state_names = base.state_names


#: the effect (registered in :data:`reachconf.diagnose.EFFECTS` on import)
TIRE_FIALA = register_effect(Effect(
    "tire_fiala", "param", ("mu",), lambda x: (1.0,), lambda x: ((0.2,), (4.0,)), model=tire_fiala_model,
    targets=_targets,
    description="Fiala brush tyre with friction coefficient mu on an axle (c_f, c_r) or both (axles): "
                "c alpha -> mu F_z fiala(c alpha / (mu F_z))"))  # fmt: skip
