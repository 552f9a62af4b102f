"""A differential-drive robot among real crowds (source report sections 7.3, 7.5, Tables 10/11).

    python examples/robot/run.py --data ../shared/data/pedestrians --out DIR [--starts 12]

The ETH and Hotel tracks are replayed as the pedestrians (they do not react to
the robot).  The robot (unicycle, v in [0, 1.5] m/s, |w| <= 2 rad/s,
|a_tra| <= 1.5 m/s², |a_rot| <= 1 rad/s², footprint radius 0.3 m, localisation
uncertainty 0.05 m) crosses each scene between fixed start and goal points
along the main pedestrian flow, against it and across it, from many start
times.  Every 0.1 s a sampling planner in the spirit of the dynamic window
approach scores the reachable (v, w) pairs by progress to the goal and
clearance; a candidate is only taken if the safety layer accepts it:

(a) online verification: the candidate held for one planning step followed by
    its fail-safe braking maneuver (full deceleration, straight on) stays clear
    of every pedestrian's reachable set (Table 9's model: acceleration- and
    velocity-constrained sets from the last observed position and backward-
    difference velocity, +-0.1 m / +-0.1 m/s, enlarged by the pedestrian's
    0.27 m radius) at every time until standstill;
(b) an ISO 13482-style fixed circular safety field sized for a pedestrian at
    full speed (2 m/s) during the robot's worst-case stopping time: the robot
    stops while anybody is inside;
(c) braking ICS: as (a), but the obstacles may move at full speed in any
    direction from their current position (no velocity information).

When no candidate is accepted the robot brakes.  A collision while moving is a
time step at which the robot moves and its footprint overlaps a pedestrian's
disk.  The replayed pedestrians do not avoid the robot, which biases the result
against every layer (in reality people make room) and makes collisions of a
standing robot possible; those are not counted, as in the report.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

from reachconf.datasets.biwi import ANNOTATION_DT, read_sequence
from reachconf.errors import ReachconfError
from reachconf.io import atomic_write_text

V_MAX, W_MAX, A_TRA, A_ROT = 1.5, 2.0, 1.5, 1.0
R_ROBOT, LOC_UNC, R_PED = 0.3, 0.05, 0.27
A_PED, V_PED, P_UNC, V_UNC = 0.6, 2.0, 0.1, 0.1
DT, HORIZON_LIMIT = 0.1, 40.0
LAYERS = ("online_verification", "iso_safety_field", "braking_ics")


class Scene:
    """Pedestrian positions on a 0.1 s grid (NaN where a pedestrian is absent)."""

    def __init__(self, tracks):
        t_end = max(tr.t[-1] for tr in tracks)
        t_start = min(tr.t[0] for tr in tracks)
        self.t = np.arange(t_start, t_end + 1e-9, DT)
        self.P = np.full((self.t.size, len(tracks), 2), np.nan)
        for j, tr in enumerate(tracks):
            on = (self.t >= tr.t[0]) & (self.t <= tr.t[-1])
            self.P[on, j, 0] = np.interp(self.t[on], tr.t, tr.p[:, 0])
            self.P[on, j, 1] = np.interp(self.t[on], tr.t, tr.p[:, 1])
        V = np.concatenate([tr.v for tr in tracks])
        Pall = np.concatenate([tr.p for tr in tracks])
        self.center = np.median(Pall, axis=0)
        flow = V[np.linalg.norm(V, axis=1) > 0.3]
        _, _, vt = np.linalg.svd(flow - 0 * flow.mean(axis=0), full_matrices=False)
        self.axis = vt[0] / np.linalg.norm(vt[0])

    def observe(self, k):
        """Positions now and 0.4 s ago (backward-difference velocity), for pedestrians present at both."""
        back = max(k - int(round(ANNOTATION_DT / DT)), 0)
        p, q = self.P[k], self.P[back]
        present = ~np.isnan(p[:, 0])
        v = np.where(np.isnan(q), np.nan, p - q) / ANNOTATION_DT  # NaN: just appeared, velocity unknown
        return p[present], v[present], present


def braking_profile(v, w):
    """Times and poses (relative) of the fail-safe maneuver: full deceleration, constant curvature."""
    t_stop = v / A_TRA
    n = max(1, int(np.ceil(t_stop / DT)))
    ts = np.linspace(0, t_stop, n + 1)
    s = v * ts - 0.5 * A_TRA * ts**2
    return ts, s, t_stop


def _box_disk_dist(d, r_box, R):
    e = np.maximum(np.abs(d) - r_box[..., None], 0.0)
    return np.sqrt(np.sum(e * e, axis=-1)) - R


def safe(layer, robot_pts, times, peds_p, peds_v):
    """Is the robot's path (points at times) clear of the obstacles' sets? Arrays: (T, 2), (T,), (N, 2)."""
    if peds_p.shape[0] == 0:
        return True
    t = times[:, None]
    clearance = R_ROBOT + LOC_UNC + R_PED
    rel = robot_pts[:, None, :] - peds_p[None, :, :]  # (T, N, 2)
    if layer == "braking_ics":
        return bool(np.all(np.linalg.norm(rel, axis=-1) > clearance + V_PED * t + P_UNC * np.sqrt(2)))
    # online verification: outside the acceleration-constrained OR the velocity-constrained set suffices;
    # a pedestrian who has just appeared has no velocity estimate: only the velocity model applies
    pred = rel - t[..., None] * np.nan_to_num(peds_v)[None, :, :]
    d_acc = _box_disk_dist(pred, np.broadcast_to(P_UNC + V_UNC * t, rel.shape[:2]), 0.5 * A_PED * t**2)
    d_acc = np.where(np.isnan(peds_v[:, 0])[None, :], -np.inf, d_acc)
    d_vel = _box_disk_dist(rel, np.full(rel.shape[:2], P_UNC), V_PED * t)
    return bool(np.all(np.maximum(d_acc, d_vel) > clearance))


def _cause(scene, k, k1, j):
    """Why a pedestrian could hit the robot: unseen at planning time, or outside its predicted set."""
    back = max(k - int(round(ANNOTATION_DT / DT)), 0)
    p, q, actual = scene.P[k, j], scene.P[back, j], scene.P[k1, j]
    if np.isnan(p[0]):
        return "pedestrian not visible when the motion was verified"
    t = (k1 - k) * DT
    d_vel = _box_disk_dist((actual - p)[None, None], np.array([[P_UNC]]), V_PED * t)[0, 0]
    if np.isnan(q[0]):
        return "pedestrian left its predicted set" if d_vel > 0 else "other"
    v = (p - q) / ANNOTATION_DT
    d_acc = _box_disk_dist((actual - p - t * v)[None, None], np.array([[P_UNC + V_UNC * t]]), 0.5 * A_PED * t * t)[0, 0]
    return "pedestrian left its predicted set" if max(d_acc, d_vel) > 0 else "other"


def run_once(scene, k0, start, goal, layer, record=False):
    x, y = start
    th = float(np.arctan2(goal[1] - start[1], goal[0] - start[0]))
    v = w = 0.0
    k_ver = k0
    steps = int(HORIZON_LIMIT / DT)
    collisions, dist, path = 0, 0.0, []
    causes = {"pedestrian not visible when the motion was verified": 0, "pedestrian left its predicted set": 0,
              "other": 0}  # fmt: skip
    field = R_ROBOT + LOC_UNC + R_PED + V_MAX**2 / (2 * A_TRA) + V_PED * (V_MAX / A_TRA + DT)
    for i in range(steps):
        k = k0 + i
        if k >= scene.t.size:
            return None  # scene ended before the run: not counted
        peds_p, peds_v, present = scene.observe(k)
        if record:
            path.append((x, y, scene.P[k].copy()))
        if np.hypot(goal[0] - x, goal[1] - y) < 0.3:
            return {"at_goal": True, "time_s": i * DT, "distance": dist, "collisions": collisions, "path": path,
                    "causes": causes}  # fmt: skip
        # candidate commands in the dynamic window
        vs = np.clip(v + np.linspace(-A_TRA, A_TRA, 7) * DT, 0.0, V_MAX)
        ws = np.clip(w + np.linspace(-A_ROT, A_ROT, 7) * DT, -W_MAX, W_MAX)
        best, best_score = None, -np.inf
        blocked = layer == "iso_safety_field" and peds_p.shape[0] and np.min(np.hypot(*(peds_p - [x, y]).T)) < field
        for vc in np.unique(vs):
            for wc in np.unique(ws):
                th1 = th + wc * DT
                x1, y1 = x + vc * np.cos(th1) * DT, y + vc * np.sin(th1) * DT
                if blocked and vc > 0:
                    continue
                if layer in ("online_verification", "braking_ics") and vc > 0:
                    ts, s, _ = braking_profile(vc, wc)
                    pts = np.column_stack([x1 + s * np.cos(th1), y1 + s * np.sin(th1)])
                    times = np.concatenate([[0.0], DT + ts])
                    pts = np.vstack([[x, y], pts])
                    if not safe(layer, pts, times, peds_p, peds_v):
                        continue
                to_goal = np.hypot(goal[0] - x1, goal[1] - y1)
                heading = abs(np.angle(np.exp(1j * (np.arctan2(goal[1] - y1, goal[0] - x1) - th1))))
                score = -to_goal - 0.5 * heading + 0.2 * vc
                if score > best_score:
                    best, best_score = (vc, wc), score
        if best is None:  # nothing accepted: brake straight on (the fail-safe verified at k_ver)
            best = (max(v - A_TRA * DT, 0.0), 0.0)
        else:
            k_ver = k
        v, w = best
        th += w * DT
        x, y = x + v * np.cos(th) * DT, y + v * np.sin(th) * DT
        dist += v * DT
        if v > 1e-6:
            k1 = min(k + 1, scene.t.size - 1)
            pk = scene.P[k1]
            hit = np.nonzero(np.hypot(pk[:, 0] - x, pk[:, 1] - y) < R_ROBOT + R_PED)[0]
            for j in hit:
                collisions += 1
                causes[_cause(scene, k_ver, k1, j)] += 1
    return {"at_goal": False, "time_s": HORIZON_LIMIT, "distance": dist, "collisions": collisions, "path": path,
            "causes": causes}


def scenarios(scene, half_length=6.0):
    c, a = scene.center, scene.axis
    n = np.array([-a[1], a[0]])
    return {"with_flow": (c - half_length * a, c + half_length * a),
            "against_flow": (c + half_length * a, c - half_length * a),
            "across_flow": (c - 0.6 * half_length * n, c + 0.6 * half_length * n)}  # fmt: skip


def plot_run(scene, res, start, goal, out):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 6))
    xy = np.array([(p[0], p[1]) for p in res["path"]])
    ax.plot(xy[:, 0], xy[:, 1], "C0-", lw=2, label="robot")
    k = len(res["path"]) // 2
    peds = res["path"][k][2]
    peds = peds[~np.isnan(peds[:, 0])]
    for p in peds:
        for t, col in ((0.8, "C1"), (1.6, "C3")):
            ax.add_patch(plt.Circle(p, R_PED + P_UNC + V_PED * t, fill=False, color=col, lw=0.5, alpha=0.6))
        ax.add_patch(plt.Circle(p, R_PED, color="k"))
    ax.plot(*start, "g^", ms=10, label="start")
    ax.plot(*goal, "r*", ms=12, label="goal")
    ax.plot(xy[k, 0], xy[k, 1], "bo", ms=8)
    ax.set_aspect("equal")
    ax.set_title("Robot run; pedestrians at mid-run with 0.8/1.6 s velocity-model sets")
    ax.legend(loc="upper left", fontsize=8)
    fig.tight_layout()
    fig.savefig(out / "robot_run.png", dpi=110)
    plt.close(fig)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default=os.environ.get("REACHCONF_DATA", "../shared/data") + "/pedestrians")
    ap.add_argument("--out", required=True)
    ap.add_argument("--starts", type=int, default=12, help="start times per sequence and scenario")
    ap.add_argument("--sequences", nargs="+", default=["eth", "hotel"])
    args = ap.parse_args(argv)
    out = Path(args.out)
    t0 = time.perf_counter()
    try:
        scenes = {s: Scene(read_sequence(args.data, s)) for s in args.sequences}
    except ReachconfError as exc:
        print(f"robot: error: {exc}", file=sys.stderr)
        return 2
    out.mkdir(parents=True, exist_ok=True)
    table: dict = {layer: {} for layer in LAYERS}
    picture = None
    for sname, scene in scenes.items():
        k_starts = np.linspace(0, scene.t.size - int(HORIZON_LIMIT / DT) - 1, args.starts).astype(int)
        for scen, (start, goal) in scenarios(scene).items():
            for layer in LAYERS:
                runs = [r for k in k_starts if (r := run_once(scene, int(k), start, goal, layer)) is not None]
                key = f"{sname}/{scen}"
                reached = [r for r in runs if r["at_goal"]]
                table[layer][key] = {
                    "runs": len(runs),
                    "at_goal": len(reached),
                    "time_s": float(np.mean([r["time_s"] for r in reached])) if reached else None,
                    "velocity": float(np.mean([r["distance"] / r["time_s"] for r in reached])) if reached else None,
                    "collisions": int(sum(r["collisions"] for r in runs)),
                    "collision_causes": {c: int(sum(r["causes"][c] for r in runs)) for c in runs[0]["causes"]}
                    if runs else {},
                }
                if picture is None and layer == "online_verification":
                    picture = (scene, int(k_starts[len(k_starts) // 2]), start, goal)
    if picture is not None:
        scene, k, start, goal = picture
        res = run_once(scene, k, start, goal, "online_verification", record=True)
        plot_run(scene, res, start, goal, out)
    result = dict(table, seconds=time.perf_counter() - t0)
    atomic_write_text(out / "robot.json", json.dumps(result, indent=2))
    lines = ["| layer | scenario | runs | at goal | mean time [s] | mean velocity [m/s] | collisions while moving |",
             "|---|---|---|---|---|---|---|"]  # fmt: skip
    for layer in LAYERS:
        for key, e in table[layer].items():
            tm = f"{e['time_s']:.1f}" if e["time_s"] is not None else "-"
            vel = f"{e['velocity']:.2f}" if e["velocity"] is not None else "-"
            lines.append(f"| {layer} | {key} | {e['runs']} | {e['at_goal']} | {tm} | {vel} | {e['collisions']} |")
    atomic_write_text(out / "robot.md", "\n".join(lines) + "\n")
    print("\n".join(lines))
    print(f"({result['seconds']:.1f} s) wrote {out / 'robot.json'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
