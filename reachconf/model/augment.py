"""Models made from other models: additive disturbances on every state equation."""

from __future__ import annotations

import sympy as sp

from reachconf.errors import ModelError
from reachconf.model.core import Model

__all__ = ["with_state_disturbances"]


def with_state_disturbances(model, prefix: str = "w_"):
    """A copy of ``model`` with an additive disturbance on every state equation: ``x_i' = f_i(x, u, w) + w_<x_i>``.

    The conformance model of a system written without disturbances (a kinematic robot, say): ``W`` then bounds the
    error of each state equation (eq. 4), and :func:`reachconf.diagnose` has a gap box to diagnose.

    Parameters
    ----------
    model : reachconf.Model
    prefix : str
        The new disturbances are named ``prefix + state``.

    Returns
    -------
    reachconf.Model
        Named ``<model.name>_w``; the model's own disturbances come first.

    Raises
    ------
    ModelError
        If a new name is already used by the model.
    """
    added = tuple(f"{prefix}{s}" for s in model.state_names)
    used = set(model.state_names + model.input_names + model.disturbance_names + model.param_names)
    taken = sorted(set(added) & used)
    if taken:
        raise ModelError(f"model {model.name!r}: with_state_disturbances: the names {taken} are taken; pass another "
                         "prefix")  # fmt: skip
    w = [sp.Symbol(n, real=True) for n in added]
    return Model(model.state_names, [e + wi for e, wi in zip(model.f_expr, w)], inputs=model.input_names,
                 disturbances=model.disturbance_names + added, params=dict(model.params),
                 outputs=dict(zip(model.output_names, model.h_expr)), name=f"{model.name}_w",
                 description=model.description)  # fmt: skip
