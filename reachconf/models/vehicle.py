"""Vehicle models of the source report, section 4.1 and 4.3.

Sign convention of the cornering stiffnesses
--------------------------------------------
Table 1 lists ``c_f = -9.7`` and ``c_r = -25.2``.  With eqs. 50/51 as printed,
``f_yf = -c_f mu g b/L ((v_y + L omega)/v_x - delta)``, a *positive* ``c_f``
gives the physical, restoring tyre force (a positive slip ``(v_y + L omega)/v_x``
produces a negative lateral force).  With the negative table values the model
is unstable.  We therefore use the magnitudes ``c_f = 9.7``, ``c_r = 25.2``
(normalised cornering stiffnesses: force per unit mass and per unit normal
acceleration ``mu g``, per radian).

Geometry: ``L`` wheelbase, ``b = (b/L) L`` the distance from the centre of
gravity to the **rear** axle and ``a = L - b`` to the front axle; ``b/L`` is
the static front-axle load share, consistent with the factor ``b/(a+b)`` in
eq. 50.  Positions ``X, Y`` and the lateral velocity ``vy`` are those of the
rear axle (COR); ``J/m`` is the yaw inertia divided by the mass.
"""

from __future__ import annotations

import math

import sympy as sp

from reachconf.model.core import Model
from reachconf.models.vehicle_controller import ControllerGains, tracking_law

__all__ = ["bicycle", "bicycle_actuated", "bicycle_closed_loop", "bicycle_closed_loop_actuated",
           "bicycle_closed_loop_rate_limited", "TABLE1", "TABLE2", "STEERING_RATE_LIMIT"]

#: Table 1 (cornering stiffnesses as positive magnitudes, see module docstring).
TABLE1 = {"J_m": 1.57, "L": 2.7, "b_L": 0.57, "c_f": 9.7, "c_r": 25.2, "mu": 1.0, "g": 9.81}

#: Table 2 actuator parameters (delta_off converted to radians).
TABLE2 = {
    "ax_off": 0.32,
    "ax_s": 0.64,
    "k_ax": 2.96,
    "delta_off": math.radians(1.09),
    "delta_s": 0.28,
    "k_delta": 9.83,
}

STATES = ("X", "Y", "psi", "vx", "vy", "omega")


def _bicycle_rhs(s, ax, delta, w1, w2, w3):
    """Right-hand side of eq. 49 with tyre forces eqs. 50/51 (per unit mass)."""
    L = s.L
    b = s.b_L * L
    a = L - b
    f_yf = -s.c_f * s.mu * s.g * (b / L) * ((s.vy + L * s.omega) / s.vx - delta) + w2
    f_yr = -s.c_r * s.mu * s.g * (a / L) * s.vy / s.vx + w3
    omega_dot = (a * f_yf - b * f_yr) / s.J_m
    return [
        s.vx * sp.cos(s.psi) - s.vy * sp.sin(s.psi),
        s.vx * sp.sin(s.psi) + s.vy * sp.cos(s.psi),
        s.omega,
        ax + s.vy * s.omega + w1,
        f_yf + f_yr - s.vx * s.omega - b * omega_dot,
        omega_dot,
    ]


def bicycle(**params) -> Model:
    """Dynamic bicycle model f_B with measured inputs, eqs. 44–52, Table 1.

    States/outputs ``X, Y, psi, vx, vy, omega`` (rear-axle position, yaw,
    longitudinal velocity, lateral velocity at the rear axle, yaw rate; SI,
    radians); inputs ``ax, delta`` (measured longitudinal acceleration and
    steering angle); disturbances ``w1, w2, w3`` (eq. 48: normalised error
    forces, longitudinal, lateral at the front axle, lateral at the rear axle,
    m/s²); ``y = x + v`` (eq. 52).
    """
    p = dict(TABLE1)
    p.update(params)
    return Model(
        name="bicycle",
        states=STATES,
        inputs=("ax", "delta"),
        disturbances=("w1", "w2", "w3"),
        params=p,
        dynamics=lambda s: _bicycle_rhs(s, s.ax, s.delta, s.w1, s.w2, s.w3),
        description="dynamic bicycle model f_B (eqs. 49-52, Table 1)",
    )


def bicycle_actuated(**params) -> Model:
    """Bicycle model with first-order actuators f_BX, eqs. 53–58, Tables 1–2.

    Extra states/outputs ``ax, delta`` (realised acceleration and steering);
    inputs ``ax_req, delta_req`` (requested); disturbances ``w1..w5`` (w4 on
    the requested acceleration, m/s², w5 on the requested steering, rad).
    ``ax' = -k_ax (ax - (ax_req + w4 + ax_off) ax_s)`` and likewise for the
    steering (eq. 58).  Table 2's ``delta_s = 0.28`` is kept as the default
    because the report gives it, but it most likely converts a steering-wheel
    request; identify the actuator parameters on your data
    (``examples/vehicle``).
    """
    p = dict(TABLE1)
    p.update(TABLE2)
    p.update(params)

    def f(s):
        body = _bicycle_rhs(s, s.ax, s.delta, s.w1, s.w2, s.w3)
        return body + [
            -s.k_ax * (s.ax - (s.ax_req + s.w4 + s.ax_off) * s.ax_s),
            -s.k_delta * (s.delta - (s.delta_req + s.w5 + s.delta_off) * s.delta_s),
        ]

    return Model(
        name="bicycle_actuated",
        states=STATES + ("ax", "delta"),
        inputs=("ax_req", "delta_req"),
        disturbances=("w1", "w2", "w3", "w4", "w5"),
        params=p,
        dynamics=f,
        description="bicycle model with actuator dynamics f_BX (eqs. 53-58, Tables 1-2)",
    )


def _gain_names():
    return list(ControllerGains.__dataclass_fields__)


def _gain_params() -> dict:
    """The default controller gains as model parameters ``gain_<name>``."""
    gains = ControllerGains()
    return {f"gain_{k}": float(getattr(gains, k)) for k in _gain_names()}


def _controller(s):
    """``(a_x, delta)`` commanded by the tracking law on the model's symbols (gains are parameters)."""
    g = ControllerGains(**{k: s[f"gain_{k}"] for k in _gain_names()})
    return tracking_law(s.X, s.Y, s.psi, s.vx, s.vy, s.omega, s.X_ref, s.Y_ref, s.psi_ref, s.v_ref, s.kappa_ref, g,
                        m=sp)  # fmt: skip


def bicycle_closed_loop(**params) -> Model:
    """Closed-loop bicycle model of section 4.3 (reachset conformance), eqs. 59/60.

    f_B driven by the continuous-time tracking controller of
    :func:`reachconf.models.vehicle_controller.tracking_law` (the same law the test
    campaign uses, written once for numpy and sympy) on the lateral, heading
    and speed errors to a reference that enters as known inputs
    ``X_ref, Y_ref, psi_ref, v_ref, kappa_ref``; each of the six ODEs gets an
    additive disturbance ``w1..w6`` (eq. 60).  Controller gains are parameters
    (``k_*`` names of :class:`reachconf.models.vehicle_controller.ControllerGains`).
    """
    p = dict(TABLE1)
    p.update(_gain_params())
    p.update(params)

    def f(s):
        ax, delta = _controller(s)
        rhs = _bicycle_rhs(s, ax, delta, 0, 0, 0)
        w = (s.w1, s.w2, s.w3, s.w4, s.w5, s.w6)
        return [r + wi for r, wi in zip(rhs, w)]

    return Model(
        name="bicycle_closed_loop",
        states=STATES,
        inputs=("X_ref", "Y_ref", "psi_ref", "v_ref", "kappa_ref"),
        disturbances=("w1", "w2", "w3", "w4", "w5", "w6"),
        params=p,
        dynamics=f,
        description="closed-loop bicycle model with tracking controller (section 4.3, eqs. 59/60)",
    )


def _actuated_closed_loop(name, description, params, rate_limit=None) -> Model:
    """Closed-loop bicycle with first-order actuators; the steering rate is limited if ``rate_limit``."""
    p = dict(TABLE1)
    p.update(TABLE2)
    p["delta_s_nominal"] = TABLE2["delta_s"]
    if rate_limit is not None:
        p["r_delta"] = rate_limit
    p.update(_gain_params())
    p.update(params)

    def f(s):
        ax_cmd, delta_cmd = _controller(s)
        rhs = _bicycle_rhs(s, s.ax, s.delta, 0, 0, 0)
        w = (s.w1, s.w2, s.w3, s.w4, s.w5, s.w6)
        target = (delta_cmd / s.delta_s_nominal + s.delta_off) * s.delta_s
        if rate_limit is None:
            steering = -s.k_delta * (s.delta - target)
        else:
            steering = s.r_delta * sp.tanh(s.k_delta * (target - s.delta) / s.r_delta)
        return [r + wi for r, wi in zip(rhs, w)] + [-s.k_ax * (s.ax - (ax_cmd + s.ax_off) * s.ax_s), steering]

    return Model(
        name=name,
        states=STATES + ("ax", "delta"),
        inputs=("X_ref", "Y_ref", "psi_ref", "v_ref", "kappa_ref"),
        disturbances=("w1", "w2", "w3", "w4", "w5", "w6"),
        params=p,
        dynamics=f,
        description=description,
    )


def bicycle_closed_loop_actuated(**params) -> Model:
    """Closed-loop bicycle with the actuators of f_BX between controller and vehicle.

    As :func:`bicycle_closed_loop`, but the controller's commands pass through
    the first-order actuators of eqs. 57/58 (Table 2 parameters; the steering
    request is ``delta_cmd / delta_s_nominal``, the acceleration request is sent
    uncorrected, as in :mod:`reachconf.datasets.vehicle_campaign.plant`).  States and outputs
    ``X, Y, psi, vx, vy, omega, ax, delta`` (the realised acceleration and
    steering angle are measured); disturbances ``w1..w6`` on the vehicle ODEs.
    """
    return _actuated_closed_loop(
        "bicycle_closed_loop_actuated",
        "closed-loop bicycle with actuator dynamics (sections 4.1.2 and 4.3)",
        params,
    )


#: the plant's steering-rate limit (``parameters_vehicle2().steering.v_max``, rad/s)
STEERING_RATE_LIMIT = 0.4


def bicycle_closed_loop_rate_limited(**params) -> Model:
    """Closed-loop bicycle whose steering actuator is rate limited (``r tanh(k e / r)``).

    As :func:`bicycle_closed_loop_actuated`, but the steering follows its target
    ``delta_t = (delta_cmd / delta_s_nominal + delta_off) delta_s`` with a
    smooth rate limit::

        delta' = r_delta tanh(k_delta (delta_t - delta) / r_delta)

    (slope ``k_delta`` for small errors, at most ``r_delta`` rad/s).  The plant
    of the campaign limits the steering rate to 0.4 rad/s
    (:data:`STEERING_RATE_LIMIT`), which the 4 m/s² double lane change reaches
    for about a quarter of the run; the first-order actuator cannot follow
    there.  Defaults: Table 2 and ``r_delta`` = 0.4 rad/s; identify them on your
    data (``examples/vehicle``).
    """
    return _actuated_closed_loop(
        "bicycle_closed_loop_rate_limited",
        "closed-loop bicycle with a rate-limited steering actuator (r tanh(k e / r))",
        params,
        rate_limit=STEERING_RATE_LIMIT,
    )
