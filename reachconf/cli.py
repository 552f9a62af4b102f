"""Command line: ``reachconf {demo,reach,conform,synth,diagnose,plot}``.

User errors (bad run file, data, options, sets) print one line and exit
with status 2; Ctrl-C saves the partial results and exits with 130.
"""

from __future__ import annotations

import argparse
import inspect
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

from reachconf.errors import DataError, ReachconfError

__all__ = ["main"]


def _write_json(path, obj):
    from reachconf.io.atomic import atomic_write

    atomic_write(path, json.dumps(obj, indent=2, default=_jsonable))


def _jsonable(v):
    if isinstance(v, np.ndarray):
        return v.tolist()
    if isinstance(v, (np.floating, np.integer, np.bool_)):
        return v.item()
    if hasattr(v, "to_list"):
        return v.to_list()
    return str(v)


def _outdir(args) -> Path | None:
    if args.out is None:
        return None
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    return out


def _savefig(fig, path: Path):
    from reachconf.plot import save_figure

    save_figure(fig, path, dpi=120, bbox_inches=None)


# ----------------------------------------------------------------------------- commands


def cmd_demo(args):
    """``reachconf demo``: the main job on the shipped lane-change suite."""
    from reachconf.demo import run_demo

    summary = run_demo(args.out or "demo", workers=args.workers)
    if args.json:
        _write_json(args.json, summary)
    return 0


def _select_cases(spec, args):
    suite = spec.suite()
    if getattr(args, "case", None):
        names = {c.name for c in suite}
        missing = [c for c in args.case if c not in names]
        if missing:
            raise DataError(f"{spec.suite_path}: no test case {missing}; cases: {sorted(names)}")
        suite = suite.select(names=args.case)
    return suite


def cmd_reach(args):
    """``reachconf reach RUN.toml``: reach tubes per test case (``.npz`` and X-Y pictures)."""
    import matplotlib.pyplot as plt

    from reachconf.conformance.reachset import initial_set
    from reachconf.reach import reach

    spec = _load(args)
    suite = _select_cases(spec, args)
    out = _outdir(args)
    results = {}
    for case in suite:
        X0 = spec.X0 if spec.X0 is not None else initial_set(spec.model, case, spec.V)
        t0 = time.perf_counter()
        tube = reach(spec.model, X0, case.t - case.t[0], inputs=case.U if spec.model.m else None, W=spec.W,
                     options=spec.reach_options)  # fmt: skip
        entry = {"seconds": time.perf_counter() - t0, "bounds": tube.bounds().tolist(), "splits": tube.splits}
        if out is not None:
            entry["npz"] = str(tube.save(out / f"{case.name}_tube.npz"))
            fig, ax = plt.subplots(figsize=(8, 4))
            tube.plot(ax=ax, label="reach tube", measured=case)
            ax.legend()
            fig.tight_layout()
            _savefig(fig, out / f"{case.name}_tube.png")
            plt.close(fig)
            entry["png"] = str(out / f"{case.name}_tube.png")
        results[case.name] = entry
        print(f"{case.name}: reach over {case.duration:g} s in {entry['seconds']:.2f} s")
    if args.json:
        _write_json(args.json, results)
    return 0


def cmd_conform(args):
    """``reachconf conform RUN.toml``: trace and/or reachset conformance per test case."""
    from reachconf.conformance.reachset import reachset_conformance
    from reachconf.conformance.trace import trace_conformance

    spec = _load(args)
    suite = _select_cases(spec, args)
    kinds = ["trace", "reachset"] if args.kind == "both" else [args.kind]
    results = {}
    for case in suite:
        entry = {}
        if "trace" in kinds:
            if spec.W is None or spec.V is None:
                raise DataError(f"{spec.path}: trace conformance needs sets.W and sets.V")
            res = trace_conformance(spec.model, case, spec.W, spec.V, method=spec.trace_method,
                                    options=spec.trace_options)  # fmt: skip
            entry["trace"] = {"conformant": res.conformant, "margins": res.margins, "seconds": res.seconds,
                              "message": res.message}  # fmt: skip
        if "reachset" in kinds:
            if spec.W is None or spec.V is None:
                raise DataError(f"{spec.path}: reachset conformance needs sets.W and sets.V")
            res = reachset_conformance(spec.model, case, spec.W, spec.V, X0=spec.X0, options=spec.reach_options,
                                       keep_tube=False)  # fmt: skip
            entry["reachset"] = {"conformant": res.conformant, "first_violation_time": res.first_violation_time,
                                 "max_violation": res.max_violation, "seconds": res.seconds,
                                 "message": res.message}  # fmt: skip
        results[case.name] = entry
        verdicts = ", ".join(f"{k}: {'conformant' if v['conformant'] else 'NOT conformant'}" for k, v in entry.items())
        print(f"{case.name}: {verdicts}")
    if args.json:
        _write_json(args.json, results)
    return 0


def cmd_synth(args):
    """``reachconf synth RUN.toml``: the minimal disturbance set (steps 1-3 and the merge)."""
    import matplotlib.pyplot as plt

    from reachconf.conformance.synthesis import synthesize_W

    spec = _load(args)
    if spec.V is None:
        raise DataError(f"{spec.path}: synthesis needs sets.V")
    suite = _select_cases(spec, args)
    res = synthesize_W(spec.model, suite, spec.V, spec.synthesis_options, workers=args.workers or spec.workers,
                       scheduler=args.scheduler)  # fmt: skip
    print(res.table())
    for c in res.cases.values():
        print(f"  {c.name}: alpha = {c.alpha:.4g}, reachset conformant: {c.conformant}, {c.seconds:.2f} s"
              + (f" ({c.message})" if c.message else ""))  # fmt: skip
    if args.json:
        res.to_json(args.json)
    out = _outdir(args)
    if out is not None:
        res.save(out / "synthesis.json")
        fig = res.plot()[0].figure
        _savefig(fig, out / "synthesis.png")
        plt.close(fig)
    return 0


def cmd_plot(args):
    """``reachconf plot FILE``: draw a saved result (tube ``.npz`` or result ``.json``)."""
    import matplotlib.pyplot as plt

    path = Path(args.result)
    if not path.is_file():
        raise DataError(f"{path}: no such result file")
    out = _outdir(args) or path.parent
    result = _load_result(path)
    kwargs = {}
    if args.dims:
        if "dims" not in inspect.signature(result.plot).parameters:
            raise DataError(f"{path}: --dims applies to tubes and reachset results, not to a {type(result).__name__}")
        kwargs["dims"] = tuple(int(d) if d.isdigit() else d for d in args.dims)
    ax = np.atleast_1d(result.plot(**kwargs))[0]
    target = out / (path.stem + ".png")
    _savefig(ax.figure, target)
    plt.close(ax.figure)
    print(f"wrote {target}")
    return 0


def _load_result(path: Path):
    """A saved result by its file: a tube ``.npz``, or a result ``.json`` (by its ``"result"`` key or its fields)."""
    from reachconf.conformance.pareto import ParetoFront
    from reachconf.conformance.reachset import ReachsetResult
    from reachconf.conformance.synthesis import SynthesisResult
    from reachconf.conformance.trace import TraceResult
    from reachconf.diagnose.locate import GapLocation
    from reachconf.diagnose.report import GapReport
    from reachconf.io.results import read_json
    from reachconf.tube import ReachTube

    if path.suffix == ".npz":
        return ReachTube.load(path)
    if path.suffix != ".json":
        raise DataError(f"{path}: unsupported result type {path.suffix!r} (use a tube .npz or a result .json)")
    d = read_json(path)
    types = {c.__name__: c for c in (SynthesisResult, ParetoFront, TraceResult, ReachsetResult, GapReport, GapLocation)}
    kind = d.get("result")
    if kind is None:  # files written before results carried their type
        kind = "SynthesisResult" if "groups" in d and "disturbances" in d else "ParetoFront" if "front" in d else None
    if kind not in types:
        raise DataError(f"{path}: not a reachconf result that can be plotted (keys {sorted(d)[:6]})")
    return types[kind].load(path)


def cmd_diagnose(args):
    """``reachconf diagnose RUN.toml --json report.json --out DIR``: the sim-to-real gap diagnosis."""
    from reachconf.diagnose.pipeline import diagnose
    from reachconf.io.cases import TestSuite
    from reachconf.runfile import diagnose_settings

    spec = _load(args)
    suite = spec.suite()
    if args.case:
        cases = [c for c in suite if c.name in set(args.case)]
        missing = sorted(set(args.case) - {c.name for c in cases})
        if missing:
            raise DataError(f"{spec.path}: no test cases named {missing} in {spec.suite_path}")
        suite = TestSuite(cases)
    kwargs = diagnose_settings(spec)
    report = diagnose(spec.model, suite, V=spec.V, **kwargs)
    out = _outdir(args)
    if args.json:
        report.to_json(args.json)
    if out is not None:
        from reachconf.io.atomic import atomic_write

        report.save(out / "report.json")
        atomic_write(out / "report.md", report.summary())
        report.save_plots(out)
    print(report.verdict)
    return 0


def _load(args):
    from reachconf.runfile import load_run

    return load_run(args.run)


# ----------------------------------------------------------------------------- parser


def build_parser() -> argparse.ArgumentParser:
    """The ``argparse`` parser of the command line."""
    p = argparse.ArgumentParser(prog="reachconf", description="Reachability-based conformance checking.")
    sub = p.add_subparsers(dest="command", required=True)

    def common(sp, run=True):
        if run:
            sp.add_argument("run", help="TOML run file (model, suite, sets, options)")
            sp.add_argument("--case", action="append", help="only this test case (repeatable)")
        sp.add_argument("--json", help="write machine-readable results to this file")
        sp.add_argument("--out", help="folder for pictures and result files")
        sp.add_argument("--workers", type=int, default=None, help="local worker processes")
        sp.add_argument("--scheduler", default=None, help="Dask scheduler address tcp://host:port")

    sp = sub.add_parser("demo", help="run the main job on the shipped example suite")
    common(sp, run=False)
    sp.set_defaults(fn=cmd_demo)
    sp = sub.add_parser("reach", help="reach tubes per test case (npz + X-Y PNG)")
    common(sp)
    sp.set_defaults(fn=cmd_reach)
    sp = sub.add_parser("conform", help="trace and/or reachset conformance per test case")
    common(sp)
    sp.add_argument("--kind", choices=("trace", "reachset", "both"), default="both")
    sp.set_defaults(fn=cmd_conform)
    sp = sub.add_parser("synth", help="minimal disturbance set: steps 1-3 and the merge (Table 6)")
    common(sp)
    sp.set_defaults(fn=cmd_synth)
    sp = sub.add_parser("diagnose", help="sim-to-real gap: where it lies, which effect causes it, how far W shrinks")
    common(sp)
    sp.set_defaults(fn=cmd_diagnose)
    sp = sub.add_parser("plot", help="plot a result (tube .npz, synthesis or Pareto JSON)")
    sp.add_argument("result")
    sp.add_argument("--out", help="folder for the PNG (default: next to the result)")
    sp.add_argument("--dims", nargs=2, help="two states of a tube (names or indices) or outputs of a reachset result")
    sp.set_defaults(fn=cmd_plot)
    return p


def main(argv=None) -> int:
    """Run the command line with ``argv`` (default ``sys.argv[1:]``); returns the exit status (0, 2 on user errors, 130 on Ctrl-C)."""
    os.environ.setdefault("MPLBACKEND", "Agg")
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return args.fn(args)
    except KeyboardInterrupt as exc:
        partial = getattr(exc, "partial", None)
        if partial is not None and getattr(args, "json", None):
            _write_json(args.json, {"interrupted": True, "partial": [getattr(r, "to_dict", lambda: r)() if r is not None else None for r in partial]})
        print("reachconf: interrupted" + (f"; partial results in {args.json}" if partial is not None and getattr(args, "json", None) else ""),
              file=sys.stderr)  # fmt: skip
        return 130
    except ReachconfError as exc:
        print(f"reachconf: error: {' '.join(str(exc).split())}", file=sys.stderr)
        return 2
    except OSError as exc:  # unreadable/unwritable files given by the user
        print(f"reachconf: error: {exc.filename or ''}: {exc.strerror or exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
