"""The adaptive default from a point or a thin box: the rates' radius floor (``AdaptiveReach.rtol``/``atol``).

Systems not used to choose ``rtol`` and ``atol`` (ARCH-COMP / Flow* benchmarks), each from a point and
from a box of radius 1e-7, with the radius alone (``rtol = atol = 0``, the behaviour before the floor) and
with the defaults.  Prints the steps, CPU seconds (warm), the widest time-point set and how many of the
simulated trajectories (the point's; the box's two corners and 18 random points; 201 samples) leave
their sets.  Run::

    python benchmarks/bench_points.py [--systems jet_engine,lorenz]
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import sympy as sp
from scipy.integrate import solve_ivp

import reachconf as rc
from reachconf.model import Model


def _model(name, states, f):
    return Model(name=name, states=states, dynamics=f, description=f"{name} (benchmarks/bench_points.py)")


def _bio(x, m=None):
    x1, x2, x3, x4, x5, x6, x7 = x
    return [-0.4 * x1 + 5 * x3 * x4, 0.4 * x1 - x2, x2 - 5 * x3 * x4, 5 * x5 * x6 - 5 * x3 * x4,
            -5 * x5 * x6 + 5 * x3 * x4, 0.5 * x7 - 5 * x5 * x6, -0.5 * x7 + 5 * x5 * x6]  # fmt: skip


#: name -> (states, right-hand side f(x, m) with m = numpy or sympy, x0, horizon)
SYSTEMS = {
    "jet_engine": (("x", "y"), lambda x, m: [-x[1] - 1.5 * x[0] ** 2 - 0.5 * x[0] ** 3 - 0.5, 3 * x[0] - x[1]],
                   [1.0, 1.0], 10.0),
    "brusselator": (("x", "y"), lambda x, m: [1 + x[0] ** 2 * x[1] - 2.5 * x[0], 1.5 * x[0] - x[0] ** 2 * x[1]],
                    [0.9, 0.1], 10.0),
    "roessler": (("x", "y", "z"), lambda x, m: [-x[1] - x[2], x[0] + 0.2 * x[1], 0.2 + x[2] * (x[0] - 5.7)],
                 [0.0, -8.4, 0.0], 6.0),
    "biology7": (tuple(f"x{i}" for i in range(1, 8)), _bio, [1.0] * 7, 2.0),
    "robertson": (("x", "y", "z"), lambda x, m: [-0.4 * x[0] + 100 * x[1] * x[2],
                                                 0.4 * x[0] - 100 * x[1] * x[2] - 1000 * x[1] ** 2, 1000 * x[1] ** 2],
                  [1.0, 0.0, 0.0], 40.0),
    "spring_pendulum": (("r", "th", "dr", "dth"),
                        lambda x, m: [x[2], x[3], x[0] * x[3] ** 2 + 9.81 * m.cos(x[1]) - 2 * (x[0] - 1),
                                      -(2 * x[2] * x[3] + 9.81 * m.sin(x[1])) / x[0]],
                        [1.2, 0.5, 0.0, 0.0], 3.0),
    "production_destruction": (("x", "y", "z"),
                               lambda x, m: [-x[0] * x[1] / (1 + x[0]), x[0] * x[1] / (1 + x[0]) - 0.3 * x[1],
                                             0.3 * x[1]],
                               [9.98, 0.01, 0.01], 100.0),
    "lorenz": (("x", "y", "z"), lambda x, m: [10 * (x[1] - x[0]), x[0] * (28 - x[2]) - x[1], x[0] * x[1] - 8 / 3 * x[2]],
               [15.0, 15.0, 36.0], 1.0),
}  # fmt: skip


def run(name, radius, options, rng):
    """``(steps, cpu, widest, outside, n_trajectories)`` or the ReachError's text."""
    states, f, x0, horizon = SYSTEMS[name]
    model = _model(name, states, lambda s: f([getattr(s, v) for v in states], sp))
    x0 = np.asarray(x0, dtype=float)
    X0 = rc.Interval(x0 - radius, x0 + radius)
    times = np.linspace(0.0, horizon, 201)
    try:  # build the model's functions first
        rc.reach(model, X0, min(horizon, 0.01), options=rc.ReachOptions())
    except rc.ReachError:
        pass
    c0 = time.process_time()
    try:
        tube = rc.reach(model, X0, times, options=options)
    except rc.ReachError as exc:
        return f"ReachError at {str(exc).split(' at t = ')[-1].split(' (')[0]}"
    cpu = time.process_time() - c0
    widths = np.array([s.interval().hi - s.interval().lo for s in tube.time_point_sets])
    lo, hi = x0 - radius, x0 + radius
    starts = [x0] if radius == 0.0 else np.vstack([lo, hi, rng.uniform(lo, hi, size=(18, x0.size))])
    outside = 0
    for p in starts:
        # the reference's absolute tolerance far below the smallest state (production-destruction's y falls to
        # 5e-11: with atol 1e-13 the reference, not the tube, was 3e-15 off at t >= 96 s)
        stiff = name == "robertson"
        X = solve_ivp(lambda t, v: f(v, np), (0.0, horizon), p, t_eval=times, rtol=1e-11 if stiff else 1e-12,
                      atol=1e-13 if stiff else 1e-24, method="Radau" if stiff else "DOP853").y.T
        outside += any(not tube.time_point_sets[k].contains(X[k], tol=1e-9) for k in range(times.size))
    return tube.log.steps, cpu, widths.max(), outside, len(starts)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--systems", default=",".join(SYSTEMS), help="comma-separated names (default: all)")
    args = parser.parse_args(argv)
    settings = [("radius alone", rc.ReachOptions(algorithm=rc.AdaptiveReach(rtol=0.0, atol=0.0))),
                ("defaults", rc.ReachOptions())]
    rng = np.random.default_rng(0)
    print(f"{'system':24s} {'start':>11s} {'setting':>13s}  steps, CPU s (warm), widest set, trajectories outside")
    for name in args.systems.split(","):
        for radius in (0.0, 1e-7):
            for label, opts in settings:
                r = run(name, radius, opts, rng)
                start = "point" if radius == 0.0 else f"radius {radius:g}"
                cells = r if isinstance(r, str) else f"{r[0]:6d}  {r[1]:7.3f}  {r[2]:.2e}  {r[3]}/{r[4]}"
                print(f"{name:24s} {start:>11s} {label:>13s}  {cells}", flush=True)


if __name__ == "__main__":
    main()
