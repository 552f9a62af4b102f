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

__all__ = ["STAMP_ULPS", "stamp_rounding"]

#: ulps of the largest time stamp allowed between times that should coincide
STAMP_ULPS = 8.0


def stamp_rounding(*times) -> float:
    """``STAMP_ULPS`` float spacings of the largest ``|t|`` among ``times`` (seconds)."""
    return STAMP_ULPS * float(np.finfo(float).eps) * max(abs(float(t)) for t in times)
