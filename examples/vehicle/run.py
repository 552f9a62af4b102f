"""Vehicle use case end to end (source report sections 4-5): Tables 3, 4, 6, 8 and Figures 7-8.

    python examples/vehicle/run.py --out DIR [--quick] [--workers 2]

0. the campaign: 4 maneuvers x 2 lateral accelerations x 5 repetitions from the
   multi-body plant (``reachconf.campaign``), saved to DIR/campaign and reused;
1. identification of the nominal bicycle parameters (J/m, b/L, c_f, c_r) by
   least squares (equation error on smoothed state derivatives);
2. trace conformance: f_B with measured inputs (Table 3) and f_BX with
   requested inputs after identifying Table 2's actuator parameters (Table 4);
3. reachset-conformance synthesis of the closed-loop model for all eight
   maneuvers: steps 1-3 per case and the merge per maneuver (Table 6);
4. X-Y reach tubes with the measured traces, one per maneuver (Figures 7, 8);
5. Table 8: trace bounds of f_B against the plant with every actuator effect
   and all noise switched off, open loop (feed-forward only) and closed loop.

Writes DIR/vehicle.json (keys table3, table4, table6, table8, timings, ...),
DIR/vehicle.md and the PNGs.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from identify import fit_actuators, fit_bicycle  # noqa: E402

import reachconf as rc  # noqa: E402
from reachconf.campaign.generate import make_campaign  # noqa: E402
from reachconf.campaign.plant import NO_EFFECTS  # noqa: E402
from reachconf.conformance import SynthesisOptions, synthesize_W  # noqa: E402
from reachconf.io import atomic_write_text, load_suite  # noqa: E402
from reachconf.models import bicycle, bicycle_actuated, bicycle_closed_loop  # noqa: E402

DEG = np.pi / 180
#: Table 3 measurement errors (X, Y, psi, vx, vy, omega); the report's nu_4 (pitch) has no counterpart here
V_TABLE3 = np.array([0.04, 0.04, 1 * DEG, 0.05, 0.05, 2 * DEG])
#: Table 4 measurement errors (+ measured ax [m/s^2] and delta [rad])
V_TABLE4 = np.array([0.04, 0.04, 1 * DEG, 0.2, 0.2, 2 * DEG, 2.0, 1 * DEG])
#: Table 5 measurement errors used for reachset conformance
V_TABLE5 = np.array([0.05, 0.05, 0.5 * DEG, 0.1, 0.1, 0.8 * DEG])
REF = ("X_ref", "Y_ref", "psi_ref", "v_ref", "kappa_ref")


def box(r):
    return rc.Interval(-np.asarray(r, float), np.asarray(r, float))


def pairs(W):
    return [[float(a), float(b)] for a, b in zip(W.lo, W.hi)]


def trace_table(model, suite, V, select, workers, decimate=4):
    """Minimal trace bounds (Alg. 2 boxes, verified) per group and their hull (Tables 3/4 analogue).

    The per-step traces of section 3.2.1 drift out of V on these noisy
    measurements, so the boxes come from the optimal-control formulation on
    every ``decimate``-th sample (25 Hz; the QP cost grows with the samples).
    """
    from reachconf.io import TestSuite

    cases = suite.map(lambda c: c.select(*select).decimate(decimate))
    out = {}
    for g, members in cases.groups().items():
        try:
            out[g] = pairs(rc.minimal_trace_bounds(model, TestSuite(members, name=g), V=V, method="optctrl",
                                                   workers=workers))  # fmt: skip
        except rc.ReachconfError as exc:
            out[g] = f"not verified: {exc}"
    boxes = [np.array(b) for b in out.values() if not isinstance(b, str)]
    key = "all" if len(boxes) == len(out) else "hull_of_verified_groups"
    if boxes:
        out[key] = np.stack([np.min([b[:, 0] for b in boxes], axis=0), np.max([b[:, 1] for b in boxes], axis=0)],
                            axis=1).tolist()  # fmt: skip
    return out


def plot_tubes(model, suite, synth, V, out, opts):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from reachconf.conformance import reachset_conformance

    files = []
    for g, members in suite.groups().items():
        W = synth.groups.get(g)
        if W is None:
            continue
        fig, ax = plt.subplots(figsize=(10, 3.2))
        res = reachset_conformance(model, members[0], W, V, options=opts)
        if res.tube is not None:
            res.tube.plot(dims=("X", "Y"), ax=ax, color="C0", alpha=0.2, outline=False, label="reach tube, W_RC,Mnvr")
        for i, c in enumerate(members):
            ax.plot(c.signal("X"), c.signal("Y"), ".", ms=1, color="k", label="measured" if i == 0 else None)
        ax.set_title(f"{g}: X-Y reach tube of the closed-loop model (case {members[0].name}) and all measured runs")
        ax.set_xlabel("X [m]")
        ax.set_ylabel("Y [m]")
        ax.legend(loc="upper left", fontsize=7)
        fig.tight_layout()
        path = out / f"tube_{g}.png"
        fig.savefig(path, dpi=110)
        plt.close(fig)
        files.append(str(path))
    return files


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", required=True)
    ap.add_argument("--quick", action="store_true", help="1 repetition per maneuver, fewer alpha steps")
    ap.add_argument("--workers", type=int, default=None)
    args = ap.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    reps = 1 if args.quick else 5
    timings = {}

    t0 = time.perf_counter()
    camp_dir = out / ("campaign_quick" if args.quick else "campaign")
    if (camp_dir / "suite.toml").exists():
        suite = load_suite(camp_dir)
    else:
        suite = make_campaign(camp_dir, repetitions=reps)
    # Table 8's campaigns: no actuator effects, no noise; feed-forward only and closed loop
    plain = {}
    for label, ff in (("open_loop", True), ("closed_loop", False)):
        folder = out / f"campaign_no_effects_{label}"
        if (folder / "suite.toml").exists():
            plain[label] = load_suite(folder)
        else:
            plain[label] = make_campaign(folder, effects=NO_EFFECTS, repetitions=1, feedforward_only=ff)
    timings["campaign"] = time.perf_counter() - t0
    print(f"campaign: {len(suite)} cases, groups {list(suite.groups())} ({timings['campaign']:.1f} s)")
    t_after = time.perf_counter()

    # 1. identification of the nominal bicycle parameters
    t0 = time.perf_counter()
    params, ident = fit_bicycle(suite)
    fB = bicycle(**params)
    timings["identification"] = time.perf_counter() - t0
    print(f"1. bicycle parameters {params} ({timings['identification']:.1f} s)")

    # 2. Tables 3 and 4
    t0 = time.perf_counter()
    table3 = trace_table(fB, suite, box(V_TABLE3), (("ax", "delta"), fB.output_names), args.workers)
    timings["table3"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    act = fit_actuators(suite)
    fBX = bicycle_actuated(**params, **act["params"])
    table4 = trace_table(fBX, suite, box(V_TABLE4), (("ax_req", "delta_req"), fBX.output_names), args.workers)
    timings["table4"] = time.perf_counter() - t0
    print(f"2. Table 3 ({timings['table3']:.1f} s) and Table 4 ({timings['table4']:.1f} s); actuators {act['params']}")

    # 3. Table 6: closed-loop synthesis for all eight maneuvers
    t0 = time.perf_counter()
    fCL = bicycle_closed_loop(**params)
    cl_suite = suite.map(lambda c: c.select(REF, fCL.output_names))
    ropts = rc.ReachOptions(algorithm="lin", tensor_order=3, time_step=0.01, zonotope_order=20)
    sopts = SynthesisOptions(alpha_iterations=6 if args.quick else 10, step2_decimate=4, reach=ropts)
    synth = synthesize_W(fCL, cl_suite, box(V_TABLE5), sopts, workers=args.workers)
    timings["table6"] = time.perf_counter() - t0
    synth.to_json(out / "synthesis.json")
    print(f"3. Table 6 ({timings['table6']:.1f} s)\n" + synth.table())

    # 4. pictures
    t0 = time.perf_counter()
    pngs = plot_tubes(fCL, cl_suite, synth, box(V_TABLE5), out, ropts)
    timings["figures"] = time.perf_counter() - t0

    # 5. Table 8: f_B against the plant without actuator effects and noise, open and closed loop
    t0 = time.perf_counter()
    table8 = {}
    tiny = box(np.full(6, 1e-3))
    for label, s8 in plain.items():
        table8[label] = trace_table(fB, s8, tiny, (("ax", "delta"), fB.output_names), args.workers)
    timings["table8"] = time.perf_counter() - t0
    timings["after_campaign"] = time.perf_counter() - t_after
    print(f"5. Table 8 ({timings['table8']:.1f} s): " + json.dumps({k: v.get("all", "see groups") for k, v in table8.items()}))

    result = {
        "table3": table3, "table4": table4,
        "table6": {g: pairs(W) for g, W in synth.groups.items()},
        "table6_alpha": synth.group_alpha, "table6_conformant": synth.group_conformant,
        "table6_cases": {k: {"alpha": c.alpha, "conformant": c.conformant, "seconds": c.seconds,
                             "message": c.message} for k, c in synth.cases.items()},
        "table8": table8, "timings": timings,
        "bicycle_parameters": params, "identification": ident, "actuator_parameters": act,
        "V": {"table3": V_TABLE3.tolist(), "table4": V_TABLE4.tolist(), "table5": V_TABLE5.tolist()},
        "pictures": pngs, "cases": len(suite),
    }  # fmt: skip
    atomic_write_text(out / "vehicle.json", json.dumps(result, indent=2, default=float))
    print(f"timings: {json.dumps({k: round(v, 1) for k, v in timings.items()})}")
    print(f"wrote {out / 'vehicle.json'}")
    return 0


if __name__ == "__main__":
    os.environ.setdefault("MPLBACKEND", "Agg")
    sys.exit(main())
