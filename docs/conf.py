"""Sphinx configuration of the reachconf documentation (built by .ci/run with warnings as errors)."""

import os
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
os.environ.setdefault("MPLBACKEND", "Agg")

project = "reachconf"
author = "the reachconf developers"
copyright = "2026, " + author
try:
    from importlib.metadata import version as _version

    release = _version("reachconf")
except Exception:  # pragma: no cover - a plain source checkout
    release = "0.1.0"

extensions = ["sphinx.ext.autodoc", "sphinx.ext.autosummary", "sphinx.ext.napoleon", "sphinx.ext.mathjax"]
autosummary_generate = True
autosummary_imported_members = False
autodoc_default_options = {"members": True, "undoc-members": False, "show-inheritance": True, "ignore-module-all": True}
autodoc_member_order = "bysource"
autodoc_typehints = "none"
napoleon_google_docstring = False
napoleon_numpy_docstring = True
napoleon_use_rtype = False
napoleon_use_ivar = True  # attributes as fields: dataclass fields are not described twice
templates_path = ["_templates"]
exclude_patterns = ["_build"]
html_theme = "alabaster"
html_static_path = []
# "more than one target": type fields link every word, e.g. the "p" of "ndarray (K, p)" to Model.p and Track.p
suppress_warnings = ["autosummary.import_cycle", "ref.python"]
