"""Command line: ``reachconf {demo,reach,conform,synth,pareto,diagnose,plot,warmup}``.

Everything a command needs is checked before the work starts, in this
order: the output paths (``--out`` is a folder or can be created, ``--json``
is a file name, both writable; both are locked so that a second run into
them fails at once), the run file, the test suite and the options.

Exit statuses:

=====  =====================================================================
0      done; every verdict decided (conformant or not conformant)
2      user error: one line ``reachconf: error: ...`` naming the file,
       argument, row or column (nothing was computed if it was found before
       the work)
3      done, but some verdict is *undecided* (a reach failed, a trace
       diverged); the summary and the JSON say which and why
4      no worker left (``reachconf.runner.WorkersLost``): the finished
       cases went to a new file, as with Ctrl-C
130    interrupted (Ctrl-C); partial results went to a new file
       (``<json>.partial.json`` or ``<out>/<command>.partial.json``), never
       over an earlier complete one
1      an internal error (a bug: please report the traceback)
=====  =====================================================================
"""

from __future__ import annotations

import argparse
import os
import signal
import sys
import threading
from pathlib import Path

from reachconf import commands
from reachconf.blas_threads import one_blas_thread
from reachconf.cli_cases import add_pool_options, apply_worker_timeout, pool_settings, positive_seconds
from reachconf.errors import DataError, ReachconfError

__all__ = ["main", "build_parser", "EXIT_OK", "EXIT_USER_ERROR", "EXIT_UNDECIDED", "EXIT_WORKERS_LOST",
           "EXIT_INTERRUPTED"]  # fmt: skip

EXIT_OK = 0
#: a user error (bad run file, data, options, output path)
EXIT_USER_ERROR = 2
#: finished, but at least one verdict is undecided (or a reach failed)
EXIT_UNDECIDED = 3
#: no worker left on the cluster (finished cases saved as with Ctrl-C)
EXIT_WORKERS_LOST = 4
#: Ctrl-C
EXIT_INTERRUPTED = 130


def _interrupted_at_start(signum, frame):  # pragma: no cover - exercised through a subprocess
    sys.stderr.write("reachconf: interrupted\n")
    raise SystemExit(EXIT_INTERRUPTED)  # unwinds the import in progress without a traceback


# Ctrl-C while Python imports numpy, scipy, numba (the first second of a run) must not print a traceback:
# when this module is the program, that handler is installed before anything heavy is imported; main()
# replaces it by the KeyboardInterrupt that saves partial results.
_PROGRAM = Path(sys.argv[0] if sys.argv else "")
if __name__ == "__main__" or _PROGRAM.stem == "reachconf" or _PROGRAM.parts[-2:] == ("reachconf", "__main__.py"):
    signal.signal(signal.SIGINT, _interrupted_at_start)


class _Run:
    """What a command has done so far: outputs, partial results (saved on Ctrl-C), undecided verdicts."""

    def __init__(self, args, outputs):
        self.args = args
        self.outputs = outputs
        self.partial = None  # results so far (a dict filled as the command goes)
        self.undecided = False


def _select_cases(spec, args, segments=True):
    """The run's cases (``--case``), cut into segments by ``--segment-length`` / ``--segment-step`` or the file's
    ``segment_length`` / ``segment_step`` (the flags win)."""
    from reachconf.runfile import check_segment_length, check_segment_step, select_cases

    suite = select_cases(spec.suite(), getattr(args, "case", None), spec.suite_path)
    length, step = getattr(args, "segment_length", None), getattr(args, "segment_step", None)
    if length is not None:
        length = check_segment_length(length, "--segment-length", spec.X0)
    length = length if length is not None else spec.segment_length
    if step is not None:
        step = check_segment_step(step, length, "--segment-step", "--segment-length or segment_length")
    elif spec.segment_step is not None and length is not None:
        step = check_segment_step(spec.segment_step, length, f"{spec.path}: segment_step", "segment_length")
    return suite.segments(length, step=step) if segments and length is not None else suite


def _load(args):
    from reachconf.runfile import load_run

    return load_run(args.run)


def _savefig(fig, path: Path):
    import matplotlib.pyplot as plt

    from reachconf.plot import save_figure

    save_figure(fig, path, dpi=120, bbox_inches=None)
    plt.close(fig)


# ----------------------------------------------------------------------------- commands


def cmd_demo(args, run):
    """``reachconf demo``: the main job on the shipped lane-change suite."""
    from reachconf.demo import run_demo

    workers, scheduler = pool_settings(args, None)
    summary = run_demo(run.outputs.folder, workers=workers, scheduler=scheduler)
    if args.json:
        run.outputs.write_json(args.json, summary)
    return EXIT_OK


#: cases with more samples than this show progress bars (Alg. 2 and a reach take seconds per 10,000 samples)
PROGRESS_SAMPLES = 10_000
#: reach tubes needing more than this are streamed (bounds of every step, sets of every k-th step kept)
STREAM_TUBE_BYTES = 512 * 2**20


def cmd_reach(args, run):
    """``reachconf reach RUN.toml``: reach tubes per test case (``.npz`` and X-Y pictures)."""
    import dataclasses

    import matplotlib.pyplot as plt

    from reachconf.cli_cases import map_cases, reach_case
    from reachconf.conformance.reachset import initial_set, reach_plan

    spec = _load(args)
    suite = _select_cases(spec, args)
    X0s = spec.initial_sets(suite) or {case.name: initial_set(spec.model, case, spec.V) for case in suite}
    out = run.outputs.folder
    # pre-flight: every case's memory before the first one starts; big tubes are streamed
    # streamed: when the tube would not fit in memory, or when a time limit may stop the case early
    plan = {case.name: reach_plan(spec.model, spec.reach_options, case, STREAM_TUBE_BYTES) or args.time_limit is not None
            for case in suite}  # fmt: skip
    results = run.partial = {}
    cases = {case.name: case for case in suite}

    def jobs(parallel):
        out_ = []
        for case in suite:
            ropts = spec.reach_options
            if ropts.progress is None and (parallel or case.t.size >= PROGRESS_SAMPLES):
                ropts = dataclasses.replace(ropts, progress=not parallel)  # no bars drawn by workers
            out_.append((spec.model, case, X0s[case.name], spec.W, ropts, plan[case.name], args.time_limit))
        return out_

    def on_result(name, res):
        case = cases[name]
        if "error" in res:
            run.undecided = True
            results[name] = {"failed": True, "message": res["error"], "seconds": res["seconds"]}
            print(f"{name}: reach failed: {' '.join(res['error'].split())}")
            return
        tube = res["tube"]
        entry = {"failed": False, "seconds": res["seconds"], "splits": tube.splits}
        if plan[name]:  # every step's bounds are in the .npz; the JSON gets their hull
            hull = tube.interval_hull()
            entry.update(streamed=True, keep_every=tube.keep_every, interval_hull=[hull.lo.tolist(), hull.hi.tolist()])
        else:
            entry["bounds"] = tube.bounds()
        if out is not None:
            entry["npz"] = str(tube.save(out / f"{name}_tube.npz"))
            fig, ax = plt.subplots(figsize=(8, 4))
            tube.plot(ax=ax, label="reach tube", measured=case)
            ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0)  # beside: no "best" search
            fig.tight_layout()
            _savefig(fig, out / f"{name}_tube.png")
            entry["png"] = str(out / f"{name}_tube.png")
        results[name] = entry
        print(f"{name}: reach over {case.duration:g} s in {entry['seconds']:.2f} s")

    map_cases(args, spec, reach_case, list(cases), jobs, on_result, desc="reach")
    _write_results(run, results, "reach.json")
    return EXIT_UNDECIDED if run.undecided else EXIT_OK


def _write_results(run, results, name):
    """``--json`` and ``<out>/name`` (strict JSON)."""
    if run.args.json:
        run.outputs.write_json(run.args.json, results)
    if run.outputs.folder is not None:
        run.outputs.write_json(run.outputs.folder / name, results)


def cmd_conform(args, run):
    """``reachconf conform RUN.toml``: trace and/or reachset conformance per test case."""
    from reachconf.budget import check_memory
    from reachconf.cli_cases import conform_case, map_cases
    from reachconf.conformance.reachset import reach_bytes_per_step, reach_step_count
    from reachconf.conformance.trace import trace_bytes_per_sample
    from reachconf.verdict import Verdict

    spec = _load(args)
    suite = _select_cases(spec, args)
    kinds = ["trace", "reachset"] if args.kind == "both" else [args.kind]
    if spec.W is None or spec.V is None:
        raise DataError(f"{spec.path}: {' and '.join(kinds)} conformance needs sets.W and sets.V")
    # pre-flight: every case's memory before the first one starts
    for case in suite:
        if "trace" in kinds:
            per, fixed = trace_bytes_per_sample(spec.model, spec.trace_options, spec.trace_method)
            check_memory(f"{spec.path}: trace conformance of case {case.name!r}", case.t.size, per, fixed)
        if "reachset" in kinds:
            per, fixed = reach_bytes_per_step(spec.model, spec.reach_options, False)
            check_memory(f"{spec.path}: reachset conformance of case {case.name!r} (the [reach] options' step count)",
                         reach_step_count(case.t, spec.reach_options), per, fixed)  # fmt: skip
    results = run.partial = {}
    X0s = spec.initial_sets(suite) or {}  # no entry: eq. 67

    def jobs(parallel):
        return [(spec.model, case, spec.W, spec.V, X0s.get(case.name), kinds, spec.trace_method, spec.trace_options,
                 spec.reach_options, False if parallel else (True if case.t.size >= PROGRESS_SAMPLES else None),
                 args.time_limit)
                for case in suite]  # fmt: skip

    def on_result(name, entry):
        parts = []
        for kind, e in entry.items():
            verdict = Verdict(e["verdict"])
            run.undecided |= verdict is Verdict.UNDECIDED
            why = f" ({' '.join(e['message'].split())})" if verdict is Verdict.UNDECIDED else ""
            parts.append(f"{kind}: {verdict.label}{why}")
        results[name] = entry  # complete cases only: a Ctrl-C saves these
        print(f"{name}: {', '.join(parts)}")

    map_cases(args, spec, conform_case, [case.name for case in suite], jobs, on_result, desc="conform")
    _write_results(run, results, "conformance.json")
    return EXIT_UNDECIDED if run.undecided else EXIT_OK


def cmd_synth(args, run):
    """``reachconf synth RUN.toml``: the minimal disturbance set (steps 1-3 and the merge)."""
    from reachconf.conformance.synthesis import synthesize_W
    from reachconf.verdict import Verdict

    spec = _load(args)
    if spec.V is None:
        raise DataError(f"{spec.path}: synthesis needs sets.V")
    suite = _select_cases(spec, args)
    workers, scheduler = pool_settings(args, spec)  # --scheduler overrides the file's workers
    res = synthesize_W(spec.model, suite, spec.V, spec.synthesis_options_for(suite), workers=workers, scheduler=scheduler)
    print(res.table())
    for c in res.cases.values():
        print(f"  {c.name}: alpha = {c.alpha:.4g}, W_RC {c.verdict.label}, {c.seconds:.2f} s"
              + (f" ({c.message})" if c.message else ""))  # fmt: skip
    if args.json:
        res.save(args.json)
    if run.outputs.folder is not None:
        res.save(run.outputs.folder / "synthesis.json")
        if res.groups:
            _savefig(res.plot()[0].figure, run.outputs.folder / "synthesis.png")
    return EXIT_UNDECIDED if res.verdict is Verdict.UNDECIDED else EXIT_OK


def cmd_diagnose(args, run):
    """``reachconf diagnose RUN.toml --json report.json --out DIR``: the sim-to-real gap diagnosis."""
    from reachconf.diagnose.pipeline import diagnose
    from reachconf.io.atomic import atomic_write
    from reachconf.runfile import diagnose_settings
    from reachconf.runner.pool import progress_shown

    spec = _load(args)
    suite = _select_cases(spec, args, segments=False)
    kwargs = diagnose_settings(spec, cases=getattr(args, "case", None))
    workers = args.workers if args.workers is not None else spec.workers
    report = diagnose(spec.model, suite, V=spec.V, progress=progress_shown(), workers=workers, **kwargs)
    if args.json:
        report.to_json(args.json)
    out = run.outputs.folder
    if out is not None:
        report.save(out / "report.json")
        atomic_write(out / "report.md", report.summary())
        report.save_plots(out)
    print(report.verdict)
    return EXIT_OK


# ----------------------------------------------------------------------------- parser


class _Parser(argparse.ArgumentParser):
    """argparse with the package's one-line errors (status 2)."""

    def error(self, message):
        self.exit(EXIT_USER_ERROR, f"reachconf: error: {self.prog.split()[-1]}: {message} (see --help)\n")


def build_parser() -> argparse.ArgumentParser:
    """The ``argparse`` parser of the command line (usage errors: one line, status 2)."""
    p = _Parser(prog="reachconf", description="Reachability-based conformance checking.",
                epilog="exit status: 0 done, 1 internal error (a bug), 2 user error, 3 some verdict undecided, "
                       "4 no worker left on the Dask cluster, 130 interrupted")  # fmt: skip
    sub = p.add_subparsers(dest="command", required=True, parser_class=_Parser)

    def common(sp, run=True, pool=True, out_required=False, time_limit=False):
        if run:
            sp.add_argument("run", help="TOML run file (model, suite, sets, options)")
            sp.add_argument("--case", action="append", help="only this test case (repeatable)")
        sp.add_argument("--json", help="write machine-readable results to this file")
        sp.add_argument("--out", required=out_required, help="folder for pictures and result files"
                        + (" (required)" if out_required else ""))  # fmt: skip
        if pool:  # (diagnose adds its own --workers: forked fit processes, no Dask scheduler)
            add_pool_options(sp, commands.positive_int)
        if time_limit:  # (only reach and conform can stop a case early)
            sp.add_argument("--time-limit", type=positive_seconds, default=None, dest="time_limit",
                            help="seconds per case and kind; a case projected to take longer stops after its first "
                                 "part (reach: the tube is then streamed, every step's bounds and at most 2000 "
                                 "sets kept)")  # fmt: skip
        if run and pool:
            sp.add_argument("--segment-length", type=positive_seconds, default=None, dest="segment_length",
                            help="check consecutive segments of this many seconds of each case, each from its "
                                 "own first sample (overrides the run file's segment_length)")  # fmt: skip
            sp.add_argument("--segment-step", type=positive_seconds, default=None, dest="segment_step",
                            help="start a segment every this many seconds (at most the length: overlapping "
                                 "windows; default the length)")  # fmt: skip

    sp = sub.add_parser("demo", help="run the main job on the shipped example suite")
    common(sp, run=False)
    sp.set_defaults(fn=cmd_demo)
    sp = sub.add_parser("reach", help="reach tubes per test case (npz + X-Y PNG)")
    common(sp, time_limit=True)
    sp.set_defaults(fn=cmd_reach)
    sp = sub.add_parser("conform", help="trace and/or reachset conformance per test case")
    common(sp, time_limit=True)
    sp.add_argument("--kind", choices=("trace", "reachset", "both"), default="both")
    sp.set_defaults(fn=cmd_conform)
    sp = sub.add_parser("synth", help="minimal disturbance set: steps 1-3 and the merge (Table 6)")
    common(sp)
    sp.set_defaults(fn=cmd_synth)
    sp = sub.add_parser("diagnose", help="sim-to-real gap: where it lies, which effect causes it, how far W shrinks")
    common(sp, pool=False)
    sp.add_argument("--workers", type=commands.positive_int, default=None,
                    help="processes for the candidates' fits (default: the run file's workers, else one per core, "
                         "at most 8)")  # fmt: skip
    sp.set_defaults(fn=cmd_diagnose, scheduler=None, worker_timeout=None)
    commands.add_commands(sub, common, {"warmup": commands.cmd_warmup, "pareto": lambda args, run: commands.cmd_pareto(
        args, run, _load, _select_cases, _savefig)})  # fmt: skip
    sp = sub.add_parser("plot", help="plot a result (tube .npz; conform, synthesis, Pareto or diagnosis JSON)")
    sp.add_argument("result")
    sp.add_argument("--out", help="folder for the PNG (default: next to the result)")
    sp.add_argument("--dims", nargs=2, help="two states of a tube (names or indices) or two outputs of a saved ReachsetResult")
    sp.set_defaults(fn=lambda args, run: commands.cmd_plot(args, run, _savefig), json=None)
    return p


# ----------------------------------------------------------------------------- main


def _one_line(exc) -> str:
    if isinstance(exc, ReachconfError):
        text = str(exc)
    else:  # an OSError about a path the user gave
        name = exc.filename if getattr(exc, "filename", None) else None
        reason = getattr(exc, "strerror", None) or str(exc) or type(exc).__name__
        text = f"{name}: {reason}" if name else reason
    return "reachconf: error: " + " ".join(text.split())


def _outputs(args):
    from reachconf.io.output import RunOutputs, check_not_input, check_output_folder
    from reachconf.runfile import input_paths

    if args.command == "plot":  # one picture next to the result or in --out: checked, not locked
        if args.out is not None:
            check_output_folder(args.out)
        return RunOutputs("plot", folder=args.out)
    folder = args.out if args.out is not None or args.command != "demo" else "demo"
    files, folders = input_paths(args.run) if getattr(args, "run", None) else ([], [])
    for path, option in ((folder, "--out"), (args.json, "--json")):
        if path is not None:
            check_not_input(path, option, files, folders)
    return RunOutputs(args.command, folder=folder, json=args.json).open()


def _save_partial(run, exc) -> str:
    """Partial results to a new file; the message tail for stderr."""
    from reachconf.io.jsonfile import to_jsonable

    done = getattr(exc, "partial", None)  # reachconf.runner.Interrupted: the jobs finished so far
    partial = run.partial if done is None else [r for r in done if r is not None]
    if not partial:
        return "; no results finished yet"
    data = {"interrupted": True, "complete": False, "command": run.args.command, "partial": to_jsonable(partial)}
    target = run.outputs.save_partial(data)
    if target is None:
        return "; partial results not saved (no --json or --out given)"
    return f"; partial results in {target}"


def _handle_interrupt(run, exc, lost=False) -> int:
    old = signal.signal(signal.SIGINT, signal.SIG_IGN) if _in_main_thread() else None
    try:
        tail = _save_partial(run, exc)
    except ReachconfError as err:
        tail = f"; partial results not saved: {err}"
    finally:
        if old is not None:
            signal.signal(signal.SIGINT, old)
    print(f"{_one_line(exc) if lost else 'reachconf: interrupted'}{tail}", file=sys.stderr)
    return EXIT_WORKERS_LOST if lost else EXIT_INTERRUPTED


def _in_main_thread() -> bool:
    return threading.current_thread() is threading.main_thread()


def _on_ctrl_c(signum, frame):  # any error after this counts as the interruption (_caused_by_ctrl_c)
    _on_ctrl_c.pressed = True
    if frame is not None and _swallows_exceptions(frame):  # raised here it would be printed and ignored, the run
        os.kill(os.getpid(), signal.SIGINT)  # going on: deliver it again once that code has returned
        return
    raise KeyboardInterrupt


def _swallows_exceptions(frame) -> bool:
    """Is ``frame`` code whose exceptions Python prints and ignores (a weakref callback of the import system, as
    when Ctrl-C comes while numpy is imported; a ``__del__``)?"""
    code = frame.f_code
    return code.co_name == "__del__" or (code.co_name == "cb" and code.co_filename.startswith("<frozen importlib"))


def _caused_by_ctrl_c(exc: BaseException) -> bool:
    """Did Ctrl-C cause ``exc``?  Inside compiled code (numba, a solver, numpy importing ``datetime``) it
    surfaces as a SystemError, ImportError or library error that may not carry the KeyboardInterrupt."""
    from reachconf.script import caused_by_ctrl_c

    return bool(getattr(_on_ctrl_c, "pressed", False)) or caused_by_ctrl_c(exc)


def main(argv=None) -> int:
    """Run the command line; returns the exit status (see the module docstring)."""
    os.environ.setdefault("MPLBACKEND", "Agg")
    _on_ctrl_c.pressed = False
    previous = signal.signal(signal.SIGINT, _on_ctrl_c) if _in_main_thread() else None
    run = None
    try:
        try:
            args = build_parser().parse_args(argv)
        except SystemExit as exc:  # --help (0) or a usage error (2, printed by _Parser.error)
            return exc.code if isinstance(exc.code, int) else EXIT_USER_ERROR
        run = _Run(args, None)
        apply_worker_timeout(args)
        run.outputs = _outputs(args)  # checked and locked before anything is computed
        try:
            with one_blas_thread():  # small matrices: OpenBLAS's idle threads only take cores from the work
                return args.fn(args, run)
        except Exception as exc:
            if type(exc).__name__ == "WorkersLost":  # reachconf.runner.WorkersLost: keep the finished cases
                return _handle_interrupt(run, exc, lost=True)
            if not _caused_by_ctrl_c(exc):
                raise
            return _handle_interrupt(run, exc)
        except KeyboardInterrupt as exc:
            return _handle_interrupt(run, exc)
        finally:
            run.outputs.close()
    except BaseException as exc:
        if isinstance(exc, KeyboardInterrupt) or (isinstance(exc, Exception) and _caused_by_ctrl_c(exc)):
            print("reachconf: interrupted", file=sys.stderr)  # while checking the arguments: nothing to save
            return EXIT_INTERRUPTED
        if isinstance(exc, (ReachconfError, OSError)):
            print(_one_line(exc), file=sys.stderr)
            return EXIT_USER_ERROR
        raise
    finally:
        if previous is not None:
            signal.signal(signal.SIGINT, previous)


if __name__ == "__main__":
    sys.exit(main())
