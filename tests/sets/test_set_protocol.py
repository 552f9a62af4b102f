"""The common set protocol, box ⊕ disk sets and the reduction-method types: soundness by sampling, and tightness."""

import math

import numpy as np
import pytest

import reachconf as rc
from reachconf.sets import PCA, BoxDisk, Girard, ReachSet, SetUnion, box_disk_distance, disk_zonotope


def _sets(rng):
    Z = rc.Zonotope(rng.normal(size=2), rng.normal(size=(2, 5)))
    return {
        "interval": rc.Interval([-1.0, 0.5], [2.0, 1.5]),
        "zonotope": Z,
        "union": SetUnion([Z, Z + np.array([3.0, -1.0])]),
        "boxdisk": BoxDisk([0.5, -0.5], [0.3, 0.1], 0.4),
    }


def _inside_points(name, S, rng, k=400):
    if name == "boxdisk":
        ang, rad = rng.uniform(0, 2 * np.pi, k), S.radius * np.sqrt(rng.uniform(0, 1, k))
        box = rng.uniform(-S.half_widths, S.half_widths, size=(k, 2))
        return S.center + box + np.column_stack([rad * np.cos(ang), rad * np.sin(ang)])
    return np.vstack([p.to_zonotope().sample(k // len(S.pieces), rng) for p in S.pieces])


@pytest.mark.parametrize("name", ["interval", "zonotope", "union", "boxdisk"])
def test_every_set_type_follows_the_protocol(name):
    rng = np.random.default_rng(1)
    S = _sets(rng)[name]
    assert isinstance(S, ReachSet)
    assert S.dim == 2 and len(S.pieces) >= 1
    P = _inside_points(name, S, rng)
    assert np.all(S.contains(P, tol=1e-9))
    H = S.interval()
    assert np.all(H.contains(P, tol=1e-9))
    # tight hull: each face is attained (up to the sampling) by a point of the set
    assert np.all(P.max(axis=0) >= H.hi - 0.1 * (H.hi - H.lo)) and np.all(P.min(axis=0) <= H.lo + 0.1 * (H.hi - H.lo))
    M = np.array([[0.8, -0.6], [0.6, 0.8]]) * 1.5
    image = S.linear_map(M)
    assert np.all(image.contains(P @ M.T, tol=1e-9))
    # tightness of the image: a point well outside (beyond the hull of the mapped samples by half its size) is not in it
    Q = P @ M.T
    far = Q.max(axis=0) + 0.5 * (Q.max(axis=0) - Q.min(axis=0))
    assert not image.contains(far)
    ax = S.plot(None, dims=(0, 1))
    assert ax is not None


def test_box_disk_membership_is_exact():
    rng = np.random.default_rng(2)
    S = BoxDisk([1.0, 2.0], [0.5, 0.2], 0.3)
    # the rounded corner: points just inside and just outside along the diagonal from the box corner
    corner = np.array([1.5, 2.2])
    u = np.array([1.0, 1.0]) / math.sqrt(2)
    assert S.contains(corner + (0.3 - 1e-9) * u) and not S.contains(corner + (0.3 + 1e-9) * u)
    # a face: distance along the axis
    assert S.contains([1.0, 2.5 - 1e-9]) and not S.contains([1.0, 2.5 + 1e-9])
    # vectorised distance equals the per-set one
    D = rng.normal(size=(50, 2))
    np.testing.assert_allclose(box_disk_distance(D - S.center, S.half_widths, S.radius), S.distance(D))
    # boundary points lie on the set's boundary
    B = S.boundary(72)
    np.testing.assert_allclose(S.distance(B), 0.0, atol=1e-12)


def test_box_disk_zonotope_encloses_and_is_tight():
    rng = np.random.default_rng(3)
    S = BoxDisk([0.0, 0.0], [0.2, 0.1], 1.0)
    Z = S.to_zonotope(8)
    P = _inside_points("boxdisk", S, rng, 2000)
    assert np.all(Z.contains(P))
    # the 16-gon exceeds the disk by at most 1 / cos(pi / 16) in every direction
    for a in np.linspace(0, 2 * np.pi, 17):
        d = np.array([math.cos(a), math.sin(a)])
        exact = S.radius + np.abs(d) @ S.half_widths
        assert exact - 1e-12 <= Z.support(d) <= exact + S.radius * (1 / math.cos(math.pi / 16) - 1) + 1e-9
    with pytest.raises(rc.SetError):
        BoxDisk([0.0, 0.0], [0.1, -0.1], 1.0)
    assert np.allclose(disk_zonotope(1.0, 8).generators, disk_zonotope(1.0, 8, (0.0, 0.0)).generators)


@pytest.mark.parametrize("method, name", [(Girard(), "girard"), (PCA(), "pca")])
def test_reduction_types_are_the_strings(method, name):
    rng = np.random.default_rng(4)
    Z = rc.Zonotope(rng.normal(size=4), rng.normal(size=(4, 30)))
    a, b = Z.reduce(3, method), Z.reduce(3, name)
    np.testing.assert_array_equal(a.center, b.center)
    np.testing.assert_array_equal(a.generators, b.generators)
    assert str(method) == name
    with pytest.raises(rc.SetError, match="unknown reduction method"):
        Z.reduce(3, "nonsense")
