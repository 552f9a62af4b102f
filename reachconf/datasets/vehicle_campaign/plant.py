"""The "real vehicle" of the campaign: a multi-body plant with actuators, delays and sensors.

The DLR measurements of the report are not public, so the test campaign is
generated from a high-fidelity plant: the 29-state multi-body model of
``commonroad-vehicle-models`` (``vehicle_dynamics_mb``, BMW 320i parameters,
``parameters_vehicle2``) in closed loop with the tracking controller of
:mod:`reachconf.models.vehicle_controller` running at 100 Hz (sample and hold).
Between the controller's requests and the plant sit (each configurable, each
can be switched off):

* transport delays of the requests (``steer_delay``, ``accel_delay``);
* first-order actuator lags, offsets and scales as in Table 2
  (``delta' = k_delta (delta_s (delta_req + delta_off) - delta)``, the same for
  ``a_x``); the controller sends ``delta_req = delta_cmd / delta_s_nominal``,
  i.e. it knows the nominal steering ratio but not the offset, and sends the
  acceleration uncorrected (the longitudinal "mis-configuration" of
  section 4.1.2);

and between the plant and the controller and the logged measurements:

* sensor offsets (``yaw_offset``, ...) and INS-like white noise
  (``noise_*`` standard deviations, truncated at 2 sigma: a bounded error, as
  conformance with a finite V presumes; 2 sigma stays inside the report's
  Table 3 and Table 5 measurement errors).

The logged states are those of the bicycle model, at the rear axle:
``X, Y`` (rear-axle position), ``psi``, ``vx``, ``vy`` (rear-axle lateral
velocity), ``omega``.  The wheel steering angle and the longitudinal
acceleration actually realised are logged as ``delta, ax``; the requests as
``delta_req, ax_req``; the reference as ``X_ref ... kappa_ref``.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from reachconf.models.vehicle import TABLE2
from reachconf.models.vehicle_controller import ControllerGains, tracking_law

__all__ = ["PlantEffects", "simulate_maneuver", "NO_EFFECTS"]


@dataclass(frozen=True)
class PlantEffects:
    """Actuator and sensor effects between controller and multi-body plant (SI units, radians).

    Set a lag to ``None`` for an ideal actuator, delays/offsets/noise to 0 to switch them off.
    """

    k_delta: float | None = TABLE2["k_delta"]
    delta_off: float = TABLE2["delta_off"]
    delta_s: float = TABLE2["delta_s"]
    k_ax: float | None = TABLE2["k_ax"]
    ax_off: float = TABLE2["ax_off"]
    ax_s: float = TABLE2["ax_s"]
    steer_delay: float = 0.06
    accel_delay: float = 0.12
    delta_s_nominal: float = TABLE2["delta_s"]
    yaw_offset: float = np.radians(0.3)
    noise_pos: float = 0.015
    noise_psi: float = np.radians(0.1)
    noise_vel: float = 0.02
    noise_omega: float = np.radians(0.2)
    noise_actuator: float = 0.0

    def without(self, *names) -> "PlantEffects":
        """A copy with the named effects switched off (``"steer_lag"``, ``"noise"``, ``"offsets"``, ...)."""
        off = {}
        for name in names:
            if name == "steer_lag":
                off["k_delta"] = None
            elif name == "accel_lag":
                off["k_ax"] = None
            elif name == "delays":
                off.update(steer_delay=0.0, accel_delay=0.0)
            elif name == "offsets":
                off.update(delta_off=0.0, ax_off=0.0, yaw_offset=0.0)
            elif name == "scales":
                off.update(delta_s=1.0, ax_s=1.0, delta_s_nominal=1.0)
            elif name == "noise":
                off.update(noise_pos=0.0, noise_psi=0.0, noise_vel=0.0, noise_omega=0.0, noise_actuator=0.0)
            elif name in self.__dataclass_fields__:
                off[name] = 0.0
            else:
                raise ValueError(f"unknown effect {name!r}")
        return replace(self, **off)


#: every effect switched off: the plant receives exactly what the controller commands
NO_EFFECTS = PlantEffects().without("steer_lag", "accel_lag", "delays", "offsets", "scales", "noise")


def _params():
    from vehiclemodels.parameters_vehicle2 import parameters_vehicle2

    return parameters_vehicle2()


def _rear_axle(x, b):
    """Bicycle-model states at the rear axle from the multi-body state (CoG of the sprung mass)."""
    psi, vx, omega, vy = x[4], x[3], x[5], x[10]
    return np.array([x[0] - b * np.cos(psi), x[1] - b * np.sin(psi), psi, vx, vy - b * omega, omega])


def simulate_maneuver(ref: dict, effects: PlantEffects = PlantEffects(), gains: ControllerGains = ControllerGains(),
                      seed: int = 0, dt_sim: float = 0.002, rate: float = 100.0,
                      feedforward_only: bool = False) -> dict:  # fmt: skip
    """Closed-loop (or feed-forward-only) run of the multi-body plant along a reference.

    Parameters
    ----------
    ref : dict
        From :func:`reachconf.datasets.vehicle_campaign.maneuvers.reference_path` (sampled at ``rate``).
    effects : PlantEffects
    seed : int
        Seed of the sensor noise.
    dt_sim : float
        RK4 step of the plant (s); the controller runs every ``1 / rate`` s.
    feedforward_only : bool
        Open loop: steer ``L kappa_ref`` and hold the speed (no feedback).

    Returns
    -------
    dict of arrays sampled at ``ref["t"]``: measured ``X, Y, psi, vx, vy, omega``,
    ``delta, ax`` (realised), ``delta_req, ax_req``, the reference signals and
    ``true_*`` (noise-free rear-axle states).
    """
    from vehiclemodels.init_mb import init_mb
    from vehiclemodels.vehicle_dynamics_mb import vehicle_dynamics_mb

    p = _params()
    b = p.b
    rng = np.random.default_rng(seed)
    t = np.asarray(ref["t"], dtype=float)
    K = t.size
    sub = int(round(1.0 / (rate * dt_sim)))
    h = 1.0 / (rate * sub)
    v0 = float(ref["v_ref"][0])
    psi0 = float(ref["psi_ref"][0])
    x = np.array(init_mb([ref["X_ref"][0] + b * np.cos(psi0), ref["Y_ref"][0] + b * np.sin(psi0), 0.0, v0, psi0, 0.0, 0.0], p),
                 dtype=float)  # fmt: skip
    delta_act, ax_act = 0.0, 0.0
    # request queues for the transport delays (in controller periods)
    n_sd = int(round(effects.steer_delay * rate))
    n_ad = int(round(effects.accel_delay * rate))
    q_delta = [0.0] * n_sd  # a request waits n periods before it reaches the actuator
    q_ax = [0.0] * n_ad
    noise_sd = np.array([effects.noise_pos, effects.noise_pos, effects.noise_psi, effects.noise_vel, effects.noise_vel,
                         effects.noise_omega])  # fmt: skip
    offset = np.array([0, 0, effects.yaw_offset, 0, 0, 0.0])
    log = {k: np.empty(K) for k in ("X", "Y", "psi", "vx", "vy", "omega", "delta", "ax", "delta_req", "ax_req")}
    true = np.empty((K, 6))

    def rhs(x, d_act, a_act, d_cmd_eff, a_cmd_eff):
        # steering: the MB model takes the steering rate; realise the first-order lag through it
        if effects.k_delta is None:
            v_delta = (d_cmd_eff - x[2]) / h  # ideal: reach the command within one step
        else:
            v_delta = effects.k_delta * (d_cmd_eff - x[2])
        acc = a_cmd_eff if effects.k_ax is None else a_act
        dx = np.asarray(vehicle_dynamics_mb(x, [v_delta, acc], p), dtype=float)
        da = 0.0 if effects.k_ax is None else effects.k_ax * (a_cmd_eff - a_act)
        return dx, da

    for k in range(K):
        state = _rear_axle(x, b)
        meas = state + offset + noise_sd * np.clip(rng.standard_normal(6), -2.0, 2.0)
        true[k] = state
        if feedforward_only:
            a_cmd = 0.0
            d_cmd = gains.wheelbase * ref["kappa_ref"][k]
        else:
            a_cmd, d_cmd = tracking_law(*meas, ref["X_ref"][k], ref["Y_ref"][k], ref["psi_ref"][k], ref["v_ref"][k],
                                        ref["kappa_ref"][k], gains)  # fmt: skip
        delta_req = d_cmd / effects.delta_s_nominal
        ax_req = a_cmd
        q_delta.append(delta_req)
        q_ax.append(ax_req)
        d_eff = effects.delta_s * (q_delta.pop(0) + effects.delta_off)
        a_eff = effects.ax_s * (q_ax.pop(0) + effects.ax_off)
        log["X"][k], log["Y"][k], log["psi"][k], log["vx"][k], log["vy"][k], log["omega"][k] = meas
        log["delta"][k] = x[2] + effects.noise_actuator * rng.standard_normal()
        log["ax"][k] = (a_eff if effects.k_ax is None else ax_act) + effects.noise_actuator * rng.standard_normal()
        log["delta_req"][k] = delta_req
        log["ax_req"][k] = ax_req
        if k == K - 1:
            break
        for _ in range(sub):  # RK4 on the plant + acceleration actuator
            k1, a1 = rhs(x, delta_act, ax_act, d_eff, a_eff)
            k2, a2 = rhs(x + 0.5 * h * k1, delta_act, ax_act + 0.5 * h * a1, d_eff, a_eff)
            k3, a3 = rhs(x + 0.5 * h * k2, delta_act, ax_act + 0.5 * h * a2, d_eff, a_eff)
            k4, a4 = rhs(x + h * k3, delta_act, ax_act + h * a3, d_eff, a_eff)
            x = x + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
            ax_act = ax_act + h / 6 * (a1 + 2 * a2 + 2 * a3 + a4)
    out = dict(log)
    for key in ("X_ref", "Y_ref", "psi_ref", "v_ref", "kappa_ref"):
        out[key] = np.asarray(ref[key], dtype=float)
    for i, key in enumerate(("X", "Y", "psi", "vx", "vy", "omega")):
        out["true_" + key] = true[:, i]
    out["t"] = t
    return out
