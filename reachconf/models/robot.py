"""Differential-drive robot of section 7.3."""

from __future__ import annotations

import sympy as sp

from reachconf.model.core import Model

__all__ = ["diff_drive"]


def diff_drive() -> Model:
    """Kinematic differential-drive robot: ``px' = v cos(phi)``, ``py' = v sin(phi)``, ``phi' = omega``.

    Inputs ``v_tra`` (m/s) and ``v_rot`` (rad/s) are known from the robot's
    controller; localisation uncertainty enters through the initial set.
    """
    return Model(
        name="diff_drive",
        states=("px", "py", "phi"),
        inputs=("v_tra", "v_rot"),
        dynamics=lambda s: [s.v_tra * sp.cos(s.phi), s.v_tra * sp.sin(s.phi), s.v_rot],
        description="differential-drive robot (section 7.3)",
    )
