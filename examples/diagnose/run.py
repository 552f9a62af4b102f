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


sys.path.insert(0, str(Path(__file__).resolve().parent))

from withheld import WITHHELD, nominal_bicycle_params, withheld_suite  # noqa: E402

import reachconf as rc  # noqa: E402
from reachconf.io import atomic_write  # noqa: E402
from reachconf.models import bicycle  # noqa: E402

FIT = ("J_m", "b_L", "c_f", "c_r")


def judge(report, truth) -> dict:
    """Did the report name the withheld effects (first, or as indistinguishable), and no other?

    ``correct``: every true effect named (or among the explanations the verdict
    cannot separate) and no wrong name; ``params_ok``: the named true effects'
    parameters within 25 % of the truth.
    """
    from protocol import judge as judge_decision

    j = judge_decision(report.decision, truth)
    ok = not j["wrong"] and not j["outcome"].startswith("WRONG") and all(v != "missed" for v in j["effects"].values())
    params_ok = all(abs(p["relative_error"]) <= 0.25 for p in j["params"]) if truth else None
    named = ", ".join(f"{e['effect']}({e['target']})" for e in report.named) or "none"
    return {"correct": bool(ok), "named": named, "status": report.status, "params_ok": params_ok, "judge": j}


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
    row = {"withheld": name, "truth": truth, **verdict, "verdict": report.verdict, "named_effects": report.named,
           "alternatives": report.decision.get("alternatives", []), "best": report.best,
           "seconds_generate": t_gen, "seconds_diagnose": report.seconds, "cpu_seconds_diagnose": report.cpu_seconds,
           "cases": len(list(suite)), "before_after": report.before_after}  # fmt: skip
    return row


def table(rows) -> str:
    """Markdown table of the withheld-effect suites."""
    lines = ["| withheld | truth | verdict | named (95 % interval) | alternatives | W volume shrink | correct |",
             "|---|---|---|---|---|---|---|"]  # fmt: skip
    for r in rows:
        truth = "; ".join(f"{t['effect']}({t['target']}) " + ", ".join(f"{k}={v:.4g}" for k, v in t["params"].items())
                          for t in r["truth"]) or "none"  # fmt: skip
        ps = "; ".join(f"{e['effect']}({e['target']}) " + ", ".join(
            f"{k}={v:.4g} [{e['interval'][k][0]:.4g}, {e['interval'][k][1]:.4g}]" for k, v in e["params"].items())
            for e in r["named_effects"]) or "none"  # fmt: skip
        alts = "; ".join(f"{a['label']} (z {a['z']:.1f})" for a in r["alternatives"]) or "-"
        sv = r["before_after"].get("W_volume_shrink")
        lines.append(f"| {r['withheld']} | {truth} | {r['status']} | {ps} | {alts} | "
                     f"{'n/a' if sv is None else f'{sv:.2f}'} | {'yes' if r['correct'] else 'NO'} |")  # fmt: skip
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
    ap.add_argument("--available", action="store_true",
                    help="protocol: only tabulate the stored results (e.g. of a run stopped at a deadline)")
    ap.add_argument("--no-tubes", action="store_true", help="protocol: test set without the before/after reach tubes")
    ap.add_argument("--start-state", default=None, choices=("prefix", "auto", "past", "centered"),
                    help="protocol: DiagnoseOptions.start_state of every diagnosis (default: the library's default)")
    ap.add_argument("--loss-scale", default=None, choices=("sensor", "residual", "case"),
                    help="protocol: DiagnoseOptions.loss_scale of every diagnosis (default: the library's default)")
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
    from reachconf.script import run_script

    sys.exit(run_script(main, "diagnose"))
