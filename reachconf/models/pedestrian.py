"""Pedestrian models of section 7.2 (eqs. 73 and 74) and the disk input sets."""

from __future__ import annotations

import math

import numpy as np

from reachconf.errors import SetError
from reachconf.model import Model
from reachconf.sets import Zonotope

__all__ = ["pedestrian_acc", "pedestrian_vel", "disk_zonotope"]


def pedestrian_acc() -> Model:
    """Acceleration-constrained pedestrian, eq. 73.

    States ``px, py, vx, vy``; the acceleration ``(ax, ay)`` is a disturbance in
    the disk of radius ``a_max`` (enclose it with :func:`disk_zonotope`).
    """
    return Model(
        name="pedestrian_acc",
        states=("px", "py", "vx", "vy"),
        disturbances=("ax", "ay"),
        dynamics=lambda s: [s.vx, s.vy, s.ax, s.ay],
        outputs=("px", "py"),
        description="acceleration-constrained pedestrian (eq. 73)",
    )


def pedestrian_vel() -> Model:
    """Velocity-constrained pedestrian, eq. 74: ``p' = v`` with ``|v| <= v_max`` a disturbance."""
    return Model(
        name="pedestrian_vel",
        states=("px", "py"),
        disturbances=("vx", "vy"),
        dynamics=lambda s: [s.vx, s.vy],
        outputs=("px", "py"),
        description="velocity-constrained pedestrian (eq. 74)",
    )


def disk_zonotope(radius: float, n_generators: int = 8, center=(0.0, 0.0)) -> Zonotope:
    """A zonotope enclosing the disk of the given radius: a circumscribed regular ``2k``-gon.

    ``k`` generators of length ``r tan(pi / 2k)`` at angles ``i pi / k``; the
    polygon's apothem is ``r``, so it contains the disk and exceeds it by a
    factor ``1 / cos(pi / 2k)`` at its corners.
    """
    if not (math.isfinite(radius) and radius >= 0):
        raise SetError(f"radius must be a finite non-negative number, got {radius!r}")
    k = int(n_generators)
    if k < 2:
        raise SetError(f"n_generators must be at least 2, got {n_generators!r}")
    length = radius * math.tan(math.pi / (2 * k)) * (1 + 1e-12)
    angles = np.arange(k) * math.pi / k
    G = length * np.vstack([np.cos(angles), np.sin(angles)])
    return Zonotope(np.asarray(center, dtype=float), G)
