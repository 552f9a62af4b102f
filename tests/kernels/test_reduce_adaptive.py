"""The error-bounded reduction of the adaptive reach: it encloses its input, with and without the outlier cap."""

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from reachconf import Zonotope
from reachconf_kernels.reduce_adaptive import OUTLIER, reduce_adaptive

TOL = 1e-9


def _sampled(c, G, rng, k=150):
    m = G.shape[1]
    B = np.vstack([rng.choice([-1.0, 1.0], size=(k, m)), rng.uniform(-1, 1, size=(k, m))])
    return c + B @ G.T


def _support(G, d):
    return float(np.abs(d @ G).sum())


@settings(max_examples=60, deadline=None)
@given(st.integers(0, 2**31 - 1), st.integers(1, 5), st.integers(0, 40), st.sampled_from([0.0, 0.01, 0.1, 1.0]),
       st.sampled_from([1.0, 2.0, 5.0]), st.sampled_from([0.0, 1.0, OUTLIER]))  # fmt: skip
def test_reduction_encloses_its_input_whatever_the_states_scales(seed, n, m, tol, order, outlier):
    rng = np.random.default_rng(seed)
    scales = 10.0 ** rng.uniform(-3, 3, size=n)  # states of very different extents (a position of km, an angle)
    c = rng.normal(size=n) * scales
    G = rng.normal(size=(n, m)) * scales[:, None]
    G[:, rng.uniform(size=m) < 0.1] = 0.0  # some zero generators
    G[rng.uniform(size=n) < 0.2, :] = 0.0  # some states without extent
    keep = int(rng.integers(0, min(m, n) + 1))
    cr, Gr = reduce_adaptive(c, G, tol, order, keep, outlier)
    np.testing.assert_array_equal(cr, c)
    np.testing.assert_array_equal(Gr[:, :keep], G[:, :keep])  # the kept images stay the first columns
    assert Gr.shape[1] <= max(int(n * order), keep + n, n) + n
    assert Zonotope(cr, Gr).contains(_sampled(c, G, rng), tol=TOL * (1 + np.abs(c).max())).all()
    # and not by being large: boxing keeps the interval hull (up to the outward rounding)
    np.testing.assert_allclose(np.abs(Gr).sum(axis=1), np.abs(G).sum(axis=1), rtol=1e-12, atol=1e-300)


@settings(max_examples=30, deadline=None)
@given(st.integers(0, 2**31 - 1), st.integers(2, 6), st.integers(5, 30))
def test_the_outlier_cap_changes_nothing_when_no_state_is_an_outlier(seed, n, m):
    """States within 30x of each other (every benchmark instance): the same generators are boxed as without the cap."""
    rng = np.random.default_rng(seed)
    G = rng.normal(size=(n, m)) * (10.0 ** rng.uniform(0, 1.4, size=n))[:, None]
    _, plain = reduce_adaptive(np.zeros(n), G, 0.05, 50.0, 0, 0.0)
    _, capped = reduce_adaptive(np.zeros(n), G, 0.05, 50.0, 0, OUTLIER)
    np.testing.assert_array_equal(capped, plain)


def test_a_wide_state_does_not_set_the_tolerance_of_the_narrow_ones():
    """One state 10^5 times wider than four coupled narrow ones: with the cap most of their coupling is kept.

    The narrow states' generators lie along (1, 1, 1, 1) (the states move together); boxing them loses that: the
    support of the set along (1, -1, 0, 0) grows from 0 to their sum.
    """
    rng = np.random.default_rng(3)
    wide = np.zeros((5, 4))
    wide[0] = rng.uniform(1e3, 2e3, size=4)
    narrow = np.zeros((5, 6))
    narrow[1:] = rng.uniform(0.01, 0.02, size=6)  # x2 = x3 = x4 = x5 along every generator
    G = np.hstack([wide, narrow])
    d = np.array([0.0, 1.0, -1.0, 0.0, 0.0])
    assert _support(G, d) == 0.0
    _, plain = reduce_adaptive(np.zeros(5), G, 0.01, 50.0, 0, 0.0)
    _, capped = reduce_adaptive(np.zeros(5), G, 0.01, 50.0, 0, OUTLIER)
    full = 2 * narrow[1].sum()  # every narrow generator boxed
    assert _support(plain, d) > 0.99 * full  # the bound 0.01 x the diagonal (~1.2e4) allows all of them
    assert _support(capped, d) < 0.5 * full  # the wide state counts as 100 narrow radii (~9): the bound ~0.2
