"""Reachability benchmark: Van der Pol, Laub-Loomis, closed-loop bicycle (issue: nonlinear engine).

Prints, with the settings used: verdict, time (warm cache, best of ``--repeat``)
and final width, next to Flow* 2.1.0's CPU times measured on this machine type
(``../shared/research/peers.md``).  Run::

    python benchmarks/bench_reach.py [--repeat 3] [--profile]
    python benchmarks/bench_reach.py --adaptive   # default-vs-tuned table (ReachOptions(): "adaptive")
    python benchmarks/bench_reach.py --adaptive-heldout   # the defaults on instances not used to tune them
    python benchmarks/bench_reach.py --tightness   # the defaults' final boxes against the worst cases (rc.worst_case)

The first run of a fresh checkout also compiles the kernels and models
(printed separately as "warm-up"); the figures are for warm caches.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

import reachconf as rc
from reachconf.models import laub_loomis, vanderpol

FLOWSTAR = {
    "vanderpol": "4.0 s (TM order 5, symbolic remainders; 7.4 s at order 6)",
    "laub_loomis W=0.01": "not reported",
    "laub_loomis W=0.05": "461 s (symbolic remainders only)",
    "laub_loomis W=0.1": "not reported (18 s on newer hardware/version per its site)",
}


def _best(fn, repeat):
    best, result = np.inf, None
    for _ in range(repeat):
        t0 = time.perf_counter()
        result = fn()
        best = min(best, time.perf_counter() - t0)
    return best, result


VDP_OPTIONS = rc.ReachOptions(
    algorithm="lin", tensor_order=3, time_step=0.01, taylor_terms=4, zonotope_order=20, error_order=10,
    max_error=0.03, max_splits=64, split_method="generator",
)  # fmt: skip


def bench_vanderpol(repeat):
    model = vanderpol(mu=1.0)
    X0 = rc.Interval([1.25, 2.35], [1.55, 2.45])

    def run():
        return rc.reach(model, X0, 7.0, options=VDP_OPTIONS)

    run()  # warm-up
    seconds, tube = _best(run, repeat)
    ymax = tube.bounds()[:, 1, 1].max()
    fin = tube.final_set().interval()
    return {
        "benchmark": "vanderpol mu=1, T=7, y<2.75",
        "verified": bool(ymax < 2.75),
        "seconds": seconds,
        "detail": f"max y = {ymax:.4f}; final width x {fin.hi[0] - fin.lo[0]:.4f}, y {fin.hi[1] - fin.lo[1]:.4f}; "
        f"splits {tube.splits}",
        "flowstar": FLOWSTAR["vanderpol"],
        "settings": VDP_OPTIONS,
    }


LL_OPTIONS = {
    0.01: rc.ReachOptions(algorithm="lin", tensor_order=2, time_step=0.02, zonotope_order=20),
    0.05: rc.ReachOptions(algorithm="lin", tensor_order=3, time_step=0.02, zonotope_order=20, error_order=5),
    0.1: rc.ReachOptions(algorithm="lin", tensor_order=3, time_step=0.005, zonotope_order=50, error_order=10,
                         max_error=0.3, max_splits=64),
}  # fmt: skip


def bench_laub_loomis(repeat):
    model = laub_loomis()
    x0 = np.array([1.2, 1.05, 1.5, 2.4, 1.0, 0.1, 0.45])
    rows = []
    for W, opts in LL_OPTIONS.items():
        X0 = rc.Interval(x0 - W, x0 + W)
        spec = 4.5 if W < 0.1 else 5.0

        def run():
            return rc.reach(model, X0, 20.0, options=opts)

        try:
            run()
            seconds, tube = _best(run, repeat)
            x4max = tube.bounds()[:, 1, 3].max()
            fin = tube.final_set().interval()
            rows.append({
                "benchmark": f"laub_loomis W={W}, T=20, x4<{spec}",
                "verified": bool(x4max < spec),
                "seconds": seconds,
                "detail": f"max x4 = {x4max:.4f}; final width x4 {fin.hi[3] - fin.lo[3]:.4f}; splits {tube.splits}",
                "flowstar": FLOWSTAR[f"laub_loomis W={W}"],
                "settings": opts,
            })
        except rc.ReachError as exc:
            rows.append({"benchmark": f"laub_loomis W={W}", "verified": False, "seconds": float("nan"),
                         "detail": f"ReachError: {exc}", "flowstar": FLOWSTAR[f"laub_loomis W={W}"],
                         "settings": opts})  # fmt: skip
    return rows


def closed_loop_lc_problem():
    """The closed-loop bicycle's 8-s lane change: ``(model, X0, times, inputs, W, options)``."""
    from reachconf.datasets.vehicle_campaign import reference_path
    from reachconf.models import bicycle_closed_loop

    model = bicycle_closed_loop()
    ref = reference_path("LC", 2.0, 10.0)
    t = np.round(np.arange(0.0, 8.0 + 1e-9, 0.01), 10)  # 8 s: the path, then straight on
    U = np.column_stack([np.interp(t, ref["t"], ref[k]) for k in model.input_names])
    U[:, 0] = np.where(t > ref["t"][-1], ref["X_ref"][-1] + 10.0 * (t - ref["t"][-1]), U[:, 0])
    x0 = np.array([0.0, 0.0, 0.0, 10.0, 0.0, 0.0])
    X0 = rc.Interval(x0 - [0.05, 0.05, np.radians(0.5), 0.1, 0.1, np.radians(0.8)],
                     x0 + [0.05, 0.05, np.radians(0.5), 0.1, 0.1, np.radians(0.8)])  # Table 5 errors
    # Table 6, LC row (w1..w6)
    W = rc.Interval([-0.0831, -0.1173, -0.0593, -0.3203, -0.1503, -0.4414],
                    [0.0552, 0.0274, 0.0678, 0.7775, 0.1051, 0.7231])  # fmt: skip
    opts = rc.ReachOptions(algorithm="lin", tensor_order=3, time_step=0.01, zonotope_order=20)
    return model, X0, t[::2], U[::2], W, opts  # 50 Hz samples (time-point sets), 0.01 s steps


def bench_closed_loop_bicycle(repeat):
    try:
        model, X0, times, Us, W, opts = closed_loop_lc_problem()
    except ImportError as exc:  # pragma: no cover - campaign not available
        return {"benchmark": "closed-loop bicycle", "verified": None, "seconds": float("nan"),
                "detail": f"skipped: {exc}", "flowstar": "-", "settings": None}  # fmt: skip

    def run():
        return rc.reach(model, X0, times, inputs=Us, W=W, options=opts)

    try:
        run()
        seconds, tube = _best(run, repeat)
        fin = tube.final_set().interval()
        detail = (f"8 s lane change at 10 m/s, Table 6 LC box; final width X {fin.hi[0] - fin.lo[0]:.3f} m, "
                  f"Y {fin.hi[1] - fin.lo[1]:.3f} m; splits {tube.splits}")  # fmt: skip
        ok = True
    except rc.ReachError as exc:
        seconds, detail, ok = float("nan"), f"ReachError: {exc}", False
    return {"benchmark": "closed-loop bicycle LC 8 s (per reach)", "verified": ok, "seconds": seconds,
            "detail": detail, "flowstar": "-", "settings": opts}  # fmt: skip


# ----------------------------------------------- the defaults (no hand tuning) against the hand-tuned settings
#: ``ReachOptions()`` untouched: ``algorithm="adaptive"``
ADAPTIVE = rc.ReachOptions()
assert isinstance(ADAPTIVE.alg, rc.AdaptiveReach)


def adaptive_instances():
    """``(name, model, X0, times, inputs, W, verified(tube) -> (bool, str), tuned options or None)`` per instance."""
    from reachconf.models import coupled_vanderpol

    x0 = np.array([1.2, 1.05, 1.5, 2.4, 1.0, 0.1, 0.45])

    def below(dims, limit, label):
        def check(tube):
            top = tube.bounds()[:, 1, dims].max()
            return bool(top < limit), f"max {label} = {top:.4f} (< {limit})"

        return check

    rows = [
        ("vanderpol mu=1, T=7", vanderpol(1.0), rc.Interval([1.25, 2.35], [1.55, 2.45]), 7.0, None, None,
         below([1], 2.75, "y"), VDP_OPTIONS),
        ("vanderpol mu=2, T=8", vanderpol(2.0), rc.Interval([1.55, 2.35], [1.85, 2.45]), 8.0, None, None,
         below([1], 4.0, "y"), None),
        ("coupled vanderpol mu=1, T=7", coupled_vanderpol(1.0),
         rc.Interval([1.25, 2.35, 1.25, 2.35], [1.55, 2.45, 1.55, 2.45]), 7.0, None, None,
         below([1, 3], 2.75, "y1, y2"), None),
    ]
    for W, opts in LL_OPTIONS.items():
        spec = 4.5 if W < 0.1 else 5.0
        rows.append((f"laub_loomis W={W}, T=20", laub_loomis(), rc.Interval(x0 - W, x0 + W), 20.0, None, None,
                     below([3], spec, "x4"), opts))  # fmt: skip
    try:
        model, X0, times, Us, Wcl, opts = closed_loop_lc_problem()

        def finished(tube):
            fin = tube.final_set().interval()
            return True, f"final width X {fin.hi[0] - fin.lo[0]:.3f} m, Y {fin.hi[1] - fin.lo[1]:.3f} m"

        rows.append(("closed-loop bicycle LC 8 s", model, X0, times, Us, Wcl, finished, opts))
    except ImportError:  # pragma: no cover - campaign not available
        pass
    return rows


def _timed(run, repeat):
    """``(CPU seconds best of repeat, wall seconds best of repeat, tube or ReachError)`` after one warm-up run."""
    try:
        run()
    except rc.ReachError as exc:
        return float("nan"), float("nan"), exc
    cpu, wall, tube = np.inf, np.inf, None
    for _ in range(repeat):
        c0, w0 = time.process_time(), time.perf_counter()
        tube = run()
        cpu, wall = min(cpu, time.process_time() - c0), min(wall, time.perf_counter() - w0)
    return cpu, wall, tube


def bench_adaptive(repeat):
    """Default-vs-tuned table: ``ReachOptions()`` untouched ("adaptive") against the hand-tuned settings."""
    print(f"{'instance':30s} {'tuned':>22s} {'defaults':>22s} {'ratio':>6s}   (CPU s, best of {repeat}, warm)")
    rows = []
    for name, model, X0, times, U, W, check, tuned in adaptive_instances():
        cells = []
        for opts in (tuned, ADAPTIVE):
            if opts is None:
                cells.append((float("nan"), None, "no hand-tuned setting"))
                continue
            cpu, wall, res = _timed(lambda o=opts: rc.reach(model, X0, times, inputs=U, W=W, options=o), repeat)
            if isinstance(res, rc.ReachError):
                cells.append((cpu, False, f"ReachError: {str(res)[:160]}"))
            else:
                ok, detail = check(res)
                if res.log is not None:
                    detail += f"; {res.log.steps} steps, splits {res.splits}"
                cells.append((cpu, ok, detail))
        ratio = cells[1][0] / cells[0][0] if cells[0][1] and cells[1][1] else float("nan")
        fmt = lambda c: f"{c[0]:7.3f} {'verified' if c[1] else ('FAILED' if c[1] is False else '-'):>9s}"  # noqa: E731
        print(f"{name:30s} {fmt(cells[0]):>22s} {fmt(cells[1]):>22s} {ratio:6.2f}")
        print(f"    tuned:    {cells[0][2]}")
        print(f"    adaptive: {cells[1][2]}")
        rows.append((name, cells, ratio))
    return rows


def lin_search_grid():
    """The hand-tuning tried for the instances without a tuned setting: 60 ``"lin"`` settings (tensor order 3)."""
    grid = [dict(time_step=dt, max_error=me, max_splits=ms, zonotope_order=20, error_order=10, split_method="generator")
            for dt in (0.01, 0.005, 0.0025) for me in (0.03, 0.01) for ms in (64, 256)]
    grid += [dict(time_step=dt, max_error=me, max_splits=256, zonotope_order=zo, error_order=eo, split_method=sm)
             for dt in (0.005, 0.002) for me in (0.003, 0.001, 0.0003) for zo in (20, 50) for eo in (10, 20)
             for sm in ("generator", "box")]
    return [rc.ReachOptions(algorithm="lin", tensor_order=3, taylor_terms=4, **g) for g in grid]


def search_lin():
    """Try :func:`lin_search_grid` on every default-vs-tuned instance that has no hand-tuned setting."""
    for name, model, X0, times, U, W, check, tuned in adaptive_instances():
        if tuned is not None:
            continue
        found = 0
        for opts in lin_search_grid():
            c0 = time.process_time()
            try:
                ok, detail = check(rc.reach(model, X0, times, inputs=U, W=W, options=opts))
            except rc.ReachError as exc:
                ok, detail = False, f"ReachError: {str(exc)[:110]}"
            found += ok
            print(f"{name}: dt {opts.time_step}, max_error {opts.max_error}, max_splits {opts.max_splits}, "
                  f"orders {opts.zonotope_order}/{opts.error_order}, {opts.split_method}: "
                  f"{'VERIFIED' if ok else 'no'} ({detail}; {time.process_time() - c0:.1f} s CPU)", flush=True)
        print(f"{name}: {found} of {len(lin_search_grid())} settings verified\n", flush=True)


def heldout_instances():
    """``(name, model, X0, horizon, state index)``: instances not used to choose the adaptive algorithm's rules."""
    from reachconf.models import coupled_vanderpol

    x0 = np.array([1.2, 1.05, 1.5, 2.4, 1.0, 0.1, 0.45])
    return [
        ("vanderpol mu=0.5 [1.25,1.55]x[2.35,2.45] T=7", vanderpol(0.5), rc.Interval([1.25, 2.35], [1.55, 2.45]), 7.0, 1),
        ("vanderpol mu=1.5 [1.4,1.7]x[2.35,2.45] T=8", vanderpol(1.5), rc.Interval([1.4, 2.35], [1.7, 2.45]), 8.0, 1),
        ("vanderpol mu=2 [1.0,1.2]x[2.0,2.1] T=8", vanderpol(2.0), rc.Interval([1.0, 2.0], [1.2, 2.1]), 8.0, 1),
        ("vanderpol mu=1 [1.0,1.4]x[2.2,2.4] T=7", vanderpol(1.0), rc.Interval([1.0, 2.2], [1.4, 2.4]), 7.0, 1),
        ("coupled vanderpol mu=1, 2nd box [1.3,1.6]x[2.3,2.4] T=7", coupled_vanderpol(1.0),
         rc.Interval([1.25, 2.35, 1.3, 2.3], [1.55, 2.45, 1.6, 2.4]), 7.0, 3),
        ("laub_loomis W=0.02, T=20", laub_loomis(), rc.Interval(x0 - 0.02, x0 + 0.02), 20.0, 3),
        ("laub_loomis W=0.08, T=20", laub_loomis(), rc.Interval(x0 - 0.08, x0 + 0.08), 20.0, 3),
    ]  # fmt: skip


def bench_adaptive_heldout(repeat):
    """The untouched adaptive algorithm on :func:`heldout_instances`: CPU s, largest value of the state, splits."""
    print(f"{'instance':56s} {'adaptive':>9s}   (CPU s, best of {repeat}, warm; largest value of the state)")
    for name, model, X0, horizon, i in heldout_instances():
        cpu, _, res = _timed(lambda m=model, X=X0, T=horizon: rc.reach(m, X, T, options=ADAPTIVE), repeat)
        if isinstance(res, rc.ReachError):
            print(f"{name:56s} ReachError: {str(res)[:160]}")
            continue
        print(f"{name:56s} {cpu:9.3f}   max {model.state_names[i]} = {res.bounds()[:, 1, i].max():.4f}; "
              f"{res.log.steps} steps, splits {res.splits}, budgets {[float(b) for b in res.log.budgets_tried]}")


def bench_tightness():
    """Each instance's default tube at its end against the worst case (``rc.worst_case``: a simulated trajectory).

    Per state: the width of the final time-point set's box over the width the model really reaches (its largest
    and smallest value found over X0 and W, an inner bound); 1.00 would be exact.
    """
    print(f"{'instance':30s} final box width / worst-case width per state (defaults; worst case: rc.worst_case)")
    for name, model, X0, times, U, W, _, _ in adaptive_instances():
        try:
            tube = rc.reach(model, X0, times, inputs=U, W=W, options=ADAPTIVE)
        except rc.ReachError as exc:
            print(f"{name:30s} ReachError: {str(exc)[:120]}")
            continue
        grid = np.asarray(times, dtype=float) if np.ndim(times) else np.linspace(0.0, float(times), 701)
        box = tube.final_set().interval()
        ratios = []
        for i in range(model.n):
            e = np.eye(model.n)[i]
            hi = rc.worst_case(model, X0, grid, e, inputs=U, W=W).value
            lo = -rc.worst_case(model, X0, grid, -e, inputs=U, W=W).value
            ratios.append((box.hi[i] - box.lo[i]) / max(hi - lo, 1e-300))
        print(f"{name:30s} " + " ".join(f"{model.state_names[i]} {r:.2f}" for i, r in enumerate(ratios)))


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--profile", action="store_true", help="profile the Van der Pol run (cProfile)")
    parser.add_argument("--adaptive", action="store_true",
                        help="only the default-vs-tuned table (algorithm='adaptive' against the hand-tuned settings)")
    parser.add_argument("--adaptive-heldout", action="store_true",
                        help="only algorithm='adaptive' on instances not used to choose its rules")
    parser.add_argument("--tightness", action="store_true",
                        help="only the defaults' final boxes against the worst cases (rc.worst_case)")
    parser.add_argument("--search-lin", action="store_true",
                        help="try 60 hand-tuned 'lin' settings on the instances without one (about 15 min)")
    args = parser.parse_args(argv)
    if args.search_lin:
        search_lin()
        return
    if args.tightness:
        bench_tightness()
        return
    if args.adaptive_heldout:
        bench_adaptive_heldout(args.repeat)
        return
    if args.adaptive:
        bench_adaptive(args.repeat)
        return
    t0 = time.perf_counter()
    rows = [bench_vanderpol(args.repeat), *bench_laub_loomis(args.repeat), bench_closed_loop_bicycle(args.repeat)]
    print(f"(warm-up, compilation and all repeats took {time.perf_counter() - t0:.1f} s)\n")
    print(f"{'benchmark':42s} {'verified':>8s} {'time [s]':>9s}  Flow* 2.1.0 here")
    for r in rows:
        print(f"{r['benchmark']:42s} {str(r['verified']):>8s} {r['seconds']:9.3f}  {r['flowstar']}")
        print(f"    {r['detail']}")
        print(f"    settings: {r['settings']}")
    if args.profile:
        import cProfile
        import pstats

        model = vanderpol()
        X0 = rc.Interval([1.25, 2.35], [1.55, 2.45])
        prof = cProfile.Profile()
        prof.enable()
        rc.reach(model, X0, 7.0, options=VDP_OPTIONS)
        prof.disable()
        pstats.Stats(prof).sort_stats("cumulative").print_stats(12)


if __name__ == "__main__":
    main()
