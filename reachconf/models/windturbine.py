"""Reduced model of the NREL 5-MW wind turbine, source report section 6 and Appendix F.

States ``Omega`` (rotor speed, rad/s), ``xT`` (tower-top fore-aft position, m),
``xT_dot`` (its velocity, m/s); inputs ``Mg`` (generator torque on the
high-speed shaft, N·m), ``theta`` (blade pitch, rad), ``v0`` (rotor-effective
wind speed, m/s); outputs ``Omega``, ``xT`` and ``MyT`` (tower-base fore-aft
bending moment, N·m, eq. 80); disturbances ``w1, w2, w3`` added to the three
ODEs (section 6.3).

Equations (69, 77, 78, 80)::

    Omega'  = (Ma - i Mg) / J
    xT'     = xT_dot
    xT_dot' = (Fa - c_Te xT_dot - k_Te xT) / m_Te
    Fa = 1/2 rho pi R^2 cT(lambda, theta) v_rel^2
    Ma = 1/2 rho pi R^3 cP(lambda, theta) / lambda v_rel^2,   lambda = Omega R / v_rel,
    v_rel = v0 - xT_dot,   MyT = h_H (c_Te xT_dot + k_Te xT)

Deviations from the report, on purpose
--------------------------------------
* Eq. 69a divides the generator torque by the gearbox ratio and Appendix F
  writes ``J = J_R + J_G / i^2``.  With ``Mg`` the high-speed-shaft torque
  (OpenFAST's GenTq, about 43 kN·m at rated) and ``J_G = 534.116 kg m^2`` the
  generator inertia about the *high-speed* shaft (NREL 5-MW definition), the
  low-speed-shaft equivalents are ``i Mg`` and ``i^2 J_G``; this gives
  ``J = 4.385e7 kg m^2``, the published drivetrain inertia of the NREL 5-MW
  turbine.  We use these.
* ``R`` in eq. 77 is the effective radius ``R_eff = R cos(gamma)``.
* Table 14 lacks the cT coefficients and its cP coefficients do not fit the
  NREL 5-MW performance table; the defaults below are least-squares fits to
  ``Cp_Ct_Cq.NREL5MW.txt`` (see :mod:`reachconf.datasets.aero`), to be
  refitted over the operating region of the data at hand.
"""

from __future__ import annotations

import math

from reachconf.model.core import Model

__all__ = ["wind_turbine", "nrel5mw_parameters", "CP_DEFAULT", "CT_DEFAULT"]

#: cP coefficients p21, p20, p12, p11, p10, p02, p01, p00 (eq. 78a, theta in rad),
#: least-squares fit over TSR 3..12 and pitch 0..15 deg of the NREL 5-MW table.
CP_DEFAULT = {"p21": 0.073, "p20": -0.014, "p12": 1.741, "p11": -1.771, "p10": 0.254,
              "p02": -11.727, "p01": 6.688, "p00": -0.570}  # fmt: skip
#: cT coefficients t21, t20, t11, t10, t01, t00 (eq. 78b), same fit.
CT_DEFAULT = {"t21": 0.0647, "t20": -0.0125, "t11": -1.4068, "t10": 0.2467, "t01": 3.6397, "t00": -0.3831}


def nrel5mw_parameters() -> dict:
    """Physical parameters of Table 15 and the derived ones of Appendix F (SI units)."""
    rho, R, gamma = 1.225, 63.0, math.radians(2.5)
    m_T, m_N, m_R = 347460.0, 240000.0, 110000.0
    J_H, J_B, m_B, d_cm, r_H = 115926.0, 11776047.0, 17740.0, 20.475, 1.5
    J_G, i, f0, d_s, h_H = 534.116, 97.0, 0.324, 0.01, 90.0
    J_Bp = J_B + m_B * math.cos(gamma) ** 2 * (2 * d_cm * r_H + r_H**2)
    J_R = J_H + 3 * J_Bp
    m_Te = 0.25 * m_T + m_N + m_R
    return {
        "rho": rho,
        "R": R * math.cos(gamma),
        "J": J_R + i**2 * J_G,
        "i": i,
        "m_Te": m_Te,
        "c_Te": 4 * math.pi * m_Te * d_s * f0,
        "k_Te": m_Te * (2 * math.pi * f0) ** 2,
        "h_H": h_H,
    }


def wind_turbine(**params) -> Model:
    """Open-loop reduced wind-turbine model (eqs. 69, 77, 78, 80; Table 15)."""
    p = nrel5mw_parameters()
    p.update(CP_DEFAULT)
    p.update(CT_DEFAULT)
    p.update(params)

    def f(s):
        v_rel = s.v0 - s.xT_dot
        lam = s.Omega * s.R / v_rel
        th = s.theta
        cP = (s.p21 * lam**2 * th + s.p20 * lam**2 + s.p12 * lam * th**2 + s.p11 * lam * th + s.p10 * lam
              + s.p02 * th**2 + s.p01 * th + s.p00)  # fmt: skip
        cT = s.t21 * lam**2 * th + s.t20 * lam**2 + s.t11 * lam * th + s.t10 * lam + s.t01 * th + s.t00
        area = math.pi * s.R**2
        Fa = 0.5 * s.rho * area * cT * v_rel**2
        # Ma = 1/2 rho pi R^3 cP / lambda v_rel^2 = 1/2 rho pi R^2 cP v_rel^3 / Omega
        Ma = 0.5 * s.rho * area * cP * v_rel**3 / s.Omega
        return [
            (Ma - s.i * s.Mg) / s.J + s.w1,
            s.xT_dot + s.w2,
            (Fa - s.c_Te * s.xT_dot - s.k_Te * s.xT) / s.m_Te + s.w3,
        ]

    return Model(
        name="wind_turbine",
        states=("Omega", "xT", "xT_dot"),
        inputs=("Mg", "theta", "v0"),
        disturbances=("w1", "w2", "w3"),
        params=p,
        dynamics=f,
        outputs=lambda s: {"Omega": s.Omega, "xT": s.xT, "MyT": s.h_H * (s.c_Te * s.xT_dot + s.k_Te * s.xT)},
        description="reduced NREL 5-MW wind turbine (section 6, Appendix F)",
    )
