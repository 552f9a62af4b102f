"""Code generation benchmark: generation and compile time and code size per model, before and after.

Every build runs in a fresh process with an empty ``REACHCONF_CACHE`` (cold:
sympy derivation, code generation, numba compilation of the generated
module); the package's own numba kernels are warmed up first (they compile
once per installation, not per model).  "Before" is the generator of a
baseline commit (default: the last commit with the symbolic third-order
tensors, ``GENERATOR_VERSION = "1"``), extracted with ``git archive`` into a
temporary folder and run on the same machine in the same run; it builds one
module for tensor order 2 (interval Hessian) and one for order 3 (plus the
third-order tensors).  "After" is this checkout's single build (interval
Taylor-mode remainders, both orders)::

    python benchmarks/bench_codegen.py [--models vanderpol,bicycle] [--baseline REF | --no-baseline]
                                       [--baseline-timeout 1800]

``--reach`` also compares the reach results of both remainders (``ReachOptions.remainder``
"taylor" against "tensor") on the problems of ``bench_reach.py``: the width of the final set
and of the tube's box per state, tensor over Taylor (>= 1: the Taylor remainder is as tight or
tighter), and the warm reach time.

Models are passed to the child processes as sympy expressions, so the
baseline builds exactly the same equations (also of models it did not ship,
such as ``bicycle_closed_loop_rate_limited``).  Prints wall and CPU seconds
(CPU is the better guide on a shared machine) and the load average.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tarfile
import tempfile
import time
from pathlib import Path

import sympy as sp

REPO = Path(__file__).resolve().parents[1]
BASELINE = "3238e77"  # last commit of the symbolic-tensor generator (GENERATOR_VERSION "1")
MODELS = ("vanderpol", "laub_loomis", "bicycle", "bicycle_actuated", "bicycle_closed_loop",
          "bicycle_closed_loop_actuated", "bicycle_closed_loop_rate_limited", "wind_turbine", "pedestrian_acc",
          "pedestrian_vel", "diff_drive")  # fmt: skip

CHILD = r"""
import json, sys, time
spec = json.loads(sys.stdin.read())
import sympy as sp
import reachconf as rc
from reachconf import codegen
syms = {k: sp.Symbol(k, real=True) for k in spec["names"]}
model = rc.Model(name=spec["name"], states=spec["states"], inputs=spec["inputs"],
                 disturbances=spec["disturbances"], params=spec["params"],
                 dynamics=[sp.sympify(e, locals=syms) for e in spec["f"]],
                 outputs={k: sp.sympify(e, locals=syms) for k, e in spec["h"].items()})
kw = {"order": spec["order"]} if spec["order"] else {}
timing = {}
generate = codegen.generate_source


def timed(*args, **kwargs):
    t = time.perf_counter()
    result = generate(*args, **kwargs)
    timing["gen"] = time.perf_counter() - t
    return result


codegen.generate_source = timed  # compile_model looks it up at call time
c1, t1 = time.process_time(), time.perf_counter()
comp = codegen.compile_model(model, **kw)
total = time.perf_counter() - t1
print(json.dumps({"gen": timing["gen"], "compile": total - timing["gen"], "wall": total,
                  "cpu": time.process_time() - c1, "bytes": comp.path.stat().st_size,
                  "tape": int(comp.tape.size) if getattr(comp, "tape", None) is not None else 0}))
"""

WARM = r"""
import reachconf as rc
import numpy as np
m = rc.Model(name="warm", states=("x", "y"), params={"k": 1.0}, dynamics=lambda s: [s.y, -s.k * s.x + s.x**3])
rc.reach(m, rc.Interval([0.9, -0.1], [1.1, 0.1]), 0.1, options=rc.ReachOptions(tensor_order=3, time_step=0.05))
rc.reach(m, rc.Interval([0.9, -0.1], [1.1, 0.1]), 0.1, options=rc.ReachOptions(tensor_order=2, time_step=0.05))
"""


def model_spec(name: str) -> dict:
    from reachconf.models import get_model

    m = get_model(name)
    return {
        "name": m.name, "states": list(m.state_names), "inputs": list(m.input_names),
        "disturbances": list(m.disturbance_names), "params": dict(m.params),
        "names": list(m.state_names + m.input_names + m.disturbance_names + m.param_names),
        "f": [sp.srepr(e) for e in m.f_expr], "h": {k: sp.srepr(e) for k, e in zip(m.output_names, m.h_expr)},
    }  # fmt: skip


def run_child(code: str, tree: Path, spec: dict | None, timeout: float):
    with tempfile.TemporaryDirectory(prefix="reachconf-bench-cache-") as cache:
        env = dict(os.environ, PYTHONPATH=str(tree), REACHCONF_CACHE=cache, MPLBACKEND="Agg")
        try:
            out = subprocess.run([sys.executable, "-c", code], input=json.dumps(spec or {}), env=env, cwd=cache,
                                 capture_output=True, text=True, timeout=timeout)  # fmt: skip
        except subprocess.TimeoutExpired:
            return {"timeout": timeout}
    if out.returncode != 0:
        return {"error": out.stderr.strip().splitlines()[-1] if out.stderr.strip() else f"exit {out.returncode}"}
    return json.loads(out.stdout.strip().splitlines()[-1]) if spec is not None else {}


def extract(ref: str, folder: Path) -> Path:
    data = subprocess.run(["git", "-C", str(REPO), "archive", ref], capture_output=True, check=True).stdout
    tar = folder / "baseline.tar"
    tar.write_bytes(data)
    with tarfile.open(tar) as tf:
        tf.extractall(folder / "tree", filter="data")
    return folder / "tree"


def fmt(r: dict) -> str:
    if "timeout" in r:
        return f"> {r['timeout']:.0f} s (stopped)"
    if "error" in r:
        return f"error: {r['error'][:40]}"
    return f"{r['gen']:6.1f} + {r['compile']:6.1f} = {r['wall']:6.1f} s ({r['cpu']:5.1f} CPU), {r['bytes'] / 1e3:5.0f} kB"


def reach_problems():
    """``(name, model, X0, times, inputs, W, options)`` of ``bench_reach.py``."""
    import numpy as np

    import reachconf as rc

    sys.path.insert(0, str(Path(__file__).resolve().parent))
    import bench_reach as br
    from reachconf.models import laub_loomis, vanderpol

    x0 = np.array([1.2, 1.05, 1.5, 2.4, 1.0, 0.1, 0.45])
    rows = [("vanderpol", vanderpol(mu=1.0), rc.Interval([1.25, 2.35], [1.55, 2.45]), 7.0, None, None,
             br.VDP_OPTIONS)]  # fmt: skip
    for W in (0.01, 0.05):
        rows.append((f"laub_loomis W={W}", laub_loomis(), rc.Interval(x0 - W, x0 + W), 20.0, None, None,
                     br.LL_OPTIONS[W]))  # fmt: skip
    rows.append(("closed-loop bicycle LC", *br.closed_loop_lc_problem()))
    return rows


def compare_reach():
    """Print the reach of both remainders side by side (see the module docstring)."""
    import dataclasses

    import numpy as np

    import reachconf as rc

    print("\n| problem | final set width, tensor / taylor (min, median, max over states) | tube box, same | "
          "warm seconds taylor / tensor |")  # fmt: skip
    print("|---|---|---|---|")
    for name, model, X0, times, U, W, opts in reach_problems():
        out = {}
        for rem in ("taylor", "tensor"):
            o = dataclasses.replace(opts, remainder=rem, progress=False)
            rc.reach(model, X0, times, inputs=U, W=W, options=o)  # warm-up (and the build)
            t0 = time.perf_counter()
            tube = rc.reach(model, X0, times, inputs=U, W=W, options=o)
            fin = tube.final_set().interval()
            hull = tube.interval_hull()
            out[rem] = (fin.hi - fin.lo, hull.hi - hull.lo, time.perf_counter() - t0)
        r_fin = out["tensor"][0] / out["taylor"][0]
        r_hull = out["tensor"][1] / out["taylor"][1]
        print(f"| {name} | {r_fin.min():.3f}, {np.median(r_fin):.3f}, {r_fin.max():.3f} | {r_hull.min():.3f}, "
              f"{np.median(r_hull):.3f}, {r_hull.max():.3f} | {out['taylor'][2]:.2f} / {out['tensor'][2]:.2f} |",
              flush=True)  # fmt: skip


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--models", default=",".join(MODELS))
    ap.add_argument("--baseline", default=BASELINE, help=f"git ref of the 'before' generator (default {BASELINE})")
    ap.add_argument("--no-baseline", action="store_true")
    ap.add_argument("--baseline-timeout", type=float, default=1800.0, help="seconds per baseline build")
    ap.add_argument("--json", help="also write the figures to this file")
    ap.add_argument("--reach", action="store_true", help="only compare the reach results of both remainders")
    args = ap.parse_args(argv)
    if args.reach:
        compare_reach()
        return
    names = [s for s in args.models.split(",") if s]
    print(f"load average at start: {os.getloadavg()}; {os.cpu_count()} CPUs")
    rows = {}
    with tempfile.TemporaryDirectory(prefix="reachconf-bench-") as tmp:
        trees = {"after": REPO}
        if not args.no_baseline:
            trees["before"] = extract(args.baseline, Path(tmp))
        for label, tree in trees.items():
            t0 = time.perf_counter()
            run_child(WARM, tree, None, 3600)
            print(f"{label}: kernel warm-up {time.perf_counter() - t0:.1f} s (once per installation)", flush=True)
        for name in names:
            spec = model_spec(name)
            row = rows[name] = {}
            row["after"] = run_child(CHILD, REPO, dict(spec, order=None), 3600)
            print(f"{name:34s} after          {fmt(row['after'])}, tape {row['after'].get('tape', '-')} ops",
                  flush=True)  # fmt: skip
            if "before" in trees:
                for order in (2, 3):
                    row[f"before_o{order}"] = r = run_child(CHILD, trees["before"], dict(spec, order=order),
                                                            args.baseline_timeout)  # fmt: skip
                    print(f"{name:34s} before order {order} {fmt(r)}", flush=True)
    print(f"\nload average at the end: {os.getloadavg()}")
    print("\n| model | before, order 2 | before, order 3 | after (both orders) | CPU ratio o3/after |")
    print("|---|---|---|---|---|")
    for name, row in rows.items():
        b2, b3, a = row.get("before_o2", {}), row.get("before_o3", {}), row["after"]
        ratio = f"{b3['cpu'] / a['cpu']:.0f}x" if "cpu" in b3 and "cpu" in a else ("> " + f"{b3['timeout'] / a['cpu']:.0f}x (wall)" if "timeout" in b3 and "cpu" in a else "-")
        print(f"| {name} | {fmt(b2) if b2 else '-'} | {fmt(b3) if b3 else '-'} | {fmt(a)} | {ratio} |")
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=2))


if __name__ == "__main__":
    main()
