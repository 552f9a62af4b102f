"""Wind turbine on real OpenFAST output (source report section 6, Figures 9-10).

    python examples/windturbine/run.py --data ../shared/data/windturbine --out DIR

For each data file: SI units, the start-up transient left out, inputs Mg
(GenTq, high-speed shaft), theta (BldPitch1; 0 for the FAST.Farm runs, which
do not record pitch and stay below rated), v0 (the rotor-averaged RtVAvgxh
where the file has it, else the hub-height Wind1VelX); outputs Omega
(RotSpeed), xT (TTDspFA), MyT (TwrBsMyt).  Per-step trace conformance
(section 3.2.1; eq. 69 with the output map eq. 80, the relative objective of
eq. 70 and the output-space step of eq. 71), all samples at once; the
re-simulation of the model with the found disturbances against the
reference; the disturbance scatter with the reference derivative boxes of
eq. 72 (Figure 9) and the undisturbed model against the reference (Figure 10).

Writes DIR/windturbine.json: per file ``samples``, ``max_rel_deviation``
(``Omega``, ``xT``, ``MyT``: largest |re-simulated - reference| over the
reference's range), ``W_box`` (three [lo, hi]), ``seconds``.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

import reachconf as rc
from reachconf.conformance import TraceOptions, trace_conformance
from reachconf.conformance.trace import _outputs
from reachconf.datasets.openfast import read_output
from reachconf.io import TestCase, atomic_write_text
from reachconf.models import get_model
from reachconf.simulate import simulate

FILES = {
    "5MW_Land_DLL_WTurb": ("5MW_Land_DLL_WTurb.outb", 10.0),
    "FASTFarm_TSinflow_8mps_T1": ("FASTFarm_TSinflow_8mps_T1.csv.gz", 20.0),
    "FASTFarm_TSinflow_8mps_T2": ("FASTFarm_TSinflow_8mps_T2.csv.gz", 20.0),
}
OUTPUTS = ("Omega", "xT", "MyT")


def make_case(model, path, t_skip, seconds=None):
    out = read_output(path)
    t = out.time
    keep = t >= t_skip
    if seconds is not None:
        keep &= t <= t_skip + seconds
    pitch = np.radians(out["BldPitch1"]) if "BldPitch1" in out.channels else np.zeros_like(t)
    v0 = out["RtVAvgxh"] if "RtVAvgxh" in out.channels else out["Wind1VelX"]
    U = np.column_stack([out["GenTq"] * 1e3, pitch, v0])[keep]
    Y = np.column_stack([out["RotSpeed"] * 2 * np.pi / 60, out["TTDspFA"], out["TwrBsMyt"] * 1e3])[keep]
    return TestCase(Path(path).name.split(".")[0], "wind", t[keep], U, Y, model.input_names, model.output_names)


def evaluate(model, case):
    t0 = time.perf_counter()
    huge = rc.Interval(np.full(model.q, -1e12), np.full(model.q, 1e12))
    # V: the quantisation of the binary output (65,536 levels over each channel's range)
    quant = np.ptp(case.Y, axis=0) / 65536
    V = rc.Interval(-quant, quant)
    res = trace_conformance(model, case, huge, V, method="perstep", options=TraceOptions(objective="relative"))
    Yh = _outputs(model, res.X, np.array(case.U))
    dev = np.max(np.abs(Yh - case.Y), axis=0) / np.ptp(case.Y, axis=0)
    W = res.disturbance_box()
    return res, {
        "samples": int(case.t.size),
        "conformant": bool(res.conformant),
        "max_rel_deviation": dict(zip(OUTPUTS, map(float, dev))),
        "W_box": W.to_list(),
        "seconds": time.perf_counter() - t0,
    }


def plot(model, case, res, out):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from reachconf.conformance.trace import state_estimate

    Xm = state_estimate(model, case)
    dX = np.diff(Xm, axis=0) / np.diff(case.t)[:, None]  # eq. 72 on the states behind the outputs
    lo, hi = dX.min(axis=0), dX.max(axis=0)
    W = res.W_trace
    names = ["e_Omega' [rad/s²]", "e_xT' [m/s]", "e_xT'' [m/s²]"]
    fig, axes = plt.subplots(1, 3, figsize=(13, 3.8))
    for ax, (i, j) in zip(axes, [(0, 1), (1, 2), (0, 2)]):
        ax.plot(W[:, i], W[:, j], ".", ms=1.5, alpha=0.5)
        ax.add_patch(plt.Rectangle((lo[i], lo[j]), hi[i] - lo[i], hi[j] - lo[j], fill=False, lw=1.5, color="k"))
        ax.set_xlabel(names[i])
        ax.set_ylabel(names[j])
    fig.suptitle(f"{case.name}: per-step disturbances and the reference derivative box (eq. 72)")
    fig.tight_layout()
    fig.savefig(out / f"{case.name}_disturbances.png", dpi=110)
    plt.close(fig)
    X0 = simulate(model, Xm[0], case.t, inputs=np.array(case.U), substeps=10)
    Y0 = _outputs(model, X0, np.array(case.U))
    fig, axes = plt.subplots(3, 1, figsize=(9, 7), sharex=True)
    for k, ax in enumerate(axes):
        ax.plot(case.t, case.Y[:, k], "k-", lw=1, label="OpenFAST")
        ax.plot(case.t, Y0[:, k], "C1-", lw=1, label="abstract model, w = 0")
        ax.set_ylabel(OUTPUTS[k])
    axes[0].legend(fontsize=8)
    axes[-1].set_xlabel("t [s]")
    fig.suptitle(f"{case.name}: undisturbed abstract model against the reference (Figure 10)")
    fig.tight_layout()
    fig.savefig(out / f"{case.name}_undisturbed.png", dpi=110)
    plt.close(fig)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default=os.environ.get("REACHCONF_DATA", "../shared/data") + "/windturbine")
    ap.add_argument("--out", required=True)
    ap.add_argument("--seconds", type=float, default=None, help="use only this many seconds per file")
    args = ap.parse_args(argv)
    data = Path(args.data)
    out = Path(args.out)
    model = get_model("wind_turbine")
    result = {}
    try:
        for name, (fname, t_skip) in FILES.items():
            case = make_case(model, data / fname, t_skip, args.seconds)
            res, entry = evaluate(model, case)
            out.mkdir(parents=True, exist_ok=True)
            plot(model, case, res, out)
            result[name] = entry
            dev = ", ".join(f"{k} {v:.2e}" for k, v in entry["max_rel_deviation"].items())
            print(f"{name}: {entry['samples']} samples, max relative deviation {dev}, {entry['seconds']:.1f} s")
    except rc.ReachconfError as exc:
        print(f"windturbine: error: {exc}", file=sys.stderr)
        return 2
    atomic_write_text(out / "windturbine.json", json.dumps(result, indent=2))
    print(f"wrote {out / 'windturbine.json'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
