"""Path-tracking controller of the vehicle campaign, written once for numpy and sympy.

A continuous-time law on the errors to a reference point that moves along the
path at the reference speed (the closed-loop model of section 4.3, eqs.
59/60)::

    e_y   = -(X - X_ref) sin(psi_ref) + (Y - Y_ref) cos(psi_ref)     lateral error
    e_psi = psi - psi_ref                                            heading error
    delta = L kappa_ref - k_y e_y - k_psi e_psi - k_omega (omega - v_ref kappa_ref)
    a_x   = -k_v (vx - v_ref)

``L kappa_ref`` is the kinematic feed-forward steering for the path
curvature.  The default gains track the campaign maneuvers at 10 m/s within
0.1 m (2 m/s²) and 0.18 m (4 m/s²) of lateral error, and keep the closed-loop
reach tubes with the report's Table 6 disturbance box bounded over 8 s
(weaker gains, e.g. k_y = 0.08, k_psi = 0.9, let the linearised tube blow up).  The error of ``e_psi`` is used without angle wrapping: the
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
    k_y : float, default 0.3
        Steering per metre of lateral error (rad/m).
    k_psi : float, default 2.0
        Steering per radian of heading error.
    k_omega : float, default 0.2
        Steering per rad/s of yaw-rate error (damping).
    k_v : float, default 1.5
        Acceleration per m/s of speed error (1/s).
    wheelbase : float, default 2.7
        Wheelbase of the feed-forward steering (m).
    """

    k_y: float = 0.3
    k_psi: float = 2.0
    k_omega: float = 0.2
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
