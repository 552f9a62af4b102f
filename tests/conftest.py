"""Shared pytest configuration and fixtures.

The test folders mirror the package: ``kernels/`` (reachconf_kernels),
``sets/``, ``model/``, ``io/``, ``reach/``, ``conformance/``, ``diagnose/``,
``datasets/``, ``cli/``; ``usecases/`` runs the examples (one command each) on
reduced data; ``test_architecture.py`` checks the package's imports and sizes.
Test file names are unique across folders (the folders are not packages).
"""

import importlib.util
import json
import math
import os
from pathlib import Path

import pytest

os.environ.setdefault("MPLBACKEND", "Agg")
# every xdist worker is a process per core already: a diagnosis forks no fit workers of its own there
# (tests/diagnose/test_parallel.py asks for them explicitly)
if os.environ.get("PYTEST_XDIST_WORKER"):
    os.environ.setdefault("REACHCONF_DIAGNOSE_WORKERS", "1")

REPO_ROOT = Path(__file__).resolve().parents[1]
DATA_ROOT = Path(os.environ.get("REACHCONF_DATA", REPO_ROOT.parent / "shared" / "data"))


def load_example(name: str):
    """Import ``examples/<name>/run.py`` as a module."""
    spec = importlib.util.spec_from_file_location(f"{name}_run", REPO_ROOT / "examples" / name / "run.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


@pytest.hookimpl(optionalhook=True)
def pytest_xdist_auto_num_workers(config) -> int | None:
    """Workers for ``-n auto`` (``pyproject.toml``'s ``addopts``): one per core, but at most one per 3 GiB of memory
    and at most 8 — each worker holds its own compiled kernels and models (up to about 2 GiB) and, on an empty
    cache, compiles them again.  ``PYTEST_XDIST_AUTO_NUM_WORKERS`` set: xdist's own choice (that number)."""
    if os.environ.get("PYTEST_XDIST_AUTO_NUM_WORKERS"):
        return None
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
    try:
        memory = os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (AttributeError, ValueError, OSError):  # not a POSIX system: count the cores only
        memory = cores * 3 * 2**30
    return max(1, min(cores, int(memory // (3 * 2**30)), 8))


@pytest.fixture(scope="session")
def repo_root() -> Path:
    """The repository's root folder."""
    return REPO_ROOT


@pytest.fixture(scope="session")
def data_root() -> Path:
    """The shared real-data folder (``$REACHCONF_DATA`` or ``../shared/data``)."""
    return DATA_ROOT


def toml_value(v) -> str:
    """A TOML value (str, number incl. nan/inf, bool, list, inline table) for the fuzz tests."""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (int, float)):
        return repr(v) if math.isfinite(v) else ("nan" if math.isnan(v) else ("inf" if v > 0 else "-inf"))
    if isinstance(v, str):
        return json.dumps(v, ensure_ascii=False)
    if isinstance(v, list):
        return "[" + ", ".join(toml_value(x) for x in v) + "]"
    return "{" + ", ".join(f"{json.dumps(k)} = {toml_value(x)}" for k, x in v.items()) + "}"


def toml_text(doc: dict) -> str:
    """A minimal TOML writer for fuzzed documents (tables as [sections], nested ones inline)."""
    plain = [f"{json.dumps(k)} = {toml_value(v)}" for k, v in doc.items() if not isinstance(v, dict)]
    tables = [f"[{json.dumps(k)}]\n" + "\n".join(f"{json.dumps(a)} = {toml_value(b)}" for a, b in v.items())
              for k, v in doc.items() if isinstance(v, dict)]  # fmt: skip
    return "\n".join(plain + tables) + "\n"


@pytest.fixture
def scored():
    """``scored(parts, losses)``: a diagnosis model scored on held-out windows, from ``[(effect, target), ...]``
    and its per-window losses (``reachconf.diagnose.select.Scored``)."""
    import numpy as np

    from reachconf.diagnose import EFFECTS
    from reachconf.diagnose.fit import Candidate
    from reachconf.diagnose.select import Scored

    def make(parts, losses):
        return Scored(Candidate(tuple((EFFECTS[e], t) for e, t in parts)), np.asarray(losses, float))

    return make
