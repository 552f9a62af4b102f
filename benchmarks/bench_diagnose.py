"""Gap-diagnosis benchmark: one 18-case vehicle suite as in issue 18 (goal: under 30 s on 2 cores).

The suite: the multi-body plant with a 0.15 s steering lag withheld, lane change,
double lane change and slalom at 2 and 4 m/s², 3 runs each, the controller's
commands recorded as inputs (the protocol's suite generator,
``examples/diagnose/protocol.py``); generated once into ``--cache``.  Prints the
wall-clock and CPU time of ``rc.diagnose`` per step, for the call a new user
makes (``rc.diagnose(bicycle(), suite)``, every parameter refitted) and for the
protocol's set-up (identified nominal parameters, four refitted), and the
number of model fits.  The issue measured 85-90 s for the former (27 candidates
at 2-4 s each).  Machine load inflates both figures; compare CPU time.  The
new user's call runs twice: with the default ``workers`` (one forked process
per core for the candidates' fits) and, as the baseline of the same run, with
``workers=1`` (everything in this process); the report must be the same.

Run: ``python benchmarks/bench_diagnose.py [--cache DIR] [--repeat 1]``
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "examples" / "diagnose"))

from protocol import SuiteSpec, steering_lag  # noqa: E402
from protocol_eval import load_or_make  # noqa: E402
from withheld import nominal_bicycle_params  # noqa: E402

import reachconf as rc  # noqa: E402
from reachconf.models import bicycle  # noqa: E402

FIT = ("J_m", "b_L", "c_f", "c_r")


def suite_spec() -> SuiteSpec:
    changes, truth = steering_lag(0.15)
    groups = tuple((k, a) for k in ("LC", "DLC", "SL") for a in (2.0, 4.0))
    return SuiteSpec("bench-18-cases", "benchmark", "steering lag", groups, changes, tuple(truth), 1.0, 3, 424242)


def _run(label, model, suite, **kw):
    t0 = time.perf_counter()
    rep = rc.diagnose(model, suite, progress=False, **kw)
    wall, cpu = time.perf_counter() - t0, rep.cpu_seconds  # CPU incl. the fit workers'
    steps = ", ".join(f"{k} {v:.1f}" for k, v in rep.base["cpu_seconds_by_step"].items())
    print(f"{label}: {wall:.1f} s wall, {cpu:.1f} s CPU, {rep.base['workers']} process(es) for the fits ({steps})")
    print(f"  verdict: {rep.verdict[:160]}")
    return wall, cpu, rep


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--cache", default=os.path.join(os.environ.get("REACHCONF_CACHE", "."), "bench_diagnose"))
    ap.add_argument("--repeat", type=int, default=1)
    args = ap.parse_args()
    t0 = time.perf_counter()
    suite = load_or_make(suite_spec(), args.cache)
    path = Path(args.cache) / "nominal.json"
    if not path.exists():
        path.write_text(json.dumps(nominal_bicycle_params()))
    nominal = json.loads(path.read_text())  # the data sheet, c_f and c_r identified on clean runs (seed 99)
    print(f"suite: {len(list(suite))} cases, {sum(c.t.size for c in suite)} samples "
          f"(generated or loaded in {time.perf_counter() - t0:.0f} s)")  # fmt: skip
    _run("warm-up (compiled code, small)", bicycle(**nominal), list(suite)[:4], fit_params=FIT)
    for _ in range(args.repeat):
        w1, c1, r1 = _run("rc.diagnose(bicycle(), suite)", bicycle(), suite)
        w0, c0, r0 = _run("baseline: rc.diagnose(bicycle(), suite, workers=1)", bicycle(), suite, workers=1)
        same = r0.verdict == r1.verdict and r0.decision == r1.decision
        w2, c2, _ = _run("rc.diagnose(bicycle(**nominal), suite, fit_params=FIT)", bicycle(**nominal), suite,
                         fit_params=FIT)  # fmt: skip
        print(f"goal < 30 s: new user {w1:.1f} s wall / {c1:.1f} s CPU; protocol set-up {w2:.1f} s / {c2:.1f} s CPU; "
              f"issue's figure 85-90 s: ratio {87.5 / w1:.1f}x (wall, new user)")  # fmt: skip
        print(f"fit workers: {r1.base['workers']} processes {w1:.1f} s against 1 process {w0:.1f} s wall: "
              f"{w0 / w1:.2f}x; same report: {same}")  # fmt: skip


if __name__ == "__main__":
    main()
