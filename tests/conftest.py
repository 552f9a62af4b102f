"""Shared pytest configuration and fixtures.

The test folders mirror the package: ``kernels/`` (reachconf_kernels),
``sets/``, ``model/``, ``io/``, ``reach/``, ``conformance/``, ``diagnose/``,
``datasets/``, ``cli/``; ``usecases/`` runs the examples (one command each) on
reduced data; ``test_architecture.py`` checks the package's imports and sizes.
Test file names are unique across folders (the folders are not packages).
"""

import importlib.util
import os
from pathlib import Path

import pytest

os.environ.setdefault("MPLBACKEND", "Agg")

REPO_ROOT = Path(__file__).resolve().parents[1]
DATA_ROOT = Path(os.environ.get("REACHCONF_DATA", REPO_ROOT.parent / "shared" / "data"))


def load_example(name: str):
    """Import ``examples/<name>/run.py`` as a module."""
    spec = importlib.util.spec_from_file_location(f"{name}_run", REPO_ROOT / "examples" / name / "run.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


@pytest.fixture(scope="session")
def repo_root() -> Path:
    """The repository's root folder."""
    return REPO_ROOT


@pytest.fixture(scope="session")
def data_root() -> Path:
    """The shared real-data folder (``$REACHCONF_DATA`` or ``../shared/data``)."""
    return DATA_ROOT
