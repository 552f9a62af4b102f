"""Known effects injected into the recorded real-car signals (withheld-effect checks of the diagnosis).

The recording is the truth of what the car did.  Each injection changes what
the *model* is given so that the true system has an effect the model lacks:

=================  ===================================================================  ==========================
name               injected into the recorded signals                                     the diagnosis should name
=================  ===================================================================  ==========================
``dead_time``      ``delta_rec(t) = delta(t + T)``: the real angle is the record delayed   ``dead_time(delta)`` T
``lag``            ``delta_rec`` = the request of a first-order lag whose output is the   ``actuator_lag(delta)`` tau
                   recorded angle (exact inverse of the library's lag filter)
``steer_offset``   ``delta_rec = delta - c``: the real angle is ``delta_rec + c``          ``input_offset(delta)`` c
``yaw_bias``       ``omega_rec = omega + b`` (sensor bias)                                 ``output_offset(omega)`` b
``ax_scale``       ``ax_rec = ax / k``: the real acceleration is ``k ax_rec``              ``input_scale(ax)`` k
=================  ===================================================================  ==========================

:func:`inject` works on the columns of :func:`data.read_run` before the run
is cut into cases, so the injected effect is continuous across cases.
"""

from __future__ import annotations

import numpy as np

#: name -> (effect, target, parameter) the diagnosis should report
INJECTIONS = {"dead_time": ("dead_time", "delta", "T"), "lag": ("actuator_lag", "delta", "tau"),
              "steer_offset": ("input_offset", "delta", "c"), "yaw_bias": ("output_offset", "omega", "c"),
              "ax_scale": ("input_scale", "ax", "k")}  # fmt: skip


def lag_request(t, y, tau):
    """The zero-order-hold request ``u`` whose first-order lag (interval means, as
    :func:`reachconf_kernels.signals.first_order_lag` computes them) is ``y``."""
    t = np.asarray(t, float)
    y = np.asarray(y, float)
    u = np.empty_like(y)
    state = y[0]
    u[0] = y[0]
    for k in range(y.size - 1):
        r = (t[k + 1] - t[k]) / tau
        g = -np.expm1(-r) / r  # interval mean weight of the state
        u[k] = (y[k] - g * state) / (1.0 - g) if k > 0 else y[0]
        state = u[k] + (state - u[k]) * np.exp(-r)
    u[-1] = u[-2]
    return u


def inject(cols, name, value):
    """The recorded columns with the effect ``name`` of size ``value`` injected; and the truth.

    Returns ``(cols, truth)`` with ``truth = {"effect", "target", "params"}``.
    """
    if name not in INJECTIONS:
        raise ValueError(f"unknown injection {name!r}; known: {sorted(INJECTIONS)}")
    out = {k: np.array(v, float) for k, v in cols.items()}
    t = out["t"]
    if name == "dead_time":
        out["delta"] = np.interp(t + value, t, cols["delta"])
    elif name == "lag":
        out["delta"] = lag_request(t, cols["delta"], value)
    elif name == "steer_offset":
        out["delta"] = cols["delta"] - value
    elif name == "yaw_bias":
        out["omega"] = cols["omega"] + value
    elif name == "ax_scale":
        out["ax"] = cols["ax"] / value
    effect, target, param = INJECTIONS[name]
    return out, {"effect": effect, "target": target, "params": {param: float(value)}}
