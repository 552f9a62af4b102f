"""Symbolic system models: ``x' = f(x, u, w; p)``, ``y = h(x, u; p) + v``.

A :class:`Model` is written once with sympy (source report eqs. 6–8): named
states ``x``, known inputs ``u``, disturbances ``w`` (non-deterministic, in a set
``W``), parameters ``p`` and outputs ``y`` with an additive measurement error
``v`` in a set ``V``.  Everything else — Jacobians, Hessians, third-order tensors
and their interval (Lagrange-remainder) enclosures — is generated from it and
compiled with numba by :mod:`reachconf.model.codegen`.

Examples
--------
>>> import reachconf as rc
>>> vdp = rc.Model(
...     name="vanderpol",
...     states=("x", "y"),
...     params={"mu": 1.0},
...     dynamics=lambda s: [s.y, s.mu * (1 - s.x**2) * s.y - s.x],
... )
>>> vdp.state_names, vdp.output_names
(('x', 'y'), ('x', 'y'))
>>> vdp.with_params(mu=2.0).params["mu"]
2.0

The same model written as a class::

    class VanDerPol(rc.Model):
        states = ("x", "y")
        params = {"mu": 1.0}

        def dynamics(self, s):
            return [s.y, s.mu * (1 - s.x**2) * s.y - s.x]
"""

from __future__ import annotations

import copy
import hashlib
import keyword
import math
import pickle
from collections.abc import Callable, Mapping, Sequence
from types import MappingProxyType

import numpy as np
import sympy as sp

from reachconf.errors import ModelError
from reachconf.model.codegen import compile_model
from reachconf.model.names import call_with_symbols, model_expression, warn_unused_signals
from reachconf.model.recipe import rebuild_model

__all__ = ["Model", "Symbols", "require_model"]

#: per-process caches that are rebuilt, never pickled
_NOT_SHIPPED = ("_affine_cache", "_recipe")


class Symbols:
    """Namespace of the sympy symbols of a model, by attribute or by key.

    ``s.x`` and ``s["x"]`` are the symbol of the signal or parameter ``x``.
    """

    def __init__(self, symbols: Mapping[str, sp.Symbol]):
        object.__setattr__(self, "_symbols", dict(symbols))

    def __getstate__(self):
        return self._symbols

    def __setstate__(self, state):
        object.__setattr__(self, "_symbols", dict(state))

    def __getattr__(self, name):
        if name.startswith("__") or name == "_symbols":
            raise AttributeError(name)
        try:
            return self._symbols[name]
        except KeyError:
            raise ModelError(
                f"unknown name {name!r} in the model definition; known names: "
                f"{', '.join(self._symbols) or '(none)'}"
            ) from None

    def __getitem__(self, name):
        return self.__getattr__(name)

    def __setattr__(self, name, value):
        raise ModelError("the symbol namespace is read-only")

    def __iter__(self):
        return iter(self._symbols)

    def __contains__(self, name):
        return name in self._symbols


def _names(value, what: str) -> tuple[str, ...]:
    if value is None:
        return ()
    if isinstance(value, str):
        value = (value,)
    try:
        names = tuple(value)
    except TypeError:
        raise ModelError(f"{what} must be a sequence of names, got {type(value).__name__}") from None
    for name in names:
        if not isinstance(name, str) or not name.isidentifier() or keyword.iskeyword(name):
            raise ModelError(f"{what}: {name!r} is not a valid signal name (use a Python identifier)")
        if name.startswith("_"):
            raise ModelError(f"{what}: {name!r} starts with '_', which is reserved (use a name without it)")
        if name == "t" and what in ("inputs", "outputs"):  # columns of a test case, beside its time column t
            raise ModelError(f"{what}: 't' is the time column of test cases; give the signal another name")
    if len(set(names)) != len(names):
        dup = sorted({n for n in names if names.count(n) > 1})
        raise ModelError(f"{what}: duplicate names {dup}")
    return names


class Model:
    """A nonlinear system ``x' = f(x, u, w; p)``, ``y = h(x, u; p) + v``.

    Parameters
    ----------
    states : sequence of str
        Names of the state variables ``x`` (eq. 1).
    dynamics : callable or sequence or mapping
        ``f``: either a callable ``dynamics(s)`` receiving the :class:`Symbols`
        namespace and returning one sympy expression per state (a list in
        state order or a dict keyed by state name), or the expressions
        themselves (using symbols named like the signals).
    inputs : sequence of str, optional
        Known inputs ``u`` (eq. 2), piecewise constant between samples.
    disturbances : sequence of str, optional
        Disturbances ``w`` (eq. 4); they range over a set ``W``.
    params : mapping of str to float, optional
        Parameters with their nominal values.
    outputs : callable, sequence of str, or mapping, optional
        ``h``: a callable ``outputs(s)`` returning a dict ``name -> expression``,
        a mapping ``name -> expression``, or a sequence of state names (those
        states are measured).  Default: every state is measured (``y = x + v``,
        eq. 52).  The measurement error ``v`` is additive, one per output.
    name : str, optional
        Name of the model (used in messages and cache file names).
    description : str, optional
        Free text (equations, source).

    Raises
    ------
    ModelError
        On duplicate or invalid names, expressions that use unknown symbols,
        a wrong number of dynamics expressions, or non-finite parameters.
    """

    # Class-level defaults so that models can be defined as subclasses.
    name: str = "model"
    states: Sequence[str] = ()
    inputs: Sequence[str] = ()
    disturbances: Sequence[str] = ()
    params: Mapping[str, float] = {}
    outputs = None
    description: str = ""

    def __init__(
        self,
        states: Sequence[str] | None = None,
        dynamics: Callable | Sequence | Mapping | None = None,
        *,
        inputs: Sequence[str] | None = None,
        disturbances: Sequence[str] | None = None,
        params: Mapping[str, float] | None = None,
        outputs=None,
        name: str | None = None,
        description: str | None = None,
    ):
        cls = type(self)
        self.name = str(name if name is not None else cls.name)
        self.description = description if description is not None else (cls.description or (cls.__doc__ or ""))
        self.state_names = _names(states if states is not None else cls.states, "states")
        self.input_names = _names(inputs if inputs is not None else cls.inputs, "inputs")
        self.disturbance_names = _names(
            disturbances if disturbances is not None else cls.disturbances, "disturbances"
        )
        # the names also under the constructor's own words (``model.inputs`` was the empty class default: an outside
        # user passed it to a TestCase and got "U must have shape (100, 0)")
        self.states, self.inputs, self.disturbances = self.state_names, self.input_names, self.disturbance_names
        raw_params = params if params is not None else cls.params
        if not isinstance(raw_params, Mapping):
            raise ModelError(f"model {self.name!r}: params must be a mapping name -> value, got "
                             f"{type(raw_params).__name__}")  # fmt: skip
        param_values = dict(raw_params)
        self.param_names = _names(tuple(param_values), "params")
        if not self.state_names:
            raise ModelError(f"model {self.name!r}: at least one state is required")

        all_names = self.state_names + self.input_names + self.disturbance_names + self.param_names
        if len(set(all_names)) != len(all_names):
            dup = sorted({n for n in all_names if all_names.count(n) > 1})
            raise ModelError(
                f"model {self.name!r}: names used twice across states/inputs/disturbances/params: {dup}"
            )
        self._symbols = {n: sp.Symbol(n, real=True) for n in all_names}
        self.symbols = Symbols(self._symbols)

        if dynamics is None:
            dynamics = getattr(self, "dynamics", None)
            if dynamics is None or not callable(dynamics):
                raise ModelError(f"model {self.name!r}: no dynamics given")
        self.f_expr = self._state_exprs(dynamics)
        if outputs is None:
            outputs = getattr(self, "outputs", None)
        self.output_names, self.h_expr = self._output_exprs(outputs)
        self.params = MappingProxyType({k: self._check_param(k, v) for k, v in param_values.items()})
        warn_unused_signals(self)

    # ------------------------------------------------------------------ build
    def _check_param(self, key, value) -> float:
        try:
            value = float(value)
        except (TypeError, ValueError):
            raise ModelError(f"model {self.name!r}: parameter {key!r} must be a number, got {value!r}") from None
        if not math.isfinite(value):
            raise ModelError(f"model {self.name!r}: parameter {key!r} must be finite, got {value}")
        return value

    def _sympify(self, expr, where: str) -> sp.Expr:
        return model_expression(expr, self._symbols, self.param_names, where, self.name)

    def _call(self, fn, what: str):
        """``fn(self.symbols)``: a user's dynamics or outputs function, its errors named."""
        return call_with_symbols(fn, self.symbols, what, self.name)

    def _state_exprs(self, dynamics) -> tuple[sp.Expr, ...]:
        result = self._call(dynamics, "dynamics") if callable(dynamics) else dynamics
        n = len(self.state_names)
        if isinstance(result, Mapping):
            unknown = sorted(set(result) - set(self.state_names))
            missing = [s for s in self.state_names if s not in result]
            if unknown:
                raise ModelError(f"model {self.name!r}: dynamics given for unknown states {unknown}")
            if missing:
                raise ModelError(f"model {self.name!r}: no dynamics for states {missing}")
            result = [result[s] for s in self.state_names]
        if isinstance(result, sp.MatrixBase):
            result = list(result)
        if not isinstance(result, (list, tuple)):
            raise ModelError(
                f"model {self.name!r}: dynamics must return one expression per state ({n}), "
                f"got {type(result).__name__}"
            )
        if len(result) != n:
            raise ModelError(
                f"model {self.name!r}: dynamics has {len(result)} expressions for {n} states {self.state_names}"
            )
        return tuple(self._sympify(e, f"dynamics of {s!r}") for s, e in zip(self.state_names, result))

    def _output_exprs(self, outputs):
        if outputs is None:  # every state measured: the states' names are the outputs'
            return _names(self.state_names, "outputs"), tuple(self._symbols[s] for s in self.state_names)
        result = self._call(outputs, "outputs") if callable(outputs) else outputs
        if isinstance(result, Mapping):
            names = _names(tuple(result), "outputs")
            clash = [k for k in names if k in self.input_names + self.disturbance_names + self.param_names]
            if clash:  # a test case has one column per signal name
                raise ModelError(f"model {self.name!r}: outputs {clash} have the name of an input, disturbance or "
                                 f"parameter; name them differently")  # fmt: skip
            exprs = tuple(self._sympify(result[k], f"output {k!r}") for k in names)
        else:
            names = _names(result, "outputs")
            unknown = [k for k in names if k not in self.state_names]
            if unknown:
                raise ModelError(
                    f"model {self.name!r}: outputs {unknown} are not states; give a mapping name -> expression"
                )
            exprs = tuple(self._symbols[k] for k in names)
        if not names:
            raise ModelError(f"model {self.name!r}: at least one output is required")
        for expr, k in zip(exprs, names):
            bad = [s.name for s in expr.free_symbols if s.name in self.disturbance_names]
            if bad:
                raise ModelError(
                    f"model {self.name!r}: output {k!r} depends on disturbances {bad}; measurement errors are "
                    f"additive (y = h(x, u) + v)"
                )
        return names, exprs

    # ----------------------------------------------------------- properties
    @property
    def n(self) -> int:
        """Number of states."""
        return len(self.state_names)

    @property
    def m(self) -> int:
        """Number of known inputs."""
        return len(self.input_names)

    @property
    def q(self) -> int:
        """Number of disturbances."""
        return len(self.disturbance_names)

    @property
    def p(self) -> int:
        """Number of outputs."""
        return len(self.output_names)

    @property
    def nz(self) -> int:
        """Length of the stacked vector ``z = (x, u, w)`` all derivatives are taken over."""
        return self.n + self.m + self.q

    @property
    def param_vector(self) -> np.ndarray:
        """Parameter values as a float64 array in :attr:`param_names` order."""
        return np.array([self.params[k] for k in self.param_names], dtype=np.float64)

    @property
    def z_symbols(self) -> tuple[sp.Symbol, ...]:
        """The symbols of ``z = (x, u, w)``, in that order."""
        names = self.state_names + self.input_names + self.disturbance_names
        return tuple(self._symbols[k] for k in names)

    @property
    def p_symbols(self) -> tuple[sp.Symbol, ...]:
        """The parameter symbols in :attr:`param_names` order."""
        return tuple(self._symbols[k] for k in self.param_names)

    def index(self, name: str) -> tuple[str, int]:
        """Role (``"state"``, ``"input"``, ``"disturbance"``, ``"output"``) and index of a signal."""
        for role, names in (
            ("state", self.state_names),
            ("input", self.input_names),
            ("disturbance", self.disturbance_names),
            ("output", self.output_names),
        ):
            if name in names:
                return role, names.index(name)
        raise ModelError(f"model {self.name!r} has no signal {name!r}")

    def output_indices(self, names: Sequence[str]) -> list[int]:
        """Indices of output names; :class:`ModelError` naming any unknown one."""
        unknown = [k for k in names if k not in self.output_names]
        if unknown:
            raise ModelError(f"model {self.name!r} has no outputs {unknown}; outputs are {self.output_names}")
        return [self.output_names.index(k) for k in names]

    def is_linear(self) -> bool:
        """True when ``f`` is affine in ``(x, u, w)`` (all second derivatives vanish)."""
        z = self.z_symbols
        zset = set(z)
        for expr in self.f_expr:
            for zi in expr.free_symbols & zset:  # a derivative can only vary in the variables it holds (not nz^2 checks)
                d = sp.diff(expr, zi)
                if any(sp.diff(d, zj) != 0 for zj in d.free_symbols & zset):
                    return False
        return True

    # -------------------------------------------------------------- derive
    def with_params(self, **params) -> "Model":
        """A copy of the model with some parameter values replaced.

        The expressions (and thus the compiled code) are shared: parameters are
        passed to the compiled functions at run time, so no recompilation.

        Raises
        ------
        ModelError
            If a name is not a parameter of the model or a value is not finite.
        """
        unknown = sorted(set(params) - set(self.param_names))
        if unknown:
            raise ModelError(
                f"model {self.name!r} has no parameters {unknown}; parameters are {list(self.param_names)}"
            )
        new = object.__new__(type(self))
        new.__dict__.update(self.__dict__)
        merged = dict(self.params)
        merged.update({k: new._check_param(k, v) for k, v in params.items()})
        new.params = MappingProxyType(merged)
        return new

    def __getstate__(self):
        # compiled code and caches stay behind (rebuilt from the disk cache in the new process)
        state = {k: v for k, v in self.__dict__.items() if not (k.startswith("_compiled_") or k in _NOT_SHIPPED)}
        state["params"] = dict(self.params)
        return state

    def __setstate__(self, state):
        state = dict(state)
        state["params"] = MappingProxyType(state["params"])
        self.__dict__.update(state)

    @property
    def structure_key(self) -> str:
        """Hash of what the compiled code depends on: class, names and expressions (not the parameter values).

        Models with equal keys share their compiled code; a worker process
        keeps the models it built under this key (see :func:`rebuild_model`).
        """
        key = self.__dict__.get("_structure_key")
        if key is None:
            h = hashlib.sha256(f"{type(self).__module__}.{type(self).__qualname__}".encode())
            for part in (self.name, self.state_names, self.input_names, self.disturbance_names, self.param_names,
                         self.output_names, *(sp.srepr(e) for e in self.f_expr + self.h_expr)):  # fmt: skip
                h.update(repr(part).encode() + b"\0")
            key = self.__dict__["_structure_key"] = h.hexdigest()[:24]
        return key

    def __reduce__(self):
        # the model travels as a build recipe: its class, its structure key, its parameter values and its
        # pickled names and expressions (made once per model); a worker that has built a model with the same
        # key keeps and reuses it with its compiled code, without unpickling the expressions again
        recipe = self.__dict__.get("_recipe")
        if recipe is None:
            state = self.__getstate__()
            del state["params"]
            recipe = self.__dict__["_recipe"] = pickle.dumps(state, protocol=pickle.HIGHEST_PROTOCOL)
        cls = type(self) if type(self).__module__ != "__main__" else Model  # workers do not import the script
        return (rebuild_model, (cls, self.structure_key, dict(self.params), recipe))

    def __copy__(self):
        return self.with_params()

    def __deepcopy__(self, memo):
        new = object.__new__(type(self))
        new.__setstate__(copy.deepcopy(self.__getstate__(), memo))
        return new

    def compiled(self, order: int = 2, remainder: str = "taylor"):
        """The compiled functions of this model (see :func:`reachconf.model.codegen.compile_model`).

        ``remainder="tensor"`` builds the older symbolic interval Hessian and,
        with ``order=3``, third-order tensor; the default ``"taylor"`` build
        serves every order.  Compilation happens once per expression set and
        is cached on disk.
        """
        key = "_compiled_taylor" if remainder == "taylor" else f"_compiled_{remainder}_{order}"
        cached = self.__dict__.get(key)
        if cached is None:
            cached = compile_model(self, order=order, remainder=remainder)
            self.__dict__[key] = cached
        return cached

    # --------------------------------------------------------- evaluation
    def _z(self, x, u, w) -> np.ndarray:
        z = np.zeros(self.nz)
        z[: self.n] = _vector(x, self.n, "x")
        z[self.n : self.n + self.m] = _vector(u, self.m, "u")
        z[self.n + self.m :] = _vector(w, self.q, "w")
        return z

    def f(self, x, u=None, w=None) -> np.ndarray:
        """Evaluate ``f(x, u, w)`` numerically (compiled)."""
        out = np.empty(self.n)
        self.compiled().f(self._z(x, u, w), self.param_vector, out)
        return out

    def h(self, x, u=None) -> np.ndarray:
        """Evaluate the noise-free output map ``h(x, u)`` numerically (compiled)."""
        out = np.empty(self.p)
        self.compiled().h(self._z(x, u, None), self.param_vector, out)
        return out

    def __repr__(self) -> str:
        return (
            f"Model({self.name!r}, states={self.state_names}, inputs={self.input_names}, "
            f"disturbances={self.disturbance_names}, outputs={self.output_names}, params={dict(self.params)})"
        )


def _vector(value, size: int, name: str) -> np.ndarray:
    if value is None:
        return np.zeros(size)
    arr = np.asarray(value, dtype=np.float64).reshape(-1)
    if arr.shape != (size,):
        raise ModelError(f"{name} must have {size} entries, got shape {np.shape(value)}")
    if not np.all(np.isfinite(arr)):
        raise ModelError(f"{name} contains NaN or inf")
    return arr


def require_model(model, where: str) -> "Model":
    """``model`` if it is a :class:`Model`, else :class:`ModelError` naming ``where`` (e.g. ``"synthesize_W"``)."""
    if not isinstance(model, Model):
        raise ModelError(f"{where}: model must be a reachconf Model, got {type(model).__name__}")
    return model
