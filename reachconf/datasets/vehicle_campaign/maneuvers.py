"""Reference paths of the vehicle campaign (source report section 4, Appendix A).

Lane change (LC), swerve (SW), double lane change (DLC) and slalom (SL) at
constant speed, scaled so that the peak lateral acceleration of the path
equals ``a_lat``.  All paths are built from smooth pieces with continuous
curvature (no kinks, so the feed-forward curvature has no spikes):

* a transition of lateral offset ``A`` over length ``L``:
  ``Y = A (u - sin(2 pi u) / (2 pi))``, ``u = x / L``, whose peak curvature is
  ``2 pi A / L^2``; so ``L = sqrt(2 pi A v^2 / a_lat)``;
* a slalom ``Y = A e(x) sin(2 pi x / P)`` with a smooth one-period envelope
  ``e`` in and out, ``P = 2 pi v sqrt(A / a_lat)``.
"""

from __future__ import annotations

import numpy as np

from reachconf.errors import OptionsError

__all__ = ["MANEUVERS", "reference_path", "excitation_path", "lane_change"]

#: maneuver code -> description
MANEUVERS = {"LC": "lane change", "SW": "swerve", "DLC": "double lane change", "SL": "slalom"}

LANE_WIDTH = 3.5
LEAD_IN = 10.0
LEAD_OUT = 15.0


def lane_change(x, x0, length, amp):
    """A smooth transition of lateral offset ``amp`` over ``[x0, x0 + length]`` and its derivatives.

    ``y = amp (u - sin(2 pi u) / (2 pi))`` with ``u = (x - x0) / length``
    clipped to [0, 1]: the curvature is continuous (no kink in the path); its
    peak is ``2 pi amp / length^2``.

    Parameters
    ----------
    x : array_like
        Positions along the path.
    x0, length, amp : float
        Start, length and lateral offset of the transition.

    Returns
    -------
    y, dy, ddy : ndarray
        Offset and its first and second derivatives with respect to ``x``.
    """
    u = np.clip((x - x0) / length, 0.0, 1.0)
    on = (u > 0.0) & (u < 1.0)
    y = amp * (u - np.sin(2 * np.pi * u) / (2 * np.pi))
    dy = np.where(on, amp * (1 - np.cos(2 * np.pi * u)) / length, 0.0)
    ddy = np.where(on, amp * 2 * np.pi * np.sin(2 * np.pi * u) / length**2, 0.0)
    return y, dy, ddy


def _profile(kind, x, a_lat, v):
    L = np.sqrt(2 * np.pi * LANE_WIDTH * v**2 / a_lat)
    if kind == "LC":
        y, dy, ddy = lane_change(x, LEAD_IN, L, LANE_WIDTH)
        return y, dy, ddy, LEAD_IN + L + LEAD_OUT
    if kind in ("SW", "DLC"):
        gap = 0.0 if kind == "SW" else 12.0
        y1, d1, dd1 = lane_change(x, LEAD_IN, L, LANE_WIDTH)
        y2, d2, dd2 = lane_change(x, LEAD_IN + L + gap, L, -LANE_WIDTH)
        return y1 + y2, d1 + d2, dd1 + dd2, LEAD_IN + 2 * L + gap + LEAD_OUT
    if kind == "SL":
        amp = 1.5
        k = np.sqrt(a_lat / (v**2 * amp))  # v^2 amp k^2 = a_lat at the crests
        P = 2 * np.pi / k
        length = 4 * P  # one period of ramp-in, two full periods, one of ramp-out
        s = x - LEAD_IN
        on = (s > 0) & (s < length)
        # smooth envelope e(s): S(s/P) rising over the first period, S((length-s)/P) falling over the last
        u_in = np.clip(s / P, 0, 1)
        u_out = np.clip((length - s) / P, 0, 1)
        rising = s < P
        falling = s > length - P
        u = np.where(rising, u_in, np.where(falling, u_out, 1.0))
        sgn = np.where(falling, -1.0, 1.0)  # d/ds of (length - s)/P
        e = np.where(rising | falling, u - np.sin(2 * np.pi * u) / (2 * np.pi), 1.0)
        e1 = np.where(rising | falling, sgn * (1 - np.cos(2 * np.pi * u)) / P, 0.0)
        e2 = np.where(rising | falling, 2 * np.pi * np.sin(2 * np.pi * u) / P**2, 0.0)
        sn, cs = np.sin(k * s), np.cos(k * s)
        y = np.where(on, amp * e * sn, 0.0)
        dy = np.where(on, amp * (e1 * sn + e * k * cs), 0.0)
        ddy = np.where(on, amp * (e2 * sn + 2 * e1 * k * cs - e * k**2 * sn), 0.0)
        return y, dy, ddy, LEAD_IN + length + LEAD_OUT
    raise OptionsError(f"unknown maneuver {kind!r}; known: {sorted(MANEUVERS)}")


def reference_path(kind: str, a_lat: float, v: float = 10.0, rate: float = 100.0) -> dict:
    """Reference signals of a maneuver sampled at ``rate``.

    Returns a dict with ``t`` and the closed-loop model's inputs ``X_ref,
    Y_ref, psi_ref, v_ref, kappa_ref`` (arrays), plus ``length`` (m).  The
    reference point moves along X at speed ``v`` (``v_ref`` is the path speed).
    """
    if not (a_lat > 0 and v > 0 and rate > 0):
        raise OptionsError("a_lat, v and rate must be positive")
    # the path's true curvature is y'' / (1 + y'^2)^1.5 (and the slalom envelope adds some): rescale the
    # design acceleration until the true peak lateral acceleration is a_lat
    target = a_lat
    for _ in range(3):
        _, _, _, total = _profile(kind, np.zeros(1), a_lat, v)
        xs = np.linspace(0.0, total, int(total / 0.005) + 1)
        _, dys, ddys, _ = _profile(kind, xs, a_lat, v)
        peak = np.max(np.abs(v**2 * ddys / (1 + dys**2) ** 1.5))
        a_lat = a_lat * target / peak
    _, _, _, total = _profile(kind, np.zeros(1), a_lat, v)
    # move along the path at constant speed v: x(t) from the arc length s(x)
    xs = np.linspace(0.0, total, int(total / 0.005) + 1)
    _, dys, _, _ = _profile(kind, xs, a_lat, v)
    seg = np.sqrt(1 + dys**2)
    arc = np.concatenate([[0.0], np.cumsum(0.5 * (seg[1:] + seg[:-1]) * np.diff(xs))])
    t = np.round(np.arange(0.0, arc[-1] / v + 1e-9, 1.0 / rate), 10)
    x = np.interp(v * t, arc, xs)
    y, dy, ddy, _ = _profile(kind, x, a_lat, v)
    slope = np.sqrt(1 + dy**2)
    return {"t": t, "X_ref": x, "Y_ref": y, "psi_ref": np.arctan(dy), "v_ref": np.full_like(t, v),
            "kappa_ref": ddy / slope**3, "length": float(arc[-1])}  # fmt: skip


def excitation_path(a_lat: float = 3.0, v: float = 10.0, dv: float = 2.0, duration: float = 14.0,
                    wavelengths=(40.0, 6.0), speed_period: float = 7.0, steer_rate: float = 0.3,
                    wheelbase: float = 2.7, rate: float = 100.0) -> dict:  # fmt: skip
    """A diagnosis maneuver: a lateral chirp at a varying speed (kind ``"EX"``).

    The path weaves with a wavelength falling from ``wavelengths[0]`` to
    ``wavelengths[1]`` (steering from about 0.25 Hz to 2 Hz) while the
    reference speed swings ``v +- dv`` with period ``speed_period``: the
    steering excites lags and delays over a band of frequencies, the speed
    swings the acceleration channel, so that lag, dead time, scale and offset
    leave different marks.  The weave's amplitude grows with the cube of the
    wavelength, which keeps the kinematic steering rate ``L v dkappa/ds`` of
    the path constant along it; the whole is scaled so that this rate stays
    below ``steer_rate`` (rad/s; the plant's steering-rate limit is 0.4) and the
    lateral acceleration below ``a_lat``.  Same keys as :func:`reference_path`.
    """
    if not (a_lat > 0 and v > dv >= 0 and duration > 0 and rate > 0 and steer_rate > 0):
        raise OptionsError("excitation_path: need a_lat > 0, v > dv >= 0, and positive duration, steer_rate, rate")
    t = np.round(np.arange(0.0, duration + 1e-9, 1.0 / rate), 10)
    w = 2 * np.pi / speed_period
    v_ref = v + dv * np.sin(w * t)
    s = v * t + dv / w * (1 - np.cos(w * t))  # arc length of the reference point
    total = float(s[-1]) + 1.0
    lam0, lam1 = wavelengths
    xs = np.linspace(0.0, total, int(total / 0.005) + 1)
    lam = lam0 + (lam1 - lam0) * xs / total
    phase = np.concatenate([[0.0], np.cumsum(0.5 * (2 * np.pi / lam[1:] + 2 * np.pi / lam[:-1]) * np.diff(xs))])
    env, _, _ = lane_change(xs, 0.0, 10.0, 1.0)
    fall, _, _ = lane_change(xs, total - 10.0, 10.0, 1.0)
    shape = (env - fall) * (lam / lam0) ** 3 * np.sin(phase)
    d1 = np.gradient(shape, xs)
    d2 = np.gradient(d1, xs)
    d3 = np.gradient(d2, xs)
    v_top = v + dv
    amp = min(a_lat / (np.max(np.abs(d2)) * v_top**2), steer_rate / (wheelbase * v_top * np.max(np.abs(d3))))
    y, dy, ddy = amp * shape, amp * d1, amp * d2
    seg = np.sqrt(1 + dy**2)
    arc = np.concatenate([[0.0], np.cumsum(0.5 * (seg[1:] + seg[:-1]) * np.diff(xs))])
    x = np.interp(s, arc, xs)
    yi, dyi, ddyi = (np.interp(x, xs, a) for a in (y, dy, ddy))
    slope = np.sqrt(1 + dyi**2)
    return {"t": t, "X_ref": x, "Y_ref": yi, "psi_ref": np.arctan(dyi), "v_ref": v_ref,
            "kappa_ref": ddyi / slope**3, "length": float(s[-1])}  # fmt: skip
