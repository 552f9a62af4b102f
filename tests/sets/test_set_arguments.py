"""Bad scalar arguments of set methods are SetErrors naming the argument; sample(0) is empty; scale is outward."""

from fractions import Fraction

import numpy as np
import pytest

import reachconf as rc

Z = rc.Zonotope([0.0, 0.0], [[1.0, 0.5], [0.0, 1.0]])
B = rc.Interval([0.0, -1.0], [1.0, 2.0])


@pytest.mark.parametrize(
    "call, message",
    [
        (lambda: Z.reduce("1"), "order must be a number >= 1"),
        (lambda: Z.reduce(0.5), "order must be a number >= 1"),
        (lambda: Z.sample(-1), "n must be a non-negative integer"),
        (lambda: Z.sample(2.5), "n must be a non-negative integer"),
        (lambda: B.sample("3"), "n must be a non-negative integer"),
        (lambda: Z.vertices_sample(-1), "n must be a non-negative integer"),
        (lambda: Z.sample(3, rng="x"), "rng must be a seed"),
        (lambda: B.sample(3, rng=-1), "rng must be a seed"),
        (lambda: Z.contains(np.zeros(2), tol="a"), "tol must be a finite number >= 0"),
        (lambda: Z.contains(np.zeros(2), tol=-1), "tol must be a finite number >= 0"),
        (lambda: B.contains(np.zeros(2), tol=float("nan")), "tol must be a finite number >= 0"),
        (lambda: B.is_subset(B, tol=float("nan")), "tol must be a finite number >= 0"),
        (lambda: Z.compact(-1), "tol must be a finite number >= 0"),
        (lambda: B.scale("2"), "alpha must be a finite non-negative number"),
        (lambda: rc.Interval([-1e308], [1e308]), "overflows in dimension 0"),
    ],
)
def test_bad_scalar_arguments_are_set_errors(call, message):
    with pytest.raises(rc.SetError, match=message):
        call()


def test_sample_zero_points_is_an_empty_array():
    assert Z.sample(0).shape == (0, 2) and B.sample(0).shape == (0, 2) and Z.vertices_sample(0).shape == (0, 2)
    assert Z.sample(np.int64(5), rng=np.random.default_rng(1)).shape == (5, 2)


def test_scale_encloses_the_exact_scaled_box():
    """Audit: scale was not outward rounded (about 1 ulp short in 3 of 4 random boxes); checked with exact fractions."""
    rng = np.random.default_rng(1)
    for _ in range(2000):
        lo = rng.normal(size=3) * 10.0 ** rng.integers(-3, 4, size=3)
        hi = lo + rng.random(3) * 10.0 ** rng.integers(-6, 3, size=3)
        alpha = float(rng.random() * 4)
        box = rc.Interval(lo, hi).scale(alpha)
        for i in range(3):
            c = (Fraction(lo[i]) + Fraction(hi[i])) / 2
            r = (Fraction(hi[i]) - Fraction(lo[i])) / 2 * Fraction(alpha)
            assert Fraction(box.lo[i]) <= c - r and c + r <= Fraction(box.hi[i])
            slack = Fraction(16 * np.finfo(float).eps) * (abs(c) + r)  # and tight: a few ulps wider at most
            assert c - r - Fraction(box.lo[i]) <= slack and Fraction(box.hi[i]) - (c + r) <= slack
    assert B.scale(1.0) is B and B.scale(1) is B


def _exact_scaled(lo, hi, alpha):
    c = (Fraction(lo) + Fraction(hi)) / 2
    r = (Fraction(hi) - Fraction(lo)) / 2 * Fraction(alpha)
    return c - r, c + r


def test_scale_is_outward_on_subnormal_and_tiny_boxes():
    """Audit: the relative slack ``4 eps (|c| + r)`` of scale vanishes on subnormals, where halving and scaling
    round by an absolute amount: ``[5e-324, 1.5e-323].scale(0.5)`` was the point ``1e-323`` (the exact box is
    ``[7.5e-324, 1.25e-323]``) and ``[0, 5e-324].scale(3)`` the point 0.  Seeded boxes from the smallest subnormal
    to 1e300, checked with exact fractions."""
    tiny = 5e-324
    cases = [(5e-324, 1.5e-323, 0.5), (0.0, 5e-324, 3.0), (-5e-324, 5e-324, 0.3), (2.2250738585072014e-308,
             2.225073858507202e-308, 0.7), (-1e-310, 3e-320, 1.9), (1e300, 1.5e300, 0.25), (-8e307, 8e307, 0.0), (1.7e308, 1.79e308, 0.5)]  # fmt: skip
    rng = np.random.default_rng(20261203)
    for _ in range(3000):
        e = rng.integers(-1074, 1024, size=2)
        m = rng.integers(0, 5, size=2) if rng.random() < 0.3 else rng.random(2)  # small integer multiples too
        a, b = (float(np.ldexp(float(mm), int(ee))) * float(rng.choice([-1, 1])) for mm, ee in zip(m, e))
        if rng.random() < 0.3:
            b = a + tiny * float(rng.integers(0, 9))
        lo, hi = min(a, b), max(a, b)
        alpha = float(rng.choice([rng.random() * 4, float(rng.integers(0, 5)), 10.0 ** rng.uniform(-300, 3)]))
        if np.isfinite(hi - lo) and np.isfinite(alpha * (hi - lo)):
            cases.append((lo, hi, alpha))
    for lo, hi, alpha in cases:
        box = rc.Interval([lo], [hi]).scale(alpha)
        elo, ehi = _exact_scaled(lo, hi, alpha)
        assert Fraction(box.lo[0]) <= elo and ehi <= Fraction(box.hi[0]), (lo, hi, alpha, box)
        # tight: a few ulps of the magnitude and a few subnormals wider at most
        slack = Fraction(16 * np.finfo(float).eps) * (abs(elo) + abs(ehi)) + 16 * Fraction(tiny)
        assert elo - Fraction(box.lo[0]) <= slack and Fraction(box.hi[0]) - ehi <= slack, (lo, hi, alpha, box)
