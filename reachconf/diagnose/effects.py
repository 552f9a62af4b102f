"""Library of candidate unmodelled effects for the gap diagnosis (source report sections 4.1.2, 4.2.3).

An :class:`Effect` is a transformation of a model with parameters to fit,
applied to a named input, output, state or parameter (its *target*):

===================  ========  ===========================================================
name                 target    what the real system does that the model does not
===================  ========  ===========================================================
``actuator_lag``     input     ``u_real' = (u - u_real) / tau`` (first-order actuator)
``dead_time``        input     ``u_real(t) = u(t - T)`` (transport delay)
``input_offset``     input     ``u_real = u + c``
``input_scale``      input     ``u_real = k u`` (applied after an offset: ``k (u + c)``, Table 2)
``output_offset``    output    ``y_measured = y + c`` (sensor bias)
``output_scale``     output    ``y_measured = k y``
``tire_saturation``  param     every force term linear in a stiffness ``c`` saturates:
                               ``c s -> c s / sqrt(1 + (c s / F)^2)`` (smooth, odd, limit F)
``drag``             state     ``v' -> v' - c_d v |v|`` (quadratic speed term)
===================  ========  ===========================================================

A lag's state at the start of a case is not known (a case cut from a longer
run starts with the actuator in motion): the diagnosis fits it per case
(``Effect.start``) on the samples before the case's first prediction window.

Input and output effects act on known signals, so the diagnosis applies them
to the test case (:meth:`Effect.apply_signal`, compiled filters of
:mod:`reachconf_kernels.signals`) and keeps the base model's compiled code;
:meth:`Effect.apply_model` builds the equivalent sympy model (an extra lag
state, a first-order Padé state for the dead time, a substituted input or
output) for reachability.  Model effects (``tire_saturation``, ``drag``) are
sympy transformations whose new parameters are fitted through
:meth:`reachconf.Model.with_params` (compiled once).  Add your own with
:func:`register_effect`.
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from typing import Callable

import numpy as np
import sympy as sp

from reachconf.errors import ModelError, OptionsError
from reachconf.model.core import Model
from reachconf_kernels.signals import first_order_lag, first_order_lag_from, transport_delay

__all__ = ["Effect", "EFFECTS", "register_effect", "registered_effect", "effect_param_name"]


@dataclass(frozen=True)
class Effect:
    """A candidate unmodelled effect.

    Parameters
    ----------
    name : str
    kind : {"input", "output", "param", "state"}
        What the target names.
    params : tuple of str
        Names of the effect's parameters.
    guess : callable
        ``guess(signal) -> tuple`` initial parameter values from the target
        signal (``None`` for param/state targets).
    bounds : callable
        ``bounds(signal) -> (lo, hi)`` tuples of parameter bounds.
    signal : callable, optional
        Input/output effects: ``signal(t, x, theta) -> x'`` (input: what the
        system really receives; output: what the sensor reports).
    inverse : callable, optional
        Output effects: ``inverse(y_measured, theta) -> y``.
    model : callable, optional
        ``model(base, target, names) -> Model``: the sympy transformation,
        ``names`` the model-parameter names of the effect's parameters.
    targets : callable, optional
        ``targets(model) -> list of str``: where the effect can act
        (default: every input/output/state/parameter of its kind).
    order : int
        Composition order on one target (offsets before scales: ``k (u + c)``).
    start_grid : tuple of float, optional
        Values of the first parameter tried before the least squares starts
        (the best one is its start), for losses with several minima in it: a
        delay on a periodic maneuver fits a wrong period from a fixed start.
    null : tuple of float, optional
        The parameter values at which the effect does nothing (an offset's 0,
        a scale's 1, a delay's 0); None when there is none (a saturation's
        limit at infinity).  The consistency route of the naming rule
        measures the effect's size across maneuvers from it.
    start : callable, optional
        Input effects with a memory: ``start(t, x, theta, s) -> x'`` with the
        effect's state at ``t_0`` moved by ``s`` from where ``signal`` starts
        it.  A case cut from a longer run starts with the actuator in motion;
        the diagnosis fits ``s`` per case (:func:`reachconf.diagnose.fit.case_starts`).
    units : tuple of str, optional
        Units of the parameters for the verdict's text (``("s",)`` for a time
        constant); None where they are those of the target (an offset) or none
        (a gain).
    """

    name: str
    kind: str
    params: tuple
    guess: Callable
    bounds: Callable
    signal: Callable | None = None
    inverse: Callable | None = None
    model: Callable | None = None
    targets: Callable | None = None
    order: int = 0
    description: str = ""
    start_grid: tuple | None = None
    null: tuple | None = None
    start: Callable | None = None
    units: tuple | None = None

    def __reduce__(self):
        # a registered effect travels by name (its callables are often lambdas): the diagnosis's worker
        # processes (reachconf.diagnose.parallel) send fit results holding it back to the calling process
        if self.registered:
            return (registered_effect, (self.name,))
        return (Effect, tuple(getattr(self, f.name) for f in fields(self)))

    @property
    def registered(self) -> bool:
        """Whether this effect is the library's effect of its name (:func:`register_effect`)."""
        return EFFECTS.get(self.name) is self

    def __post_init__(self):
        if self.kind not in ("input", "output", "param", "state"):
            raise OptionsError(f"effect {self.name!r}: kind must be input, output, param or state")
        if self.kind in ("input", "output") and self.signal is None:
            raise OptionsError(f"effect {self.name!r}: an {self.kind} effect needs a signal transformation")
        if self.kind == "output" and self.inverse is None:
            raise OptionsError(f"effect {self.name!r}: an output effect needs its inverse")
        if self.kind in ("param", "state") and self.model is None:
            raise OptionsError(f"effect {self.name!r}: a {self.kind} effect needs a model transformation")
        if self.start is not None and (self.kind != "input" or not callable(self.start)):
            raise OptionsError(f"effect {self.name!r}: start must be a callable of an input effect "
                               f"(start(t, x, theta, s)), got {self.start!r} on a {self.kind} effect")  # fmt: skip
        if self.start_grid is not None:
            g = np.asarray(self.start_grid, dtype=float) if np.ndim(self.start_grid) == 1 else None
            if g is None or g.size == 0 or not np.all(np.isfinite(g)):
                raise OptionsError(f"effect {self.name!r}: start_grid must be a non-empty sequence of finite numbers, "
                                   f"got {self.start_grid!r}")  # fmt: skip
        if self.null is not None and (np.ndim(self.null) != 1 or len(self.null) != len(self.params)
                                      or not np.all(np.isfinite(np.asarray(self.null, dtype=float)))):
            raise OptionsError(f"effect {self.name!r}: null must give one finite value per parameter "
                               f"{self.params}, got {self.null!r}")  # fmt: skip

    def applicable(self, model) -> list:
        """Targets of ``model`` this effect can act on."""
        if self.targets is not None:
            try:
                found = list(self.targets(model))
            except TypeError as exc:  # not iterable, or a wrong signature
                raise OptionsError(f"effect {self.name!r}: targets(model) must give a list of names: {exc}") from None
            if not all(isinstance(t, str) for t in found):
                raise OptionsError(f"effect {self.name!r}: targets(model) must give names (str), got {found!r}"[:300])
            return found
        return list({"input": model.input_names, "output": model.output_names, "state": model.state_names,
                     "param": model.param_names}[self.kind])  # fmt: skip

    def start_values(self, target: str, signal, t=None, x=None) -> tuple:
        """The checked start and bounds of the parameters: ``(guess, lo, hi)``, each a float tuple.

        ``signal``: the target's samples (input/output effects) or None; ``t, x``: one case's time
        and target samples, on which a signal effect must give finite values at its start.

        Raises
        ------
        OptionsError
            ``guess`` or ``bounds`` not one finite number per parameter, ``lo >= hi``, or the effect's
            signal not finite at the start (a user-written effect, named with its target).
        """
        where = f"effect {self.name!r} on {target!r}"
        n = len(self.params)
        try:
            g = np.asarray(self.guess(signal), dtype=float).reshape(-1)
            lo, hi = (np.asarray(b, dtype=float).reshape(-1) for b in self.bounds(signal))
        except (TypeError, ValueError) as exc:
            raise OptionsError(f"{where}: guess(signal) must give {n} numbers and bounds(signal) a pair (lo, hi) "
                               f"of {n} numbers each: {exc}"[:300]) from None  # fmt: skip
        if not g.size == lo.size == hi.size == n:
            raise OptionsError(f"{where}: guess gives {g.size} values and bounds {lo.size} and {hi.size} for its "
                               f"{n} parameter(s) {self.params}")  # fmt: skip
        if not (np.all(np.isfinite(g)) and np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))):
            raise OptionsError(f"{where}: guess and bounds must be finite, got {tuple(g)}, {tuple(lo)}, {tuple(hi)}")
        if np.any(lo >= hi):
            i = int(np.nonzero(lo >= hi)[0][0])
            raise OptionsError(f"{where}: the lower bound of {self.params[i]!r} must be below the upper, got "
                               f"[{lo[i]}, {hi[i]}]")  # fmt: skip
        if self.signal is not None and t is not None and x is not None:
            with np.errstate(all="ignore"):
                out = np.asarray(self.apply_signal(t, x, np.clip(g, lo, hi)), dtype=float)
            start = tuple(map(float, np.clip(g, lo, hi)))
            if out.shape != np.shape(x):
                raise OptionsError(f"{where}: its signal must give one value per sample ({np.shape(x)}), got an "
                                   f"array of shape {out.shape} at the start {start}")  # fmt: skip
            if not np.all(np.isfinite(out)):
                raise OptionsError(f"{where}: its signal gives NaN or inf at the start {start} (on the first "
                                   f"training case)")  # fmt: skip
        return tuple(map(float, g)), tuple(map(float, lo)), tuple(map(float, hi))

    def apply_signal(self, t, x, theta, start: float = 0.0):
        """What the system receives (input effects) or the sensor reports (output effects) for the signal ``x``.

        ``start``: the effect's state at ``t_0`` moved by this much (effects with a ``start`` only).
        """
        # writeable contiguous copies: suites loaded from disk hold read-only arrays, compiled filters need mutable ones
        t = np.array(t, dtype=float, order="C")
        x = np.array(x, dtype=float, order="C")
        theta = tuple(float(v) for v in theta)
        if start != 0.0 and self.start is not None:
            return self.start(t, x, theta, float(start))
        return self.signal(t, x, theta)

    def apply_model(self, base, target: str, theta=None):
        """The base model with this effect on ``target`` as a new :class:`~reachconf.Model`.

        The effect's parameters become model parameters named by
        :func:`effect_param_name`, set to ``theta`` (or the bounds' midpoint).
        """
        names = tuple(effect_param_name(self.name, p, target) for p in self.params)
        if self.model is not None:
            new = self.model(base, target, names)
        else:
            new = _signal_effect_model(self, base, target, names)
        if theta is not None:
            new = new.with_params(**dict(zip(names, map(float, theta))))
        return new


def effect_param_name(effect: str, param: str, target: str) -> str:
    """Model-parameter name of an effect parameter, e.g. ``actuator_lag_tau_delta``."""
    return f"{effect}_{param}_{target}"


# --------------------------------------------------------------------------- model rewriting
def _rebuild(base, f_expr, h_expr=None, states=None, params=None, name=None):
    states = tuple(states or base.state_names)
    new_params = dict(base.params)
    new_params.update(params or {})
    h_expr = base.h_expr if h_expr is None else h_expr
    outputs = dict(zip(base.output_names, h_expr))
    return Model(states=states, dynamics=list(f_expr), inputs=base.input_names, disturbances=base.disturbance_names,
                 params=new_params, outputs=outputs, name=name or base.name,
                 description=base.description)  # fmt: skip


def _sym(name):
    return sp.Symbol(name, real=True)


def _signal_effect_model(effect, base, target, names):
    """sympy version of an input/output effect (for reachability and user models)."""
    u = _sym(target)
    nm = f"{base.name}+{effect.name}({target})"
    if effect.kind == "input":
        if effect.name == "actuator_lag":
            xa = _sym(f"{target}_act")
            tau = _sym(names[0])
            f = [e.subs(u, xa) for e in base.f_expr] + [(u - xa) / tau]
            h = [e.subs(u, xa) for e in base.h_expr]
            return _rebuild(base, f, h, base.state_names + (f"{target}_act",), {names[0]: 0.1}, nm)
        if effect.name == "dead_time":
            # first-order Padé: u(t - T) ~ 2 z - u with z' = 2 (u - z) / T
            z = _sym(f"{target}_pade")
            T = _sym(names[0])
            ue = 2 * z - u
            f = [e.subs(u, ue) for e in base.f_expr] + [2 * (u - z) / T]
            h = [e.subs(u, ue) for e in base.h_expr]
            return _rebuild(base, f, h, base.state_names + (f"{target}_pade",), {names[0]: 0.05}, nm)
        c = _sym(names[0])
        ue = u + c if effect.name == "input_offset" else c * u
        default = 0.0 if effect.name == "input_offset" else 1.0
        return _rebuild(base, [e.subs(u, ue) for e in base.f_expr], [e.subs(u, ue) for e in base.h_expr], None,
                        {names[0]: default}, nm)  # fmt: skip
    if effect.kind == "output":
        i = base.output_names.index(target)
        c = _sym(names[0])
        h = list(base.h_expr)
        h[i] = h[i] + c if effect.name == "output_offset" else c * h[i]
        return _rebuild(base, base.f_expr, h, None, {names[0]: 0.0 if effect.name == "output_offset" else 1.0}, nm)
    raise ModelError(f"effect {effect.name!r} has no model transformation")


def _tire_saturation_model(base, target, names):
    c = _sym(target)
    F = _sym(names[0])
    hit = []

    def saturate(e):
        hit.append(e)
        return e / sp.sqrt(1 + (e / F) ** 2)

    f = [e.replace(_is_product_with(c, base), saturate) for e in base.f_expr]
    if not hit:
        raise ModelError(f"tire_saturation: no force term is a product with parameter {target!r}")
    return _rebuild(base, f, None, None, {names[0]: 10.0}, f"{base.name}+tire_saturation({target})")


def _drag_model(base, target, names):
    i = base.state_names.index(target)
    v = _sym(target)
    cd = _sym(names[0])
    f = list(base.f_expr)
    f[i] = f[i] - cd * v * sp.sqrt(v**2 + sp.Rational(1, 10**6))  # smooth v |v| (Abs has no second derivative)
    return _rebuild(base, f, None, None, {names[0]: 0.0}, f"{base.name}+drag({target})")


# --------------------------------------------------------------------------- the library
def _lag(t, u, th):
    return first_order_lag(t, u, max(th[0], 1e-6))


def _lag_start(t, u, th, s):
    return first_order_lag_from(t, u, max(th[0], 1e-6), u[0] + s)


def _delay(t, u, th):
    return transport_delay(t, u, max(th[0], 0.0))


def _spread(x):
    """Typical size of a signal: its root mean square (an offset may be as large as the signal's mean)."""
    s = float(np.sqrt(np.mean(np.square(x))))
    return s if s > 0 else 1.0


def _is_product_with(c, model):
    """The predicate of :func:`_tire_saturation_model`: a product with the symbol ``c`` as one of its factors and a
    state or input among its symbols (a force ``c s(x, u)``; a constant load ``c_load / J`` is not one)."""
    signals = {model.symbols[n] for n in model.state_names + model.input_names}
    return lambda a: a.is_Mul and c in a.args and bool(a.free_symbols & signals)


def _stiffness_params(model):
    """Candidate stiffnesses: parameters named ``c_...`` that multiply a term of the dynamics.

    A ``c_`` parameter in no product with a state or input (an additive load ``c_load``)
    has no force term to saturate and is not a target.
    """
    out = []
    for p in model.param_names:
        if p.startswith("c_"):
            c = model.symbols[p]
            if any(e.find(_is_product_with(c, model)) for e in model.f_expr):
                out.append(p)
    return out


def _velocity_states(model):
    return [s for s in model.state_names if s.startswith("v")]


EFFECTS: dict = {}


def registered_effect(name: str) -> Effect:
    """The library's effect called ``name`` (how a registered :class:`Effect` is unpickled)."""
    if name not in EFFECTS:
        raise OptionsError(f"effect {name!r} is not registered here (register_effect); known: {sorted(EFFECTS)}")
    return EFFECTS[name]


def register_effect(effect: Effect) -> Effect:
    """Add an effect to the library (replaces one of the same name)."""
    if not isinstance(effect, Effect):
        raise OptionsError(f"register_effect needs an Effect, got {type(effect).__name__}")
    EFFECTS[effect.name] = effect
    return effect


register_effect(Effect("actuator_lag", "input", ("tau",), lambda x: (0.05,), lambda x: ((0.002,), (1.0,)),
                       signal=_lag, order=2, description="first-order actuator lag, time constant tau [s]",
                       null=(0.0,), start=_lag_start, units=("s",)))  # fmt: skip
register_effect(Effect("dead_time", "input", ("T",), lambda x: (0.04,), lambda x: ((0.0,), (0.5,)),
                       signal=_delay, order=3, description="transport delay T [s] on an input",
                       start_grid=(0.02, 0.05, 0.08, 0.12, 0.16, 0.2, 0.3), null=(0.0,), units=("s",)))  # fmt: skip
register_effect(Effect("input_offset", "input", ("c",), lambda x: (0.0,),
                       lambda x: ((-2 * _spread(x),), (2 * _spread(x),)),
                       signal=lambda t, u, th: u + th[0], order=0, description="additive input offset c", null=(0.0,)))  # fmt: skip
register_effect(Effect("input_scale", "input", ("k",), lambda x: (1.0,), lambda x: ((0.2,), (5.0,)),
                       signal=lambda t, u, th: th[0] * u, order=1, description="input gain k", null=(1.0,)))  # fmt: skip
register_effect(Effect("output_offset", "output", ("c",), lambda x: (0.0,),
                       lambda x: ((-_spread(x),), (_spread(x),)),
                       signal=lambda t, y, th: y + th[0], inverse=lambda y, th: y - th[0], order=0,
                       description="sensor bias c (measured = true + c)", null=(0.0,)))  # fmt: skip
register_effect(Effect("output_scale", "output", ("k",), lambda x: (1.0,), lambda x: ((0.2,), (5.0,)),
                       signal=lambda t, y, th: th[0] * y, inverse=lambda y, th: y / th[0], order=1,
                       description="sensor gain k (measured = k true)", null=(1.0,)))  # fmt: skip
register_effect(Effect("tire_saturation", "param", ("F",), lambda x: (10.0,), lambda x: ((0.5,), (200.0,)),
                       model=_tire_saturation_model, targets=_stiffness_params,
                       description="force terms linear in stiffness c saturate at F: c s -> c s / sqrt(1 + (c s / F)^2)"))  # fmt: skip
# c_d >= 0: a drag only opposes the motion (a negative c_d would be a thrust growing with speed, which at nearly
# constant speed mimics any accelerating offset); the start is inside (a least-squares start on the bound stays there)
register_effect(Effect("drag", "state", ("c_d",), lambda x: (0.002,), lambda x: ((0.0,), (0.05,)),
                       model=_drag_model, targets=_velocity_states,
                       description="quadratic speed term v' -= c_d v |v| (c_d >= 0) on a velocity state",
                       null=(0.0,)))  # fmt: skip
