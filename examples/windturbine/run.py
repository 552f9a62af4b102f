"""Wind turbine on real OpenFAST output (source report section 6, Figures 9-10).

    python examples/windturbine/run.py --data ../shared/data/windturbine --out DIR [--quick]

For each data file (the README of the data folder describes them):

* SI units (rpm -> rad/s, kN·m -> N·m, deg -> rad); the start-up transient is
  left out (t < 10 s for the 60 s land-based run, t < 20 s for the 90 s
  FAST.Farm runs, as the data README suggests).
* Inputs: ``Mg`` = GenTq (high-speed shaft, as the model expects),
  ``theta`` = BldPitch1 (the FAST.Farm runs record no pitch; they stay below
  rated, so theta = 0 as the README says — an inference, not a record),
  ``v0`` = RtVAvgxh where the file has it (the rotor-disk average of the
  longitudinal wind, the report's definition of the rotor-effective wind
  speed, section 6.2.3), else Wind1VelX (the only wind channel of the
  land-based run: a single hub-height point, which over-estimates the
  rotor-effective power of the turbulent wind).
  Outputs ``Omega`` = RotSpeed, ``xT`` = TTDspFA, ``MyT`` = TwrBsMyt.
* Aero maps of eq. 78: ``--aero fit`` (default) refits the cP/cT polynomials
  to the NREL 5-MW performance table over the (tip-speed ratio, pitch) box
  the turbine visits in that file; ``--aero default`` keeps the model's
  whole-table fit.  Both are always evaluated for the undisturbed model.
* Per-step trace conformance (section 3.2.1; eq. 69 with the output map
  eq. 80, the relative objective eq. 70, the output-space step eq. 71) on
  every sample, vectorised; the model is re-simulated with the found
  disturbances (Alg. 1 line 3) and its largest deviation from the reference
  is reported as a fraction of each output's range (the report: < 0.1 %).
* Figure 9 analogue (``figure9_disturbances.png``): scatter of w1, w2, w3 of
  all files with the boxes of eq. 72 — the min/max finite-difference
  derivatives of the reference states ``g^{-1}(y)`` (Omega', xT', xT''; the
  derivatives of the outputs themselves, as eq. 72 literally reads, would
  have the units of dMyT/dt, not of w3).  Figure 10 analogue
  (``<file>_undisturbed.png``): the undisturbed model against the reference.

Writes DIR/windturbine.json (per file: ``samples``, ``max_rel_deviation``,
``W_box``, ``seconds`` and the details listed in ``evaluate``); bad --data:
one-line error, exit 2.
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import time
from pathlib import Path

import numpy as np

import reachconf as rc
from reachconf.conformance import TraceOptions, trace_disturbances
from reachconf.datasets.aero import fit_aero, read_performance_table
from reachconf.datasets.openfast import read_output
from reachconf.io import TestCase, atomic_write, json_text
from reachconf.model import evaluate_outputs, simulate, state_estimate
from reachconf.models.windturbine import CP_DEFAULT, CT_DEFAULT, wind_turbine
from reachconf.plot import save_figure

REPO_ROOT = Path(__file__).resolve().parents[2]
#: name -> (file, start of the evaluated window [s], label)
FILES = {
    "5MW_Land_DLL_WTurb": ("5MW_Land_DLL_WTurb.outb", 10.0, "land, 12 m/s, 160 Hz"),
    "FASTFarm_TSinflow_8mps_T1": ("FASTFarm_TSinflow_8mps_T1.csv.gz", 20.0, "FAST.Farm T1, 8 m/s, 10 Hz"),
    "FASTFarm_TSinflow_8mps_T2": ("FASTFarm_TSinflow_8mps_T2.csv.gz", 20.0, "FAST.Farm T2 (wake), 8 m/s, 10 Hz"),
}
TABLE = "Cp_Ct_Cq.NREL5MW.txt"
OUTPUTS = ("Omega", "xT", "MyT")
QUICK_SECONDS = 8.0
RPM = math.pi / 30.0


def default_data() -> Path:
    root = os.environ.get("REACHCONF_DATA")
    return (Path(root) if root else REPO_ROOT.parent / "shared" / "data") / "windturbine"


def make_case(model, path, t_skip, seconds=None):
    """The test case of one file (SI units, transient left out) and what was taken from where."""
    out = read_output(path)
    expected = {"RotSpeed": "rpm", "TTDspFA": "m", "TwrBsMyt": "kN-m", "GenTq": "kN-m", "BldPitch1": "deg"}
    wrong = {n: out.units.get(n) for n, u in expected.items() if n in out.units
             and out.units[n].lower().replace("·", "-") != u.lower()}  # fmt: skip
    if wrong:  # the conversions below assume OpenFAST's units
        raise rc.DataError(f"{path}: channels in other units than OpenFAST's {expected}: {wrong}")
    t = out.time
    keep = t >= t_skip - 1e-9
    if seconds is not None:
        keep &= t <= t_skip + seconds + 1e-9
    if keep.sum() < 3:
        raise rc.DataError(f"{path}: fewer than 3 samples after t = {t_skip} s")
    if "BldPitch1" in out:
        pitch, pitch_src = np.radians(out["BldPitch1"]), "BldPitch1"
    else:
        pitch, pitch_src = np.zeros_like(t), "0 (not recorded; below rated, README)"
    v0_src = "RtVAvgxh" if "RtVAvgxh" in out else "Wind1VelX"
    U = np.column_stack([out["GenTq"] * 1e3, pitch, out[v0_src]])[keep]
    Y = np.column_stack([out["RotSpeed"] * RPM, out["TTDspFA"], out["TwrBsMyt"] * 1e3])[keep]
    # measurement error V: the quantisation of the int16 binary, plus the CSV's 6 significant digits
    step = np.array([out.quantisation_step("RotSpeed") * RPM, out.quantisation_step("TTDspFA"),
                     out.quantisation_step("TwrBsMyt") * 1e3])  # fmt: skip
    if out.file_id is None:
        step = step + 5e-6 * np.max(np.abs(Y), axis=0)
    name = Path(path).name.split(".")[0]
    case = TestCase(name, "windturbine", t[keep], U, Y, model.input_names, model.output_names)
    return case, {"v0": v0_src, "theta": pitch_src, "quantisation": step}


def refit_aero(table, model, case):
    """eq. 78 refitted on the table's grid box around the (TSR, pitch) points the turbine visits."""
    lam = case.Y[:, 0] * model.params["R"] / case.U[:, 2]
    th = np.degrees(case.U[:, 1])
    tsr = (math.floor(lam.min() * 2) / 2, math.ceil(lam.max() * 2) / 2)
    pitch = (math.floor(th.min()), max(math.ceil(th.max()), math.floor(th.min()) + 2))
    fit = fit_aero(table, tsr_range=tsr, pitch_range_deg=pitch)
    d = fit.to_dict()
    d["visited_tsr"] = [float(lam.min()), float(lam.max())]
    d["visited_pitch_deg"] = [float(th.min()), float(th.max())]
    return fit, d


def _finite(x):
    x = float(x)
    return x if math.isfinite(x) else None


def undisturbed(model, case, x0):
    """Figure 10: the model with w = 0 from the reference's first state; outputs and deviations."""
    with np.errstate(all="ignore"):
        X = simulate(model, x0, case.t, inputs=np.array(case.U), substeps=10)
        Yh = evaluate_outputs(model, X, np.array(case.U))
        rng = np.ptp(case.Y, axis=0)
        err = np.abs(Yh - case.Y) / rng
    return Yh, {
        "max_rel_deviation": {k: _finite(v) for k, v in zip(OUTPUTS, np.max(err, axis=0))},
        "rms_rel_deviation": {k: _finite(v) for k, v in zip(OUTPUTS, np.sqrt(np.mean(err**2, axis=0)))},
    }


def eq72_box(model, case):
    """eq. 72 on the reference states g^{-1}(y): min/max finite-difference derivatives (Omega', xT', xT'')."""
    Xm = state_estimate(model, case)
    dX = np.diff(Xm, axis=0) / np.diff(case.t)[:, None]
    return dX.min(axis=0), dX.max(axis=0)


def balance(model, case):
    """Mean force/torque balances on the reference (windowed means).

    ``aero_torque_over_generator_torque``: mean aerodynamic torque of eq. 77b
    (the model's cP, the reference's Omega, theta, v0 and the measured tower
    velocity dxT/dt) over the mean ``i Mg``; about 1 for aero maps and a
    rotor-effective wind that fit the reference — the open-loop rotor speed
    drifts by the imbalance (Figure 10).  ``thrust_over_tower_spring_force``:
    the same for eq. 77a against ``k_Te xT``.  ``MyT_over_eq80_static``: mean
    MyT over mean ``h_H k_Te xT``; eq. 80 inverted for the state xT_dot
    divides the difference by the small ``c_Te``, so a few per cent here show
    up as a mean offset of the estimated xT_dot (``xT_dot_estimate_mean``,
    against the measured mean dxT/dt) that w2 has to compensate.
    """
    from reachconf.datasets.aero import cp_poly, ct_poly

    p = model.params
    t, Y = case.t, np.asarray(case.Y)
    Om, xT, MyT = Y.T
    Mg, th, v0 = np.asarray(case.U).T
    xTd = np.gradient(xT, t)
    v = v0 - xTd
    lam = Om * p["R"] / v
    area = math.pi * p["R"] ** 2
    Ma = 0.5 * p["rho"] * area * cp_poly(p, lam, th) * v**3 / Om
    Fa = 0.5 * p["rho"] * area * ct_poly(p, lam, th) * v**2
    return {
        "aero_torque_over_generator_torque": float(np.mean(Ma) / np.mean(p["i"] * Mg)),
        "thrust_over_tower_spring_force": float(np.mean(Fa) / np.mean(p["k_Te"] * xT)),
        "MyT_over_eq80_static": float(np.mean(MyT) / np.mean(p["h_H"] * p["k_Te"] * xT)),
        "xT_dot_estimate_mean": float(np.mean(state_estimate(model, case)[:, 2])),
        "dxT_dt_mean": float(np.mean(xTd)),
    }


def evaluate(model, case, meta):
    """Per-step trace conformance on every sample and the re-simulation deviation."""
    rng = np.ptp(case.Y, axis=0)
    V = rc.Interval(-meta["quantisation"], meta["quantisation"])
    objective = "relative" if np.all(case.Y != 0) else "absolute"  # eq. 70 needs non-zero data
    t0 = time.perf_counter()
    res = trace_disturbances(model, case, "perstep", V=V, options=TraceOptions(objective=objective))
    seconds = time.perf_counter() - t0
    Yh = evaluate_outputs(model, res.X, np.array(case.U))  # res.X: the IVP re-simulation with the found w
    dev = np.max(np.abs(Yh - case.Y), axis=0) / rng
    dev_value = np.max(np.abs(Yh - case.Y) / np.abs(case.Y), axis=0)  # the report's reading: of the reference value
    lo, hi = eq72_box(model, case)
    Wt = res.W_trace
    inside = (Wt >= lo) & (Wt <= hi)
    entry = {
        "samples": int(case.t.size),
        "t_range": [float(case.t[0]), float(case.t[-1])],
        "conformant": bool(res.conformant),
        "max_rel_deviation": {k: _finite(v) for k, v in zip(OUTPUTS, dev)},
        "W_box": res.disturbance_box().to_list(),
        "seconds": seconds,
        "max_rel_deviation_to_value": {k: _finite(v) for k, v in zip(OUTPUTS, dev_value)},
        "objective": objective,
        "V_box": [[-float(q), float(q)] for q in meta["quantisation"]],
        "eq72_box": [[float(a), float(b)] for a, b in zip(lo, hi)],
        "fraction_inside_eq72_box": {w: float(f) for w, f in zip(model.disturbance_names, inside.mean(axis=0))},
        "inputs": {"Mg": "GenTq", "theta": meta["theta"], "v0": meta["v0"]},
    }
    return res, entry, (lo, hi)


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def plot_figure9(results, out):
    plt = _pyplot()

    names = ["w1 = e_Omega' [rad/s²]", "w2 = e_xT' [m/s]", "w3 = e_xT'' [m/s²]"]
    fig, axes = plt.subplots(1, 3, figsize=(14, 4.2))
    for c, (label, Wt, (lo, hi)) in enumerate(results):
        col = f"C{c}"
        for ax, (i, j) in zip(axes, [(0, 1), (1, 2), (0, 2)]):
            ax.plot(Wt[:, i], Wt[:, j], ".", ms=1.2, alpha=0.35, color=col, label=label if i == 0 and j == 1 else None,
                    rasterized=True)  # fmt: skip
            ax.add_patch(plt.Rectangle((lo[i], lo[j]), hi[i] - lo[i], hi[j] - lo[j], fill=False, lw=1.4, color=col))
            ax.set_xlabel(names[i])
            ax.set_ylabel(names[j])
    leg = axes[0].legend(fontsize=7, markerscale=6)
    for h in leg.legend_handles:
        h.set_alpha(1)
    fig.suptitle("Per-step disturbances (trace conformance, eqs. 70/71) and the reference derivative boxes of eq. 72")
    fig.tight_layout()
    save_figure(fig, out / "figure9_disturbances.png", dpi=110, bbox_inches=None)
    plt.close(fig)


def plot_figure10(case, label, Y_fit, Y_def, out):
    plt = _pyplot()

    scale = (1.0 / RPM, 1.0, 1e-3)
    units = ("Omega [rpm]", "xT [m]", "MyT [kN·m]")
    fig, axes = plt.subplots(3, 1, figsize=(9, 7), sharex=True)
    for k, ax in enumerate(axes):
        ax.plot(case.t, case.Y[:, k] * scale[k], "k-", lw=1, label="OpenFAST")
        ax.plot(case.t, Y_fit[:, k] * scale[k], "C1-", lw=1, label="model, w = 0, eq. 78 refitted")
        ax.plot(case.t, Y_def[:, k] * scale[k], "C0--", lw=0.8, alpha=0.7, label="model, w = 0, whole-table fit")
        ax.set_ylabel(units[k])
        lo, hi = np.min(case.Y[:, k]), np.max(case.Y[:, k])
        pad = 0.6 * (hi - lo)
        ax.set_ylim((lo - pad) * scale[k], (hi + pad) * scale[k])  # diverging curves stay readable
    axes[0].legend(fontsize=7)
    axes[-1].set_xlabel("t [s]")
    fig.suptitle(f"{label}: undisturbed open-loop model against the reference (Figure 10)")
    fig.tight_layout()
    save_figure(fig, out / f"{case.name}_undisturbed.png", dpi=110, bbox_inches=None)
    plt.close(fig)


def prepare_file(base, table, path, t_skip, seconds):
    """The case of one file and its eq. 78 refit: every file is read and checked before any work is done."""
    case, meta = make_case(base, path, t_skip, seconds)
    try:
        fit, fit_info = refit_aero(table, base, case)
    except rc.DataError as exc:  # the window, not the table, is too small (a short --seconds)
        raise rc.DataError(f"{path}: the turbine's operating points in this window (t = {case.t[0]:g} to "
                           f"{case.t[-1]:g} s) cover too little of the Cp/Ct table for eq. 78 — a longer --seconds? "
                           f"({exc})") from exc  # fmt: skip
    return case, meta, fit, fit_info


def run_file(base, prepared, aero_mode):
    t_all = time.perf_counter()
    case, meta, fit, fit_info = prepared
    m_fit = base.with_params(**fit.params)
    m_def = base.with_params(**CP_DEFAULT, **CT_DEFAULT)
    model = m_fit if aero_mode == "fit" else m_def
    res, entry, box = evaluate(model, case, meta)
    x0 = state_estimate(model, case)[0]
    Y_fit, und_fit = undisturbed(m_fit, case, x0)
    Y_def, und_def = undisturbed(m_def, case, x0)
    entry["aero"] = {"mode": aero_mode, "refit": fit_info}
    entry["undisturbed"] = {"refit": und_fit, "default": und_def}
    entry["mean_balance"] = {"refit": balance(m_fit, case), "default": balance(m_def, case)}
    if aero_mode == "fit":  # the disturbances the whole-table coefficients would need, for comparison
        res_d = trace_disturbances_only(m_def, case)
        entry["W_box_default_coefficients"] = res_d
    return case, res, entry, box, (Y_fit, Y_def), t_all


def trace_disturbances_only(model, case):
    objective = "relative" if np.all(case.Y != 0) else "absolute"
    res = trace_disturbances(model, case, "perstep", options=TraceOptions(objective=objective))
    return res.disturbance_box().to_list()


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default=None, help="data folder (default: ../shared/data/windturbine from the repo root)")
    ap.add_argument("--out", required=True, help="output folder")
    ap.add_argument("--quick", action="store_true", help=f"only the first {QUICK_SECONDS:g} s after the transient")
    ap.add_argument("--seconds", type=float, default=None, help="only this many seconds after the transient")
    ap.add_argument("--aero", choices=("fit", "default"), default="fit",
                    help="eq. 78 coefficients: refitted over the visited region (default) or the whole-table fit")
    ap.add_argument("--no-plots", action="store_true")
    args = ap.parse_args(argv)
    data = Path(args.data) if args.data else default_data()
    seconds = QUICK_SECONDS if args.quick and args.seconds is None else args.seconds
    out = Path(args.out)
    try:
        if not data.is_dir():
            raise rc.DataError(f"{data}: no such data folder")
        missing = [f for f, *_ in FILES.values() if not (data / f).is_file()] + (
            [] if (data / TABLE).is_file() else [TABLE])
        if missing:
            raise rc.DataError(f"{data}: missing {', '.join(missing)}")
        if seconds is not None and not seconds > 0:
            raise rc.DataError("--seconds must be positive")
        table = read_performance_table(data / TABLE)
        base = wind_turbine()
        prepared = {name: prepare_file(base, table, data / fname, t_skip, seconds)
                    for name, (fname, t_skip, _) in FILES.items()}  # fmt: skip
        out.mkdir(parents=True, exist_ok=True)
        result, fig9 = {}, []
        for name, (fname, t_skip, label) in FILES.items():
            case, res, entry, box, (Y_fit, Y_def), t_all = run_file(base, prepared[name], args.aero)
            fig9.append((label, res.W_trace, box))
            if not args.no_plots:
                plot_figure10(case, label, Y_fit, Y_def, out)
            entry["seconds_total"] = time.perf_counter() - t_all
            result[name] = entry
            dev = ", ".join(f"{k} {v:.1e}" if v is not None else f"{k} diverged"
                            for k, v in entry["max_rel_deviation"].items())  # fmt: skip
            und = entry["undisturbed"]["refit" if args.aero == "fit" else "default"]["rms_rel_deviation"]
            und = ", ".join(f"{k} {v:.2f}" if v is not None else f"{k} diverged" for k, v in und.items())
            print(f"{name}: {entry['samples']} samples, conformance {entry['seconds']:.2f} s; re-simulated max "
                  f"deviation / range: {dev}; undisturbed RMS deviation / range: {und}")  # fmt: skip
        if not args.no_plots:
            plot_figure9(fig9, out)
    except (rc.ReachconfError, OSError) as exc:
        print(f"windturbine: error: {exc}", file=sys.stderr)
        return 2
    atomic_write(out / "windturbine.json", json_text(result))
    print(f"wrote {out / 'windturbine.json'}")
    return 0


if __name__ == "__main__":
    from reachconf.script import run_script

    sys.exit(run_script(main, "windturbine"))
