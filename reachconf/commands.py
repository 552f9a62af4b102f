"""Command-line commands of the scale-out, ``reachconf pareto`` and ``reachconf warmup``, and ``reachconf plot``.

``reachconf pareto RUN.toml --out DIR [--workers N | --scheduler ADDR]``
samples the Pareto front of conformant disturbance boxes
(:func:`reachconf.conformance.pareto.pareto_front`) and writes ``front.json``
and ``front.png`` into ``DIR``.  It starts from the run file's ``sets.W``;
without one, the synthesis runs first (on the same workers) and the front
starts from the smallest box holding every group's ``W_RC,Mnvr`` (also saved,
as ``synthesis.json``).  Every check of every case is a task of the run's one
pool.  ``reachconf plot FILE`` draws a saved result.

``reachconf warmup MODEL|RUN.toml ... [--scheduler ADDR]`` builds and compiles
what runs of the models need, here and on every worker of a Dask cluster
(:func:`reachconf.warmup.warm_up`).

The flow is :func:`reachconf.cli.main`'s: outputs checked and locked first,
then the run file, the scheduler address (form and a TCP probe) and the
options, all before the first expensive call.
"""

from __future__ import annotations

import argparse

from reachconf.errors import DataError, OptionsError

__all__ = ["cmd_pareto", "cmd_warmup", "add_commands", "pareto_start", "positive_int"]


def pareto_start(synthesis):
    """The smallest box holding every group's ``W_RC,Mnvr`` (every case's ``W_RC`` without a merge)."""
    import numpy as np

    from reachconf.sets.core import Interval

    boxes = list(synthesis.groups.values()) or [c.W_RC for c in synthesis.cases.values()]
    return Interval(np.min([b.lo for b in boxes], axis=0), np.max([b.hi for b in boxes], axis=0))


def cmd_pareto(args, run, load, select_cases, savefig):
    """``reachconf pareto RUN.toml --out DIR``: the Pareto front of conformant boxes (``front.json``, ``front.png``).

    ``load``, ``select_cases`` and ``savefig`` are the command line's run-file
    loader, case selection and figure writer.
    """
    from reachconf.conformance.pareto import pareto_front
    from reachconf.conformance.synthesis import PRELOAD, synthesize_W
    from reachconf.cli_cases import pool_settings
    from reachconf.runner import Pool

    if run.outputs.folder is None:
        raise OptionsError("pareto: --out DIR is required (front.json and front.png go there)")
    pool_settings(args, None)  # the address and the flags, before the run file
    spec = load(args)
    if spec.V is None:
        raise DataError(f"{spec.path}: the Pareto front needs sets.V")
    suite = select_cases(spec, args)
    options = spec.synthesis_options_for(suite)  # [sets] X0 or unmeasured per case
    out = run.outputs.folder
    run.partial = {}
    workers, scheduler = pool_settings(args, spec)  # --scheduler overrides the file's workers
    with Pool(workers, scheduler, preload=PRELOAD) as pool:
        print(f"workers: {pool.describe()}", flush=True)
        start = spec.W
        if start is not None:
            print("start: the run file's [sets] W (every box keeps its centre; without W: the synthesis's boxes)")
        if start is None:
            synth = synthesize_W(spec.model, suite, spec.V, options, pool=pool)
            synth.save(out / "synthesis.json")
            run.partial["synthesis"] = synth.to_dict()
            start = pareto_start(synth)
            print(f"start: the hull of the synthesis's boxes ({synth.seconds:.1f} s; merge {synth.merge_seconds:.1f} s)")
        front = pareto_front(spec.model, suite, spec.V, start, check=args.check, iterations=args.iterations,
                             options=options, pool=pool)  # fmt: skip
    front.save(out / "front.json")
    savefig(front.plot().figure, out / "front.png")
    names = front.disturbance_names
    for box, order in zip(front.boxes, front.orders):
        widths = ", ".join(f"{names[i]} {w:.4g}" for i, w in enumerate(box.hi - box.lo))
        print(f"order {list(order)}: widths {widths}")
    for line in front.log:
        print(f"  workers: {line}")
    print(f"wrote {out / 'front.json'} and {out / 'front.png'} ({len(front.boxes)} non-dominated boxes)")
    return 0


def cmd_warmup(args, run):
    """``reachconf warmup MODEL|RUN.toml ...``: build and compile ahead of runs, here and on a cluster's workers."""
    from reachconf.runner import check_scheduler
    from reachconf.warmup import warm_up

    check_scheduler(args.scheduler)
    report = warm_up(args.targets, scheduler=args.scheduler, orders=tuple(args.orders))
    if args.json:
        run.outputs.write_json(args.json, report)
    return 0


#: more bisection steps than this cannot change a float64 bound (2**-60 of the range)
MAX_BISECTION_STEPS = 60


def cmd_plot(args, run, savefig):
    """``reachconf plot FILE``: draw a saved result (tube ``.npz`` or result ``.json``)."""
    import inspect
    from pathlib import Path

    import numpy as np

    from reachconf.checks import require_file
    from reachconf.drawable import load_drawable

    path = Path(args.result)
    require_file(path, "result file")
    out = run.outputs.folder or path.parent
    result = load_drawable(path)
    kwargs = {}
    if args.dims:
        if "dims" not in inspect.signature(result.plot).parameters:
            raise DataError(f"{path}: --dims applies to a tube (<case>_tube.npz of reachconf reach) or a saved "
                            f"ReachsetResult, not to a {type(result).__name__}, which holds no sets to project")
        kwargs["dims"] = tuple(int(d) if d.isdigit() else d for d in args.dims)
    try:
        ax = np.atleast_1d(result.plot(**kwargs))[0]
    except (ValueError, IndexError, KeyError, TypeError, AttributeError) as exc:  # parts that do not fit together
        raise DataError(f"{path}: cannot be drawn ({type(exc).__name__}: {exc})") from None
    target = out / (path.stem + ".png")
    savefig(ax.figure, target)
    print(f"wrote {target}")
    return 0


def bisection_steps(text):
    """``--iterations``: an int in 1..MAX_BISECTION_STEPS (``argparse`` type; a one-line usage error otherwise)."""
    value = positive_int(text)
    if value > MAX_BISECTION_STEPS:
        raise argparse.ArgumentTypeError(f"must be at most {MAX_BISECTION_STEPS} (a float64 bound cannot change "
                                         f"after that many halvings), got {value}")  # fmt: skip
    return value


def positive_int(text):
    """An option's value as an int >= 1 (``argparse`` type; a one-line usage error otherwise)."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be a positive integer, got {text!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be a positive integer, got {value}")
    return value


def add_commands(sub, common, handlers):
    """Add ``pareto`` and ``warmup`` to the subparsers ``sub``; ``common(sp)`` adds the shared options.

    ``handlers`` maps ``"pareto"`` and ``"warmup"`` to the functions the
    parsed arguments call (``args.fn``).
    """
    sp = sub.add_parser("pareto", help="Pareto front of conformant disturbance boxes (front.json, front.png)")
    common(sp, out_required=True)
    sp.add_argument("--check", choices=("reachset", "trace"), default="reachset", help="conformance notion")
    sp.add_argument("--iterations", type=bisection_steps, default=8,
                    help=f"bisection steps per channel, 1..{MAX_BISECTION_STEPS} (default 8)")  # fmt: skip
    sp.set_defaults(fn=handlers["pareto"])
    sp = sub.add_parser("warmup", help="build and compile models ahead of runs, here and on a Dask cluster's workers")
    sp.add_argument("targets", nargs="+", metavar="MODEL|RUN.toml", help="model names or run files")
    sp.add_argument("--scheduler", default=None, help="Dask scheduler address tcp://host:port")
    sp.add_argument("--orders", type=int, nargs="+", choices=(2, 3), default=[2, 3],
                    help="tensor orders to build for model names (default: 2 3)")  # fmt: skip
    sp.add_argument("--json", help="write the timings to this file")
    sp.set_defaults(fn=handlers["warmup"], out=None, workers=None)
