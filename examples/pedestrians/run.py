"""Pedestrian prediction on the BIWI ETH/Hotel recordings: Table 9 (source report sections 7.2, 7.4).

    python examples/pedestrians/run.py --data ../shared/data/pedestrians --out DIR

The reachable set of a pedestrian is the intersection of the acceleration-
constrained model (eq. 73: p'' = a, |a| <= a_max) and the velocity-constrained
model (eq. 74: p' = v, |v| <= v_max), with initial uncertainty +-0.1 m and
+-0.1 m/s (boxes), a_max = 0.6 m/s^2, v_max = 2.0 m/s, horizon 1.6 s.  At
time t the position sets are exactly

    acc: p0 + t v0  (+)  box(0.1 + 0.1 t)  (+)  disk(a_max t^2 / 2)
    vel: p0         (+)  box(0.1)          (+)  disk(v_max t)

(Minkowski sums; "exact" mode).  CORA encloses the disks by zonotopes, which
makes the sets larger; ``--disk zonotope`` reproduces that with the
circumscribed 16-gon of :func:`reachconf.sets.disk_zonotope`.
A test passes when every future position (every 0.4 s up to 1.6 s) lies in
the intersection at its time.  Failures are classified as in section 7.4:
"speed above v_max" (outside the velocity model's set only), "turning or
accelerating too fast" (outside the acceleration model's set only), or both.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

from reachconf.datasets.biwi import prediction_cases, read_sequence
from reachconf.errors import ReachconfError
from reachconf.io import atomic_write, json_text
from reachconf.plot import save_figure
from reachconf.sets import Zonotope, box_disk_distance, disk_zonotope

A_MAX, V_MAX, HORIZON, P_UNC, V_UNC = 0.6, 2.0, 1.6, 0.1, 0.1
REPORT = {"pedestrians": 420, "test_cases": 20084, "passed": 19843, "rate": 98.80}


def required(cases):
    """Per case, the smallest a_max and v_max under which it passes (the models' set sizes are monotone)."""
    t = cases.offsets[None, :]
    pred = cases.p0[:, None, :] + t[..., None] * cases.v0[:, None, :]
    # distances from the boxes (disk radius 0): a case passes while they are within the disks' radii
    d_acc = box_disk_distance(cases.future - pred, np.broadcast_to(P_UNC + V_UNC * t, pred.shape[:2])[..., None])
    d_vel = box_disk_distance(cases.future - cases.p0[:, None, :], np.full(pred.shape[:2], P_UNC)[..., None])
    a_req = np.max(2.0 * d_acc / t**2, axis=1)
    v_req = np.max(d_vel / t, axis=1)
    return a_req, v_req


def zonotope_verdicts(cases, a_max, v_max, n_gen=8):
    """CORA-style sets: disks enclosed by a circumscribed 2k-gon (zonotope), boxes exact."""
    ok_acc = np.ones(len(cases), bool)
    ok_vel = np.ones(len(cases), bool)
    for k, t in enumerate(cases.offsets):
        pred = cases.p0 + t * cases.v0
        Za = disk_zonotope(a_max * t * t / 2, n_gen) + Zonotope([0, 0], np.eye(2) * (P_UNC + V_UNC * t))
        Zv = disk_zonotope(v_max * t, n_gen) + Zonotope([0, 0], np.eye(2) * P_UNC)
        ok_acc &= Za.contains(cases.future[:, k] - pred, tol=1e-12)
        ok_vel &= Zv.contains(cases.future[:, k] - cases.p0, tol=1e-12)
    return ok_acc, ok_vel


def evaluate(cases, a_max=A_MAX, v_max=V_MAX, disk="exact"):
    if disk == "exact":
        a_req, v_req = required(cases)
        ok_acc, ok_vel = a_req <= a_max, v_req <= v_max
    else:
        ok_acc, ok_vel = zonotope_verdicts(cases, a_max, v_max)
    passed = ok_acc & ok_vel
    failures = {
        "speed above v_max": int(np.sum(ok_acc & ~ok_vel)),
        "turning or accelerating too fast (above a_max)": int(np.sum(~ok_acc & ok_vel)),
        "both": int(np.sum(~ok_acc & ~ok_vel)),
    }
    n = len(cases)
    return {"pedestrians": int(np.unique(cases.pid).size), "test_cases": n, "passed": int(passed.sum()),
            "rate": 100.0 * float(passed.mean()), "failures": failures}  # fmt: skip


def setups(data, disk):
    """The set-ups the report leaves open: sequences, start-time spacing, velocity estimate."""
    seqs = {"hotel": read_sequence(data, "hotel"), "eth": read_sequence(data, "eth")}
    out = {}
    for seq_label, tracks in (("hotel", seqs["hotel"]), ("eth+hotel", seqs["eth"] + seqs["hotel"])):
        for step in (0.4, 0.1):
            for vel in ("backward", "file"):
                cases = prediction_cases(tracks, HORIZON, start_step=step, velocity=vel)
                out[f"{seq_label}, start every {step:g} s, {vel} velocity"] = (cases, evaluate(cases, disk=disk))
    return out


def plot_curve(cases, out: Path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    a_req, v_req = required(cases)
    grid = np.round(np.arange(0.1, 3.01, 0.05), 3)
    rate = [100.0 * float(np.mean((a_req <= a) & (v_req <= V_MAX))) for a in grid]
    quant = {}
    for q in (90.0, 95.0, 99.0, 99.9):
        quant[f"{q:g}%"] = {"a_max_alone": float(np.percentile(a_req, q)), "v_max_alone": float(np.percentile(v_req, q))}
    fig, ax = plt.subplots(figsize=(6, 3.5))
    ax.plot(grid, rate, "-")
    ax.axvline(A_MAX, color="k", ls=":", label=f"a_max = {A_MAX} (report)")
    ax.set_xlabel("a_max [m/s²]")
    ax.set_ylabel("tests passed [%]")
    ax.set_title(f"Pass rate vs a_max (v_max = {V_MAX} m/s), {len(cases)} test cases")
    ax.grid(alpha=0.3)
    ax.legend()
    fig.tight_layout()
    save_figure(fig, out / "pass_rate_curve.png", dpi=120, bbox_inches=None)
    plt.close(fig)
    curve = {"v_max": V_MAX, "a_max": grid.tolist(), "rate_percent": rate, "quantiles": quant}
    atomic_write(out / "pass_rate_curve.json", json_text(curve))
    return curve


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default=str(Path(os.environ.get("REACHCONF_DATA") or Path(__file__).resolve().parents[2].parent
                                                  / "shared" / "data") / "pedestrians"),
                    help="data folder (default: ../shared/data/pedestrians from the repo root, or $REACHCONF_DATA)")
    ap.add_argument("--out", required=True)
    ap.add_argument("--disk", choices=("exact", "zonotope"), default="exact")
    args = ap.parse_args(argv)
    out = Path(args.out)
    t_start = time.perf_counter()
    try:
        variants = setups(args.data, args.disk)
    except ReachconfError as exc:
        print(f"pedestrians: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("pedestrians: interrupted before any set-up was complete; nothing written", file=sys.stderr)
        return 130
    out.mkdir(parents=True, exist_ok=True)
    # causal: starts on the annotations (every 0.4 s), velocity from the past; a finer start interpolates the
    # position and the "backward" velocity between annotations, i.e. from the next one (0.1-0.3 s ahead)
    default = "hotel, start every 0.4 s, backward velocity"
    cases, table = variants[default]
    curve = plot_curve(cases, out)
    seconds = time.perf_counter() - t_start
    result = dict(table, seconds=seconds, setup=default, disk=args.disk, report=REPORT,
                  setups={k: v for k, (_, v) in variants.items()}, pass_rate_curve=curve["quantiles"])  # fmt: skip
    atomic_write(out / "table9.json", json_text(result))
    lines = ["| set-up | pedestrians | test cases | passed | rate |", "|---|---|---|---|---|",
             f"| report (Table 9) | {REPORT['pedestrians']} | {REPORT['test_cases']} | {REPORT['passed']} | {REPORT['rate']:.2f} % |"]  # fmt: skip
    for k, v in result["setups"].items():
        lines.append(f"| {k}{' (default)' if k == default else ''} | {v['pedestrians']} | {v['test_cases']} | "
                     f"{v['passed']} | {v['rate']:.2f} % |")  # fmt: skip
    lines += ["", "Failures of the default set-up: " + ", ".join(f"{k}: {n}" for k, n in table["failures"].items())]
    atomic_write(out / "table9.md", "\n".join(lines) + "\n")
    print("\n".join(lines))
    print(f"({seconds:.1f} s) wrote {out / 'table9.json'}")
    return 0


if __name__ == "__main__":
    from reachconf.script import run_script

    sys.exit(run_script(main, "pedestrians"))
