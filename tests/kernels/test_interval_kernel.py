"""Soundness of the outward-rounded interval kernel against mpmath at 200 bits.

For every operation, points of the operand intervals (end points, interior
points, and the critical points of sin/cos) are pushed through the exact
operation with mpmath; the exact result must lie in the computed interval.
"""

import math

import mpmath
import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from reachconf_kernels import interval as iv

mp = mpmath.mp
mp.prec = 200

ADVERSARIAL = [0.0, -0.0, 5e-324, -5e-324, 2.2250738585072014e-308, 1e-300, -1e-300, 1e-16, 0.1, -0.1,
               1.0, -1.0, 1.0000000000000002, 0.9999999999999999, math.pi, -math.pi, math.pi / 2, 1e8, -1e8,
               1e150, -1e150, 1e300, -1e300, 3.0, 7.0 / 3.0]  # fmt: skip

finite = st.floats(allow_nan=False, allow_infinity=False, min_value=-1e300, max_value=1e300)
moderate = st.floats(allow_nan=False, allow_infinity=False, min_value=-1e6, max_value=1e6)
anyfloat = st.one_of(finite, st.sampled_from(ADVERSARIAL))


def interval_from(a, b):
    return (a, b) if a <= b else (b, a)


def points(lo, hi, k=5):
    pts = {lo, hi}
    if math.isfinite(lo) and math.isfinite(hi):
        for t in np.linspace(0, 1, k):
            pts.add(lo + (hi - lo) * float(t) if hi - lo < 1e308 else lo / 2 + hi / 2)
    return [p for p in pts if lo <= p <= hi]


def inside(lo, hi, exact):
    return mpmath.mpf(lo) <= exact <= mpmath.mpf(hi)


def check_binary(op, exact_op, a, b):
    lo, hi = op(a[0], a[1], b[0], b[1])
    assert lo <= hi
    for x in points(*a):
        for y in points(*b):
            ex = exact_op(mpmath.mpf(x), mpmath.mpf(y))
            assert inside(lo, hi, ex), (op.__name__, a, b, x, y, lo, hi, ex)


@settings(max_examples=300, deadline=None)
@given(anyfloat, anyfloat, anyfloat, anyfloat)
def test_add_sub_mul_contain_exact(a1, a2, b1, b2):
    a, b = interval_from(a1, a2), interval_from(b1, b2)
    check_binary(iv.add, lambda x, y: x + y, a, b)
    check_binary(iv.sub, lambda x, y: x - y, a, b)
    check_binary(iv.mul, lambda x, y: x * y, a, b)


@settings(max_examples=300, deadline=None)
@given(anyfloat, anyfloat, anyfloat, anyfloat)
def test_div_contains_exact(a1, a2, b1, b2):
    a, b = interval_from(a1, a2), interval_from(b1, b2)
    if b[0] <= 0.0 <= b[1]:
        with pytest.raises(ZeroDivisionError):
            iv.div(a[0], a[1], b[0], b[1])
        return
    check_binary(iv.div, lambda x, y: x / y, a, b)


def test_div_of_unbounded_intervals_is_unbounded_not_nan():
    """``inf / inf`` candidates were NaN: ``[-inf, 1] / [1, inf]`` gave ``[-5e-324, 1]`` (unsound: -1e300 / 1 lies in
    it) and ``[1, inf] / [1, inf]`` gave NaN bounds; the quotient of two unbounded ends is unbounded."""
    inf = math.inf
    assert iv.div(-inf, 1.0, 1.0, inf) == (-inf, iv.up(1.0))
    lo, hi = iv.div(1.0, inf, 1.0, inf)
    assert lo <= 0.0 and hi == inf
    lo, hi = iv.div(-inf, inf, -inf, -2.0)
    assert (lo, hi) == (-inf, inf)
    lo, hi = iv.div(1.0, inf, -inf, -1.0)
    assert lo == -inf and 0.0 <= hi


def test_signed_zero_and_rounding_direction():
    lo, hi = iv.add(0.1, 0.1, 0.2, 0.2)
    assert mpmath.mpf(lo) < mpmath.mpf(0.1) + mpmath.mpf(0.2) < mpmath.mpf(hi)
    lo, hi = iv.mul(0.0, 0.0, -np.inf, np.inf)  # 0 * unbounded = 0 (widened by one ulp)
    assert lo <= 0.0 <= hi and hi - lo < 1e-300
    lo, hi = iv.mul(-0.0, 0.0, 1.0, 2.0)
    assert lo <= 0.0 <= hi
    lo, hi = iv.sub(5e-324, 5e-324, 5e-324, 5e-324)
    assert lo < 0.0 < hi


@settings(max_examples=300, deadline=None)
@given(anyfloat, anyfloat, st.integers(min_value=-6, max_value=9))
def test_sqr_pow_contain_exact(a1, a2, k):
    lo_a, hi_a = interval_from(a1, a2)
    lo, hi = iv.sqr(lo_a, hi_a)
    for x in points(lo_a, hi_a):
        assert inside(lo, hi, mpmath.mpf(x) ** 2)
    if k < 0 and lo_a <= 0.0 <= hi_a:
        with pytest.raises(ZeroDivisionError):
            iv.pow(lo_a, hi_a, k)
        return
    lo, hi = iv.pow(lo_a, hi_a, k)
    for x in points(lo_a, hi_a):
        assert inside(lo, hi, mpmath.mpf(x) ** k), (lo_a, hi_a, k, x, lo, hi)


@settings(max_examples=300, deadline=None)
@given(anyfloat, anyfloat)
def test_sqrt_exp_log_atan_tanh_abs_contain_exact(a1, a2):
    lo_a, hi_a = interval_from(a1, a2)
    pts = points(lo_a, hi_a)
    lo, hi = iv.atan(lo_a, hi_a)
    assert all(inside(lo, hi, mpmath.atan(mpmath.mpf(x))) for x in pts)
    lo, hi = iv.tanh(lo_a, hi_a)
    assert -1.0 <= lo <= hi <= 1.0
    assert all(inside(lo, hi, mpmath.tanh(mpmath.mpf(x))) for x in pts)
    # tight: no wider than the exact range plus a few ulps of rounding
    assert hi - lo <= float(mpmath.tanh(hi_a) - mpmath.tanh(lo_a)) + 1e-15 * (1 + abs(hi) + abs(lo))
    lo, hi = iv.abs(lo_a, hi_a)
    assert all(inside(lo, hi, abs(mpmath.mpf(x))) for x in pts)
    if hi_a < 700:
        lo, hi = iv.exp(lo_a, hi_a)
        assert all(inside(lo, hi, mpmath.exp(mpmath.mpf(x))) for x in pts)
    if lo_a >= 0.0:
        lo, hi = iv.sqrt(lo_a, hi_a)
        assert all(inside(lo, hi, mpmath.sqrt(mpmath.mpf(x))) for x in pts)
    else:
        with pytest.raises(ValueError):
            iv.sqrt(lo_a, hi_a)
    if lo_a > 0.0:
        lo, hi = iv.log(lo_a, hi_a)
        assert all(inside(lo, hi, mpmath.log(mpmath.mpf(x))) for x in pts)
    else:
        with pytest.raises(ValueError):
            iv.log(lo_a, hi_a)


def trig_points(lo, hi, offsets):
    """End points, interior points and every offset + k*pi/2 critical point inside."""
    pts = [mpmath.mpf(p) for p in points(lo, hi, 9)]
    halfpi = mpmath.pi / 2
    k0 = int(mpmath.floor(mpmath.mpf(lo) / halfpi))
    k1 = int(mpmath.ceil(mpmath.mpf(hi) / halfpi))
    if k1 - k0 < 20:
        for k in range(k0, k1 + 1):
            c = k * halfpi
            if mpmath.mpf(lo) <= c <= mpmath.mpf(hi):
                pts.append(c)
    return pts


@settings(max_examples=400, deadline=None)
@given(st.one_of(moderate, st.sampled_from(ADVERSARIAL[:20])), st.floats(min_value=0, max_value=8))
def test_sin_cos_contain_exact(a, width):
    lo_a, hi_a = a, a + width
    assume(math.isfinite(hi_a))
    pts = trig_points(lo_a, hi_a, None)
    slo, shi = iv.sin(lo_a, hi_a)
    clo, chi = iv.cos(lo_a, hi_a)
    for x in pts:
        assert inside(slo, shi, mpmath.sin(x)), (lo_a, hi_a, x)
        assert inside(clo, chi, mpmath.cos(x)), (lo_a, hi_a, x)


@settings(max_examples=300, deadline=None)
@given(st.floats(min_value=-1.5, max_value=1.5), st.floats(min_value=0, max_value=0.07))
def test_tan_contains_exact(a, width):
    lo_a, hi_a = a, a + width
    if hi_a >= math.pi / 2:
        with pytest.raises(ValueError):
            iv.tan(lo_a, hi_a)
        return
    lo, hi = iv.tan(lo_a, hi_a)
    for x in points(lo_a, hi_a):
        assert inside(lo, hi, mpmath.tan(mpmath.mpf(x)))


def test_trig_of_large_arguments_and_full_periods():
    assert iv.sin(0.0, 7.0) == (-1.0, 1.0)
    assert iv.cos(-1e300, 1e300) == (-1.0, 1.0)
    for x in (1e6, 1e10, 1e15, 2.0**52):
        lo, hi = iv.sin(x, x)
        assert inside(lo, hi, mpmath.sin(mpmath.mpf(x)))
        lo, hi = iv.cos(x, x)
        assert inside(lo, hi, mpmath.cos(mpmath.mpf(x)))


@settings(max_examples=200, deadline=None)
@given(anyfloat, anyfloat, anyfloat, anyfloat)
def test_min_max(a1, a2, b1, b2):
    a, b = interval_from(a1, a2), interval_from(b1, b2)
    lo, hi = iv.min(a[0], a[1], b[0], b[1])
    for x in points(*a):
        for y in points(*b):
            assert lo <= min(x, y) <= hi
    lo, hi = iv.max(a[0], a[1], b[0], b[1])
    for x in points(*a):
        for y in points(*b):
            assert lo <= max(x, y) <= hi


def test_matvec_matmul_contain_exact():
    rng = np.random.default_rng(3)
    for _ in range(20):
        A = rng.normal(size=(3, 4)) * 10.0 ** rng.integers(-5, 5)
        dA = np.abs(rng.normal(size=A.shape)) * 1e-3
        x = rng.normal(size=4)
        dx = np.abs(rng.normal(size=4)) * 0.1
        ylo, yhi = iv.matvec(A - dA, A + dA, x - dx, x + dx)
        B = rng.normal(size=(4, 2))
        Clo, Chi = iv.matmul_point(A, B, B)
        for _ in range(10):
            As = A + dA * rng.uniform(-1, 1, A.shape)
            xs = x + dx * rng.uniform(-1, 1, 4)
            for i in range(3):
                exact = mpmath.fsum(mpmath.mpf(As[i, j]) * mpmath.mpf(xs[j]) for j in range(4))
                assert inside(ylo[i], yhi[i], exact)
        for i in range(3):
            for j in range(2):
                exact = mpmath.fsum(mpmath.mpf(A[i, r]) * mpmath.mpf(B[r, j]) for r in range(4))
                assert inside(Clo[i, j], Chi[i, j], exact)


def test_array_versions_match_the_scalar_kernel_and_contain_exact():
    from reachconf_kernels import interval_arrays as ia

    rng = np.random.default_rng(7)
    a = np.sort(rng.normal(size=(2, 200)) * 3, axis=0)
    b = np.sort(rng.normal(size=(2, 200)) * 3, axis=0)
    b = np.where(b[0] * b[1] > 0, b, b + 10)  # keep divisors away from 0
    pos = np.abs(a) + 0.1
    pos = np.sort(pos, axis=0)
    for name in ("add", "sub", "mul", "div", "min", "max"):
        lo, hi = getattr(ia, name)(a[0], a[1], b[0], b[1])
        for i in range(0, 200, 17):
            assert (lo[i], hi[i]) == getattr(iv, name)(a[0, i], a[1, i], b[0, i], b[1, i])
    for name, x in (("neg", a), ("sqr", a), ("sqrt", pos), ("exp", a), ("log", pos), ("sin", a), ("cos", a),
                    ("atan", a), ("tanh", a), ("abs", a)):  # fmt: skip
        lo, hi = getattr(ia, name)(x[0], x[1])
        for i in range(0, 200, 17):
            assert (lo[i], hi[i]) == getattr(iv, name)(x[0, i], x[1, i])
    lo, hi = ia.pow(a[0], a[1], 3)
    for i in range(200):
        for p in (a[0, i], a[1, i]):
            assert inside(lo[i], hi[i], mpmath.mpf(p) ** 3)


BINARY = ("add", "sub", "mul", "div", "min", "max", "hull")
UNARY = ("neg", "sqr", "sqrt", "exp", "log", "atan", "tanh", "sin", "cos", "tan", "abs")


def test_a_nan_bound_gives_nan_bounds():
    """Audit: ``mul(nan, 1, 2, 3)`` was ``[2, 3]`` (comparisons drop NaN), and so were div, min, max, hull, sqr,
    sqrt, exp, tanh, sin, cos, abs, pow for some NaN position: a finite box out of an undefined operand.  Every
    kernel now returns ``(nan, nan)`` when any bound is NaN, in the scalar and the array versions."""
    from reachconf_kernels import interval_arrays as ia

    nan = math.nan
    for name in BINARY:
        for pos in range(4):
            args = [0.5, 3.0, 2.0, 3.0]
            args[pos] = nan
            r = getattr(iv, name)(*args)
            assert math.isnan(r[0]) and math.isnan(r[1]), (name, pos, r)
            if name != "hull":
                lo, hi = getattr(ia, name)(*(np.array([v]) for v in args))
                assert np.isnan(lo[0]) and np.isnan(hi[0]), (name, pos)
    for name in UNARY:
        for pos in range(2):
            args = [0.5, 0.7]
            args[pos] = nan
            r = getattr(iv, name)(*args)
            assert math.isnan(r[0]) and math.isnan(r[1]), (name, pos, r)
            lo, hi = getattr(ia, name)(*(np.array([v]) for v in args))
            assert np.isnan(lo[0]) and np.isnan(hi[0]), (name, pos)
    for k in (-3, -2, -1, 0, 1, 2, 3):
        for args in ((nan, 0.7), (0.5, nan)):
            r = iv.pow(*args, k)
            assert math.isnan(r[0]) and math.isnan(r[1]), (k, args, r)
    lo, hi = iv.matvec(np.array([[1.0, nan]]), np.array([[1.0, 2.0]]), np.ones(2), np.ones(2))
    assert np.isnan(lo[0]) and np.isnan(hi[0])


def test_the_user_interval_refuses_nan_bounds():
    """The kernels propagate NaN; the user-facing set never holds one."""
    from reachconf.errors import SetError
    from reachconf.sets import Interval

    for lo, hi in (([math.nan], [1.0]), ([0.0], [math.nan]), ([math.nan], [math.nan])):
        with pytest.raises(SetError, match="NaN"):
            Interval(lo, hi)


def test_sin_cos_of_huge_arguments_are_sound():
    """Audit check (no change needed): beyond 1e15 an interval of a few ulps is nearly ``[-1, 1]``; sound (the
    extremum test's widening ``8 eps |x|`` exceeds the rounding of ``k 2 pi``, and beyond 5.8e19 the integer ``k``
    overflows only for point intervals, whose value ``sin(x)`` is then used).  Seeded points from 1e15 to 1e308
    against mpmath with enough bits for the argument reduction."""
    rng = np.random.default_rng(20261203)
    with mpmath.workprec(1400):
        for e in range(15, 309, 4):
            for sign in (1.0, -1.0):
                x = sign * float(rng.uniform(1, 10)) * 10.0**e
                for w in (0.0, float(np.spacing(x)) * int(rng.integers(1, 4)), float(rng.uniform(0, 6)) * (e < 17)):
                    lo, hi = (x, x + w) if sign > 0 else (x - w, x)
                    for op, exact in ((iv.sin, mpmath.sin), (iv.cos, mpmath.cos)):
                        rlo, rhi = op(lo, hi)
                        for p in {lo, hi, lo / 2 + hi / 2}:
                            assert mpmath.mpf(rlo) <= exact(mpmath.mpf(p)) <= mpmath.mpf(rhi), (op, lo, hi, p)
