"""Products of the small matrices of one reachability step, as plain loops.

The matrices of a step are a few states wide.  For them numba's ``@`` (a BLAS
call) costs far more than the arithmetic: the call itself, the atomic
reference counting of its array arguments and temporaries, and the BLAS
thread pool waking up.  Measured on Van der Pol (2 states, 10,865 steps):
those three took 40 % of the run.  The loops below sum in index order; the
callers' rounding allowances (``4e-16`` per term and dimension, see
:mod:`reachconf_kernels.linsys`) bound the error of any summation order.
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def mat_mat(A, B):
    """``A @ B`` for ``A`` (n, k) and ``B`` (k, m)."""
    n, k = A.shape
    m = B.shape[1]
    out = np.zeros((n, m))
    for i in range(n):
        for r in range(k):
            a = A[i, r]
            for j in range(m):
                out[i, j] += a * B[r, j]
    return out


@njit(cache=True)
def mat_vec(A, x):
    """``A @ x`` for ``A`` (n, k) and ``x`` (k,)."""
    n, k = A.shape
    out = np.empty(n)
    for i in range(n):
        s = 0.0
        for r in range(k):
            s += A[i, r] * x[r]
        out[i] = s
    return out


@njit(cache=True)
def abs_terms_times(T, x):
    """``sum_i |T[i]| @ x`` for ``T`` (terms, n, k) and ``x`` (k,), summed term by term in order."""
    terms, n, k = T.shape
    out = np.empty(n)
    for a in range(n):
        total = 0.0
        for i in range(terms):
            s = 0.0
            for r in range(k):
                s += abs(T[i, a, r]) * x[r]
            total += s
        out[a] = total
    return out


@njit(cache=True)
def abs_row_sums_of_product(A, B):
    """``|A @ B|.sum(axis=1)`` for ``A`` (n, k) and ``B`` (k, m), without the (n, m) temporary."""
    n, k = A.shape
    m = B.shape[1]
    out = np.zeros(n)
    for i in range(n):
        for j in range(m):
            s = 0.0
            for r in range(k):
                s += A[i, r] * B[r, j]
            out[i] += abs(s)
    return out
