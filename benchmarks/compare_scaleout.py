"""Before/after figures of issue 20 on the demo suite: the runs the issue timed, with the public API only.

    PYTHONPATH=<tree> python benchmarks/compare_scaleout.py [--skip-dask]

Uses only calls that exist before and after issue 20 (``synthesize_W(workers=, scheduler=)``,
``pareto_front(workers=)``), so the same script times an older tree (``git archive <commit>``) and this
one.  Printed: the synthesis of the demo suite serially, with ``workers=2``, on a new 2-worker multi-process
Dask cluster (first run: fresh worker processes, warm disk caches) and again on the same cluster; the merge
time of each; the Pareto front from the run file's W with one bisection per channel (37 checks) serially and
with ``workers=2``; the load average.
"""

from __future__ import annotations

import argparse
import os
import sys
import time

from reachconf.conformance import pareto_front, synthesize_W
from reachconf.demo import demo_run_file
from reachconf.runfile import load_run


def merge_wall(res, concurrent_groups: bool) -> float:
    """The merge's wall time: ``merge_seconds`` where results have it, else from the groups' times."""
    if hasattr(res, "merge_seconds"):
        return res.merge_seconds
    times = list(res.group_seconds.values()) or [0.0]
    return max(times) if concurrent_groups else sum(times)


def timed(label, fn, concurrent_groups=False):
    c0, t0 = time.process_time(), time.perf_counter()
    res = fn()
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    merge = merge_wall(res, concurrent_groups) if hasattr(res, "group_seconds") else float("nan")
    print(f"| {label} | {wall:.1f} | {merge:.2f} | {cpu:.1f} | {os.getloadavg()[0]:.1f} |", flush=True)
    return res


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--skip-dask", action="store_true")
    args = ap.parse_args()
    os.environ.setdefault("REACHCONF_PROGRESS", "0")
    spec = load_run(demo_run_file())
    suite, model, V, opts = spec.suite(), spec.model, spec.V, spec.synthesis_options
    import reachconf

    print(f"{reachconf.__file__}: {len(suite)} cases; load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
    t0 = time.perf_counter()
    synthesize_W(model, suite, V, opts, progress=False)  # warm caches (model builds, kernels)
    print(f"warm-up {time.perf_counter() - t0:.1f} s\n")
    print("| run | wall [s] | merge [s] | CPU of this process [s] | load |\n|---|---|---|---|---|")
    serial = timed("synthesis, serial", lambda: synthesize_W(model, suite, V, opts, progress=False))
    timed("synthesis, workers=2", lambda: synthesize_W(model, suite, V, opts, workers=2, progress=False),
          concurrent_groups=True)  # fmt: skip
    if not args.skip_dask:
        from distributed import LocalCluster

        with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cluster:
            address = cluster.scheduler_address
            timed("synthesis, Dask 2 processes, fresh workers",
                  lambda: synthesize_W(model, suite, V, opts, scheduler=address, progress=False))  # fmt: skip
            timed("synthesis, Dask 2 processes, second run",
                  lambda: synthesize_W(model, suite, V, opts, scheduler=address, progress=False))  # fmt: skip
    f1 = timed("Pareto (37 checks), serial", lambda: pareto_front(model, suite, V, spec.W, iterations=1))
    f2 = timed("Pareto (37 checks), workers=2", lambda: pareto_front(model, suite, V, spec.W, iterations=1, workers=2))
    same = [b.to_list() for b in f1.boxes] == [b.to_list() for b in f2.boxes]
    print(f"\nPareto fronts identical: {same}; synthesis verdicts: {sorted(serial.group_conformant.items())}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
