"""The particular solution of a time-varying input with its higher Taylor terms boxed encloses the full one.

``particular_varying(..., keep_terms=1)`` (the adaptive algorithm's steps) returns the
generators of the first term only and boxes the others; every point of the
term-by-term set (independent factors per term, as a time-varying input has)
must lie in it.
"""

import numpy as np
import pytest

from reachconf.sets.containment import contains_points
from reachconf_kernels.linsys import linear_step_matrices, particular_varying


def _as_zonotope(c, G, rad):
    return c, np.hstack([G, np.diag(rad)])


@pytest.mark.parametrize("seed", range(8))
def test_boxed_higher_terms_enclose_every_term_by_term_point(seed):
    rng = np.random.default_rng(seed)
    n, m = int(rng.integers(2, 5)), int(rng.integers(1, 7))
    A = rng.normal(size=(n, n)) * rng.uniform(0.5, 20.0)
    dt, r = float(rng.uniform(0.005, 0.2)), int(rng.integers(2, 7))
    _, E, T, *_ = linear_step_matrices(A, dt, r)
    c, G = rng.normal(size=n), rng.normal(size=(n, m)) * rng.uniform(0.01, 2.0)
    cc_all, G_all, rad_all = particular_varying(T, E, dt, c, G)
    cc_box, G_box, rad_box = particular_varying(T, E, dt, c, G, 1)
    assert G_all.shape[1] == T.shape[0] * m and G_box.shape[1] == m
    np.testing.assert_array_equal(cc_all, cc_box)
    assert np.all(rad_box >= rad_all)
    # points of the term-by-term set: vertices-heavy factors, one per term and generator, and the box
    k = 4000
    beta = rng.choice([-1.0, 1.0], size=(k, G_all.shape[1])) * rng.uniform(0.7, 1.0, size=(k, G_all.shape[1]))
    delta = rng.uniform(-1.0, 1.0, size=(k, n))
    P = cc_all + beta @ G_all.T + delta * rad_all
    zc, zG = _as_zonotope(cc_box, G_box, rad_box)
    inside = contains_points(zc, zG, P, tol=1e-12)
    assert inside.all(), f"{(~inside).sum()} of {k} points outside"
    # and the boxed set is not needlessly larger than the full set's interval hull
    hull_all = np.abs(G_all).sum(axis=1) + rad_all
    hull_box = np.abs(G_box).sum(axis=1) + rad_box
    assert np.all(hull_box <= hull_all * (1 + 1e-9) + 1e-300)


def test_keep_every_term_by_default():
    rng = np.random.default_rng(0)
    A = rng.normal(size=(3, 3))
    _, E, T, *_ = linear_step_matrices(A, 0.05, 4)
    c, G = rng.normal(size=3), rng.normal(size=(3, 2))
    a = particular_varying(T, E, 0.05, c, G)
    b = particular_varying(T, E, 0.05, c, G, -1)
    for x, y in zip(a, b):
        np.testing.assert_array_equal(x, y)
