"""Outward-rounded interval arithmetic on float64 bounds (numba, scalar calling convention).

Every function takes the bounds of each operand as separate scalars and
returns a tuple ``(lo, hi)`` that contains the exact real result of the
operation applied to any reals in the operands::

    lo, hi = mul(alo, ahi, blo, bhi)

Rounding: ``+ - * /`` and ``sqrt`` are correctly rounded by IEEE 754, so each
computed bound is widened outward by one or two ulps (:func:`down`, :func:`up`).  ``exp, log,
sin, cos, tan, atan, tanh`` come from the C library, which is not correctly rounded
(glibc: below 1 ulp for exp/log/sin/cos/atan, about 2 ulp for tanh, about 2 ulp for tan); their
bounds are widened by ``TRANSCENDENTAL_ULPS = 4`` ulps plus an absolute
``4 * eps`` for sin/cos/tan (whose argument reduction of large arguments
loses absolute, not relative, accuracy).  Results of sin/cos/tanh are clamped
to ``[-1, 1]``.

Elementwise versions on ``(lo, hi)`` arrays are in
:mod:`reachconf_kernels.interval_arrays`.

Errors (raised inside compiled code, translated by the Python layer):
``ZeroDivisionError`` for a division by an interval containing 0, ``ValueError``
for ``log``/``sqrt`` of an interval reaching below the domain and ``tan``
across a pole.  Generated model code checks these conditions itself and
returns a status code instead of raising.

Conventions: ``[0, 0] * [-inf, inf] = [0, 0]``; overflow gives ``inf``
bounds, never NaN; a NaN bound in any operand gives ``(nan, nan)`` (checked
before the guards above, so no error is raised for it), never a finite box.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

TRANSCENDENTAL_ULPS = 4
_EPS = 2.220446049250313e-16
_PI_LO = 3.141592653589793  # float(pi) < pi
_PI_HI = 3.1415926535897936  # next float above pi
_TWO_PI_LO = 6.283185307179586
_HALF_PI = 1.5707963267948966


_STEP = 2.220446049250313e-16  # 2^-52
_TINY = 5e-324  # smallest subnormal
_MAX = 1.7976931348623157e308


@njit(cache=True, inline="always")
def down(x):
    """A float one or two ulps towards -inf (inf-safe; NaN stays NaN).

    ``x - (|x| 2^-52 + 2^-1074)``: the subtracted amount is at least the
    spacing of the floats at ``x`` (``|x| 2^-52`` is exact, the smallest
    subnormal covers 0 and the subnormals), so the difference rounded to
    nearest lies strictly below ``x``.  Ten times cheaper than libm's
    ``nextafter``; at most one ulp wider.
    """
    if x == -np.inf or x != x:
        return x
    if x == np.inf:
        return _MAX
    return x - (math.fabs(x) * _STEP + _TINY)


@njit(cache=True, inline="always")
def up(x):
    """A float one or two ulps towards +inf (see :func:`down`)."""
    if x == np.inf or x != x:
        return x
    if x == -np.inf:
        return -_MAX
    return x + (math.fabs(x) * _STEP + _TINY)


@njit(cache=True, inline="always")
def _mn(a, b):
    return a if a < b else b


@njit(cache=True, inline="always")
def _mx(a, b):
    return a if a > b else b


@njit(cache=True, inline="always")
def _nan2(a, b):
    """Is either bound NaN (``x != x``)?  Such an operand is undefined: every kernel returns ``(nan, nan)``."""
    return a != a or b != b


@njit(cache=True, inline="always")
def _nan4(a, b, c, d):
    return a != a or b != b or c != c or d != d


@njit(cache=True)
def _down_n(x, k):
    for _ in range(k):
        x = down(x)
    return x


@njit(cache=True)
def _up_n(x, k):
    for _ in range(k):
        x = up(x)
    return x


@njit(cache=True, inline="always")
def const(x):
    """Degenerate interval of an exactly representable float."""
    return x, x


@njit(cache=True, inline="always")
def hull(alo, ahi, blo, bhi):
    """Interval hull of two intervals: ``(min(alo, blo), max(ahi, bhi))``."""
    if _nan4(alo, ahi, blo, bhi):
        return np.nan, np.nan
    return (alo if alo < blo else blo), (ahi if ahi > bhi else bhi)


@njit(cache=True, inline="always")
def contains_zero(lo, hi):
    """True if ``0`` lies in ``[lo, hi]``."""
    return lo <= 0.0 <= hi


@njit(cache=True, inline="always")
def add(alo, ahi, blo, bhi):
    """``[a] + [b]``, outward rounded."""
    if _nan4(alo, ahi, blo, bhi):
        return np.nan, np.nan
    return down(alo + blo), up(ahi + bhi)


@njit(cache=True, inline="always")
def sub(alo, ahi, blo, bhi):
    """``[a] - [b]``, outward rounded."""
    if _nan4(alo, ahi, blo, bhi):
        return np.nan, np.nan
    return down(alo - bhi), up(ahi - blo)


@njit(cache=True, inline="always")
def neg(alo, ahi):
    """``-[a]`` (exact)."""
    if _nan2(alo, ahi):
        return np.nan, np.nan
    return -ahi, -alo


@njit(cache=True, inline="always")
def _prod(a, b):
    # 0 * inf = 0 (the other factor is a real number inside an interval)
    if a == 0.0 or b == 0.0:
        return 0.0
    return a * b


@njit(cache=True, inline="always")
def _outward4(a, b, c, d):
    """Smallest and largest of four correctly rounded candidates, widened one ulp outward."""
    return down(_mn(_mn(a, b), _mn(c, d))), up(_mx(_mx(a, b), _mx(c, d)))


@njit(cache=True)
def mul(alo, ahi, blo, bhi):
    """``[a] * [b]``, outward rounded (``0 * inf = 0``)."""
    if _nan4(alo, ahi, blo, bhi):
        return np.nan, np.nan
    return _outward4(_prod(alo, blo), _prod(alo, bhi), _prod(ahi, blo), _prod(ahi, bhi))


@njit(cache=True, inline="always")
def _quot(a, b):
    # inf / inf = inf with the quotient's sign (an unbounded numerator may outgrow an unbounded denominator), not NaN
    if math.isinf(a) and math.isinf(b):
        return a if b > 0.0 else -a
    return a / b


@njit(cache=True)
def div(alo, ahi, blo, bhi):
    """``[a] / [b]``, outward rounded; ``ZeroDivisionError`` if ``[b]`` contains 0."""
    if _nan4(alo, ahi, blo, bhi):
        return np.nan, np.nan
    if blo <= 0.0 <= bhi:
        raise ZeroDivisionError("interval division by an interval containing 0")
    return _outward4(_quot(alo, blo), _quot(alo, bhi), _quot(ahi, blo), _quot(ahi, bhi))


@njit(cache=True)
def sqr(alo, ahi):
    """``[a]^2`` (tighter than ``[a] * [a]`` when ``[a]`` contains 0), outward rounded."""
    if _nan2(alo, ahi):
        return np.nan, np.nan
    if alo >= 0.0:
        return down(alo * alo), up(ahi * ahi)
    if ahi <= 0.0:
        return down(ahi * ahi), up(alo * alo)
    m = -alo if -alo > ahi else ahi
    return 0.0, up(m * m)


@njit(cache=True)
def pow(alo, ahi, k):
    """Integer power ``x**k`` (k < 0 needs 0 outside the interval)."""
    if _nan2(alo, ahi):
        return np.nan, np.nan
    if k >= 0:
        return _pow_nonneg(alo, ahi, k)
    if alo <= 0.0 <= ahi:
        raise ZeroDivisionError("interval negative power of an interval containing 0")
    plo, phi = _pow_nonneg(alo, ahi, -k)
    if plo <= 0.0 <= phi:  # |x|^-k underflowed to 0: x^k is beyond the float range
        if k % 2 == 0 or alo > 0.0:  # x^k > 0
            return (down(1.0 / phi) if phi > 0.0 else 0.0), np.inf
        return -np.inf, (up(1.0 / plo) if plo < 0.0 else 0.0)
    return div(1.0, 1.0, plo, phi)


@njit(cache=True)
def _pow_nonneg(alo, ahi, k):
    # not recursive on purpose: numba's cache cannot link recursive callees into generated code
    if k == 0:
        return 1.0, 1.0
    if k == 1:
        return alo, ahi
    if k % 2 == 0:
        # even: monotone in |x|
        if alo >= 0.0:
            mlo, mhi = alo, ahi
        elif ahi <= 0.0:
            mlo, mhi = -ahi, -alo
        else:
            mlo, mhi = 0.0, (-alo if -alo > ahi else ahi)
        lo = mlo
        hi = mhi
        for _ in range(k - 1):
            lo = down(lo * mlo)
            hi = up(hi * mhi)
        return (lo if lo > 0.0 else 0.0), hi
    # odd: monotone increasing; directed rounding chains on |x|, x^k = -(-x)^k for x < 0
    if alo < 0.0:
        m = -alo
        t = m
        for _ in range(k - 1):
            t = up(t * m)
        lo = -t
    else:
        t = alo
        for _ in range(k - 1):
            t = down(t * alo)
        lo = t if t > 0.0 else 0.0  # x >= 0 => x^k >= 0 (an underflow may round below 0)
    if ahi < 0.0:
        m = -ahi
        t = m
        for _ in range(k - 1):
            t = down(t * m)
        hi = -t if t > 0.0 else 0.0
    else:
        t = ahi
        for _ in range(k - 1):
            t = up(t * ahi)
        hi = t
    return lo, hi


@njit(cache=True)
def sqrt(alo, ahi):
    """``sqrt([a])``, outward rounded; ``ValueError`` below 0."""
    if _nan2(alo, ahi):
        return np.nan, np.nan
    if alo < 0.0:
        raise ValueError("interval sqrt of an interval reaching below 0")
    lo = down(math.sqrt(alo))
    return (lo if lo > 0.0 else 0.0), up(math.sqrt(ahi))


@njit(cache=True)
def exp(alo, ahi):
    """``exp([a])``, widened for the C library's rounding."""
    if _nan2(alo, ahi):
        return np.nan, np.nan
    lo = _down_n(math.exp(alo), TRANSCENDENTAL_ULPS)
    return (lo if lo > 0.0 else 0.0), _up_n(math.exp(ahi), TRANSCENDENTAL_ULPS)


@njit(cache=True)
def log(alo, ahi):
    """``log([a])``, widened for the C library's rounding; ``ValueError`` for ``lo <= 0``."""
    if _nan2(alo, ahi):
        return np.nan, np.nan
    if alo <= 0.0:
        raise ValueError("interval log of an interval reaching 0 or below")
    return _down_n(math.log(alo), TRANSCENDENTAL_ULPS), _up_n(math.log(ahi), TRANSCENDENTAL_ULPS)


@njit(cache=True)
def atan(alo, ahi):
    """``atan([a])``, widened for the C library's rounding."""
    if _nan2(alo, ahi):
        return np.nan, np.nan
    return _down_n(math.atan(alo), TRANSCENDENTAL_ULPS), _up_n(math.atan(ahi), TRANSCENDENTAL_ULPS)


@njit(cache=True)
def tanh(alo, ahi):
    """``tanh([a])``, widened for the C library's rounding and clamped to ``[-1, 1]``."""
    if _nan2(alo, ahi):
        return np.nan, np.nan
    lo = _down_n(math.tanh(alo), TRANSCENDENTAL_ULPS)
    hi = _up_n(math.tanh(ahi), TRANSCENDENTAL_ULPS)
    return (lo if lo > -1.0 else -1.0), (hi if hi < 1.0 else 1.0)


@njit(cache=True)
def _trig_margin(x):
    return 4.0 * _EPS * (1.0 + math.fabs(x) * _EPS)


@njit(cache=True)
def _contains_point(alo, ahi, offset):
    """Does [alo, ahi] (conservatively) contain offset + 2 k pi for some integer k?"""
    # k range with the lower/upper bounds of 2 pi
    kmin = math.floor((alo - offset) / _TWO_PI_LO) - 1
    kmax = math.ceil((ahi - offset) / _TWO_PI_LO) + 1
    k = kmin
    while k <= kmax:
        lo_pt = offset + k * _TWO_PI_LO
        hi_pt = offset + k * 6.283185307179587
        # the true point lies in [min, max] of these, widened
        plo = _mn(lo_pt, hi_pt) - 8 * _EPS * (1 + math.fabs(lo_pt))
        phi = _mx(lo_pt, hi_pt) + 8 * _EPS * (1 + math.fabs(lo_pt))
        if phi >= alo and plo <= ahi:
            return True
        k += 1
    return False


@njit(cache=True)
def cos(alo, ahi):
    """``cos([a])`` with its extrema inside the interval, widened and clamped to ``[-1, 1]``."""
    if _nan2(alo, ahi):
        return np.nan, np.nan
    if ahi - alo >= _TWO_PI_LO or not (math.isfinite(alo) and math.isfinite(ahi)):
        return -1.0, 1.0
    ca = math.cos(alo)
    cb = math.cos(ahi)
    lo = _mn(ca, cb)
    hi = _mx(ca, cb)
    lo = _down_n(lo, TRANSCENDENTAL_ULPS) - _mx(_trig_margin(alo), _trig_margin(ahi))
    hi = _up_n(hi, TRANSCENDENTAL_ULPS) + _mx(_trig_margin(alo), _trig_margin(ahi))
    if _contains_point(alo, ahi, 0.0):
        hi = 1.0
    if _contains_point(alo, ahi, _PI_LO):
        lo = -1.0
    return (lo if lo > -1.0 else -1.0), (hi if hi < 1.0 else 1.0)


@njit(cache=True)
def sin(alo, ahi):
    """``sin([a])`` with its extrema inside the interval, widened and clamped to ``[-1, 1]``."""
    if _nan2(alo, ahi):
        return np.nan, np.nan
    if ahi - alo >= _TWO_PI_LO or not (math.isfinite(alo) and math.isfinite(ahi)):
        return -1.0, 1.0
    sa = math.sin(alo)
    sb = math.sin(ahi)
    lo = _mn(sa, sb)
    hi = _mx(sa, sb)
    lo = _down_n(lo, TRANSCENDENTAL_ULPS) - _mx(_trig_margin(alo), _trig_margin(ahi))
    hi = _up_n(hi, TRANSCENDENTAL_ULPS) + _mx(_trig_margin(alo), _trig_margin(ahi))
    if _contains_point(alo, ahi, _HALF_PI):
        hi = 1.0
    if _contains_point(alo, ahi, -_HALF_PI):
        lo = -1.0
    return (lo if lo > -1.0 else -1.0), (hi if hi < 1.0 else 1.0)


@njit(cache=True)
def tan(alo, ahi):
    """``tan([a])``, widened; ``ValueError`` across a pole."""
    if _nan2(alo, ahi):
        return np.nan, np.nan
    if ahi - alo >= _PI_LO or _contains_point(alo, ahi, _HALF_PI) or _contains_point(alo, ahi, -_HALF_PI):
        raise ValueError("interval tan across a pole")
    margin = _mx(_trig_margin(alo), _trig_margin(ahi))
    ta = math.tan(alo)
    tb = math.tan(ahi)
    return (_down_n(ta, TRANSCENDENTAL_ULPS) - margin * (1 + ta * ta),
            _up_n(tb, TRANSCENDENTAL_ULPS) + margin * (1 + tb * tb))  # fmt: skip


@njit(cache=True)
def abs(alo, ahi):
    """``|[a]|`` (exact)."""
    if _nan2(alo, ahi):
        return np.nan, np.nan
    if alo >= 0.0:
        return alo, ahi
    if ahi <= 0.0:
        return -ahi, -alo
    return 0.0, (-alo if -alo > ahi else ahi)


@njit(cache=True)
def min(alo, ahi, blo, bhi):
    """Elementwise minimum ``min([a], [b])`` (exact)."""
    if _nan4(alo, ahi, blo, bhi):
        return np.nan, np.nan
    return (alo if alo < blo else blo), (ahi if ahi < bhi else bhi)


@njit(cache=True)
def max(alo, ahi, blo, bhi):
    """Elementwise maximum ``max([a], [b])`` (exact)."""
    if _nan4(alo, ahi, blo, bhi):
        return np.nan, np.nan
    return (alo if alo > blo else blo), (ahi if ahi > bhi else bhi)


@njit(cache=True)
def matvec(Alo, Ahi, xlo, xhi):
    """Interval matrix times interval vector, outward rounded."""
    n, m = Alo.shape
    ylo = np.zeros(n)
    yhi = np.zeros(n)
    for i in range(n):
        slo = 0.0
        shi = 0.0
        for j in range(m):
            plo, phi = mul(Alo[i, j], Ahi[i, j], xlo[j], xhi[j])
            slo = down(slo + plo)
            shi = up(shi + phi)
        ylo[i] = slo
        yhi[i] = shi
    return ylo, yhi


@njit(cache=True)
def matmul(Alo, Ahi, Blo, Bhi):
    """Interval matrix product, outward rounded."""
    n, k = Alo.shape
    m = Blo.shape[1]
    Clo = np.zeros((n, m))
    Chi = np.zeros((n, m))
    for i in range(n):
        for j in range(m):
            slo = 0.0
            shi = 0.0
            for r in range(k):
                plo, phi = mul(Alo[i, r], Ahi[i, r], Blo[r, j], Bhi[r, j])
                slo = down(slo + plo)
                shi = up(shi + phi)
            Clo[i, j] = slo
            Chi[i, j] = shi
    return Clo, Chi


@njit(cache=True)
def matvec_point(A, xlo, xhi):
    """Point matrix times interval vector."""
    return matvec(A, A, xlo, xhi)


@njit(cache=True)
def matmul_point(A, Blo, Bhi):
    """Point matrix times interval matrix."""
    return matmul(A, A, Blo, Bhi)
