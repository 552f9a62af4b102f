"""Pedestrian models of section 7.2 (eqs. 73 and 74).

Their disk input sets and the box ⊕ disk reachable positions are set types of
:mod:`reachconf.sets.disk` (:func:`disk_zonotope`, :class:`BoxDisk`), also
importable from here.
"""

from __future__ import annotations

from reachconf.model.core import Model
from reachconf.sets.disk import BoxDisk, disk_zonotope

__all__ = ["pedestrian_acc", "pedestrian_vel", "disk_zonotope", "BoxDisk"]


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
