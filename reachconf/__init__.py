"""reachconf: is your model of a cyber-physical system conformant to the real one?

Reachability-first conformance checking: interval and zonotope set kernels
(:mod:`reachconf.sets`), symbolic models with compiled derivatives
(:mod:`reachconf.model`), sound nonlinear reachability (:mod:`reachconf.reach`),
trace and reachset conformance with minimal disturbance-set synthesis
(:mod:`reachconf.conformance`) and sim-to-real gap diagnosis
(:mod:`reachconf.diagnose`).

Every public name is imported when it is first used, so ``import reachconf``
stays cheap.  ``reachconf.reach`` and ``reachconf.diagnose`` are the
functions; their modules of the same names stay importable
(``from reachconf.reach import ReachOptions``, ``from reachconf.diagnose import scales``; not
``import reachconf.diagnose.scales as s``, which meets the function).  Modules that moved keep
their old import paths (``reachconf.simulate``, ``reachconf.campaign``, ...).
"""

from __future__ import annotations

import importlib
import importlib.abc
import importlib.util
import sys
import types

from reachconf.errors import (
    ConformanceError,
    DataError,
    ModelError,
    OptionsError,
    ReachconfError,
    ReachError,
    ResourceError,
    SetArgumentError,
    SetError,
    SolverError,
)

# public name -> module that defines it
_LAZY = {
    "Interval": "reachconf.sets.core",
    "Zonotope": "reachconf.sets.core",
    "SetUnion": "reachconf.sets.union",
    "BoxDisk": "reachconf.sets.disk",
    "as_box": "reachconf.sets.convert",
    "as_zonotope": "reachconf.sets.convert",
    "Model": "reachconf.model.core",
    "simulate": "reachconf.model.simulate",
    "worst_case": "reachconf.model.worst_case",
    "modal_form": "reachconf.model.modal",
    "with_state_disturbances": "reachconf.model.augment",
    "reach": "reachconf.reach",
    "reach_run": "reachconf.reach",
    "reach_streamed": "reachconf.reach_stream",
    "ReachOptions": "reachconf.reach_options",
    "AdaptiveReach": "reachconf.reach_options",
    "ReachTube": "reachconf.tube",
    "models": "reachconf.models",
    "load_suite": "reachconf.io.files",
    "save_suite": "reachconf.io.files",
    "TestSuite": "reachconf.io.cases",
    "TestCase": "reachconf.io.cases",
    "atomic_write": "reachconf.io.atomic",
    "trace_conformance": "reachconf.conformance.trace",
    "trace_disturbances": "reachconf.conformance.trace",
    "TraceOptions": "reachconf.conformance.trace",
    "TraceResult": "reachconf.conformance.trace",
    "minimal_trace_bounds": "reachconf.conformance.bounds",
    "case_box": "reachconf.conformance.bounds",
    "reachset_conformance": "reachconf.conformance.reachset",
    "ReachsetResult": "reachconf.conformance.reachset",
    "synthesize_W": "reachconf.conformance.synthesis",
    "SynthesisOptions": "reachconf.conformance.synthesis",
    "SynthesisResult": "reachconf.conformance.synthesis",
    "pareto_front": "reachconf.conformance.pareto",
    "ParetoFront": "reachconf.conformance.pareto",
    "diagnose": "reachconf.diagnose.pipeline",
    "DiagnoseOptions": "reachconf.diagnose.options",
    "GapReport": "reachconf.diagnose.report",
    "locate_gap": "reachconf.diagnose.locate",
    "identify": "reachconf.diagnose.identify",
    "Pool": "reachconf.runner.pool",
    "WorkersLost": "reachconf.runner.tasks",
    "Interrupted": "reachconf.runner.tasks",
    "warm_up": "reachconf.warmup",
}

#: old module path -> the module's home since the layout of issue 14 (the old paths keep working)
MOVED_MODULES = {
    "reachconf.codegen": "reachconf.model.codegen",
    "reachconf.output_map": "reachconf.model.outputs",
    "reachconf.simulate": "reachconf.model.simulate",
    "reachconf.containment": "reachconf.sets.containment",
    "reachconf.campaign": "reachconf.datasets.vehicle_campaign",
    "reachconf.campaign.controller": "reachconf.models.vehicle_controller",
    "reachconf.campaign.maneuvers": "reachconf.datasets.vehicle_campaign.maneuvers",
    "reachconf.campaign.plant": "reachconf.datasets.vehicle_campaign.plant",
    "reachconf.campaign.generate": "reachconf.datasets.vehicle_campaign.generate",
}

__all__ = [
    "__version__",
    "ReachconfError",
    "SetError",
    "SetArgumentError",
    "ModelError",
    "ReachError",
    "DataError",
    "ConformanceError",
    "SolverError",
    "OptionsError",
    "ResourceError",
    *_LAZY,
]


def __getattr__(name):
    if name == "__version__":
        from importlib import metadata

        try:
            value = metadata.version("reachconf")
        except metadata.PackageNotFoundError:  # pragma: no cover - a plain source checkout
            value = "0+unknown"
    else:
        module_name = _LAZY.get(name)
        if module_name is None:
            raise AttributeError(f"module 'reachconf' has no attribute {name!r}")
        module = importlib.import_module(module_name)
        value = module if name == "models" else getattr(module, name)
    globals()[name] = value
    return value


def __dir__():
    return sorted(set(globals()) | set(_LAZY))


class _Package(types.ModuleType):
    """``reachconf`` itself: importing the module ``reachconf.reach`` (or the package ``reachconf.diagnose``)
    must not replace the function of the same name on the package, which the import system would do."""

    def __setattr__(self, name, value):
        if name in ("reach", "diagnose") and isinstance(value, types.ModuleType):
            return  # the module stays in sys.modules; the package attribute is the function
        super().__setattr__(name, value)


class _MovedModuleFinder(importlib.abc.MetaPathFinder, importlib.abc.Loader):
    """Resolves the old module paths of :data:`MOVED_MODULES` to the modules themselves (no copies)."""

    def find_spec(self, fullname, path=None, target=None):
        if fullname in MOVED_MODULES:
            return importlib.util.spec_from_loader(fullname, self)
        return None

    def create_module(self, spec):
        module = importlib.import_module(MOVED_MODULES[spec.name])
        self._spec = module.__spec__  # the import system overwrites it with the alias spec: restored below
        return module

    def exec_module(self, module):
        module.__spec__ = self._spec


sys.modules[__name__].__class__ = _Package
if not any(isinstance(f, _MovedModuleFinder) for f in sys.meta_path):
    sys.meta_path.insert(0, _MovedModuleFinder())
