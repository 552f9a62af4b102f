"""Why DLC_4's trace box ``W_opt`` cannot be reached: a measured diagnosis of the failing reach.

(Table 6's DLC_4 row is verified since 3 Dec 2026 with α < 1 — the α-search bisects below a failed
reach, ``SynthesisOptions.alpha_below_failed_reach`` — but ``W_opt`` itself, α = 1, still explodes:
this script measures why, and what a reach that kept it would need.)

    python examples/vehicle/dlc4.py --campaign DIR/campaign [--runs DLC_4_5,DLC_4_1]
                                    [--steering rate_limited] [--samples 100] [--out FILE.json]
                                    [--params DIR/vehicle.json]

``DIR/campaign`` is the campaign ``run.py --out DIR`` saved.  The models are
identified as in ``run.py`` (step 1; ``--params``: taken from its
``vehicle.json`` instead), then per run:

1. steps 1-2 of the synthesis: ``W_opt``, the smallest trace-conformant box;
2. step 3's reach (eq. 67's initial set, ``W_opt``, α = 1) with Table 6's
   options (tensor order 2 and 3) and with the default ``ReachOptions()``
   (``"adaptive"``): where each fails and why;
3. the same ``W_opt`` on the other steering actuator's model (is the
   actuator's nonlinearity the cause?);
4. the initial set shrunk to its centre (the best any split of the state set
   can do) and α scaled down: when the reach fails then;
5. one channel of ``W_opt`` at a time (the others at their centres): which drive the failure;
6. up to the failure of the tensor-order-2 reach, the width of its sets per
   state over the spread of ``--samples`` simulated trajectories (corners
   of the initial set, corners of ``W`` held or switched at random), and,
   for the rate-limited actuator, the range of the argument
   ``k (delta_t - delta) / r`` of its ``tanh`` in both;
7. the worst case over the whole run (:func:`reachconf.worst_case`): at every half
   second, the largest and smallest steering angle, yaw rate and ``tanh``
   argument any disturbance in ``W_opt`` and start in ``X0`` can reach
   (bang-bang disturbances from the adjoint of the linearised trajectory,
   iterated on the model until no step improves), against the reach's
   range: does the model's *true* reachable set explode, or only the reach?
8. the runs cut into segments of ``--segment-lengths`` seconds
   (:meth:`reachconf.io.TestCase.segments`, the report's section 4.3.3),
   each checked from its own first sample: the synthesis per segment and
   merged over all the runs' segments, and how far the segments' own
   ``W_opt`` centres move from one segment to the next.

Prints the findings and writes them to ``--out`` (JSON: ``{"runs": [one dict per run], "segments": item 8}``).
Measured: 27 s wall for two runs with ``--params`` (items 1-7, warm caches); 52 s for all five DLC_4 runs with
item 8 (the segments of 0.5, 1 and 2 s).
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
# run.py by its path: another example's ``run`` module may already be imported under that name
_spec = importlib.util.spec_from_file_location("vehicle_run_for_dlc4", HERE / "run.py")
R = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(R)

from identify import fit_actuators, fit_bicycle, fit_rate_limited_steering  # noqa: E402

import reachconf as rc  # noqa: E402
from reachconf.conformance.bounds import minimize_box, step1_trace  # noqa: E402
from reachconf.conformance.reachset import initial_set  # noqa: E402
from reachconf.io import load_suite  # noqa: E402
from reachconf.model.simulate import simulate  # noqa: E402
from reachconf.models import bicycle_closed_loop_actuated, bicycle_closed_loop_rate_limited  # noqa: E402
from reachconf.models.vehicle_controller import ControllerGains, tracking_law  # noqa: E402

#: the reaches compared in item 2
OPTIONS = {"order 2": R.REACH_TABLE6_FAST, "order 3": R.REACH_TABLE6, "adaptive": rc.ReachOptions()}
#: α values of item 4
ALPHAS = (0.1, 0.25, 0.5, 1.0)


def models(suite, found=None):
    """Both closed-loop models with the parameters identified on ``suite`` (as in ``run.py``).

    ``found``: ``run.py``'s ``vehicle.json`` as a dict, whose identified parameters are used instead.
    """
    if found is not None:
        params, act = found["bicycle_parameters"], found["actuator_parameters"]["params"]
        steer = found["steering_rate_limited"]["params"]
    else:
        params, _ = fit_bicycle(suite)
        act = fit_actuators(suite)["params"]
        steer = fit_rate_limited_steering(suite)["params"]
    return {"first_order": bicycle_closed_loop_actuated(**params, **act),
            "rate_limited": bicycle_closed_loop_rate_limited(**params, **{**act, **steer})}  # fmt: skip


def reach_until(model, X0, t, U, W, options):
    """``(tube or None, failure time or None, message)`` of the reach over the samples ``t``."""
    try:
        return rc.reach(model, X0, t, inputs=U, W=W, options=options), None, ""
    except rc.ReachError as exc:
        return None, float(exc.time or 0.0), str(exc)


def sample(model, X0, t, U, W, count, seed=1):
    """States (count, K, n) of trajectories from corners/points of X0 with corners of W held or switched."""
    rng = np.random.default_rng(seed)
    lo, hi = X0.lo, X0.hi
    out = []
    for i in range(count):
        x0 = rng.uniform(lo, hi) if i % 2 else np.where(rng.random(lo.size) < 0.5, lo, hi)
        if i % 4 < 2:  # one corner of W held over the whole run
            w = np.tile(np.where(rng.random(model.q) < 0.5, W.hi, W.lo), (t.size - 1, 1))
        else:  # corners switched at random (mean dwell about 0.3 s at 100 Hz)
            switch = np.cumsum(rng.random(t.size - 1) < 0.03)
            w = np.where(rng.random((switch[-1] + 1, model.q)) < 0.5, W.hi, W.lo)[switch]
        out.append(simulate(model, x0, t, inputs=U, disturbances=w, substeps=4))
    return np.array(out)


def tanh_argument(model, X, u):
    """``k (delta_t - delta) / r`` of the rate-limited steering at states ``X (..., n)`` and inputs ``u``."""
    p = model.params
    gains = ControllerGains(**{k: p[f"gain_{k}"] for k in ControllerGains.__dataclass_fields__})
    _, cmd = tracking_law(*[X[..., i] for i in range(6)], *u, gains)
    target = (cmd / p["delta_s_nominal"] + p["delta_off"]) * p["delta_s"]
    return p["k_delta"] * (target - X[..., 7]) / p["r_delta"]


def worst_cases(model, tube, X0, t, U, W):
    """Item 7: per half second, the worst-case range of delta, omega (and the tanh argument) against the reach's."""
    names = model.state_names
    funcs = {"delta": lambda x, u: x[names.index("delta")], "omega": lambda x, u: x[names.index("omega")]}
    if model.name == "bicycle_closed_loop_rate_limited":
        funcs["tanh argument"] = lambda x, u: tanh_argument(model, x, u)
    rows = []
    for K in range(50, t.size, 50):
        row = {"t": float(t[K])}
        for label, g in funcs.items():
            hi = rc.worst_case(model, X0, t, g, inputs=U, W=W, at=K).value
            lo = -rc.worst_case(model, X0, t, lambda x, u: -g(x, u), inputs=U, W=W, at=K).value
            row[label] = [round(lo, 4), round(hi, 4)]
            if tube is not None and K < len(tube.times):
                Z = tube.time_point_sets[K]
                cz, G = np.asarray(Z.center), np.asarray(Z.generators)
                g0 = g(cz, U[K])
                grad = np.array([(g(cz + 1e-6 * e, U[K]) - g0) / 1e-6 for e in np.eye(cz.size)])  # affine in x
                rad = float(np.abs(grad @ G).sum())
                row[label + " reach"] = [round(g0 - rad, 4), round(g0 + rad, 4)]
        rows.append(row)
    return rows


def widths(model, tube, X, U):
    """Per sample time of the tube: reach width / sampled spread per state, and the tanh argument's ranges."""
    rows = []
    for k in range(0, len(tube.times), 10):
        Z = tube.time_point_sets[k]
        iv = Z.interval()
        spread = np.maximum(X[:, k].max(0) - X[:, k].min(0), 1e-12)
        row = {"t": float(tube.times[k]), "ratio": ((iv.hi - iv.lo) / spread).round(2).tolist()}
        if model.name == "bicycle_closed_loop_rate_limited":
            a = tanh_argument(model, X[:, k], U[k])
            c, G = np.asarray(Z.center), np.asarray(Z.generators)  # the argument is affine in the state
            a0 = tanh_argument(model, c, U[k])
            grad = np.array([(tanh_argument(model, c + 1e-6 * e, U[k]) - a0) / 1e-6 for e in np.eye(c.size)])
            rad = float(np.abs(grad @ G).sum())
            row["arg_samples"] = [round(float(a.min()), 3), round(float(a.max()), 3)]
            row["arg_reach"] = [round(float(a0 - rad), 3), round(float(a0 + rad), 3)]
        rows.append(row)
    return rows


def diagnose(name, suite, built, steering, count):
    """Items 1-5 of the module docstring for one run."""
    model, other = built[steering], built["first_order" if steering == "rate_limited" else "rate_limited"]
    case = next(c for c in suite if c.name == name).select(R.REF, model.output_names)
    V = R.box(R.V_TABLE6)
    start, _ = step1_trace(model, case, V, "auto", rc.TraceOptions())
    W_opt, res = minimize_box(model, case, V, start.disturbance_box(), start, options=rc.TraceOptions())
    t, U, _ = case.case_arrays(model)
    t = t - t[0]
    X0 = initial_set(model, case, V).interval()
    out = {"run": name, "steering": steering, "W_opt": R.pairs(W_opt), "trace_conformant": bool(res.conformant),
           "reach": {}, "other_actuator": {}, "alpha": {}}  # fmt: skip
    for label, opts in OPTIONS.items():
        _, when, msg = reach_until(model, X0, t, U, W_opt, opts)
        out["reach"][label] = {"fails_at": when, "message": msg[:400]}
    _, when, msg = reach_until(other, X0, t, U, W_opt, OPTIONS["order 2"])
    out["other_actuator"] = {"model": other.name, "fails_at": when, "message": msg[:200]}
    point = rc.Interval(X0.center, X0.center)
    for a in ALPHAS:
        W = rc.Interval(W_opt.center - a * W_opt.radius, W_opt.center + a * W_opt.radius)
        out["alpha"][str(a)] = {"fails_at": reach_until(model, X0, t, U, W, OPTIONS["order 2"])[1],
                                "fails_at_from_centre": reach_until(model, point, t, U, W, OPTIONS["order 2"])[1]}
    c, g = W_opt.center, W_opt.radius
    out["channels"] = {}
    for j, name_j in enumerate(model.disturbance_names):
        only = np.where(np.arange(g.size) == j, g, 0.0)
        out["channels"][name_j] = {"radius": float(g[j]), "fails_at": reach_until(
            model, X0, t, U, rc.Interval(c - only, c + only), OPTIONS["order 2"])[1]}  # fmt: skip
    X = sample(model, X0, t, U, W_opt, count)
    when = out["reach"]["order 2"]["fails_at"]
    cut = t.size if when is None else int(np.searchsorted(t, when - 0.05))
    tube, _, _ = reach_until(model, X0, t[:cut], U[:cut], W_opt, OPTIONS["order 2"])
    out["widths"] = [] if tube is None else widths(model, tube, X, U)
    out["sampled_spread_max"] = (X.max(0) - X.min(0)).max(0).round(4).tolist()
    out["worst_case"] = worst_cases(model, tube, X0, t, U, W_opt)
    return out


def segmented(model, suite, names, lengths):
    """Item 8: the synthesis on the runs' segments of each length (all the runs' segments as one group)."""
    from reachconf.conformance.synthesis import synthesize_W
    from reachconf.io import TestSuite

    cases = [c.select(R.REF, model.output_names) for c in suite if c.name in names]
    V = R.box(R.V_TABLE6)
    sopts = rc.SynthesisOptions(alpha_iterations=8, merge_iterations=6, alpha_max=4.0, reach=R.REACH_TABLE6_FAST,
                                reach_fallback=R.REACH_TABLE6)  # fmt: skip
    out = {}
    for length in lengths:
        segs = TestSuite([s for c in cases for s in c.segments(length)], name="segments")
        segs = segs.map(lambda s: replace(s, group="DLC_4"))
        res = synthesize_W(model, segs, V, sopts, progress=False)
        centres = np.array([c.W_opt.center for c in res.cases.values()])
        out[str(length)] = {"segments": len(segs), "conformant_alone": sum(c.conformant for c in res.cases.values()),
                            "merged": res.group_verdict["DLC_4"].value, "merged_alpha": res.group_alpha["DLC_4"],
                            "merged_W": R.pairs(res.groups["DLC_4"]),
                            "W_opt_centres": [[round(float(a), 3), round(float(b), 3)]
                                              for a, b in zip(centres.min(0), centres.max(0))]}  # fmt: skip
    return out


def report_segments(seg, names) -> str:
    """Item 8 as text."""
    lines = ["segments (all runs' segments one group; each from its own first sample):"]
    for length, r in seg.items():
        lines.append(f"  {float(length):g} s: {r['conformant_alone']}/{r['segments']} conformant alone, merged "
                     f"{r['merged']} (alpha {r['merged_alpha']:.3g}); the segments' W_opt centres range over "
                     + ", ".join(f"{n} [{a:.2g}, {b:.2g}]" for n, (a, b) in zip(names, r["W_opt_centres"])))
    return "\n".join(lines)


def report(d, names) -> str:
    """The findings of one run as text."""
    fails = (lambda v: "reaches the end" if v is None else f"fails at t = {v:.2f} s")  # noqa: E731
    lines = [f"{d['run']} ({d['steering']}): W_opt " + ", ".join(f"[{a:.3g}, {b:.3g}]" for a, b in d["W_opt"])]
    for label, r in d["reach"].items():
        lines.append(f"  alpha = 1, {label}: {fails(r['fails_at'])}  {r['message'][:160]}")
    lines.append(f"  alpha = 1, same W on {d['other_actuator']['model']}: {fails(d['other_actuator']['fails_at'])}")
    for a, r in d["alpha"].items():
        lines.append(f"  alpha = {a}: {fails(r['fails_at'])}; from the centre of X0 alone: "
                     f"{fails(r['fails_at_from_centre'])}")  # fmt: skip
    lines.append("  one channel of W_opt alone: " + "; ".join(
        f"{n} (±{r['radius']:.3g}) {fails(r['fails_at'])}" for n, r in d["channels"].items()))  # fmt: skip
    lines.append("  t      reach width / sampled spread: " + " ".join(f"{n:>6s}" for n in names)
                 + ("   tanh argument: samples | reach" if d["widths"] and "arg_reach" in d["widths"][0] else ""))
    for w in d["widths"]:
        arg = f"   [{w['arg_samples'][0]:.2f}, {w['arg_samples'][1]:.2f}] | [{w['arg_reach'][0]:.2f}, " \
              f"{w['arg_reach'][1]:.2f}]" if "arg_reach" in w else ""  # fmt: skip
        lines.append(f"  {w['t']:5.2f}  {' ' * 29}" + " ".join(f"{r:6.1f}" for r in w["ratio"]) + arg)
    labels = [k for k in (d["worst_case"][0] if d["worst_case"] else {}) if k != "t" and not k.endswith(" reach")]
    lines.append("  t      worst case over W_opt and X0 (simulated) | order-2 reach: " + ", ".join(labels))
    for w in d["worst_case"]:
        cells = [f"[{w[k][0]:.3f}, {w[k][1]:.3f}]" + (f" | [{w[k + ' reach'][0]:.3f}, {w[k + ' reach'][1]:.3f}]"
                                                      if k + " reach" in w else "") for k in labels]  # fmt: skip
        lines.append(f"  {w['t']:5.2f}  " + "   ".join(cells))
    return "\n".join(lines)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--campaign", required=True, help="the campaign folder run.py saved (DIR/campaign)")
    ap.add_argument("--runs", default="DLC_4_5", help="comma-separated case names")
    ap.add_argument("--steering", choices=("first_order", "rate_limited"), default="rate_limited")
    ap.add_argument("--samples", type=int, default=100, help="simulated trajectories per run")
    ap.add_argument("--out", default=None, help="JSON file for the findings")
    ap.add_argument("--params", default=None, help="run.py's vehicle.json: its identified parameters")
    ap.add_argument("--segment-lengths", default="0.5,1,2", help="item 8: comma-separated segment lengths (s)")
    args = ap.parse_args(argv)
    from reachconf.io import atomic_write

    try:
        suite = load_suite(Path(args.campaign))
        names = args.runs.split(",")
        unknown = sorted(set(names) - {c.name for c in suite})
        if unknown:
            raise rc.DataError(f"--runs: {args.campaign} has no cases {unknown}")
        built = models(suite, json.loads(Path(args.params).read_text()) if args.params else None)
        found = []
        for name in names:
            d = diagnose(name, suite, built, args.steering, args.samples)
            print(report(d, built[args.steering].state_names), flush=True)
            found.append(d)
        model = built[args.steering]
        seg = segmented(model, suite, names, [float(x) for x in args.segment_lengths.split(",") if x])
        print(report_segments(seg, model.disturbance_names), flush=True)
        if args.out:
            atomic_write(Path(args.out), json.dumps({"runs": found, "segments": seg}, indent=1))
    except (rc.ReachconfError, OSError, json.JSONDecodeError) as exc:
        print(f"dlc4: error: {exc}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
