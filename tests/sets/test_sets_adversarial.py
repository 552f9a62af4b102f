"""Enclosing set operations on adversarial zonotopes, checked exactly (integer arithmetic on the floats).

Generators 1e12 apart, near-parallel ones, rank-deficient and zero ones, centres of 1e8 with radii of 1e-6 and
numbers of 1e+-200: the interval hull, the reductions (Girard, PCA, error-bounded) and ``compact`` must contain
the input exactly (their boxes are rounded outward), which the support function in sampled directions (the axes,
facet normals, random ones) decides without rounding.
"""

from fractions import Fraction

import numpy as np
import pytest

from reachconf import Zonotope
from reachconf_kernels.reduce_adaptive import reduce_adaptive

SHIFT = 1075  # every float is an integer multiple of 2^-1074


def _ints(a):
    """The floats of ``a`` times 2^SHIFT as Python integers (exact)."""
    out = np.empty(np.shape(a), dtype=object)
    for idx, x in np.ndenumerate(np.asarray(a, dtype=float)):
        f = Fraction(float(x))
        out[idx] = f.numerator * (1 << SHIFT) // f.denominator
    return out


def _support(c, G, d):
    """Exact ``d.c + sum_j |d.g_j|`` (scaled by 2^(2 SHIFT)) of integer arrays."""
    return int(np.dot(d, c)) + (sum(abs(int(v)) for v in np.dot(d, G)) if G.shape[1] else 0)


def adversarial_zonotope(rng, kind, n, m):
    """A zonotope of one of the adversarial kinds 0..6 (see the module docstring)."""
    G = rng.normal(size=(n, m))
    c = rng.normal(size=n)
    if kind == 1 and m:
        G *= 10.0 ** rng.uniform(-12, 0, m)
    elif kind == 2 and m > 1:
        G = np.outer(rng.normal(size=n), rng.normal(size=m)) + 10.0 ** rng.uniform(-12, -5) * rng.normal(size=(n, m))
    elif kind == 3 and m:
        r = int(rng.integers(1, max(2, n)))
        G = rng.normal(size=(n, r)) @ rng.normal(size=(r, m))
    elif kind == 4 and m:
        G[:, rng.random(m) < 0.3] = 0.0
        G[rng.random((n, m)) < 0.3] = 0.0
    elif kind == 5:
        c, G = c * 1e8, G * 1e-6
    elif kind == 6:
        scale = 10.0 ** rng.uniform(-200, 200)
        c, G = c * scale, G * scale
    return Zonotope(c, G)


def _directions(rng, Z, k=12):
    n, m = Z.generators.shape
    D = [np.eye(n), -np.eye(n), rng.normal(size=(k, n))]
    for _ in range(6 if m >= n - 1 and n > 1 else 0):
        idx = rng.choice(m, n - 1, replace=False)
        D.append(np.linalg.svd(Z.generators[:, idx].T)[2][-1:] * rng.choice([-1.0, 1.0]))
    return np.vstack(D)


def _assert_encloses(outer, inner, D, what):
    ci, Gi, co, Go = _ints(inner.center), _ints(inner.generators), _ints(outer.center), _ints(outer.generators)
    for d in D:
        di = _ints(d)
        assert _support(co, Go, di) >= _support(ci, Gi, di), f"{what}: misses the input along {d}"


@pytest.mark.parametrize("kind", range(7))
def test_reductions_hull_and_compact_enclose_exactly(kind):
    rng = np.random.default_rng(20261127 + kind)
    for _ in range(6):
        n = int(rng.integers(1, 9))
        m = int(rng.integers(0, int(rng.choice([1, 5, 20])) * n + 1))
        Z = adversarial_zonotope(rng, kind, n, m)
        D = _directions(rng, Z)
        H = Z.interval()
        ci, r = _ints(Z.center), [sum(abs(int(v)) for v in row) for row in _ints(Z.generators)]
        assert all(int(lo) <= int(c) - ri and int(hi) >= int(c) + ri
                   for lo, hi, c, ri in zip(_ints(H.lo), _ints(H.hi), ci, r)), "interval hull"  # fmt: skip
        _assert_encloses(H.to_zonotope(), Z, D, "hull as a zonotope")
        for method in ("girard", "pca"):
            for order in (1, 2.5, 20):
                R = Z.reduce(order, method)
                assert R.generators.shape[1] <= max(order * n, n)
                _assert_encloses(R, Z, D, f"{method} order {order}")
        for tol, max_order in ((0.0, 1.0), (1e-3, 5.0), (0.1, 50.0)):
            keep = int(rng.integers(0, min(m, 3) + 1))
            c, G = reduce_adaptive(np.array(Z.center), np.array(Z.generators), tol, max_order, keep)
            assert np.array_equal(G[:, :keep], Z.generators[:, :keep])
            _assert_encloses(Zonotope(c, G), Z, D, f"reduce_adaptive {tol} {max_order}")
        for tol in (0.0, 1e-3 * float(np.abs(Z.generators).max(initial=0.0))):
            _assert_encloses(Z.compact(tol), Z, D, f"compact {tol}")


def test_a_coordinate_with_no_extent_at_zero_holds_only_zero():
    """A set with no generators at 0 in a coordinate accepted points up to the absolute tolerance there (1e-9),
    not the documented scale 1e-5 |p_i| (found by a numerical audit: {(0, 0)} held (0, 5e-10))."""
    from reachconf import Zonotope

    for c in ([0.0, 0.0], [1e-3, 0.0], [0.0, 0.0, 0.0]):
        Z = Zonotope(c, np.zeros((len(c), 0)))
        off = np.array(c)
        off[-1] = 5e-10
        assert not Z.contains(off)
        assert Z.contains(np.array(c))
    Z = Zonotope([1.0, 0.0], [[1.0], [0.0]])  # a segment on the axis: its own points in, a hair off it out
    assert list(Z.contains(np.array([[1.5, 0.0], [1.5, 1e-12], [0.0, 0.0]]))) == [True, False, True]
