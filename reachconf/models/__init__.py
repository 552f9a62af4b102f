"""Built-in models, each a function returning a :class:`reachconf.Model`.

====================================  =====================================================
name                                  what
====================================  =====================================================
``vanderpol``                         Van der Pol oscillator (ARCH-COMP NLN)
``coupled_vanderpol``                 coupled Van der Pol, 4-D (ARCH-COMP NLN)
``laub_loomis``                       Laub–Loomis 7-D benchmark (ARCH-COMP NLN)
``bicycle``                           dynamic bicycle model f_B, eqs. 49–52, Table 1
``bicycle_actuated``                  f_BX with first-order actuators, eqs. 53–58, Table 2
``bicycle_closed_loop``               f_B with the tracking controller, eqs. 59/60
``bicycle_closed_loop_actuated``      the same with f_BX's actuators in the loop
``bicycle_closed_loop_rate_limited``  the same with a rate-limited steering actuator
``single_track``                      dynamic single-track model at the CG, linear tyres (real car)
``wind_turbine``                      reduced NREL 5-MW turbine, eqs. 69, 77, 78, 80
``pedestrian_acc``                    acceleration-constrained pedestrian, eq. 73
``pedestrian_vel``                    velocity-constrained pedestrian, eq. 74
``diff_drive``                        differential-drive robot, section 7.3
====================================  =====================================================

``get_model(name, **params)`` looks a model up by name (used by run files).
"""

from __future__ import annotations

import importlib

from reachconf.errors import ModelError

_REGISTRY = {
    "vanderpol": "reachconf.models.benchmarks",
    "coupled_vanderpol": "reachconf.models.benchmarks",
    "laub_loomis": "reachconf.models.benchmarks",
    "bicycle": "reachconf.models.vehicle",
    "bicycle_actuated": "reachconf.models.vehicle",
    "bicycle_closed_loop": "reachconf.models.vehicle",
    "bicycle_closed_loop_actuated": "reachconf.models.vehicle",
    "bicycle_closed_loop_rate_limited": "reachconf.models.vehicle",
    "single_track": "reachconf.models.single_track_cg",
    "wind_turbine": "reachconf.models.windturbine",
    "pedestrian_acc": "reachconf.models.pedestrian",
    "pedestrian_vel": "reachconf.models.pedestrian",
    "diff_drive": "reachconf.models.robot",
}

__all__ = sorted(_REGISTRY) + ["get_model", "available"]


def available() -> list[str]:
    """Names of the built-in models."""
    return sorted(_REGISTRY)


def get_model(name: str, **params):
    """A built-in model by name, or ``"module:attribute"`` for a user model.

    Keyword arguments are passed to the model factory (parameters, options).
    """
    if not isinstance(name, str) or not name:
        raise ModelError(f"model name must be a non-empty string, got {name!r}")
    if ":" in name:
        return _user_model(name, params)
    if name not in _REGISTRY:
        raise ModelError(f"unknown model {name!r}; built-in models: {', '.join(available())}")
    factory = getattr(importlib.import_module(_REGISTRY[name]), name)
    return factory(**params)


def _user_model(name: str, params: dict):
    """``"module:attribute"``: a Model, or a function returning one (called with ``params``)."""
    from reachconf.model.core import Model

    module_name, attr = name.split(":", 1)
    if not module_name or not attr:
        raise ModelError(f"model {name!r}: expected 'package.module:attribute'")
    try:
        module = importlib.import_module(module_name)
    except Exception as exc:  # ImportError, or whatever the user's module raises while it is imported
        hint = ""
        if isinstance(exc, ModuleNotFoundError) and exc.name == module_name.split(".", 1)[0]:
            hint = " (put its file next to the run file, or its folder on PYTHONPATH)"
        raise ModelError(f"cannot load model {name!r}: importing {module_name!r} failed: "
                         f"{type(exc).__name__}: {exc}{hint}") from None  # fmt: skip
    try:
        obj = getattr(module, attr)
    except AttributeError:
        raise ModelError(f"cannot load model {name!r}: module {module_name!r} has no attribute {attr!r}") from None
    if isinstance(obj, Model):
        return obj.with_params(**params) if params else obj
    if not callable(obj):
        raise ModelError(f"model {name!r} is a {type(obj).__name__}, not a reachconf Model or a function returning one")
    try:
        model = obj(**params)
    except Exception as exc:  # a function that is not a model factory (e.g. "os.path:join")
        raise ModelError(f"model {name!r}: calling it to get the model failed: {type(exc).__name__}: {exc}") from None
    if not isinstance(model, Model):
        raise ModelError(f"model {name!r} returned a {type(model).__name__}, not a reachconf Model")
    return model


def __getattr__(name):
    if name in _REGISTRY:
        return getattr(importlib.import_module(_REGISTRY[name]), name)
    raise AttributeError(f"module 'reachconf.models' has no attribute {name!r}")
