"""Path-tracking controller of the vehicle campaign, written once for numpy and sympy.

A continuous-time law on the errors to a reference point that moves along the
path at the reference speed (the closed-loop model of section 4.3, eqs.
59/60)::

    e_y   = -(X - X_ref) sin(psi_ref) + (Y - Y_ref) cos(psi_ref)     lateral error
    e_psi = psi - psi_ref                                            heading error
    delta = L kappa_ref - k_y e_y - k_psi e_psi - k_omega (omega - v_ref kappa_ref)
    a_x   = -k_v (vx - v_ref)

``L kappa_ref`` is the kinematic feed-forward steering for the path
curvature.  The error of ``e_psi`` is used without angle wrapping: the
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
    k_y : float, default 0.08
        Steering per metre of lateral error (rad/m).
    k_psi : float, default 0.9
        Steering per radian of heading error.
    k_omega : float, default 0.05
        Steering per rad/s of yaw-rate error (damping).
    k_v : float, default 0.8
        Acceleration per m/s of speed error (1/s).
    wheelbase : float, default 2.7
        Wheelbase of the feed-forward steering (m).
    """

    k_y: float = 0.08
    k_psi: float = 0.9
    k_omega: float = 0.05
    k_v: float = 0.8
    wheelbase: float = 2.7


def tracking_law(X, Y, psi, vx, vy, omega, X_ref, Y_ref, psi_ref, v_ref, kappa_ref, gains: ControllerGains, m=np):
    """Requested ``(a_x, delta)`` for the state and the reference; ``m`` is ``numpy`` or ``sympy``."""
    g = gains
    e_y = -(X - X_ref) * m.sin(psi_ref) + (Y - Y_ref) * m.cos(psi_ref)
    e_psi = psi - psi_ref
    delta = g.wheelbase * kappa_ref - g.k_y * e_y - g.k_psi * e_psi - g.k_omega * (omega - v_ref * kappa_ref)
    ax = -g.k_v * (vx - v_ref)
    return ax, delta
