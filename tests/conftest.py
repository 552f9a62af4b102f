"""Shared pytest configuration."""

import os
from pathlib import Path

os.environ.setdefault("MPLBACKEND", "Agg")

REPO_ROOT = Path(__file__).resolve().parents[1]
DATA_ROOT = Path(os.environ.get("REACHCONF_DATA", REPO_ROOT.parent / "shared" / "data"))
