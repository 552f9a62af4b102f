"""Saved results by their file, for ``reachconf plot``: tubes, result files and ``conform``'s verdicts."""

from __future__ import annotations

from pathlib import Path

from reachconf.errors import DataError
from reachconf.plot import VerdictSummary

__all__ = ["load_drawable"]


def load_drawable(path):
    """A saved result by its file: a tube ``.npz``, or a result ``.json`` (by its ``"result"`` key or its fields)."""
    from reachconf.conformance.pareto import ParetoFront
    from reachconf.conformance.reachset import ReachsetResult
    from reachconf.conformance.synthesis import SynthesisResult
    from reachconf.conformance.trace import TraceResult
    from reachconf.diagnose.locate import GapLocation
    from reachconf.diagnose.report import GapReport
    from reachconf.io.results import read_json
    from reachconf.tube import ReachTube

    path = Path(path)
    if path.suffix == ".npz":
        return ReachTube.load(path)
    if path.suffix != ".json":
        raise DataError(f"{path}: unsupported result type {path.suffix!r} (use a tube .npz or a result .json)")
    d = read_json(path)
    types = {c.__name__: c for c in (SynthesisResult, ParetoFront, TraceResult, ReachsetResult, GapReport, GapLocation)}
    kind = d.get("result")
    if kind is None:  # files written before results carried their type; conform's and reach's per-case summaries
        kind = "SynthesisResult" if "groups" in d and "disturbances" in d else "ParetoFront" if "front" in d else None
    if kind is None and (summary := VerdictSummary.from_dict(d)) is not None:  # reachconf conform's conformance.json
        return summary
    if not isinstance(kind, str) or kind not in types:
        raise DataError(f"{path}: not a reachconf result that can be plotted (keys {sorted(d)[:6]}); plot a tube .npz "
                        f"(reachconf reach --out), a conformance, synthesis, Pareto or diagnosis .json")  # fmt: skip
    return types[kind].load(path)
