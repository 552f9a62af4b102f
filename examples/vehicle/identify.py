"""Least-squares identification for the vehicle use case (section 4.1).

* :func:`fit_bicycle`: J/m, b/L, c_f, c_r of f_B (eqs. 49-52) by equation error
  (:func:`reachconf.diagnose.identify.identify`, ``method="equation_error"``):
  the model's lateral and yaw accelerations at the measured (smoothed) states
  and inputs against the Savitzky-Golay derivatives of the measured ``vy`` and
  ``omega``, yaw equation only (the lateral one is dominated by the plant's
  roll and load-transfer effects), with a weak prior on Table 1 to fix the
  scale that the yaw equation cannot see.  On the quick campaign this gives
  J/m = 1.47 +- 0.14 (plant: 1.64), b/L = 0.56 +- 0.09 (0.55), c_f = 16.8,
  c_r = 15.6.
  The wheelbase L is geometry, not fitted: the plant's a + b.
* :func:`fit_actuators`: Table 2's ``k, off, s`` of the two first-order
  actuators ``y' = k (s (u_req + off) - y)`` by output error of the discrete
  simulation of each actuator against the measured steering angle and
  acceleration.
* :func:`fit_rate_limited_steering`: ``k_delta, delta_off, delta_s, r_delta``
  of the rate-limited steering ``delta' = r tanh(k (s (u_req + off) - delta) / r)``
  of :func:`reachconf.models.bicycle_closed_loop_rate_limited`, by output error
  of its simulation (RK4, 4 steps per sample) against the measured steering angle.
"""

from __future__ import annotations

import numpy as np
import sympy as sp
from scipy.optimize import least_squares

from reachconf.diagnose.identify import identify
from reachconf.model.core import Model
from reachconf.model.simulate import simulate
from reachconf.models import bicycle

FIT = ("J_m", "b_L", "c_f", "c_r")


def _wheelbase():
    from vehiclemodels.parameters_vehicle2 import parameters_vehicle2

    p = parameters_vehicle2()
    return float(p.a + p.b)


def fit_bicycle(suite):
    """Identify (J_m, b_L, c_f, c_r) by equation error on the yaw equation; returns ``(params, report)``.

    Only the yaw equation is fitted: v_y' of the rear axle is a small difference of large terms
    (F_y / m - v_x omega - b omega'), and a few-% force mismatch of the multi-body plant (roll, load
    transfer, unsprung masses) in it pulled b/L to its bound; the yaw equation alone recovers the
    plant's geometry and inertia.  It is invariant to scaling (J/m, c_f, c_r) together: a weak prior
    on Table 1 (1 % of the data's weight) picks the point of that valley nearest to the nominal values.
    """
    L = _wheelbase()
    res = identify(bicycle(L=L), suite, FIT, method="equation_error", equations=("omega",), window=0.25, prior=0.01,
                   bounds=dict(zip(FIT, zip((0.1, 0.05, 0.1, 0.1), (10, 0.95, 100, 100)))))  # fmt: skip
    params = {"L": L, **res.params}
    report = {"std": res.std, "rms_residual": res.rms_residual, "samples": res.samples, "start": res.start}
    return params, report


def _first_order(u, dt, k, off, s, y0):
    """Exact discretisation of y' = k (s (u + off) - y) with u held over each step."""
    a = np.exp(-k * dt)
    y = np.empty_like(u)
    y[0] = y0
    target = s * (u + off)
    for i in range(u.size - 1):  # short per-case loop (identification only, not a hot path)
        y[i + 1] = a[i] * y[i] + (1 - a[i]) * target[i]
    return y


def fit_actuators(suite):
    """Identify Table 2's actuator parameters from requested vs measured signals."""
    out = {"params": {}, "rms": {}}
    for name, req, meas, x0 in (("delta", "delta_req", "delta", (9.0, 0.0, 0.3)), ("ax", "ax_req", "ax", (3.0, 0.0, 1.0))):
        data = [(np.diff(c.t), c.signal(req), c.signal(meas)) for c in suite]

        def resid(theta):
            k, off, s = theta
            return np.concatenate([_first_order(u, np.append(dt, dt[-1]), k, off, s, y[0]) - y for dt, u, y in data])

        sol = least_squares(resid, np.array(x0), bounds=([0.1, -1.0, 0.01], [100.0, 1.0, 10.0]))
        k, off, s = (float(v) for v in sol.x)
        out["params"].update({f"k_{name}": k, f"{name}_off": off, f"{name}_s": s})
        out["rms"][name] = float(np.sqrt(np.mean(sol.fun**2)))
        out["rms"][name + "_unmodelled"] = float(np.sqrt(np.mean(np.concatenate([u - y for _, u, y in data]) ** 2)))
    return out


def fit_rate_limited_steering(suite, start=(6.0, 0.02, 0.29, 0.5), delay=0):
    """Identify ``k_delta, delta_off, delta_s, r_delta`` of the rate-limited steering actuator.

    Returns ``{"params": {...}, "rms": rad, "max_error": {group: rad}}`` (the
    open-loop simulation error of the actuator alone, requested -> measured).
    ``delay``: transport delay of the request in samples (the actuator sees
    ``u_req`` that many samples late).
    """
    act = Model(name="steering_rate_limited", states=("d",), inputs=("u",),
                params={"k": 9.0, "off": 0.0, "s": 0.3, "r": 0.4},
                dynamics=lambda s: [s.r * sp.tanh(s.k * (s.s * (s.u + s.off) - s.d) / s.r)])  # fmt: skip
    def late(u):
        return np.concatenate([np.full(delay, u[0]), u[: u.size - delay]]) if delay else u

    data = [(c.t, late(c.signal("delta_req"))[:, None], c.signal("delta"), c.group) for c in suite]

    def sim(theta, t, u, y):
        k, off, s_, r = theta
        return simulate(act.with_params(k=k, off=off, s=s_, r=r), [y[0]], t, u, None, 4)[:, 0]

    def resid(theta):
        return np.concatenate([sim(theta, t, u, y) - y for t, u, y, _ in data])

    sol = least_squares(resid, np.array(start), bounds=([0.5, -0.2, 0.01, 0.05], [100.0, 0.2, 2.0, 5.0]),
                        x_scale="jac")  # fmt: skip
    worst = {}
    for t, u, y, g in data:
        worst[g] = max(worst.get(g, 0.0), float(np.abs(sim(sol.x, t, u, y) - y).max()))
    k, off, s_, r = (float(v) for v in sol.x)
    return {"params": {"k_delta": k, "delta_off": off, "delta_s": s_, "r_delta": r},
            "rms": float(np.sqrt(np.mean(sol.fun**2))), "max_error": worst}  # fmt: skip
