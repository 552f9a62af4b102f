"""The model and everything that evaluates it: symbolic definition, generated code, outputs, simulation.

* :mod:`reachconf.model.core` — :class:`Model` (``x' = f(x, u, w; p)``,
  ``y = h(x, u; p) + v``, written once in sympy) and :class:`Symbols`;
* :mod:`reachconf.model.codegen` — derivatives and their interval
  enclosures, generated, compiled with numba and cached on disk
  (:func:`compile_model`), printed by :mod:`reachconf.model.printers`;
* :mod:`reachconf.model.outputs` — the model evaluated on data: the output
  map on traces and on sets, state estimates from measured outputs;
* :mod:`reachconf.model.simulate` — :func:`simulate` (compiled RK4, the one
  simulation entry point) and the reference :func:`simulate_ivp`;
* :mod:`reachconf.model.worst_case` — :func:`worst_case`, the trajectory that
  drives a function of the state furthest (an inner bound of the reachable set);
* :mod:`reachconf.model.modal` — :func:`modal_form`, a linear model in real
  modal coordinates (where a stiff, non-normal system's reach does not explode);
* :mod:`reachconf.model.augment` — :func:`with_state_disturbances`, a model with
  an additive disturbance on every state equation.
"""

from reachconf.model.augment import with_state_disturbances
from reachconf.model.codegen import CompiledModel, cache_dir, compile_model
from reachconf.model.core import Model, Symbols
from reachconf.model.modal import ModalForm, modal_form
from reachconf.model.outputs import (
    affine_output,
    evaluate_outputs,
    output_enclosure,
    output_index_of_states,
    state_estimate,
    state_index_of_outputs,
)
from reachconf.model.simulate import simulate, simulate_ivp
from reachconf.model.worst_case import WorstCase, worst_case

__all__ = ["Model", "Symbols", "CompiledModel", "compile_model", "cache_dir", "simulate", "simulate_ivp",
           "affine_output", "evaluate_outputs", "output_enclosure", "output_index_of_states", "state_estimate",
           "state_index_of_outputs", "WorstCase", "worst_case", "ModalForm", "modal_form", "with_state_disturbances"]  # fmt: skip
