"""The diagnosis at low sample rates, checked on plants its low-rate defaults were not chosen on.

    python examples/diagnose/low_rate_check.py [--out low_rate_check.json] [--rate 10]

A mass-spring-damper and a pendulum, simulated on a 1-kHz grid with the
recorded command held over each sample interval (delayed for a dead time, a
lag as a state), sampled at 20 and 50 Hz with 2 % noise: lags of 0.02, 0.04
and 0.08 s, dead times of 0.03 and 0.06 s and none, two seeds (48 suites).
Each suite is diagnosed with the defaults before 3 Dec (``substeps=1``: a
lag's output held over each sample interval; ``smooth_span=None``: an
11-sample smoothing window at every rate) and with the defaults (RK4 steps of
at most 0.01 s with the effect on every step, the window at most 0.3 s long;
both chosen on a DC motor and a tank, other plants); one line per diagnosis:
status, named effects, the estimate with its 95 % interval, error and whether
the interval covers the truth.  Results: docs/notes/diagnosis.md, "Low sample
rates" (about 4 minutes on one core).  ``--rate 10``: the same plants at 10 Hz
with the defaults only (lags of 0.04, 0.08 and 0.15 s, dead times of 0.06 and
0.12 s and none, two other seeds; 24 suites): "Below 20 Hz" there.
"""

import argparse
import json
import time

import numpy as np
import sympy as sp

import reachconf as rc
from reachconf.diagnose import EFFECTS, DiagnoseOptions
from reachconf.model.simulate import simulate


def msd():
    return rc.Model(name="msd", states=("x", "v"), inputs=("F",), disturbances=("w",),
                    params={"k": 40.0, "c": 3.0, "m": 1.0},
                    dynamics=lambda s: [s.v, (s.F - s.c * s.v - s.k * s.x) / s.m + s.w])  # fmt: skip


def pendulum():
    return rc.Model(name="pend", states=("th", "om"), inputs=("u",), disturbances=("w",),
                    params={"g_l": 9.81, "b": 0.5},
                    dynamics=lambda s: [s.om, -s.g_l * sp.sin(s.th) - s.b * s.om + s.u + s.w])  # fmt: skip


#: plant -> (model, input, start state, command mean, command amplitude)
PLANTS = {"msd": (msd, "F", (0.0, 0.0), 8.0, 6.0), "pend": (pendulum, "u", (0.3, 0.0), 2.0, 2.0)}


def suite(plant, effect, value, fs, seed, n=6, dur=20.0, noise=0.02, controller="sampled"):
    """``n`` runs of random holds (0.1-0.5 s) through the plant with the withheld ``effect`` (or None); the
    commands change at the samples (``controller="sampled"``: a controller at the log's rate) or at any
    millisecond (``"fast"``: the log keeps every ``1000 / fs``-th command of a 1-kHz controller)."""
    make, inp, x0, mean, amp = PLANTS[plant]
    base = make()
    rng = np.random.default_rng(seed)
    t = np.round(np.arange(0, dur + 1e-9, 1 / fs), 10)
    ff = 1000.0
    tf = np.round(np.arange(0, dur + 1e-9, 1 / ff), 10)
    every = int(round(ff / fs))
    cases = []
    for i in range(n):
        holds = rng.uniform(0.1, 0.5, size=400).cumsum()
        levels = mean + amp * rng.uniform(-1, 1, size=holds.size)
        if controller == "sampled":
            u = levels[np.searchsorted(holds, t)]
            u_f = u[np.minimum(np.floor(tf * fs + 1e-9).astype(int), t.size - 1)]  # held over each sample interval
        else:
            u_f = levels[np.searchsorted(holds, tf)]
            u = u_f[::every]
        if effect == "dead_time":
            shift = int(round(value * ff))
            u_f = np.concatenate([np.full(shift, u_f[0]), u_f[: tf.size - shift]])
        if effect == "actuator_lag":
            pl = EFFECTS["actuator_lag"].apply_model(base, inp, (value,))
            X = simulate(pl, list(x0) + [u[0]], tf, inputs=u_f[:, None], substeps=2)[:, : base.n]
        else:
            X = simulate(base, list(x0), tf, inputs=u_f[:, None], substeps=2)
        X = X[::every]
        Y = X + rng.normal(size=X.shape) * noise * np.std(X, axis=0)
        cases.append(rc.TestCase(f"c{i}", f"g{i % 3}", t, u[:, None], Y, (inp,), base.state_names))
    return base, rc.TestSuite(cases)


def diagnosed(base, s, effect, value, opts, **keys) -> dict:
    """Diagnose the suite ``s`` with the options ``opts``; print and return its row (``keys`` first): status, named
    effects, the withheld effect's estimate and 95 % interval."""
    t0 = time.perf_counter()
    rep = rc.diagnose(base, s, effects=["actuator_lag", "dead_time", "input_offset", "input_scale"],
                      progress=False, workers=1, options=DiagnoseOptions(tube_horizon=0.0, **opts))
    named = rep.decision.get("named", [])
    est = iv = None
    for e in named:
        if e["effect"] == effect:
            k = list(e["params"])[0]
            est, iv = e["params"][k], e["interval"][k]
    row = dict(keys, effect=effect, value=value, status=rep.decision["status"], named=[e["effect"] for e in named],
               est=est, iv=iv, secs=time.perf_counter() - t0)  # fmt: skip
    what = ""
    if est is not None:
        what = (f"{est:.4f} [{iv[0]:.4f}, {iv[1]:.4f}] error {100 * (est / value - 1):+.1f} % "
                f"covered {iv[0] <= value <= iv[1]}")  # fmt: skip
    print(*keys.values(), effect, value, row["status"], row["named"], what, f"{row['secs']:.1f} s", flush=True)
    return row


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="low_rate_check.json")
    ap.add_argument("--rate", type=float, default=None,
                    help="only this rate (Hz) with the defaults: lags 0.04, 0.08, 0.15 s, dead times 0.06, 0.12 s "
                         "and none, seeds 31 and 32 (the 10-Hz check: --rate 10)")  # fmt: skip
    args = ap.parse_args()
    if args.rate is not None and not (args.rate > 0 and args.rate <= 1000):  # the plants are simulated at 1 kHz
        ap.error(f"--rate must be in (0, 1000] Hz, got {args.rate:g}")
    if args.rate is not None:
        rows = []
        for plant in ("msd", "pend"):
            for effect, values in (("actuator_lag", (0.04, 0.08, 0.15)), ("dead_time", (0.06, 0.12)), (None, (0,))):
                for value in values:
                    for seed in (31, 32):
                        base, s = suite(plant, effect, value, args.rate, seed)
                        rows.append(diagnosed(base, s, effect, value, {}, plant=plant, fs=args.rate, seed=seed,
                                              setting="default"))  # fmt: skip
        with open(args.out, "w") as f:
            json.dump(rows, f)
        return 0
    jobs = [(plant, effect, value, fs, seed)
            for plant in ("msd", "pend")
            for effect, values in (("actuator_lag", (0.02, 0.04, 0.08)), ("dead_time", (0.03, 0.06)), (None, (0,)))
            for value in values for fs in (20.0, 50.0) for seed in (11, 12)]  # fmt: skip
    rows = []
    for plant, effect, value, fs, seed in jobs:
        base, s = suite(plant, effect, value, fs, seed)
        for setting, opts in (("before", {"substeps": 1, "smooth_span": None}), ("default", {})):
            rows.append(diagnosed(base, s, effect, value, opts, plant=plant, fs=fs, seed=seed, setting=setting))
    with open(args.out, "w") as f:
        json.dump(rows, f)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
