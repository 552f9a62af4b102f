"""Gap diagnosis checked on data whose effect is withheld from the model.

    python examples/diagnose/run.py --out DIR [--repetitions 3] [--only yaw_offset ...] [--workers 2 | --scheduler ADDR]
    python examples/diagnose/run.py --protocol --out DIR [--cache DIR] [--workers 2] [--stage all] [--test-seed 2]

``--protocol`` runs the validation protocol of docs/diagnosis-validation.md
(tuning and test suites made differently; thresholds chosen on the tuning
suites; confusion tables, parameter errors and interval coverage on both):
DIR/protocol.json and DIR/protocol.md.  Without it:

For every entry of :data:`withheld.WITHHELD` (steering lag
0.1 s, steering dead time 80 ms, acceleration scale 0.64 with offset 0.32 m/s²,
yaw sensor offset 1°, steering offset 1.09°, and none), the multi-body vehicle
plant drives the excitation maneuver and a 4 m/s² slalom with that one effect;
the suite holds the controller's requests as inputs and the measured states.
The base model is ``bicycle`` with nominal parameters from an earlier
identification on effect-free runs (other seeds).  ``reachconf.diagnose`` runs
without being told the effect; the confusion table compares what it names
with the truth (parameters within 25 %).

Writes DIR/confusion.json, DIR/confusion.md and, per suite, DIR/<name>/report.{json,md} and PNGs.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from withheld import WITHHELD, nominal_bicycle_params, withheld_suite  # noqa: E402

import reachconf as rc  # noqa: E402
from reachconf.io import atomic_write  # noqa: E402
from reachconf.models import bicycle  # noqa: E402

FIT = ("J_m", "b_L", "c_f", "c_r")
ACTUATOR_OR_SENSOR = {"actuator_lag", "dead_time", "input_offset", "input_scale", "output_offset", "output_scale"}


def judge(report, truth) -> dict:
    """Did the report name the withheld effect (target and parameters within 25 %)?"""
    named = not report.verdict.startswith("no effect")
    best = report.best
    if not truth:
        claims = named and best["effect"] in ACTUATOR_OR_SENSOR
        return {"correct": not claims, "named": f"{best['effect']}({best['target']})" if named else "none",
                "params_ok": None}  # fmt: skip
    if not named:
        return {"correct": False, "named": "none", "params_ok": False}
    found = {(best["effect"], best["target"]): best["params"]}
    if report.combination:
        for (e, t) in report.combination["parts"]:
            found[(e, t)] = {k.split(".")[1].split("(")[0]: v for k, v in report.combination["params"].items()
                             if k.startswith(f"{e}.") and k.endswith(f"({t})")}  # fmt: skip
    first_ok = (best["effect"], best["target"]) in {(tr["effect"], tr["target"]) for tr in truth}
    params_ok = True
    for tr in truth:
        got = found.get((tr["effect"], tr["target"]))
        if got is None:
            params_ok = False
            continue
        for k, v in tr["params"].items():
            if not abs(got[k] - v) <= 0.25 * abs(v):
                params_ok = False
    return {"correct": bool(first_ok and params_ok), "named": f"{best['effect']}({best['target']})",
            "params_ok": params_ok}  # fmt: skip


def run_one(job):
    name, repetitions, nominal, out, reach = job
    t0 = time.perf_counter()
    suite, truth = withheld_suite(name, repetitions=repetitions)
    t_gen = time.perf_counter() - t0
    report = rc.diagnose(bicycle(**nominal), suite, fit_params=FIT, progress=False, reach=reach)
    folder = Path(out) / name
    folder.mkdir(parents=True, exist_ok=True)
    report.to_json(folder / "report.json")
    atomic_write(folder / "report.md", report.summary())
    report.save_plots(folder)
    verdict = judge(report, truth)
    best = report.best
    row = {"withheld": name, "truth": truth, **verdict, "verdict": report.verdict,
           "best": {k: best[k] for k in ("effect", "target", "params", "params_std", "shrink_volume",
                                         "prediction_gain")},
           "runner_up": {k: report.ranked_effects[1][k] for k in ("effect", "target", "shrink_volume",
                                                                   "prediction_gain")},
           "combination": report.combination, "seconds_generate": t_gen, "seconds_diagnose": report.seconds,
           "cases": len(list(suite)), "before_after": report.before_after}  # fmt: skip
    return row


def table(rows) -> str:
    lines = ["| withheld | truth | named first | fitted parameters (± std) | W volume shrink | prediction gain | "
             "runner-up (gain) | correct |", "|---|---|---|---|---|---|---|---|"]  # fmt: skip
    for r in rows:
        truth = "; ".join(f"{t['effect']}({t['target']}) " + ", ".join(f"{k}={v:.4g}" for k, v in t["params"].items())
                          for t in r["truth"]) or "none"  # fmt: skip
        b = r["best"]
        ps = ", ".join(f"{k}={v:.4g}±{b['params_std'][k]:.1g}" for k, v in b["params"].items())
        if r["combination"]:
            ps += "; with " + ", ".join(f"{k}={v:.4g}" for k, v in r["combination"]["params"].items())
        if r["named"] == "none":
            ps = f"(best, not named: {b['effect']}({b['target']}) {ps})"
        sv = "n/a" if b["shrink_volume"] is None else f"{b['shrink_volume']:.2f}"
        ru = r["runner_up"]
        lines.append(f"| {r['withheld']} | {truth} | {r['named']} | {ps} | {sv} | {100 * b['prediction_gain']:.0f} % | "
                     f"{ru['effect']}({ru['target']}) ({100 * ru['prediction_gain']:.0f} %) | "
                     f"{'yes' if r['correct'] else 'NO'} |")  # fmt: skip
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", required=True)
    ap.add_argument("--repetitions", type=int, default=3)
    ap.add_argument("--only", nargs="*", choices=sorted(WITHHELD), help="only these withheld effects")
    ap.add_argument("--workers", type=int, default=None, help="local worker processes (one pool for the run)")
    ap.add_argument("--scheduler", default=None, help="Dask scheduler address tcp://host:port instead of --workers")
    ap.add_argument("--reach", action="store_true", help="also the reachset-conformant W before/after (slower)")
    ap.add_argument("--protocol", action="store_true", help="run the validation protocol (docs/diagnosis-validation.md)")
    ap.add_argument("--cache", default=None, help="protocol: folder of the generated suites and results (OUT/cache)")
    ap.add_argument("--stage", choices=("tuning", "test", "all"), default="all", help="protocol: which suites")
    ap.add_argument("--test-seed", type=int, default=2, help="protocol: seed of the test set (another seed: another set)")
    ap.add_argument("--generate-only", action="store_true", help="protocol: only generate the suites")
    ap.add_argument("--redo", action="store_true", help="protocol: diagnose again even if a stored result matches")
    args = ap.parse_args(argv)
    if args.protocol:
        from protocol_run import run_protocol

        return run_protocol(args)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    nominal = nominal_bicycle_params()
    print(f"nominal parameters (earlier identification): {nominal}  [{time.perf_counter() - t0:.0f} s]", flush=True)
    names = args.only or list(WITHHELD)
    from reachconf.runner import Pool

    with Pool(args.workers, args.scheduler) as pool:  # the run's one pool (each suite's diagnosis is one task)
        rows = pool.map(run_one, [(n, args.repetitions, nominal, str(out), args.reach) for n in names],
                        desc="withheld suites", unit="suite")  # fmt: skip
    result = {"nominal": nominal, "rows": rows, "correct": sum(r["correct"] for r in rows), "total": len(rows),
              "seconds": time.perf_counter() - t0}  # fmt: skip
    atomic_write(out / "confusion.json", json.dumps(result, indent=2, default=float))
    md = table(rows)
    atomic_write(out / "confusion.md", md)
    print(md)
    print(f"{result['correct']} / {result['total']} correct, {result['seconds']:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
