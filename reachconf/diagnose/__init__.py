"""Sim-to-real gap diagnosis: where the gap lies, which unmodelled effect causes it, how far W shrinks.

* :mod:`reachconf.diagnose.pipeline` — :func:`diagnose`, the whole pipeline
  (``reachconf.diagnose(model, suite)``);
* :mod:`reachconf.diagnose.locate` — *where*: :func:`locate_gap`,
  :class:`GapLocation`;
* :mod:`reachconf.diagnose.effects` — the library of candidate effects
  (:data:`EFFECTS`, :class:`Effect`, :func:`register_effect`);
* :mod:`reachconf.diagnose.options` — :class:`DiagnoseOptions`;
* :mod:`reachconf.diagnose.fit` — joint least-squares fits by multi-step
  prediction, cluster-robust covariances;
* :mod:`reachconf.diagnose.select` — cross-fitting, held-out paired tests and
  the naming rule; :mod:`reachconf.diagnose.probes` — the maneuver that would
  separate two explanations; :mod:`reachconf.diagnose.verdict` — its record and text;
* :mod:`reachconf.diagnose.howfar` — minimal boxes and reach tubes before/after;
* :mod:`reachconf.diagnose.identify` — :func:`identify`, least-squares
  identification of model parameters (multi-step prediction or equation error);
* :mod:`reachconf.diagnose.sparse` — the model-free sparse-regression check;
* :mod:`reachconf.diagnose.report` — :class:`GapReport`, the result.
"""

from reachconf.diagnose.effects import EFFECTS, Effect, register_effect
from reachconf.diagnose.identify import Identification, identify
from reachconf.diagnose.locate import GapLocation, locate_gap
from reachconf.diagnose.options import DiagnoseOptions
from reachconf.diagnose.pipeline import diagnose
from reachconf.diagnose.report import GapReport
from reachconf.diagnose.tyres import TIRE_FIALA  # noqa: F401 - registers the tyre effect

__all__ = ["diagnose", "DiagnoseOptions", "GapReport", "GapLocation", "locate_gap", "EFFECTS", "Effect",
           "register_effect", "identify", "Identification"]  # fmt: skip
