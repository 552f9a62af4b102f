"""A differential-drive robot among real crowds (source report sections 7.3, 7.5, Tables 10/11).

    python examples/robot/run.py --data ../shared/data/pedestrians --out DIR [--starts 12]

The ETH and Hotel tracks are replayed as the pedestrians (they do not react to
the robot).  The robot (``layers.py``: unicycle with velocity commands held for
0.1 s, v in [0, 1.5] m/s, |w| <= 2 rad/s, |a_tra| <= 1.5 m/s², |a_rot| <= 1
rad/s², footprint radius 0.3 m, localisation uncertainty +-0.05 m / +-0.05 rad)
crosses each scene along the main pedestrian flow, against it and across it,
from many start times.  Every 0.1 s a sampling planner in the spirit of the
dynamic window approach scores the reachable (v, w) pairs by progress to the
goal; a candidate is only taken if the safety layer accepts it:

(a) online verification: the candidate held for one period followed by its
    fail-safe braking maneuver stays clear, over every period until standstill,
    of every pedestrian's reachable set (Table 9's model: acceleration- and
    velocity-constrained sets from the last observed position and backward-
    difference velocity, +-0.1 m / +-0.1 m/s, enlarged by the 0.27 m radius),
    of the growing sets of tracks lost from view in the last MEMORY seconds
    (occlusions, broken tracks) and of phantom pedestrians that may appear in
    the entry zones at any time and walk at v_max.  The entry zones are the
    places where tracks began repeatedly in the *other* time windows of the
    same sequence (never the run's own pedestrians);
(b) an ISO 13482-style fixed circular safety field sized for a pedestrian at
    full speed (2 m/s) during the robot's stopping time: the robot stops while
    anybody is inside;
(c) braking ICS: obstacles may move at full speed in any direction from their
    current position (no velocity information, no entry zones).

Start and goal of each run lie on the scenario's line, moved out of the entry
zones (ROUTE_CLEARANCE): a robot cannot safely wait in a doorway.  All layers
use the same routes.  When no candidate is accepted the robot continues the
last verified fail-safe maneuver.  A collision while moving is a pedestrian
whose disk overlaps the footprint at a 0.1 s step at which the robot moves
(counted once per run and pedestrian); each is classified (``collision_list``).
The replayed pedestrians do not avoid the robot, which biases the result
against every layer (in reality people make room) and makes collisions of a
standing robot possible; those are not counted, as in the report.
"""

from __future__ import annotations

import argparse
import importlib.util
import os
import sys
import time
from pathlib import Path

import numpy as np

from reachconf.commands import positive_int
from reachconf.datasets.biwi import ANNOTATION_DT, read_sequence
from reachconf.errors import ReachconfError
from reachconf.io import atomic_write, json_text
from reachconf.plot import save_figure
from reachconf.sets import BoxDisk


def _load_layers():
    name = "robot_layers"
    if name not in sys.modules:
        spec = importlib.util.spec_from_file_location(name, Path(__file__).with_name("layers.py"))
        sys.modules[name] = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(sys.modules[name])
    return sys.modules[name]


L = _load_layers()
from robot_layers import (A_PED, A_ROT, A_TRA, DT, LAYERS, P_UNC, R_PED, R_ROBOT, V_MAX, V_PED,  # noqa: E402
                          V_UNC, W_MAX)  # fmt: skip

HORIZON_LIMIT = 40.0
#: tracks beginning within this many seconds of a run are not used for its entry zones
ZONE_MARGIN = 30.0
#: an entry zone is a place where tracks begin repeatedly: a first position with at least
#: ZONE_MIN_NEIGHBOURS other first positions within ZONE_DENSITY_RADIUS (one-off starts are not)
ZONE_MIN_NEIGHBOURS, ZONE_DENSITY_RADIUS = 20, 1.0
#: tracks lost from view keep their (growing) reachable sets this long (s): occlusions, broken tracks
MEMORY = 2.0
#: start and goal are moved along the route until they are this far from the entry zones (m)
ROUTE_CLEARANCE = 1.5
#: runs whose route keeps less than this fraction of its length are skipped (reported)
MIN_ROUTE = 0.25


class Scene:
    """Pedestrian positions on a 0.1 s grid (NaN where a pedestrian is absent)."""

    def __init__(self, tracks):
        t_end = max(tr.t[-1] for tr in tracks)
        t_start = min(tr.t[0] for tr in tracks)
        self.t = np.arange(t_start, t_end + 1e-9, DT)
        self.P = np.full((self.t.size, len(tracks), 2), np.nan)
        self.starts = np.array([tr.p[0] for tr in tracks])
        self.pids = [tr.pid for tr in tracks]
        self.start_t = np.array([tr.t[0] for tr in tracks])
        for j, tr in enumerate(tracks):
            on = (self.t >= tr.t[0]) & (self.t <= tr.t[-1])
            self.P[on, j, 0] = np.interp(self.t[on], tr.t, tr.p[:, 0])
            self.P[on, j, 1] = np.interp(self.t[on], tr.t, tr.p[:, 1])
        seen = ~np.isnan(self.P[:, :, 0])
        self.k_first = np.argmax(seen, axis=0)
        self.k_last = self.t.size - 1 - np.argmax(seen[::-1], axis=0)
        V = np.concatenate([tr.v for tr in tracks])
        Pall = np.concatenate([tr.p for tr in tracks])
        self.center = np.median(Pall, axis=0)
        flow = V[np.linalg.norm(V, axis=1) > 0.3]
        _, _, vt = np.linalg.svd(flow, full_matrices=False)
        axis = vt[0] / np.linalg.norm(vt[0])
        # the principal axis of the walking velocities has no sign: "with the flow" is the way most walk (an outside
        # review: on ETH the SVD's sign pointed against 59 % of the walkers)
        along = float(np.mean(flow @ axis > 0))
        self.axis = axis if along >= 0.5 else -axis
        self.flow_share = max(along, 1.0 - along)  # share of the walking samples that move with the flow

    def first_position(self, j):
        return self.P[self.k_first[j], j]

    def observe(self, k, memory=0.0):
        """Pedestrians seen at k: positions, backward-difference velocities over 0.4 s (NaN: seen for
        less than that) and ages (0).  With ``memory`` > 0, also the tracks lost from view within
        the last ``memory`` seconds, at their last position and velocity, aged by the time since."""
        back = int(round(ANNOTATION_DT / DT))
        kk = np.full(self.P.shape[1], k)
        if memory > 0:
            lost = (self.k_last < k) & (self.k_last >= k - int(round(memory / DT)))
            kk[lost] = self.k_last[lost]
        idx = np.nonzero(~np.isnan(self.P[kk, np.arange(kk.size), 0]))[0]
        kk = kk[idx]
        p, q = self.P[kk, idx], self.P[np.maximum(kk - back, 0), idx]
        v = np.where(np.isnan(q), np.nan, p - q) / ANNOTATION_DT
        return p, v, (k - kk) * DT, idx


def run_once(scene, k0, start, goal, layer, zones=None, record=False):
    """One run from grid index k0; None if the scene ends first.  ``zones``: entry zones for (a)."""
    x, y = start
    th = float(np.arctan2(goal[1] - start[1], goal[0] - start[0]))
    v = w = 0.0
    k_ver = k0
    steps = int(HORIZON_LIMIT / DT)
    dist, path, hits, hit_steps = 0.0, [], {}, 0
    causes = dict.fromkeys(CAUSES, 0)
    field = L.safety_field_radius()
    for i in range(steps):
        k = k0 + i
        if k + 1 >= scene.t.size:
            return None  # scene ended before the run: not counted
        peds_p, peds_v, age, _ = scene.observe(k, MEMORY if layer == "online_verification" and zones else 0.0)
        if record:
            path.append((x, y, th, v, w, k))
        if np.hypot(goal[0] - x, goal[1] - y) < 0.3:
            return _result(True, i * DT, dist, hits, hit_steps, path, causes)
        # candidate commands in the dynamic window
        vs = np.unique(np.clip(v + np.linspace(-A_TRA, A_TRA, 7) * DT, 0.0, V_MAX))
        ws = np.unique(np.clip(w + np.linspace(-A_ROT, A_ROT, 7) * DT, -W_MAX, W_MAX))
        cands = np.array([(a, b) for a in vs for b in ws])
        if layer == "iso_safety_field":
            blocked = peds_p.shape[0] and np.min(np.hypot(*(peds_p - [x, y]).T)) < field
            ok = (cands[:, 0] == 0) | (not blocked)
        else:
            ok = L.safe_candidates(layer, (x, y, th), cands, peds_p, peds_v, zones, age)
        if ok.any():
            c = cands[ok]
            x1, y1, th1 = L.step_pose(x, y, th, c[:, 0], c[:, 1])
            heading = np.abs(np.angle(np.exp(1j * (np.arctan2(goal[1] - y1, goal[0] - x1) - th1))))
            score = -np.hypot(goal[0] - x1, goal[1] - y1) - 0.5 * heading + 0.2 * c[:, 0]
            v, w = c[int(np.argmax(score))]
            k_ver = k
        else:  # nothing accepted: continue the fail-safe maneuver verified at k_ver
            v, w = L.brake_step(v, w)
        x, y, th = (float(a) for a in L.step_pose(x, y, th, v, w))
        dist += v * DT
        if v > 1e-9:
            pk = scene.P[k + 1]
            for j in np.nonzero(np.hypot(pk[:, 0] - x, pk[:, 1] - y) < R_ROBOT + R_PED)[0]:
                hit_steps += 1
                if j not in hits:
                    model = "ics" if layer == "braking_ics" else "table9"
                    cause = _cause(scene, k_ver, k + 1, j, zones if layer == "online_verification" else None, model)
                    hits[j] = (int(k + 1), cause)
                    causes[cause] += 1
    return _result(False, HORIZON_LIMIT, dist, hits, hit_steps, path, causes)


def _result(at_goal, t, dist, hits, hit_steps, path, causes):
    return {"at_goal": at_goal, "time_s": t, "distance": dist, "collisions": len(hits), "collision_steps": hit_steps,
            "hits": hits, "path": path, "causes": causes}  # fmt: skip


CAUSES = ("pedestrian not visible when the motion was verified", "appeared outside the entry zones",
          "pedestrian left its predicted set", "other")  # fmt: skip


def _cause(scene, k, k1, j, zones, model="table9"):
    """Why pedestrian j could hit the robot at k1 although the motion was verified at k.

    ``zones`` None: the layer ignores appearances (braking ICS, or online verification without
    entry zones).  Otherwise a hit inside any set the verification used is a bug ("other")."""
    actual = scene.P[k1, j][None, None]
    t = np.array([(k1 - k) * DT])
    visible = not np.isnan(scene.P[k, j, 0])
    if zones is None:
        if not visible:
            return CAUSES[0]
        p, v, age, idx = scene.observe(k)
        i = int(np.nonzero(idx == j)[0][0])
        inside = L.pedestrian_clearance(actual, t, p[i : i + 1], v[i : i + 1], model)[0, 0, 0] <= 0
        return "other" if inside else CAUSES[2]
    p, v, age, idx = scene.observe(k, MEMORY)
    inside = p.shape[0] and np.any(L.pedestrian_clearance(actual, t, p, v, "table9", age) <= 0)
    if inside or zones.clearance(actual, t)[0, 0] <= 0:
        return "other"
    if visible:
        return CAUSES[2]
    return CAUSES[1] if zones.distance(scene.first_position(j)) > 0 else CAUSES[2]


def entry_zones(scene, t0, t1, margin=ZONE_MARGIN):
    """Entry zones for a run over [t0, t1]: first positions of the tracks that begin outside
    [t0 - margin, t1 + margin] (other time windows of the sequence, never the run's own pedestrians)."""
    from scipy.spatial import cKDTree

    other = (scene.start_t < t0 - margin) | (scene.start_t > t1 + margin)
    pts = scene.starts[other]
    near = np.array([len(n) - 1 for n in cKDTree(pts).query_ball_point(pts, ZONE_DENSITY_RADIUS)])
    return L.EntryZones(pts[near >= ZONE_MIN_NEIGHBOURS])


def scenarios(scene, half_length=6.0):
    c, a = scene.center, scene.axis
    n = np.array([-a[1], a[0]])
    return {"with_flow": (c - half_length * a, c + half_length * a),
            "against_flow": (c + half_length * a, c - half_length * a),
            "across_flow": (c - 0.6 * half_length * n, c + 0.6 * half_length * n)}  # fmt: skip


def plot_run(scene, res, zones, out):
    """One run of online verification: path, entry zones and, at the moment the robot passes closest
    to a pedestrian at speed, the reach tube of its fail-safe maneuver (reachconf.reach on
    diff_drive, footprint added) and the pedestrians' Table 9 sets until the robot stops."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    path = res["path"]
    xy = np.array([p[:2] for p in path])
    start, goal = res["route"]
    best, best_d = 1, np.inf
    for i in range(1, len(path) - 1):
        p = scene.P[path[i][5]]
        p = p[~np.isnan(p[:, 0])]
        if p.size:  # closest approach to a pedestrian at speed (1 m/s or more if there is one)
            d = np.min(np.hypot(*(p - xy[i]).T)) - 10.0 * min(path[i + 1][3], 1.0)
            if d < best_d:
                best, best_d = i, d
    x, y, th, _, _, k = path[best]
    v, w = path[best + 1][3], path[best + 1][4]
    fig, ax = plt.subplots(figsize=(7, 6.5))
    for z in zones.points:
        ax.add_patch(plt.Circle(z, zones.radius, color="C1", alpha=0.08, lw=0))
    ax.plot([], [], "s", color="C1", alpha=0.3, label="entry zones (other time windows)")
    ax.plot(xy[:, 0], xy[:, 1], "C0-", lw=1.5, label="robot path")
    tube = L.braking_reach_tube((x, y, th), v, w)
    t_stop = tube.times[-1]
    tube.plot(ax=ax, dims=("px", "py"), color="C0", alpha=0.25, outline=False)
    end = tube.project((0, 1)).time_point_sets[-1].interval()
    ax.add_patch(plt.Circle(0.5 * (end.lo + end.hi), R_ROBOT + np.hypot(*(end.hi - end.lo)) / 2, fill=False,
                            color="C0", lw=1, ls="--", label=f"fail-safe reach set at standstill (+{R_ROBOT} m footprint)"))
    ax.plot([], [], "s", color="C0", alpha=0.4, label=f"reach tube of the fail-safe maneuver (v={v:.2f} m/s)")
    p, vel, age, idx = scene.observe(k, MEMORY)
    for i in range(p.shape[0]):
        ax.add_patch(plt.Circle(p[i], R_PED, color="k" if age[i] == 0 else "0.6"))
        tt = t_stop + age[i]
        B = BoxDisk(p[i], P_UNC, V_PED * tt + R_PED).boundary()
        ax.plot(B[:, 0], B[:, 1], color="C3", lw=0.6, alpha=0.6)
        if not np.isnan(vel[i, 0]):
            B = BoxDisk(p[i] + vel[i] * tt, P_UNC + V_UNC * tt, 0.5 * A_PED * tt**2 + R_PED).boundary()
            ax.plot(B[:, 0], B[:, 1], color="C2", lw=1)
    ax.plot([], [], color="C3", lw=0.6, label="pedestrians: velocity-constrained set until standstill")
    ax.plot([], [], color="C2", lw=1, label="pedestrians: acceleration-constrained set")
    ax.plot(*start, "g^", ms=10, label="start")
    ax.plot(*goal, "r*", ms=12, label="goal")
    ax.plot(x, y, "bo", ms=5)
    ax.set_xlim(min(start[0], goal[0]) - 4, max(start[0], goal[0]) + 4)
    ax.set_ylim(min(start[1], goal[1]) - 4, max(start[1], goal[1]) + 4)
    ax.set_aspect("equal")
    ax.set_title(f"Online verification, t = {scene.t[k]:.1f} s: sets until the robot could stop ({t_stop:.1f} s)",
                 fontsize=9)  # fmt: skip
    ax.legend(loc="lower left", fontsize=6.5, framealpha=0.9)
    fig.tight_layout()
    save_figure(fig, out / "robot_run.png", dpi=90, bbox_inches=None)
    plt.close(fig)


def clip_route(start, goal, zones, clearance=ROUTE_CLEARANCE):
    """Move start and goal along the straight route until they are ``clearance`` from the entry
    zones (a robot cannot safely wait in a doorway); unchanged if the whole route is too close."""
    start, goal = np.asarray(start, dtype=float), np.asarray(goal, dtype=float)
    s = np.linspace(0.0, 1.0, 201)
    pts = start + s[:, None] * (goal - start)
    ok = np.nonzero(zones.distance(pts) >= clearance)[0]
    if ok.size == 0:
        return start, start
    return pts[ok[0]], pts[ok[-1]]


def _summary(runs, scene, sname):
    reached = [r for r in runs if r["at_goal"]]
    return {
        "runs": len(runs),
        "at_goal": len(reached),
        "time_s": float(np.mean([r["time_s"] for r in reached])) if reached else None,
        "velocity": float(np.mean([r["distance"] / r["time_s"] for r in reached])) if reached else None,
        "route_m": float(np.mean([np.hypot(*np.subtract(*r["route"])) for r in runs])) if runs else None,
        "collisions": int(sum(r["collisions"] for r in runs)),
        "collision_steps": int(sum(r["collision_steps"] for r in runs)),
        "collision_causes": {c: int(sum(r["causes"][c] for r in runs)) for c in CAUSES},
        "collision_list": [{"sequence": sname, "start_s": round(float(scene.t[r["k0"]]), 1), "pedestrian": scene.pids[j],
                            "at_s": round(float(scene.t[k1]), 1), "cause": cause}
                           for r in runs for j, (k1, cause) in r["hits"].items()],  # fmt: skip
    }


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default=str(Path(os.environ.get("REACHCONF_DATA") or Path(__file__).resolve().parents[2].parent
                                                  / "shared" / "data") / "pedestrians"),
                    help="data folder (default: ../shared/data/pedestrians from the repo root, or $REACHCONF_DATA)")
    ap.add_argument("--out", required=True)
    ap.add_argument("--starts", type=positive_int, default=12, help="start times per sequence and scenario")
    ap.add_argument("--sequences", nargs="+", default=["eth", "hotel"])
    ap.add_argument("--no-entry-zones", dest="entry_zones", action="store_false",
                    help="online verification without phantom pedestrians at the entry zones (ablation)")
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
            runs, skipped = {layer: [] for layer in LAYERS}, 0
            for k in k_starts:
                k = int(k)
                zones = entry_zones(scene, scene.t[k], scene.t[k] + HORIZON_LIMIT)
                s, g = clip_route(start, goal, zones)
                if np.hypot(*(g - s)) < MIN_ROUTE * np.hypot(*np.subtract(goal, start)):
                    skipped += 1  # the entry zones leave too little of the route: not run
                    continue
                for layer in LAYERS:
                    use = zones if layer == "online_verification" and args.entry_zones else None
                    if (r := run_once(scene, k, s, g, layer, use)) is not None:
                        r.update(k0=k, route=(s.tolist(), g.tolist()))
                        runs[layer].append(r)
            for layer in LAYERS:
                table[layer][f"{sname}/{scen}"] = dict(_summary(runs[layer], scene, sname), skipped=skipped)
            if picture is None:
                picture = (scene, runs["online_verification"], args.entry_zones)
    if picture is not None and picture[1]:
        scene, runs, k = picture
        r = max(runs, key=lambda r: r["distance"]) if runs else None
        k = r["k0"]
        zones = entry_zones(scene, scene.t[k], scene.t[k] + HORIZON_LIMIT)
        res = run_once(scene, k, *map(np.asarray, r["route"]), "online_verification", zones, record=True)
        res["route"] = r["route"]
        plot_run(scene, res, zones, out)
    result = dict(table, seconds=time.perf_counter() - t0,
                  flow={s: {"axis": sc.axis.tolist(), "share_with": sc.flow_share} for s, sc in scenes.items()})
    atomic_write(out / "robot.json", json_text(result))
    lines = ["| layer | scenario | runs | at goal | mean time [s] | mean velocity [m/s] | collisions while moving |",
             "|---|---|---|---|---|---|---|"]  # fmt: skip
    for layer in LAYERS:
        for key, e in table[layer].items():
            tm = f"{e['time_s']:.1f}" if e["time_s"] is not None else "-"
            vel = f"{e['velocity']:.2f}" if e["velocity"] is not None else "-"
            lines.append(f"| {layer} | {key} | {e['runs']} | {e['at_goal']} | {tm} | {vel} | {e['collisions']} |")
    atomic_write(out / "robot.md", "\n".join(lines) + "\n")
    print("\n".join(lines))
    print(f"({result['seconds']:.1f} s) wrote {out / 'robot.json'}")
    return 0


if __name__ == "__main__":
    from reachconf.script import run_script

    sys.exit(run_script(main, "robot"))
