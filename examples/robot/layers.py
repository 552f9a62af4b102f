"""Robot kinematics, fail-safe braking maneuver, reachable-set enclosures and the three safety layers.

Used by ``run.py``; everything here is a pure function of arrays so the tests can call it directly.

Robot (section 7.3): kinematic differential drive ``px' = v cos(phi)``, ``py' = v sin(phi)``,
``phi' = w``, velocity commands piecewise constant over the 0.1 s control period (the input of
``reachconf.models.diff_drive``), |v| <= 1.5 m/s, |w| <= 2 rad/s, a command may change by at most
a_tra * 0.1 s and a_rot * 0.1 s per period.  Localisation uncertainty: +-0.05 m in x and y and
+-0.05 rad in the heading; footprint: disk of radius 0.3 m.

Fail-safe maneuver of a candidate command (v, w): hold (v, w) for one period, then brake at full
deceleration, v_j = max(v - a_tra*0.1*j, 0), while |w| ramps down at a_rot; the robot is at rest
after the last period with v_j > 0 (turning on the spot afterwards is not motion).

In-loop enclosure of the robot's reachable set over period j: the disk around the nominal pose at
mid-period with radius ``R_ROBOT + |d_xy| + 2 sin(delta/2) * s(t_{j+1}) + v_j * 0.1 / 2`` — an arc
of length L lies within L/2 of its midpoint, and a start pose off by (dx, dy, dphi) with the same
commands moves every point of the path by ``d + (e^{i dphi} - 1)(p(t) - p(0))`` (a rigid rotation
about the start), whose norm is at most ``|d| + 2 sin(|dphi|/2) * s(t)``.  ``tests/usecases/test_robot.py``
checks that these disks enclose the reachable sets that ``reachconf.reach`` computes for
``diff_drive`` (and sampled trajectories).
"""

from __future__ import annotations

import numpy as np

from reachconf.sets import box_disk_distance

V_MAX, W_MAX, A_TRA, A_ROT = 1.5, 2.0, 1.5, 1.0
R_ROBOT, LOC_UNC, HEAD_UNC, R_PED = 0.3, 0.05, 0.05, 0.27
A_PED, V_PED, P_UNC, V_UNC = 0.6, 2.0, 0.1, 0.1
DT = 0.1
#: entry zones: a pedestrian may appear anywhere within ZONE_RADIUS of a point where a track began
#: in the other time windows of the same sequence
ZONE_RADIUS = 0.5
LAYERS = ("online_verification", "iso_safety_field", "braking_ics")
_LOC_DISK = LOC_UNC * np.sqrt(2.0)


# ------------------------------------------------------------------ kinematics
def step_pose(x, y, th, v, w, h=DT):
    """Exact unicycle motion under constant (v, w) for time h (arrays broadcast)."""
    x, y, th, v, w = np.broadcast_arrays(*(np.asarray(a, dtype=float) for a in (x, y, th, v, w)))
    small = np.abs(w) < 1e-9
    ws = np.where(small, 1.0, w)
    th1 = th + w * h
    dx = np.where(small, v * h * np.cos(th + 0.5 * w * h), v / ws * (np.sin(th1) - np.sin(th)))
    dy = np.where(small, v * h * np.sin(th + 0.5 * w * h), -v / ws * (np.cos(th1) - np.cos(th)))
    return x + dx, y + dy, th1


def braking_commands(v, w):
    """Commands (J, 2) of the fail-safe maneuver of candidate (v, w): the candidate, then full braking."""
    v, w = float(v), float(w)
    if v <= 0.0:
        return np.zeros((0, 2))
    J = int(np.ceil(v / (A_TRA * DT) - 1e-9))
    j = np.arange(J)
    return np.column_stack([np.maximum(v - A_TRA * DT * j, 0.0), np.sign(w) * np.maximum(abs(w) - A_ROT * DT * j, 0.0)])


def brake_step(v, w):
    """Next command of a running fail-safe maneuver."""
    return max(v - A_TRA * DT, 0.0), float(np.sign(w) * max(abs(w) - A_ROT * DT, 0.0))


def maneuvers(pose, cands):
    """Fail-safe maneuvers of all candidates (C, 2) from ``pose``, padded to a common length J.

    Returns ``mid`` (C, J, 2) nominal positions at mid-period, ``radius`` (C, J) of the robot's
    enclosing disks (footprint and localisation uncertainty included), ``t_hi`` (J,) the end of
    each period (relative to now) and ``moving`` (C, J): the robot moves in that period.
    """
    cands = np.asarray(cands, dtype=float).reshape(-1, 2)
    C = cands.shape[0]
    J = max(1, int(np.ceil(cands[:, 0].max(initial=0.0) / (A_TRA * DT) - 1e-9)))
    j = np.arange(J)
    V = np.maximum(cands[:, :1] - A_TRA * DT * j, 0.0)
    W = np.sign(cands[:, 1:]) * np.maximum(np.abs(cands[:, 1:]) - A_ROT * DT * j, 0.0)
    x = np.full(C, float(pose[0]))
    y = np.full(C, float(pose[1]))
    th = np.full(C, float(pose[2]))
    mid = np.empty((C, J, 2))
    s_end = np.cumsum(V * DT, axis=1)
    for k in range(J):
        mx, my, _ = step_pose(x, y, th, V[:, k], W[:, k], 0.5 * DT)
        mid[:, k, 0], mid[:, k, 1] = mx, my
        x, y, th = step_pose(x, y, th, V[:, k], W[:, k], DT)
    radius = R_ROBOT + _LOC_DISK + 2 * np.sin(HEAD_UNC / 2) * s_end + 0.5 * DT * V
    return mid, radius, (j + 1) * DT, V > 0


def stopping(v=V_MAX):
    """Stopping time and distance of the fail-safe maneuver from speed v (including the held period)."""
    cmd = braking_commands(v, 0.0)
    return cmd.shape[0] * DT, float(cmd[:, 0].sum() * DT)


# ------------------------------------------------------------ obstacle sets
def pedestrian_clearance(mid, t_hi, peds_p, peds_v, model="table9", age=None):
    """Distance from the points ``mid`` (C, J, 2) to each pedestrian's reachable set over period j.

    Shape (C, J, N), before subtracting the robot's radius and the pedestrian's.  The set over
    [t_hi - DT, t_hi] is enclosed by (Table 9) the intersection of the acceleration-constrained set
    box(p + v t, P_UNC + V_UNC t) ⊕ disk(a t²/2) and the velocity-constrained set
    box(p, P_UNC) ⊕ disk(v_max t); a point is clear of the intersection if it is clear of either.
    ``model="ics"``: obstacles at full speed in any direction, disk(p, P_UNC sqrt 2 + v_max t).
    A pedestrian without a velocity estimate (NaN) is bounded by the velocity model only.
    ``age`` (N,): time since each pedestrian was last seen (tracks lost from view keep growing sets).
    """
    rel = mid[:, :, None, :] - peds_p[None, None, :, :]  # (C, J, N, 2)
    age = np.zeros(peds_p.shape[0]) if age is None else np.asarray(age, dtype=float)
    th = t_hi[None, :, None] + age[None, None, :]
    if model == "ics":
        return np.linalg.norm(rel, axis=-1) - P_UNC * np.sqrt(2) - V_PED * th
    d_vel = box_disk_distance(rel, P_UNC, V_PED * th)
    vel = np.nan_to_num(peds_v)
    t_mid = th[..., None] - 0.5 * DT
    box = P_UNC + V_UNC * th[..., None] + np.abs(vel)[None, None] * 0.5 * DT
    d_acc = box_disk_distance(rel - t_mid * vel[None, None], box, 0.5 * A_PED * th**2)
    d_acc = np.where(np.isnan(peds_v[:, 0])[None, None, :], -np.inf, d_acc)
    return np.maximum(d_acc, d_vel)


class EntryZones:
    """Where unseen pedestrians may appear: within ZONE_RADIUS of the first positions of tracks.

    The points come from other time windows of the sequence (never from the pedestrians of the
    run that uses them).  A phantom pedestrian may appear at any zone point at any time and then
    walk at up to v_max, so at time t after verification it lies within zone ⊕ disk(v_max t).
    """

    def __init__(self, points, radius=ZONE_RADIUS):
        from scipy.spatial import cKDTree

        self.points = np.asarray(points, dtype=float).reshape(-1, 2)
        self.radius = float(radius)
        self._tree = cKDTree(self.points) if self.points.shape[0] else None

    def distance(self, q):
        """Distance from points q (..., 2) to the zones (negative inside)."""
        q = np.asarray(q, dtype=float)
        if self._tree is None:
            return np.full(q.shape[:-1], np.inf)
        d, _ = self._tree.query(q.reshape(-1, 2))
        return d.reshape(q.shape[:-1]) - self.radius

    def clearance(self, mid, t_hi):
        """Distance from ``mid`` (C, J, 2) to the phantoms' reachable set over period j, (C, J)."""
        return self.distance(mid) - V_PED * t_hi[None, :]


# ------------------------------------------------------------------ the layers
def safe_candidates(layer, pose, cands, peds_p, peds_v, zones=None, age=None):
    """Which candidate commands (C, 2) does a verification layer accept? Boolean (C,).

    Candidates with v = 0 do not move and are always accepted.  ``online_verification`` checks the
    fail-safe maneuver against the pedestrians' Table 9 sets and, if ``zones`` is given, against
    phantom pedestrians appearing in the entry zones; ``braking_ics`` against full-speed disks.
    """
    cands = np.asarray(cands, dtype=float).reshape(-1, 2)
    ok = np.ones(cands.shape[0], dtype=bool)
    movers = cands[:, 0] > 0
    if not movers.any():
        return ok
    mid, radius, t_hi, moving = maneuvers(pose, cands[movers])
    clear = np.ones(moving.shape, dtype=bool)
    if peds_p.shape[0]:
        d = pedestrian_clearance(mid, t_hi, peds_p, peds_v, "ics" if layer == "braking_ics" else "table9", age)
        clear &= np.all(d > radius[..., None] + R_PED, axis=-1)
    if zones is not None and layer == "online_verification":
        clear &= zones.clearance(mid, t_hi) > radius + R_PED
    ok[movers] = np.all(clear | ~moving, axis=1)
    return ok


def safety_field_radius():
    """ISO 13482-style protective field: the robot stops from full speed before a pedestrian at
    full speed, starting at the field's edge during the robot's stopping time (plus one period of
    reaction), can reach the footprint."""
    t_stop, d_stop = stopping(V_MAX)
    return R_ROBOT + _LOC_DISK + R_PED + d_stop + V_PED * (t_stop + DT)


# -------------------------------------------------------- reachconf reach sets
def braking_reach_tube(pose, v, w, time_step=0.01):
    """Reach tube of the fail-safe maneuver of (v, w) from ``pose`` by ``reachconf.reach`` on the
    built-in ``diff_drive`` model, localisation uncertainty as the initial set (footprint not
    added: the tube holds the reference point)."""
    import reachconf as rc
    from reachconf.models import diff_drive

    cmd = braking_commands(v, w)
    times = np.arange(cmd.shape[0] + 1) * DT
    U = np.vstack([cmd, [[0.0, 0.0]]])
    lo = np.array([pose[0] - LOC_UNC, pose[1] - LOC_UNC, pose[2] - HEAD_UNC])
    X0 = rc.Interval(lo, lo + 2 * np.array([LOC_UNC, LOC_UNC, HEAD_UNC]))
    return rc.reach(diff_drive(), X0, times, inputs=U, options=rc.ReachOptions(time_step=time_step))
