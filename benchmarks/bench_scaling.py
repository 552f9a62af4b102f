"""Scale-out benchmark: Table 6 synthesis of the 40-case vehicle campaign serially, on 2 local processes and on a
2-worker multi-process Dask cluster, from warm caches; then a Pareto front serially and on 2 processes.

Goal (issue 20): a speed-up of at least 1.7x on 2 cores for both parallel runs.  Run it on a quiet machine:

    python benchmarks/bench_scaling.py [--campaign out/vehicle/campaign] [--cases 40] [--skip-dask] [--skip-fresh]

Last, the first case on a FRESH Dask worker (a worker process with empty ``REACHCONF_CACHE`` and
``NUMBA_CACHE_DIR``, as on a new machine): before (the worker builds the model and compiles the kernels itself,
as every worker did before issue 20) and after (the run ships the generated model and numba's caches to it).

The campaign is the vehicle example's (``examples/vehicle/run.py``; generated into ``--campaign`` when missing,
about 2 min), identified as the example does, with the example's Table 6 options.  Printed per run: wall time,
merge time, the CPU time of this process and of the workers, whether the boxes are bitwise identical to the
serial run; then the speed-ups.  CPU times help when the machine is busy: ``serial CPU / busiest worker CPU`` is
what the speed-up would be with a core per worker and nothing else running.
"""

from __future__ import annotations

import argparse
import dataclasses
import importlib.util
import multiprocessing as mp
import os
import sys
import time
from pathlib import Path


from reachconf.conformance import pareto_front, synthesize_W
from reachconf.conformance.synthesis import PRELOAD
from reachconf.runner import Pool

ROOT = Path(__file__).resolve().parents[1]


def load_vehicle_example():
    """``examples/vehicle/run.py`` as a module (it puts its folder on sys.path for ``identify``)."""
    spec = importlib.util.spec_from_file_location("vehicle_run", ROOT / "examples" / "vehicle" / "run.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def table6_problem(vehicle, folder, cases, step2_decimate=1):
    """The example's Table 6 problem: closed-loop model, suite, V and synthesis options."""
    from reachconf.conformance import SynthesisOptions

    suite = vehicle.campaign(Path(folder), repetitions=5)
    if cases < len(suite):  # round robin over the maneuvers
        groups = list(suite.groups().values())
        picked = [g[i] for i in range(max(len(g) for g in groups)) for g in groups if i < len(g)][:cases]
        suite = suite.select(names=[c.name for c in picked])
    params, _ = vehicle.fit_bicycle(suite)
    act = vehicle.fit_actuators(suite)
    model = vehicle.bicycle_closed_loop_actuated(**params, **act["params"])
    cl_suite = suite.map(lambda c: c.select(vehicle.REF, model.output_names))
    opts = SynthesisOptions(alpha_iterations=8, merge_iterations=6, alpha_max=4.0, step2_decimate=step2_decimate,
                            reach=vehicle.REACH_TABLE6_FAST, reach_fallback=vehicle.REACH_TABLE6)  # fmt: skip
    return model, cl_suite, vehicle.box(vehicle.V_TABLE6), opts


def proc_cpu(pid) -> float:
    """CPU seconds (user + system) of a process of this machine, from /proc (0 where unavailable)."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
        return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")
    except (OSError, ValueError, IndexError):
        return 0.0


def same(a, b) -> bool:
    boxes = lambda r: [(c.W_RC.lo.tobytes(), c.W_RC.hi.tobytes(), c.alpha) for c in r.cases.values()] + [  # noqa: E731
        (W.lo.tobytes(), W.hi.tobytes(), r.group_alpha[g]) for g, W in r.groups.items()]
    return boxes(a) == boxes(b)


def run(label, fn, rows, worker_cpu=None):
    """Time ``fn() -> (result, workers' CPU seconds)``; print and keep a row."""
    c0, t0 = time.process_time(), time.perf_counter()
    result, workers = fn()
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    rows.append({"run": label, "wall": wall, "merge": getattr(result, "merge_seconds", float("nan")), "cpu": cpu,
                 "workers": workers, "result": result})  # fmt: skip
    extra = f", workers' CPU {' + '.join(f'{w:.1f}' for w in workers)} s" if workers else ""
    print(f"{label}: {wall:.1f} s (merge {rows[-1]['merge']:.1f} s), this process' CPU {cpu:.1f} s{extra}", flush=True)
    return result


def on_local_processes(fn):
    """``fn(pool)`` on a new pool of 2 local processes (its start-up included); returns (result, workers' CPU)."""
    with Pool(workers=2, preload=PRELOAD) as pool:
        pool.map(abs, [1, 2], progress=False)  # starts the workers
        result = fn(pool)
        return result, [proc_cpu(p.pid) for p in mp.active_children()]


def on_dask(client, fn):
    """``fn()`` on a Dask cluster; returns (result, CPU of each worker process during the call)."""
    before = dict(client.run(time.process_time))
    result = fn()
    after = client.run(time.process_time)
    return result, [after[w] - before.get(w, 0.0) for w in sorted(after)]


def fresh_worker_first_case(model, case_suite, V, opts, ship: bool) -> float:
    """Wall seconds of a one-case synthesis on a new 1-worker cluster whose worker has empty caches.

    ``ship=False``: the whole synthesis is one Dask task on the worker, which builds the model and compiles
    the kernels itself (what every worker did before issue 20).  ``ship=True``: ``synthesize_W(scheduler=...)``,
    which installs this machine's compiled model and kernels on the worker first.
    """
    import tempfile

    from distributed import Client, LocalCluster

    with tempfile.TemporaryDirectory(prefix="reachconf-fresh-") as tmp:
        env = {"REACHCONF_CACHE": f"{tmp}/cache", "NUMBA_CACHE_DIR": f"{tmp}/numba", "REACHCONF_PROGRESS": "0"}
        with LocalCluster(n_workers=1, threads_per_worker=1, processes=True, dashboard_address=None, env=env) as cl:
            with Client(cl) as client:
                t0 = time.perf_counter()
                if ship:
                    synthesize_W(model, case_suite, V, opts, scheduler=cl.scheduler_address, progress=False)
                else:
                    client.submit(synthesize_W, model, case_suite, V, opts, progress=False, pure=False).result()
                return time.perf_counter() - t0


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--campaign", default=str(ROOT / "out" / "vehicle" / "campaign"))
    ap.add_argument("--cases", type=int, default=40, help="the first N cases of the campaign (default: all 40)")
    ap.add_argument("--skip-dask", action="store_true")
    ap.add_argument("--pareto-group", default="LC_2")
    ap.add_argument("--pareto-iterations", type=int, default=3)
    ap.add_argument("--step2-decimate", type=int, default=1, help="synthesis step 2 on every k-th sample "
                    "(1: the example's Table 6 options, at the recordings' 100 Hz)")  # fmt: skip
    ap.add_argument("--skip-fresh", action="store_true", help="skip the first case on a fresh worker")
    args = ap.parse_args()
    os.environ.setdefault("REACHCONF_PROGRESS", "0")
    vehicle = load_vehicle_example()
    model, suite, V, opts = table6_problem(vehicle, args.campaign, args.cases, args.step2_decimate)
    print(f"{len(suite)} cases, groups {list(suite.groups())}; load average {os.getloadavg()[0]:.1f} on "
          f"{os.cpu_count()} cores", flush=True)

    # warm caches: the model's builds and every kernel the synthesis uses, on the first second of one case
    t0 = time.perf_counter()
    first = suite[0]
    warm = suite.select(names=[first.name]).map(lambda c: dataclasses.replace(c.segment(c.t[0], c.t[0] + 1.0),
                                                                               name=c.name))  # fmt: skip
    synthesize_W(model, warm, V, dataclasses.replace(opts, alpha_iterations=1, merge=False), progress=False)
    print(f"warm-up {time.perf_counter() - t0:.1f} s", flush=True)

    rows = []
    serial = run("serial", lambda: (synthesize_W(model, suite, V, opts, progress=False), []), rows)
    local = run("workers=2", lambda: on_local_processes(lambda pool: synthesize_W(model, suite, V, opts, pool=pool,
                                                                                 progress=False)), rows)  # fmt: skip
    results = [("workers=2", local)]
    if not args.skip_dask:
        from distributed import Client, LocalCluster

        with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cluster:
            with Client(cluster) as client:
                address = cluster.scheduler_address  # the run connects its own client, as a user's would
                dask = run("Dask, 2 worker processes", lambda: on_dask(client, lambda: synthesize_W(
                    model, suite, V, opts, scheduler=address, progress=False)), rows)  # fmt: skip
        results.append(("Dask", dask))

    group = args.pareto_group if args.pareto_group in serial.groups else next(iter(serial.groups))
    members = suite.select(names=[n for n, c in serial.cases.items() if c.group == group])
    start = serial.groups[group]
    prow = []
    if serial.group_conformant[group]:
        it = args.pareto_iterations
        f1 = run(f"Pareto {group} serial", lambda: (pareto_front(model, members, V, start, iterations=it, options=opts,
                                                                  progress=False), []), prow)  # fmt: skip
        f2 = run(f"Pareto {group} workers=2", lambda: on_local_processes(lambda pool: pareto_front(
            model, members, V, start, iterations=it, options=opts, pool=pool, progress=False)), prow)  # fmt: skip
        pareto_same = [b.to_list() for b in f1.boxes] == [b.to_list() for b in f2.boxes]
    print("\n| run | wall [s] | merge [s] | speed-up | CPU here [s] | CPU of workers [s] | identical to serial |")
    print("|---|---|---|---|---|---|---|")
    for r in rows:
        ident = "-" if r is rows[0] else ("yes" if same(serial, r["result"]) else "NO")
        wk = " + ".join(f"{w:.1f}" for w in r["workers"]) or "-"
        print(f"| {r['run']} | {r['wall']:.1f} | {r['merge']:.1f} | {rows[0]['wall'] / r['wall']:.2f}x | {r['cpu']:.1f} "
              f"| {wk} | {ident} |")  # fmt: skip
    for label, res in results:
        r = next(x for x in rows if x["result"] is res)
        ratio = rows[0]["wall"] / r["wall"]
        cpu_bound = rows[0]["cpu"] / max(r["workers"]) if r["workers"] and max(r["workers"]) > 0 else float("nan")
        print(f"{label}: speed-up {ratio:.2f}x (goal >= 1.7x: {'met' if ratio >= 1.7 else 'NOT met'}); "
              f"serial CPU / busiest worker's CPU = {cpu_bound:.2f}x")
    if prow:
        print(f"Pareto front of {group} ({len(members)} cases, {args.pareto_iterations} bisections per channel): "
              f"serial {prow[0]['wall']:.1f} s, workers=2 {prow[1]['wall']:.1f} s, speed-up "
              f"{prow[0]['wall'] / prow[1]['wall']:.2f}x, identical: {'yes' if pareto_same else 'NO'}")
    else:
        print(f"Pareto front skipped: {group} has no conformant W_RC,Mnvr")
    if not args.skip_fresh:
        one = dataclasses.replace(opts, merge=False)
        before = fresh_worker_first_case(model, warm, V, one, ship=False)
        print(f"first case on a fresh worker, before (the worker builds and compiles): {before:.1f} s", flush=True)
        after = fresh_worker_first_case(model, warm, V, one, ship=True)
        print(f"first case on a fresh worker, after (compiled code shipped): {after:.1f} s "
              f"({before / after:.1f}x faster); the case: the first second of {first.name}")  # fmt: skip
    return 0


if __name__ == "__main__":
    sys.exit(main())
