"""Built-in models, each a function returning a :class:`reachconf.Model`.

================================  =====================================================
name                              what
================================  =====================================================
``vanderpol``                     Van der Pol oscillator (ARCH-COMP NLN)
``laub_loomis``                   Laub–Loomis 7-D benchmark (ARCH-COMP NLN)
``bicycle``                       dynamic bicycle model f_B, eqs. 49–52, Table 1
``bicycle_actuated``              f_BX with first-order actuators, eqs. 53–58, Table 2
``bicycle_closed_loop``           f_B with the tracking controller, eqs. 59/60
``bicycle_closed_loop_actuated``  the same with f_BX's actuators in the loop
``wind_turbine``                  reduced NREL 5-MW turbine, eqs. 69, 77, 78, 80
``pedestrian_acc``                acceleration-constrained pedestrian, eq. 73
``pedestrian_vel``                velocity-constrained pedestrian, eq. 74
``diff_drive``                    differential-drive robot, section 7.3
================================  =====================================================

``get_model(name, **params)`` looks a model up by name (used by run files).
"""

from __future__ import annotations

import importlib

from reachconf.errors import ModelError

_REGISTRY = {
    "vanderpol": "reachconf.models.benchmarks",
    "laub_loomis": "reachconf.models.benchmarks",
    "bicycle": "reachconf.models.vehicle",
    "bicycle_actuated": "reachconf.models.vehicle",
    "bicycle_closed_loop": "reachconf.models.vehicle",
    "bicycle_closed_loop_actuated": "reachconf.models.vehicle",
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
    if ":" in name:
        module_name, attr = name.split(":", 1)
        try:
            obj = getattr(importlib.import_module(module_name), attr)
        except (ImportError, AttributeError) as exc:
            raise ModelError(f"cannot load model {name!r}: {exc}") from None
        model = obj(**params) if callable(obj) and not hasattr(obj, "f_expr") else obj
        if params and hasattr(obj, "f_expr"):
            model = obj.with_params(**params)
        return model
    if name not in _REGISTRY:
        raise ModelError(f"unknown model {name!r}; built-in models: {', '.join(available())}")
    factory = getattr(importlib.import_module(_REGISTRY[name]), name)
    return factory(**params)


def __getattr__(name):
    if name in _REGISTRY:
        return getattr(importlib.import_module(_REGISTRY[name]), name)
    raise AttributeError(f"module 'reachconf.models' has no attribute {name!r}")
