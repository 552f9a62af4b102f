"""Segments of a test case: consecutive or sliding stretches, each a test case of its own (section 4.3.3).

:meth:`reachconf.io.TestCase.segments` documents the behaviour; this module holds the cutting.
"""

from __future__ import annotations

import math

import numpy as np

from reachconf.errors import DataError
from reachconf.timestamps import stamp_rounding

__all__ = ["case_segments"]


def case_segments(case, length, partial: bool = True, step=None) -> list:
    """:meth:`reachconf.io.TestCase.segments` of ``case``."""
    length = _seconds(case, length, "segment length")
    step = length if step is None else _seconds(case, step, "segment step")
    if step > length:
        raise DataError(f"test case {case.name!r}: segment step {step:g} s is longer than the segments "
                        f"({length:g} s): samples between them would be in none")  # fmt: skip
    t = case.t
    # a sample on a boundary belongs to both segments despite rounding (of t0 + k step and of large stamps)
    tol = 1e-9 * max(1.0, length) + stamp_rounding(t[0], t[-1])
    if t[-1] - t[0] <= length + tol:  # one segment: the case itself (dropped if shorter and not partial)
        return [case] if partial or t[-1] - t[0] >= length - tol else []
    dt = float(np.min(np.diff(t)))
    if length < dt - tol:
        raise DataError(f"test case {case.name!r}: segment length {length:g} s is shorter than the sampling "
                        f"interval ({dt:g} s): a segment needs at least two samples")  # fmt: skip
    out = []
    for a in t[0] + step * np.arange(int(np.floor((t[-1] - t[0] + tol) / step)) + 1):
        keep = np.flatnonzero((t >= a - tol) & (t <= a + length + tol))
        full = a + length <= t[-1] + tol
        if keep.size < 2 and full:  # a gap in the sampling longer than a segment
            continue
        if keep.size < 2 or (not full and not partial):
            break
        if not out or keep[-1] > out[-1][1]:  # (a tail inside the last segment adds nothing)
            out.append((keep[0], keep[-1]))
        if not full:
            break
    return [_piece(case, i, j) for i, j in out]


def _seconds(case, value, what: str) -> float:
    """``value`` as a positive finite number of seconds (DataError naming the case and ``what``)."""
    try:
        value = float(value)
    except (TypeError, ValueError):
        raise DataError(f"test case {case.name!r}: {what} must be a number of seconds, got {value!r}") from None
    if not (math.isfinite(value) and value > 0):
        raise DataError(f"test case {case.name!r}: {what} must be a positive number of seconds, got {value!r}")
    return value


def _piece(case, i: int, j: int):
    """Samples ``i..j`` of ``case`` as a case named by their first and last sample times."""
    t, sl = case.t, slice(i, j + 1)
    return type(case)(f"{case.name}[{_time_label(t[i])},{_time_label(t[j])}]", case.group, t[sl], case.U[sl],
                      case.Y[sl], case.input_names, case.output_names, {k: v[sl] for k, v in case.extras.items()})


def _time_label(t: float) -> str:
    """A sample time in a segment's name: to the microsecond, without trailing zeros (``2``, ``149.99``)."""
    return np.format_float_positional(float(t), precision=6, unique=False, fractional=True, trim="-")
