"""``run.py --protocol``: generate the suites, diagnose them, choose the thresholds on tuning, report both sets."""

from __future__ import annotations

import dataclasses
import json
import time
from pathlib import Path

from protocol_eval import (
    choose_interval_method,
    choose_thresholds,
    coverage,
    generate_job,
    TUNING_RUN_THRESHOLDS,
    interleaved,
    specs_for,
    stored_row,
    suite_job,
    summary_tables,
)
from run import FIT
from withheld import nominal_bicycle_params

from reachconf.diagnose.options import DiagnoseOptions
from reachconf.io import atomic_write
from reachconf.io.jsonfile import json_text
from reachconf.runner import Pool

__all__ = ["run_protocol"]


def _nominal(cache: Path) -> dict:
    path = cache / "nominal.json"
    if path.exists():
        return json.loads(path.read_text())
    nominal = nominal_bicycle_params()
    atomic_write(path, json.dumps(nominal))
    return nominal


def _choose(rows, cache, options, defaults, result, out) -> list:
    """Thresholds and interval method chosen on the tuning rows (into ``result["tuning"]["choice"]``)."""
    choice = choose_thresholds(rows, cache)
    method = choose_interval_method(result["tuning"]["coverage"], defaults.interval)
    chosen = {**choice["chosen"], "interval_method": method}
    current = {k: getattr(defaults, k) for k in chosen}
    result["tuning"]["choice"] = {"chosen": chosen, "best": choice["best"], "defaults": current,
                                  "defaults_are_the_choice": chosen == current}  # fmt: skip
    atomic_write(out / "threshold_grid.json", json_text(choice["grid"]))
    same = " — the same." if chosen == current else " — DIFFERENT (the test set is run with the choice)."
    return ["", f"Chosen on the tuning suites: {chosen} (grid objective {choice['best']['objective']:.3f}); "
            f"DiagnoseOptions defaults: {current}{same}", ""]  # fmt: skip


def run_protocol(args) -> int:
    out = Path(args.out)
    cache = Path(args.cache) if args.cache else out / "cache"
    out.mkdir(parents=True, exist_ok=True)
    cache.mkdir(parents=True, exist_ok=True)
    t0, c0 = time.perf_counter(), time.process_time()
    # the test stage needs the tuning stage's choice: the tuning suites are evaluated first (read back when stored)
    stages = ["tuning"] if args.stage == "tuning" else ["tuning", "test"]
    nominal = _nominal(cache)
    print(f"nominal bicycle parameters (identified on clean runs, seed 99): {nominal}", flush=True)
    defaults = DiagnoseOptions()
    options = {f.name: getattr(defaults, f.name) for f in dataclasses.fields(defaults)}
    options.update(TUNING_RUN_THRESHOLDS)  # the tuning suites' run; the test set is run with the choice
    if getattr(args, "loss_scale", None):
        options["loss_scale"] = args.loss_scale
    if getattr(args, "start_state", None):
        options["start_state"] = args.start_state
    result = {"nominal": nominal, "fit_params": list(FIT), "options": options, "test_seed": args.test_seed}
    md = ["# Diagnosis validation protocol", ""]
    with Pool(args.workers, getattr(args, "scheduler", None)) as pool:  # the run's one pool
        for stage in stages:
            specs = specs_for(stage, args.test_seed)
            if args.available:  # tabulate what is stored (e.g. a run stopped at a deadline): no new work
                rows = [r for r in (stored_row(s, cache, nominal, FIT, options) for s in specs) if r is not None]
                result[f"{stage}_suites_planned"] = len(specs)
                if not rows:
                    continue
            elif args.generate_only:
                made = pool.map(generate_job, [(s, str(cache)) for s in specs], desc=f"{stage} suites", unit="suite")
                result[f"{stage}_generation_cpu_seconds"] = sum(c for _, c in made)
                continue
            else:  # one task per suite (made, then diagnosed), categories interleaved: every finished prefix is a sample
                order = interleaved(specs)
                done = pool.map(suite_job, [(s, str(cache), nominal, FIT, options, args.redo) for s in order],
                                desc=f"{stage} suites", unit="suite")  # fmt: skip
                rank = {s.name: i for i, s in enumerate(specs)}
                rows = sorted(done, key=lambda r: rank[r["spec"]["name"]])
            result[stage] = {"rows": rows, "coverage": coverage(rows), "options": dict(options)}
            title = f"{stage.capitalize()} set ({len(rows)} suites)"
            if len(rows) < len(specs):
                title = f"{stage.capitalize()} set ({len(rows)} of the {len(specs)} suites: the run was stopped)"
            md.append(summary_tables(rows, title))
            if stage == "tuning":
                md += _choose(rows, cache, options, defaults, result, out)
                options = {**options, **result["tuning"]["choice"]["chosen"]}  # the test set is run with the choice
                if args.no_tubes:  # the before/after reach tubes are not judged: skipped on the test set
                    options["tube_horizon"] = 0.0
            cpu = sum(r["cpu_seconds"] for r in rows)
            md.append(f"Diagnosis CPU time: {cpu:.0f} s for {len(rows)} suites (mean {cpu / len(rows):.1f} s, "
                      f"max {max(r['cpu_seconds'] for r in rows):.1f} s).\n")  # fmt: skip
    result["seconds"] = time.perf_counter() - t0
    result["cpu_seconds_main"] = time.process_time() - c0
    atomic_write(out / "protocol.json", json_text(result))
    atomic_write(out / "protocol.md", "\n".join(md))
    print("\n".join(md))
    return 0
