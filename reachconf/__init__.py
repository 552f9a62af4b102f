"""reachconf: is your model of a cyber-physical system conformant to the real one?

Reachability-first conformance checking: interval and zonotope set kernels
(:mod:`reachconf.sets`), symbolic models with compiled derivatives
(:mod:`reachconf.model`), sound nonlinear reachability (:mod:`reachconf.reach`),
trace and reachset conformance with minimal disturbance-set synthesis
(:mod:`reachconf.conformance`) and sim-to-real gap diagnosis
(:mod:`reachconf.diagnose`).

Public names are imported lazily so that ``import reachconf`` stays cheap.
"""

from __future__ import annotations

import importlib

from reachconf.errors import (
    ConformanceError,
    DataError,
    ModelError,
    OptionsError,
    ReachconfError,
    ReachError,
    SetError,
    SolverError,
)

__version__ = "0.1.0"

# ``reach`` is both a module and its main function: import it eagerly so that
# the function, not the submodule, is the package attribute.
from reachconf.reach import ReachOptions, reach  # noqa: E402

# ``diagnose`` likewise: the function (``reachconf.diagnose(model, suite)``), its package stays importable
from reachconf.diagnose import DiagnoseOptions, GapReport, diagnose, locate_gap  # noqa: E402

# public name -> module that defines it
_LAZY = {
    "Interval": "reachconf.sets",
    "Zonotope": "reachconf.sets",
    "Model": "reachconf.model",
    "ReachTube": "reachconf.tube",
    "models": "reachconf.models",
    "load_suite": "reachconf.io",
    "save_suite": "reachconf.io",
    "TestSuite": "reachconf.io",
    "TestCase": "reachconf.io",
    "trace_conformance": "reachconf.conformance",
    "TraceResult": "reachconf.conformance",
    "minimal_trace_bounds": "reachconf.conformance",
    "reachset_conformance": "reachconf.conformance",
    "synthesize_W": "reachconf.conformance",
    "SynthesisResult": "reachconf.conformance",
    "pareto_front": "reachconf.conformance",
}

__all__ = [
    "__version__",
    "ReachconfError",
    "SetError",
    "ModelError",
    "ReachError",
    "DataError",
    "ConformanceError",
    "SolverError",
    "OptionsError",
    "reach",
    "ReachOptions",
    "diagnose",
    "DiagnoseOptions",
    "GapReport",
    "locate_gap",
    *_LAZY,
]


def __getattr__(name):
    module_name = _LAZY.get(name)
    if module_name is None:
        raise AttributeError(f"module 'reachconf' has no attribute {name!r}")
    module = importlib.import_module(module_name)
    value = module if name == "models" and module_name == "reachconf.models" else getattr(module, name)
    globals()[name] = value
    return value


def __dir__():
    return sorted(set(globals()) | set(_LAZY))
