"""Shared pytest configuration."""

import importlib.util
import os
from pathlib import Path

os.environ.setdefault("MPLBACKEND", "Agg")

REPO_ROOT = Path(__file__).resolve().parents[1]
DATA_ROOT = Path(os.environ.get("REACHCONF_DATA", REPO_ROOT.parent / "shared" / "data"))


def load_example(name: str):
    """Import ``examples/<name>/run.py`` as a module."""
    spec = importlib.util.spec_from_file_location(f"{name}_run", REPO_ROOT / "examples" / name / "run.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod
