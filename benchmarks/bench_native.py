"""Conformance at the data's own rate and length (issue 15): figures printed by ``bench_conformance.py``.

* Alg. 2 and the box SCP per case on multi-body plant cases of 8–10 s at
  100 Hz (``bicycle`` with measured inputs, Table 5's V), wall-clock and CPU
  time; goal: Alg. 2 under 5 s per case;
* one Alg. 2 QP through cvxpy (the same matrices, the same solver) against the
  direct call: the modelling layer's share;
* memory per sample of trace conformance (Alg. 2 in windows) and reachset
  conformance (streamed reach): the slope of the peak resident memory of the
  command line between 20,000 and 100,000 samples;
* the 1,000,000-sample run (``reachconf conform --kind both`` with the demo
  run file): time and peak memory; goals: under 10 min and 2 GB on 2 cores.

Run alone: ``python benchmarks/bench_native.py [--skip-million]``.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

DEG = np.pi / 180
V5 = np.array([0.05, 0.05, 0.5 * DEG, 0.1, 0.1, 0.8 * DEG])  # Table 5
CASES = (("DLC", 2.0, None), ("DLC", 4.0, None), ("SW", 2.0, None), ("SL", 2.0, 10.0), ("SL", 4.0, 10.0))

# peak_memory (VmHWM), not ru_maxrss: after vfork + exec that is at least this (parent) process's own peak
CHILD = """
import json, resource, sys, time
from reachconf.budget import peak_memory
from reachconf.cli import main
t0 = time.perf_counter()
code = main(["conform", sys.argv[1], "--kind", sys.argv[2], "--json", sys.argv[3]])
r = resource.getrusage(resource.RUSAGE_SELF)
print(json.dumps({"exit": code, "wall": time.perf_counter() - t0, "cpu": r.ru_utime + r.ru_stime,
                  "peak_mb": peak_memory() / 2**20}))
"""


def native_cases(seed=5):
    from reachconf.datasets.vehicle_campaign.generate import make_case

    out = []
    for kind, a, horizon in CASES:
        c = make_case(kind, a, 0, seed=seed)
        if horizon is not None:
            c = c.segment(c.t[0], c.t[0] + horizon)
        out.append(c.select(("ax", "delta"), ("X", "Y", "psi", "vx", "vy", "omega")))
    return out


def qp_through_cvxpy(qp, X, W, kw):
    """The same QP (matrices of ``TraceQP.build``) through cvxpy with Clarabel: seconds."""
    import cvxpy as cp

    P, c, A, b, n_eq, _ = qp.build(X, W, "alg2", **kw)
    t0 = time.perf_counter()
    z = cp.Variable(A.shape[1])
    prob = cp.Problem(cp.Minimize(0.5 * cp.sum(cp.multiply(P.diagonal(), cp.square(z))) + c @ z),
                      [A[:n_eq] @ z == b[:n_eq], A[n_eq:] @ z <= b[n_eq:]])  # fmt: skip
    prob.solve(solver="CLARABEL")
    return time.perf_counter() - t0


def per_case_figures():
    import reachconf as rc
    from reachconf.conformance.bounds import case_box
    from reachconf.conformance.optctrl import TraceQP, solve_sparse_qp
    from reachconf.conformance.trace import trace_disturbances

    model = rc.models.bicycle()
    V = rc.Interval(-V5, V5)
    cases = native_cases()
    trace_disturbances(model, cases[0].segment(0, 1.0), method="optctrl", V=V)  # warm-up: compiled code
    print(f"native rate: {len(cases)} multi-body plant cases at 100 Hz, bicycle (measured inputs), Table 5's V")
    print(f"{'case':12s} {'samples':>8s} {'method':>9s} {'Alg. 2 wall':>12s} {'Alg. 2 cpu':>11s} {'SCP box wall':>13s} "
          f"{'cvxpy/direct QP':>16s}")  # fmt: skip
    a2, scp = [], []
    for case in cases:
        t0, c0 = time.perf_counter(), time.process_time()
        res = trace_disturbances(model, case, method="optctrl", V=V)
        wall, cpu = time.perf_counter() - t0, time.process_time() - c0
        found = case_box(model, case, V, "auto")
        # one QP of Alg. 2 directly and through cvxpy (same matrices)
        t, U, Y = case.t, np.ascontiguousarray(case.U), case.Y
        qp = TraceQP(model, np.array(t), U, Y, -V5, V5)
        qp.sw = np.ones(3)
        W0 = np.zeros((t.size - 1, 3))
        X = qp.simulate(Y[0], W0)
        kw = dict(W_lo=np.full(3, -np.inf), W_hi=np.full(3, np.inf), V_lo=-0.999 * V5, V_hi=0.999 * V5)
        P, c, A, b, n_eq, _ = qp.build(X, W0, "alg2", **kw)
        t1 = time.perf_counter()
        solve_sparse_qp(P, c, A, b, n_eq)
        direct = time.perf_counter() - t1
        via = qp_through_cvxpy(qp, X, W0, kw)
        a2.append(wall)
        scp.append(found.seconds.get("scp", 0.0))
        ok = "" if res.conformant else " (no trace)"
        print(f"{case.name:12s} {t.size:8d} {found.method:>9s} {wall:11.2f}s {cpu:10.2f}s {scp[-1]:12.2f}s "
              f"{via / direct:15.1f}x{ok}")  # fmt: skip
    print(f"Alg. 2 per case: mean {np.mean(a2):.2f} s, max {np.max(a2):.2f} s (goal < 5 s); "
          f"SCP box per case: mean {np.mean(scp):.2f} s, max {np.max(scp):.2f} s")


def cli_run(samples, kind, folder):
    """``reachconf conform`` on a straight-road recording of ``samples`` samples in a child process."""
    from reachconf.demo import demo_run_file, make_long_case
    from reachconf.io import TestSuite, save_suite

    folder = Path(folder) / f"n{samples}"
    if not (folder / "suite").exists():
        save_suite(TestSuite([make_long_case(samples, maneuver="straight", seed=2)]), folder / "suite")
        (folder / "run.toml").write_text(Path(demo_run_file()).read_text())
    out = subprocess.run([sys.executable, "-c", CHILD, str(folder / "run.toml"), kind, str(folder / f"{kind}.json")],
                         capture_output=True, text=True)  # fmt: skip
    if out.returncode != 0:
        raise RuntimeError(out.stderr[-2000:])
    info = json.loads(out.stdout.strip().splitlines()[-1])
    verdicts = json.loads((folder / f"{kind}.json").read_text())
    info["verdicts"] = {k: {kk: v["conformant"] for kk, v in e.items()} for k, e in verdicts.items()}
    return info


def memory_figures(folder):
    print("memory per sample (slope of the command line's peak resident memory, 20,000 -> 100,000 samples):")
    for kind in ("trace", "reachset"):
        lo, hi = cli_run(20_000, kind, folder), cli_run(100_000, kind, folder)
        slope = (hi["peak_mb"] - lo["peak_mb"]) * 2**20 / 80_000
        print(f"  {kind:9s}: {slope / 1024:5.2f} KB/sample (goal <= 2 KB); peak {lo['peak_mb']:.0f} MB at 20k, "
              f"{hi['peak_mb']:.0f} MB at 100k; cpu {lo['cpu']:.1f} s -> {hi['cpu']:.1f} s "
              f"({hi['cpu'] / lo['cpu']:.1f}x for 5x the samples)")  # fmt: skip


def million_run(folder):
    info = cli_run(1_000_000, "both", folder)
    print(f"1,000,000 samples (10,000 s at 100 Hz), `reachconf conform --kind both`, demo run file: "
          f"wall {info['wall'] / 60:.1f} min, cpu {info['cpu'] / 60:.1f} min, peak {info['peak_mb']:.0f} MB "
          f"(goals: < 10 min, < 2048 MB); verdicts {info['verdicts']}")  # fmt: skip


def main(million=True):
    per_case_figures()
    with tempfile.TemporaryDirectory() as tmp:
        memory_figures(tmp)
        if million:
            million_run(tmp)


if __name__ == "__main__":
    ap = argparse.ArgumentParser()
    ap.add_argument("--skip-million", action="store_true")
    main(million=not ap.parse_args().skip_million)
