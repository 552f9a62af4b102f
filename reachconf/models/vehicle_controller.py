"""Path-tracking controller of the vehicle models and campaign, written once for numpy and sympy.

A continuous-time law on the errors to a reference point that moves along the
path at the reference speed (the closed-loop model of section 4.3, eqs.
59/60)::

    e_y   = -(X - X_ref) sin(psi_ref) + (Y - Y_ref) cos(psi_ref)     lateral error
    e_psi = psi - psi_ref                                            heading error
    delta = L kappa_ref - k_y e_y - k_psi e_psi - k_omega (omega - v_ref kappa_ref)
    a_x   = -k_v (vx - v_ref)

``L kappa_ref`` is the kinematic feed-forward steering for the path
curvature.  The default gains are a compromise measured on the campaign
plant (:mod:`reachconf.datasets.vehicle_campaign.plant`, all actuator effects on, 60 ms steering
delay): stiffer gains (k_y = 0.3, k_psi = 2) lose the 4 m/s² swerve through the
actuator delay and lag, softer ones (k_y = 0.08, k_psi = 0.9) let the
linearised reach tube of the closed-loop model with the report's Table 6 box
blow up over 8 s.  With these, the 4 m/s² maneuvers are tracked within about
0.6 m, and the Table 6 reach stays bounded (tensor order 3, 0.01 s steps).  The error of ``e_psi`` is used without angle wrapping: the
campaign maneuvers never turn more than a fraction of a revolution.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["ControllerGains", "tracking_law"]


@dataclass(frozen=True)
class ControllerGains:
    """Gains of :func:`tracking_law` (SI units, radians).

    Parameters
    ----------
    k_y : float, default 0.15
        Steering per metre of lateral error (rad/m).
    k_psi : float, default 1.0
        Steering per radian of heading error.
    k_omega : float, default 0.1
        Steering per rad/s of yaw-rate error (damping).
    k_v : float, default 1.5
        Acceleration per m/s of speed error (1/s).
    wheelbase : float, default 2.7
        Wheelbase of the feed-forward steering (m).
    """

    k_y: float = 0.15
    k_psi: float = 1.0
    k_omega: float = 0.1
    k_v: float = 1.5
    wheelbase: float = 2.7


def tracking_law(X, Y, psi, vx, vy, omega, X_ref, Y_ref, psi_ref, v_ref, kappa_ref, gains: ControllerGains, m=np):
    """Requested ``(a_x, delta)`` for the state and the reference; ``m`` is ``numpy`` or ``sympy``."""
    g = gains
    e_y = -(X - X_ref) * m.sin(psi_ref) + (Y - Y_ref) * m.cos(psi_ref)
    e_psi = psi - psi_ref
    delta = g.wheelbase * kappa_ref - g.k_y * e_y - g.k_psi * e_psi - g.k_omega * (omega - v_ref * kappa_ref)
    ax = -g.k_v * (vx - v_ref)
    return ax, delta
