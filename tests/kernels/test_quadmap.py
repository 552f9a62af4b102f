"""The rounding bound of :mod:`reachconf_kernels.quadmap` covers the float arithmetic of the quadratic maps, checked
entry by entry against exact rational arithmetic, and the reach kernels' quadratic terms carry it."""

from fractions import Fraction

import numpy as np
import pytest

from reachconf_kernels import quadmap as qk
from reachconf_kernels.nonlinear import _quad_maps_poly, quadratic_error


def _exact_quad_map(c1, G1, c2, G2, Q, same):
    """Centre and generators of ``quad_map`` (``same``) or ``quad_map_mixed``, in exact rationals."""
    Z1 = [[Fraction(float(v)) for v in row] for row in np.column_stack([c1, G1])]
    Z2 = [[Fraction(float(v)) for v in row] for row in np.column_stack([c2, G2])]
    n, m1, m2 = len(Z1), len(Z1[0]), len(Z2[0])
    cs, gs = [], []
    for Qi in Q:
        Qf = [[Fraction(float(v)) for v in row] for row in Qi]
        Qh = [[sum(Z1[r][a] * Qf[r][s] * Z2[s][b] for r in range(n) for s in range(n)) for b in range(m2)]
              for a in range(m1)]  # fmt: skip
        if same:
            m = m1 - 1
            cs.append(Qh[0][0] + sum(Qh[j][j] for j in range(1, m + 1)) / 2)
            g = [Qh[j][j] / 2 for j in range(1, m + 1)]
            g += [Qh[a][b] + Qh[b][a] for a in range(m + 1) for b in range(a + 1, m + 1)]
        else:
            cs.append(Qh[0][0])
            g = [Qh[a][b] for a in range(m1) for b in range(m2) if a or b]
        gs.append(g)
    return cs, gs


def _deviation(c, G, cs, gs):
    """Per output, |computed - exact| summed over the centre and every generator (exact)."""
    return [abs(Fraction(float(c[i])) - cs[i]) + sum(abs(Fraction(float(G[i, j])) - gs[i][j]) for j in range(G.shape[1]))
            for i in range(len(cs))]  # fmt: skip


def _random(rng, n, m):
    scale = 10.0 ** rng.uniform(-3, 3)
    c = rng.normal(size=n) * scale + rng.uniform(-1, 1, size=n) * 10.0 ** rng.uniform(0, 4)
    return c, rng.normal(size=(n, m)) * scale * rng.uniform(0, 1)


@pytest.mark.parametrize("seed", range(40))
def test_rounding_bound_covers_the_exact_maps(seed):
    rng = np.random.default_rng(seed)
    n, m1, m2, k = int(rng.integers(1, 4)), int(rng.integers(0, 3)), int(rng.integers(0, 3)), int(rng.integers(1, 3))
    c1, G1 = _random(rng, n, m1)
    c2, G2 = _random(rng, n, m2)
    Q = rng.normal(size=(k, n, n)) * 10.0 ** rng.uniform(-2, 2)
    for same, (c, G), (a, b) in (
        (True, qk.quad_map(c1, G1, Q), ((c1, G1), (c1, G1))),
        (False, qk.quad_map_mixed(c1, G1, c2, G2, Q), ((c1, G1), (c2, G2))),
    ):
        cs, gs = _exact_quad_map(*a, *b, Q, same)
        rnd = qk.quad_map_rounding(*a, *b, Q)
        dev = _deviation(c, G, cs, gs)
        assert all(d <= Fraction(float(r)) for d, r in zip(dev, rnd)), (dev, rnd)
        # and it is only ulps: at most 1e-12 of s1^T |Q| s2
        s1 = np.abs(np.column_stack([a[0], a[1]])).sum(axis=1)
        s2 = np.abs(np.column_stack([b[0], b[1]])).sum(axis=1)
        assert np.all(rnd <= 1e-12 * np.einsum("i,kij,j->k", s1, np.abs(Q), s2))


def test_the_deviation_is_real():
    """Without the bound the computed maps would be wrong: some seed's computed image is off the exact one."""
    off = 0
    for seed in range(40):
        rng = np.random.default_rng(seed)
        c1, G1 = _random(rng, 3, 2)
        Q = rng.normal(size=(2, 3, 3))
        c, G = qk.quad_map(c1, G1, Q)
        off += any(d > 0 for d in _deviation(c, G, *_exact_quad_map(c1, G1, c1, G1, Q, True)))
    assert off > 0


@pytest.mark.parametrize("seed", range(10))
def test_reach_quadratic_terms_carry_the_rounding(seed):
    """``quadratic_error`` (lin) and the poly dynamic term return a rounding radius that covers their maps."""
    rng = np.random.default_rng(seed)
    n, q = 3, 1
    nz = n + 1 + q  # one known input, which the quadratic term leaves out
    idx = np.array([0, 1, 2, 4])
    H = rng.normal(size=(n, nz, nz))
    H = H + H.transpose(0, 2, 1)
    Q = 0.5 * H[:, idx][:, :, idx]
    cz, Gz = _random(rng, n + q, 2)
    qc, qG, rnd = quadratic_error(cz, Gz, H, n, idx)
    dev = _deviation(qc, qG, *_exact_quad_map(cz, Gz, cz, Gz, Q, True))
    assert all(d <= Fraction(float(r)) for d, r in zip(dev, rnd))
    cd, Gd = _random(rng, n + q, 1)
    pc, pG, prnd = _quad_maps_poly(cz, Gz, cd, Gd, H, n, idx)
    parts = [_exact_quad_map(cz, Gz, cd, Gd, Q, False), _exact_quad_map(cd, Gd, cz, Gz, Q, False),
             _exact_quad_map(cd, Gd, cd, Gd, Q, True)]  # fmt: skip
    cs = [sum(p[0][i] for p in parts) for i in range(n)]
    gs = [[g for p in parts for g in p[1][i]] for i in range(n)]
    dev = _deviation(pc, pG, cs, gs)
    assert all(d <= Fraction(float(r)) for d, r in zip(dev, prnd))
    maps = (qk.quad_map_rounding(cz, Gz, cd, Gd, Q) + qk.quad_map_rounding(cd, Gd, cz, Gz, Q)
            + qk.quad_map_rounding(cd, Gd, cd, Gd, Q))  # fmt: skip
    np.testing.assert_allclose(prnd, 1.25 * maps, rtol=1e-12)


@pytest.mark.parametrize("seed", range(24))
def test_rounding_bound_covers_underflow(seed):
    """Audit: below about 1e-155 the products underflow (an absolute error of up to 2^-1075 each, which the relative
    bound does not cover; beyond 1e-162 a product of three is 0 and so was the bound, though the exact map is not).
    Centres and generators near 1e-160 (and a large set times a tiny one, where the tiny part's underflow is scaled
    up), checked against exact rationals; the absolute term stays below 1e-300 of the sets' size."""
    rng = np.random.default_rng(1000 + seed)
    n, m1, m2, k = int(rng.integers(1, 4)), int(rng.integers(0, 3)), int(rng.integers(0, 3)), int(rng.integers(1, 3))
    kind = seed % 4
    s1, s2, sq = {0: (1e-160, 1e-160, 1.0), 1: (1e-200, 1e-200, 1.0), 2: (1e150, 1e-170, 1e-150),
                  3: (1.0, 1e-160, 1e-150)}[kind]  # fmt: skip
    c1, G1 = rng.normal(size=n) * s1, rng.normal(size=(n, m1)) * s1 * 10.0 ** rng.uniform(-2, 0)
    c2, G2 = rng.normal(size=n) * s2, rng.normal(size=(n, m2)) * s2 * 10.0 ** rng.uniform(-2, 0)
    Q = rng.normal(size=(k, n, n)) * sq
    for same, (c, G), (a, b) in (
        (True, qk.quad_map(c1, G1, Q), ((c1, G1), (c1, G1))),
        (True, qk.quad_map(c2, G2, Q), ((c2, G2), (c2, G2))),
        (False, qk.quad_map_mixed(c1, G1, c2, G2, Q), ((c1, G1), (c2, G2))),
        (False, qk.quad_map_mixed(c2, G2, c1, G1, Q), ((c2, G2), (c1, G1))),
    ):
        cs, gs = _exact_quad_map(*a, *b, Q, same)
        rnd = qk.quad_map_rounding(*a, *b, Q)
        dev = _deviation(c, G, cs, gs)
        assert all(d <= Fraction(float(r)) for d, r in zip(dev, rnd)), (kind, same, dev, rnd)
        z1 = np.abs(np.column_stack([a[0], a[1]])).sum()
        z2 = np.abs(np.column_stack([b[0], b[1]])).sum()
        relative = [1e-12 * float(Fraction(z1) * Fraction(q) * Fraction(z2)) for q in np.abs(Q).max(axis=(1, 2))]
        assert np.all(rnd <= np.array(relative) + 1e-300 * (1.0 + z1)), (kind, rnd, relative)


def test_a_zero_map_has_no_rounding_box():
    """The absolute term is added only where some exact product is non-zero (a zero row of Q or a zero set: 0)."""
    c, G = np.array([1e-200, 0.0]), np.array([[1e-200], [0.0]])
    Q = np.zeros((3, 2, 2))
    Q[1, 0, 0] = 1.0
    Q[2, 1, 1] = 1.0  # meets only the zero coordinate
    assert list(qk.quad_map_rounding(c, G, c, G, Q)) == [0.0, qk.quad_map_rounding(c, G, c, G, Q)[1], 0.0]
    assert qk.quad_map_rounding(c, G, c, G, Q)[1] > 0.0  # 1e-400 exactly, 0 in floats
