"""Conformance checking (source report sections 3–4).

* :mod:`reachconf.conformance.trace` — trace conformance (Alg. 1 with the
  per-step fit of section 3.2.1 or Alg. 2);
* :mod:`reachconf.conformance.optctrl` — Alg. 2's optimal-control QP and the
  box SCP (sparse banded QPs, Clarabel);
* :mod:`reachconf.conformance.windows` — trace conformance window by window
  (long cases in bounded memory, ``method="auto"``, the streamed verdict);
* :mod:`reachconf.conformance.bounds` — smallest trace-conformant boxes
  (synthesis step 2, Tables 3/4);
* :mod:`reachconf.conformance.reachset` — reachset conformance (eqs. 42/43, 67);
* :mod:`reachconf.conformance.synthesis` — the three-step synthesis of a
  minimal disturbance set (section 4.3.2) and the merge per maneuver;
* :mod:`reachconf.conformance.pareto` — the Pareto front of conformant boxes.
"""

from reachconf.conformance.bounds import CaseBox, case_box, minimal_trace_bounds, minimize_box
from reachconf.conformance.pareto import ParetoFront, pareto_front, plot_front_dict
from reachconf.conformance.reachset import ReachsetResult, initial_set, reachset_conformance
from reachconf.conformance.synthesis import (
    CaseSynthesis,
    SynthesisOptions,
    SynthesisResult,
    alpha_search,
    reachset_check,
    synthesize_W,
)
from reachconf.conformance.trace import (
    TraceOptions,
    TraceResult,
    simulate_verdict,
    state_estimate,
    trace_conformance,
    trace_disturbances,
)

__all__ = [
    "TraceOptions",
    "TraceResult",
    "trace_conformance",
    "trace_disturbances",
    "simulate_verdict",
    "state_estimate",
    "minimize_box",
    "minimal_trace_bounds",
    "case_box",
    "CaseBox",
    "ReachsetResult",
    "reachset_conformance",
    "initial_set",
    "SynthesisOptions",
    "CaseSynthesis",
    "SynthesisResult",
    "synthesize_W",
    "alpha_search",
    "reachset_check",
    "ParetoFront",
    "pareto_front",
    "plot_front_dict",
]
