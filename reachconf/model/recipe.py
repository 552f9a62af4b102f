"""Models as build recipes: what a worker process receives, and the models it keeps.

:meth:`reachconf.model.core.Model.__reduce__` ships a model as its class, its
structure key, its parameter values and its pickled names and expressions.
:func:`rebuild_model` (run when a job is unpickled in a worker) keeps every
model it built by structure key, so a worker process builds and compiles each
model once, however many jobs carry it.
"""

from __future__ import annotations

import pickle
import threading
from collections import OrderedDict

__all__ = ["rebuild_model", "BUILT_MODELS_KEPT", "built_models"]

#: models a process keeps (with their compiled code) by structure key; the least recently used are dropped
BUILT_MODELS_KEPT = 64
_BUILT: OrderedDict = OrderedDict()
_BUILT_LOCK = threading.Lock()


def built_models() -> dict:
    """The models this process keeps: structure key -> model (a copy of the registry)."""
    with _BUILT_LOCK:
        return dict(_BUILT)


def rebuild_model(cls, key, params, recipe):
    """A model from its build recipe (what :meth:`Model.__reduce__` ships to worker processes).

    A process keeps the models it built (with what they compiled) by
    structure key, so a worker builds and compiles each model once however
    many jobs carry it; the parameter values of the job are applied to the
    kept model (no recompilation: parameters are run-time arguments).

    Parameters
    ----------
    cls : type
        The model's class.
    key : str
        :attr:`Model.structure_key`.
    params : dict
        Parameter values.
    recipe : bytes
        The pickled names and expressions.
    """
    with _BUILT_LOCK:
        model = _BUILT.get(key)
        if model is not None:
            _BUILT.move_to_end(key)
    if model is None:
        model = object.__new__(cls)
        state = pickle.loads(recipe)
        state["params"] = dict(params)
        model.__setstate__(state)
        with _BUILT_LOCK:
            model = _BUILT.setdefault(key, model)
            while len(_BUILT) > BUILT_MODELS_KEPT:
                _BUILT.popitem(last=False)
    if dict(model.params) != dict(params):
        model = model.with_params(**params)
    return model
