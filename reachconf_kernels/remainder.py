"""Lagrange remainders from interval derivative tensors (the generator's ``remainder="tensor"`` path).

The default path bounds the remainders by interval Taylor-mode arithmetic
(:mod:`reachconf_kernels.taylor`); these contractions serve the older path,
which generates the interval Hessian and third-order tensor symbolically, so
that both can be compared (``benchmarks/bench_codegen.py``, the tests).
Both functions have the calling convention of the generated remainder
functions: a direction box ``[dlo, dhi]`` (its magnitude ``dz = max(|dlo|,
|dhi|)`` is used) and one bound per state in ``out``.
"""

from __future__ import annotations

from numba import njit


@njit(cache=True)
def hessian_remainder(Hlo, Hhi, dlo, dhi, out):
    """``out_i = 1/2 sum_jk max|H_ijk| dz_j dz_k`` (H over the box, eq. of section 4.3.1)."""
    n, nz = Hlo.shape[0], Hlo.shape[1]
    for i in range(n):
        s = 0.0
        for j in range(nz):
            dzj = max(abs(dlo[j]), abs(dhi[j]))
            if dzj == 0.0:
                continue
            for k in range(nz):
                h = max(abs(Hlo[i, j, k]), abs(Hhi[i, j, k]))
                s += h * dzj * max(abs(dlo[k]), abs(dhi[k]))
        out[i] = 0.5 * s * (1.0 + 1e-12)


@njit(cache=True)
def third_order_remainder(Tlo, Thi, dlo, dhi, out):
    """``out_i = 1/6 sum_jkl max|T_ijkl| dz_j dz_k dz_l`` (T over the box)."""
    n, nz = Tlo.shape[0], Tlo.shape[1]
    for i in range(n):
        s = 0.0
        for j in range(nz):
            dzj = max(abs(dlo[j]), abs(dhi[j]))
            if dzj == 0.0:
                continue
            for k in range(nz):
                dzk = max(abs(dlo[k]), abs(dhi[k]))
                if dzk == 0.0:
                    continue
                for l in range(nz):
                    t = max(abs(Tlo[i, j, k, l]), abs(Thi[i, j, k, l]))
                    s += t * dzj * dzk * max(abs(dlo[l]), abs(dhi[l]))
        out[i] = s / 6.0 * (1.0 + 1e-12)
