"""Conformance benchmark.

1. A 10-case synthetic vehicle suite (closed-loop bicycle, 8 s at 100 Hz):
   per case the time of the per-step trace conformance, of synthesis step 2
   (the box SCP) and of the alpha-search (10 reachability analyses + 1), then
   the whole synthesis serial vs ``workers=2``.  Goal: the whole synthesis of
   one 8 s case under 10 s (the report: three hours of fmincon per case for
   step 2).
2. Native rate (:mod:`bench_native`): multi-body plant cases of 8–10 s at
   100 Hz with ``bicycle`` and Table 5's V: Alg. 2 and box-SCP time per case
   (goal: Alg. 2 under 5 s), the QP through cvxpy vs direct (same matrices),
   memory per sample of trace and reachset conformance, and the
   1,000,000-sample run (goal: under 2 GB and 10 min on 2 cores).

Run: ``python benchmarks/bench_conformance.py [--cases 10] [--skip-synthesis] [--skip-million]``
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from reachconf.conformance import SynthesisOptions, synthesize_W, trace_conformance
from reachconf.demo import V_TRUE, W_TRUE, make_demo_suite
from reachconf.models import get_model
from reachconf.reach import ReachOptions


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--cases", type=int, default=10)
    ap.add_argument("--skip-synthesis", action="store_true", help="only the native-rate and long-recording figures")
    ap.add_argument("--skip-million", action="store_true", help="without the 1,000,000-sample run (about 10 min)")
    args = ap.parse_args()
    if not args.skip_synthesis:
        synthesis_figures(args)
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    import bench_native

    bench_native.main(million=not args.skip_million)


def synthesis_figures(args):
    model = get_model("bicycle_closed_loop")
    with tempfile.TemporaryDirectory() as tmp:
        suite = make_demo_suite(tmp, n_cases=args.cases, seed=7, duration=8.0, rate=100.0)
    opts = SynthesisOptions(alpha_iterations=10, reach=ReachOptions(time_step=0.02))
    model.compiled()
    synthesize_W(model, suite.select(names=[suite[0].name]), V_TRUE, SynthesisOptions(alpha_iterations=1),
                 progress=False)  # warm-up: load compiled code  # fmt: skip

    t_trace = []
    for case in suite:
        t0 = time.perf_counter()
        trace_conformance(model, case, W_TRUE, V_TRUE, method="perstep")
        t_trace.append(time.perf_counter() - t0)
    t0 = time.perf_counter()
    serial = synthesize_W(model, suite, V_TRUE, opts, progress=False)
    t_serial = time.perf_counter() - t0
    t0 = time.perf_counter()
    synthesize_W(model, suite, V_TRUE, opts, workers=2, progress=False)
    t_par = time.perf_counter() - t0

    print(f"suite: {len(suite)} cases x {suite[0].duration:g} s at 100 Hz, closed-loop bicycle")
    print(f"{'case':16s} {'perstep':>9s} {'step 1':>8s} {'step 2':>8s} {'alpha (11 reaches)':>19s} {'total':>8s}  alpha")
    for case, tt in zip(suite, t_trace):
        cs = serial.cases[case.name]
        st = cs.step_seconds
        print(f"{case.name:16s} {tt:8.3f}s {st['step1']:7.3f}s {st['step2']:7.3f}s {st['step3']:18.3f}s "
              f"{cs.seconds:7.3f}s  {cs.alpha:.4f}")  # fmt: skip
    per_case = np.array([c.seconds for c in serial.cases.values()])
    print(f"synthesis per case: mean {per_case.mean():.2f} s, max {per_case.max():.2f} s (goal < 10 s)")
    print(f"whole suite incl. merge: serial {t_serial:.1f} s, workers=2 {t_par:.1f} s, ratio {t_serial / t_par:.2f}x")
    print(serial.table())


if __name__ == "__main__":
    main()
