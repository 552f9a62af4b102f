"""The loop products of :mod:`reachconf_kernels.small_linalg` agree with numpy, and the exponential's
remainder bound of :mod:`reachconf_kernels.linsys` holds for non-symmetric matrices."""

import numpy as np
import pytest
from scipy.linalg import expm

from reachconf_kernels.linsys import exp_remainder, linear_step_matrices
from reachconf_kernels.small_linalg import (
    abs_row_sums_of_product,
    abs_terms_times,
    mat_mat,
    mat_vec,
)


@pytest.mark.parametrize("seed", range(12))
def test_products_agree_with_numpy(seed):
    rng = np.random.default_rng(seed)
    n, k, m = (int(v) for v in rng.integers(0, 7, size=3))
    A = rng.normal(size=(n, k)) * 10.0 ** rng.uniform(-3, 3)
    B = rng.normal(size=(k, m))
    x = rng.normal(size=k)
    scale = (np.abs(A) @ np.abs(B)).max(initial=0.0) + 1e-300
    np.testing.assert_allclose(mat_mat(A, B), A @ B, rtol=0, atol=1e-14 * scale)
    assert mat_mat(A, B).shape == (n, m)
    np.testing.assert_allclose(
        mat_vec(A, x),
        A @ x,
        rtol=1e-13,
        atol=1e-13 * (np.abs(A) @ np.abs(x)).max(initial=0),
    )
    T = rng.normal(size=(3, n, k))
    np.testing.assert_allclose(abs_terms_times(T, np.abs(x)), sum(np.abs(Ti) @ np.abs(x) for Ti in T), rtol=1e-13)
    np.testing.assert_allclose(abs_row_sums_of_product(A, B), np.abs(A @ B).sum(axis=1), rtol=1e-12,
                               atol=1e-14 * scale * max(m, 1))  # fmt: skip
    # non-contiguous operands (column slices of a Jacobian, transposes) give the same products
    J = np.hstack([A, rng.normal(size=(n, 3))])
    np.testing.assert_allclose(mat_mat(J[:, :k], B), A @ B, rtol=0, atol=1e-14 * scale)


@pytest.mark.parametrize("seed", range(10))
def test_exponential_remainder_bounds_the_truncation_for_non_symmetric_matrices(seed):
    """``|e^{A dt} - sum_{i<=r} (A dt)^i / i!| <= E`` entry-wise, with ``|A| dt`` far from symmetric."""
    rng = np.random.default_rng(100 + seed)
    n = int(rng.integers(2, 6))
    A = rng.normal(size=(n, n))
    A[np.triu_indices(n, 1)] *= 10.0 ** rng.uniform(
        0, 2
    )  # one triangle much larger: row and column norms differ
    dt, r = float(rng.uniform(0.01, 0.5)), int(rng.integers(2, 8))
    eAt, E, *_ = linear_step_matrices(A, dt, r)
    exact = expm(A * dt)
    err = np.abs(exact - eAt)
    tol = 1e-13 * np.abs(exact).max()  # expm's own accuracy
    assert np.all(err <= E + tol), f"remainder exceeded by {np.max(err - E):.3g}"
    # and the bound is not vacuous: within a factor of the true tail of the |A| dt series
    absA = np.abs(A) * dt
    tail = expm(absA) - sum(
        np.linalg.matrix_power(absA, i) / np.prod(np.arange(1, i + 1))
        for i in range(r + 1)
    )
    assert np.all(
        E <= np.maximum(tail, 0.0) * (1 + 1e-9) + 1e-12 * np.abs(expm(absA)).max()
    )
    np.testing.assert_array_equal(E, exp_remainder(A, dt, r))
