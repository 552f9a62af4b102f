"""The rounding of time stamps: how far two times that should coincide may lie apart.

Sample times are often large numbers (Unix time stamps, 1.7e9 s), whose
float spacing is far above the 1e-12 s an absolute tolerance would assume;
a time computed as ``t0 + k dt`` or ``t + dt`` differs from a stored stamp
by a few of those ulps.  :func:`stamp_rounding` is that allowance, used
wherever times are matched or merged (tube layout, ``ReachTube.at``,
fixed-step grids, test-case segments).
"""

from __future__ import annotations

import numpy as np

__all__ = ["STAMP_ULPS", "MAX_STEPS", "stamp_rounding", "steps_per_interval"]

#: ulps of the largest time stamp allowed between times that should coincide
STAMP_ULPS = 8.0

#: fixed steps per sample interval at most: far beyond any memory (the memory check refuses them), and a count that
#: would overflow (a step of 1e-300 s) cannot wrap round to one step
MAX_STEPS = 2**40


def stamp_rounding(*times) -> float:
    """``STAMP_ULPS`` float spacings of the largest ``|t|`` among ``times`` (seconds)."""
    return STAMP_ULPS * float(np.finfo(float).eps) * max(abs(float(t)) for t in times)


def steps_per_interval(samples: np.ndarray, time_step: float) -> np.ndarray:
    """Fixed steps of at most ``time_step`` per interval of ``samples`` (int64, 1 to ``MAX_STEPS``); an interval
    longer than a whole number of steps by no more than the stamps' rounding takes that number."""
    with np.errstate(over="ignore", invalid="ignore"):
        slack = 1e-9 + stamp_rounding(samples[0], samples[-1]) / time_step  # (a count of ulps of the stamps)
        steps = np.ceil(np.diff(samples) / time_step - slack)
    return np.where(np.isnan(steps), MAX_STEPS, np.clip(steps, 1, MAX_STEPS)).astype(np.int64)
