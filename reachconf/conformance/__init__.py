"""Conformance checking (source report sections 3–4).

Trace conformance (Alg. 1 with the per-step fit or Alg. 2), reachset
conformance (eqs. 42/43), the three-step synthesis of a minimal disturbance
set (section 4.3.2) and the Pareto front of conformant boxes.
"""

from reachconf.conformance.bounds import minimal_trace_bounds, minimize_box
from reachconf.conformance.trace import (
    TraceOptions,
    TraceResult,
    state_estimate,
    trace_conformance,
    trace_disturbances,
)

__all__ = [
    "TraceOptions",
    "TraceResult",
    "trace_conformance",
    "trace_disturbances",
    "state_estimate",
    "minimize_box",
    "minimal_trace_bounds",
]

try:  # written by the synthesis engineer; optional until it lands
    from reachconf.conformance.reachset import *  # noqa: F401,F403
    from reachconf.conformance.reachset import __all__ as _rs_all

    __all__ += list(_rs_all)
except ImportError:  # pragma: no cover
    pass
try:
    from reachconf.conformance.synthesis import *  # noqa: F401,F403
    from reachconf.conformance.synthesis import __all__ as _sy_all

    __all__ += list(_sy_all)
except ImportError:  # pragma: no cover
    pass
try:
    from reachconf.conformance.pareto import *  # noqa: F401,F403
    from reachconf.conformance.pareto import __all__ as _pa_all

    __all__ += list(_pa_all)
except ImportError:  # pragma: no cover
    pass
