"""Dynamic single-track model at the centre of gravity with linear tyres (a real car on measured velocities).

The model of :func:`single_track` is written for data that measure the
velocities at the centre of gravity (CG) in the body frame, the yaw rate, the
longitudinal acceleration (IMU) and the road-wheel steering angle — e.g. the
Stanford track data in ``../shared/data/realcar``.  Unlike
:func:`reachconf.models.bicycle` (rear-axle velocities, normalised stiffnesses,
position and heading states), it has no position states: a model is compared
on ``vx, vy, omega`` only.

Sign conventions (ISO 8855, z up)
---------------------------------
``x`` forward, ``y`` to the left; ``vy > 0`` is a velocity to the left,
``omega > 0`` a yaw to the left (counter-clockwise seen from above), ``delta >
0`` steers to the left, a lateral tyre force ``F_y > 0`` pushes to the left.
A positive slip angle ``alpha`` gives a positive force (``F_y = c alpha`` with
``c > 0``); ``ax`` is the longitudinal acceleration an IMU at the CG measures
(``ax = vx' - vy omega``).

Equations
---------
::

    alpha_f = delta - atan((vy + l_f omega) / vx)
    alpha_r =       - atan((vy - l_r omega) / vx)
    F_yf = c_f alpha_f,   F_yr = c_r alpha_r                  (linear tyres, per axle)
    vx'    = ax + vy omega                                    + w_vx
    vy'    = (F_yf cos(delta) + F_yr) / m - vx omega          + w_vy
    omega' = (l_f F_yf cos(delta) - l_r F_yr) / J_z           + w_omega
    y = (vx, vy, omega) + v

The longitudinal equation is kinematic (the measured ``ax`` is the real
acceleration); the tyre forces enter through the lateral and yaw equations.
The disturbances ``w_vx, w_vy`` are in m/s², ``w_omega`` in rad/s².  The model
is valid for ``vx > 0`` (the slip angles divide by it).

Saturating tyres are not in the model on purpose: they are a candidate effect
of the gap diagnosis (``tire_fiala`` in :mod:`reachconf.diagnose.tyres`), which
replaces ``c alpha`` by the Fiala brush model with a friction coefficient.
:func:`slip_angles` gives the slip-angle expressions that effect looks for.
"""

from __future__ import annotations

import sympy as sp

from reachconf.model.core import Model

__all__ = ["single_track", "slip_angles", "SINGLE_TRACK_PARAMS", "SINGLE_TRACK_AXLES", "GRAVITY"]

#: Nominal parameters given with the Stanford track data (../shared/data/realcar/README.md): mass [kg], CG to
#: front / rear axle [m], yaw inertia [kg m^2] (the estimators' "literature" value m (1.7^2 + 4.09^2) / 12),
#: cornering stiffness per axle [N/rad].  A prior, not a calibration.
SINGLE_TRACK_PARAMS = {"m": 982.0, "l_f": 1.33, "l_r": 1.07, "J_z": 1605.0, "c_f": 0.7e5, "c_r": 1.2e5}

#: Axle of each cornering-stiffness parameter and the parameter of the lever arm to the *other* axle, which
#: sets the static axle load ``m g l_other / (l_f + l_r)``.
SINGLE_TRACK_AXLES = {"c_f": ("front", "l_r"), "c_r": ("rear", "l_f")}

#: Gravitational acceleration [m/s^2] used for the static axle loads.
GRAVITY = 9.81


def slip_angles(s):
    """Front and rear slip angles ``(alpha_f, alpha_r)`` of the single-track model as sympy expressions.

    Parameters
    ----------
    s : reachconf.model.Symbols
        The model's symbol namespace (``s.vx, s.vy, s.omega, s.delta, s.l_f, s.l_r``).

    Returns
    -------
    tuple of sympy.Expr
    """
    alpha_f = s.delta - sp.atan((s.vy + s.l_f * s.omega) / s.vx)
    alpha_r = -sp.atan((s.vy - s.l_r * s.omega) / s.vx)
    return alpha_f, alpha_r


def single_track(**params) -> Model:
    """Dynamic single-track model at the centre of gravity with linear tyres (see the module docstring).

    States and outputs ``vx, vy, omega`` (longitudinal and lateral velocity at
    the CG in the body frame [m/s], yaw rate [rad/s]); inputs ``ax, delta``
    (measured longitudinal acceleration [m/s²], road-wheel steering angle
    [rad]); disturbances ``w_vx, w_vy, w_omega``, one on each ODE; parameters
    ``m, l_f, l_r, J_z, c_f, c_r`` (:data:`SINGLE_TRACK_PARAMS`: the values
    given with the Stanford track data).

    Parameters
    ----------
    **params
        Parameter values replacing the defaults.

    Returns
    -------
    Model

    Examples
    --------
    >>> from reachconf.models import single_track
    >>> car = single_track(J_z=1900.0)
    >>> car.state_names, car.input_names, car.param_names
    (('vx', 'vy', 'omega'), ('ax', 'delta'), ('m', 'l_f', 'l_r', 'J_z', 'c_f', 'c_r'))
    """
    p = dict(SINGLE_TRACK_PARAMS)
    p.update(params)

    def f(s):
        alpha_f, alpha_r = slip_angles(s)
        # the products c * alpha stay factors of the terms below: the tyre effects of the diagnosis find them there
        f_yf = s.c_f * alpha_f
        f_yr = s.c_r * alpha_r
        return [
            s.ax + s.vy * s.omega + s.w_vx,
            (f_yf * sp.cos(s.delta) + f_yr) / s.m - s.vx * s.omega + s.w_vy,
            (s.l_f * f_yf * sp.cos(s.delta) - s.l_r * f_yr) / s.J_z + s.w_omega,
        ]

    return Model(
        name="single_track",
        states=("vx", "vy", "omega"),
        inputs=("ax", "delta"),
        disturbances=("w_vx", "w_vy", "w_omega"),
        params=p,
        dynamics=f,
        description="dynamic single-track model at the CG with linear tyres (reachconf.models.single_track)",
    )
