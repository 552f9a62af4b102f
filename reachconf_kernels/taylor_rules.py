"""Taylor rules of :mod:`reachconf_kernels.taylor`: products, Faa di Bruno, derivative ranges.

Each univariate function ``phi`` contributes the enclosures of ``phi^(m)(u0)``
over the interval ``u0`` (``m = 0 .. K``), tight where the derivative is
monotone on pieces with known critical points (``tanh``, ``atan``, ``tan``,
integer and real powers); :func:`faa_di_bruno` combines them with the
coefficients of the argument.  Tape rows live in ``W[node, k] = (lo, hi)``.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from reachconf_kernels import interval as I

_INV_SQRT3 = 0.5773502691896258  # 1/sqrt(3), within 1 ulp
_TWO_THIRDS = 0.6666666666666666


@njit(cache=True)
def _hull_into(F, m, lo, hi, first):
    if first or lo < F[m, 0]:
        F[m, 0] = lo
    if first or hi > F[m, 1]:
        F[m, 1] = hi


@njit(cache=True)
def _around(c):
    """An interval that contains the real number whose float approximation (within 2 ulp) is c."""
    return I.down(I.down(c)), I.up(I.up(c))


@njit(cache=True)
def _tanh_d2(tlo, thi):
    """Enclosure of 2 t^3 - 2 t (tanh'' in terms of t = tanh) over [tlo, thi]."""
    clo, chi = I.pow(tlo, thi, 3)
    a = I.mul(2.0, 2.0, clo, chi)
    b = I.mul(2.0, 2.0, tlo, thi)
    return I.sub(a[0], a[1], b[0], b[1])


@njit(cache=True)
def tan_second_derivative(t):
    """Enclosure of 2 t + 2 t^3 (tan'' in terms of t = tan) at the point t."""
    c = I.pow(t, t, 3)
    a = I.add(t, t, c[0], c[1])
    return I.mul(2.0, 2.0, a[0], a[1])


@njit(cache=True)
def _tanh_d3(slo, shi):
    """Enclosure of -2 + 8 s - 6 s^2 (tanh''' in terms of s = tanh^2) over [slo, shi]."""
    qlo, qhi = I.sqr(slo, shi)
    a = I.mul(8.0, 8.0, slo, shi)
    b = I.mul(6.0, 6.0, qlo, qhi)
    c = I.sub(a[0], a[1], b[0], b[1])
    return I.add(c[0], c[1], -2.0, -2.0)


@njit(cache=True)
def _atan_d2(xlo, xhi):
    """Enclosure of -2 x / (1 + x^2)^2 (atan'') over [xlo, xhi]."""
    s = I.sqr(xlo, xhi)
    w = I.add(s[0], s[1], 1.0, 1.0)
    w2 = I.sqr(w[0], w[1])
    num = I.mul(-2.0, -2.0, xlo, xhi)
    return I.div(num[0], num[1], w2[0], w2[1])


@njit(cache=True)
def _atan_d3(slo, shi):
    """Enclosure of (6 s - 2) / (1 + s)^3 (atan''' in terms of s = x^2) over [slo, shi]."""
    num = I.mul(6.0, 6.0, slo, shi)
    num = I.add(num[0], num[1], -2.0, -2.0)
    w = I.add(slo, shi, 1.0, 1.0)
    w3 = I.pow(w[0], w[1], 3)
    return I.div(num[0], num[1], w3[0], w3[1])


@njit(cache=True)
def tanh_derivatives(F, tlo, thi, K):
    """phi', phi'', phi''' of tanh from the range [tlo, thi] of tanh(u0)."""
    s = I.sqr(tlo, thi)
    d1 = I.sub(1.0, 1.0, s[0], s[1])
    F[1, 0] = d1[0] if d1[0] > 0.0 else 0.0
    F[1, 1] = d1[1] if d1[1] < 1.0 else 1.0
    if K >= 2:  # 2 t^3 - 2 t: extrema at the ends and at t = +-1/sqrt(3)
        lo, hi = _tanh_d2(tlo, tlo)
        _hull_into(F, 2, lo, hi, True)
        lo, hi = _tanh_d2(thi, thi)
        _hull_into(F, 2, lo, hi, False)
        clo, chi = _around(_INV_SQRT3)
        if chi >= tlo and clo <= thi:
            lo, hi = _tanh_d2(clo, chi)
            _hull_into(F, 2, lo, hi, False)
        if -clo >= tlo and -chi <= thi:
            lo, hi = _tanh_d2(-chi, -clo)
            _hull_into(F, 2, lo, hi, False)
    if K >= 3:  # -2 + 8 s - 6 s^2 in s = t^2: extremum at s = 2/3
        slo = s[0] if s[0] > 0.0 else 0.0
        shi = s[1] if s[1] < 1.0 else 1.0
        lo, hi = _tanh_d3(slo, slo)
        _hull_into(F, 3, lo, hi, True)
        lo, hi = _tanh_d3(shi, shi)
        _hull_into(F, 3, lo, hi, False)
        clo, chi = _around(_TWO_THIRDS)
        if chi >= slo and clo <= shi:
            lo, hi = _tanh_d3(clo, chi)
            _hull_into(F, 3, lo, hi, False)


@njit(cache=True)
def atan_derivatives(F, xlo, xhi, K):
    """Derivatives 1 to K of atan over [xlo, xhi] into rows 1 to K of ``F``."""
    w = I.sqr(xlo, xhi)
    w = I.add(w[0], w[1], 1.0, 1.0)
    F[1, 0], F[1, 1] = I.div(1.0, 1.0, w[0], w[1])
    if K >= 2:  # extrema at the ends and at x = +-1/sqrt(3)
        lo, hi = _atan_d2(xlo, xlo)
        _hull_into(F, 2, lo, hi, True)
        lo, hi = _atan_d2(xhi, xhi)
        _hull_into(F, 2, lo, hi, False)
        clo, chi = _around(_INV_SQRT3)
        if chi >= xlo and clo <= xhi:
            lo, hi = _atan_d2(clo, chi)
            _hull_into(F, 2, lo, hi, False)
        if -clo >= xlo and -chi <= xhi:
            lo, hi = _atan_d2(-chi, -clo)
            _hull_into(F, 2, lo, hi, False)
    if K >= 3:  # (6 s - 2) / (1 + s)^3 in s = x^2: extremum at s = 1
        s = I.sqr(xlo, xhi)
        lo, hi = _atan_d3(s[0], s[0])
        _hull_into(F, 3, lo, hi, True)
        lo, hi = _atan_d3(s[1], s[1])
        _hull_into(F, 3, lo, hi, False)
        if s[0] <= 1.0 <= s[1]:
            lo, hi = _atan_d3(1.0, 1.0)
            _hull_into(F, 3, lo, hi, False)


@njit(cache=True)
def powi_derivatives(F, alo, ahi, k, K):
    """phi^(m) = k (k-1) ... (k-m+1) x^(k-m), m = 0..K (x must not contain 0 when k < m)."""
    F[0, 0], F[0, 1] = I.pow(alo, ahi, k)
    c = 1.0
    for m in range(1, K + 1):
        c *= k - m + 1  # exact: small integers
        if c == 0.0:
            F[m, 0] = 0.0
            F[m, 1] = 0.0
        else:
            plo, phi = I.pow(alo, ahi, k - m)
            F[m, 0], F[m, 1] = I.mul(c, c, plo, phi)


@njit(cache=True)
def powr_derivatives(F, alo, ahi, elo, ehi, K):
    """phi^(m) = e (e-1) ... (e-m+1) x^(e-m) = ... exp((e-m) log x), x > 0, interval exponent e."""
    llo, lhi = I.log(alo, ahi)
    clo, chi = 1.0, 1.0
    for m in range(K + 1):
        if m > 0:
            f = I.sub(elo, ehi, m - 1.0, m - 1.0)
            clo, chi = I.mul(clo, chi, f[0], f[1])
        em = I.sub(elo, ehi, float(m), float(m))
        q = I.mul(em[0], em[1], llo, lhi)
        x = I.exp(q[0], q[1])
        F[m, 0], F[m, 1] = I.mul(clo, chi, x[0], x[1])


@njit(cache=True)
def faa_di_bruno(W, i, a, dega, K, F):
    """Coefficients of phi(u(t)) from those of u (row a) and phi^(m)(u0) in F (rows 1..K)."""
    if K >= 1:
        W[i, 1, 0], W[i, 1, 1] = I.mul(F[1, 0], F[1, 1], W[a, 1, 0], W[a, 1, 1])
    if K >= 2:
        s = I.sqr(W[a, 1, 0], W[a, 1, 1])
        h = I.mul(F[2, 0], F[2, 1], 0.5, 0.5)
        lo, hi = I.mul(h[0], h[1], s[0], s[1])
        if dega >= 2:
            t = I.mul(F[1, 0], F[1, 1], W[a, 2, 0], W[a, 2, 1])
            lo, hi = I.add(lo, hi, t[0], t[1])
        W[i, 2, 0], W[i, 2, 1] = lo, hi
    if K >= 3:
        c = I.pow(W[a, 1, 0], W[a, 1, 1], 3)
        h = I.div(F[3, 0], F[3, 1], 6.0, 6.0)
        lo, hi = I.mul(h[0], h[1], c[0], c[1])
        if dega >= 2:
            t = I.mul(W[a, 1, 0], W[a, 1, 1], W[a, 2, 0], W[a, 2, 1])
            t = I.mul(F[2, 0], F[2, 1], t[0], t[1])
            lo, hi = I.add(lo, hi, t[0], t[1])
        if dega >= 3:
            t = I.mul(F[1, 0], F[1, 1], W[a, 3, 0], W[a, 3, 1])
            lo, hi = I.add(lo, hi, t[0], t[1])
        W[i, 3, 0], W[i, 3, 1] = lo, hi


@njit(cache=True)
def cauchy_product(W, i, a, b, da, db, K):
    """Cauchy product of rows a and b up to coefficient K (skipping structurally zero terms)."""
    for k in range(K + 1):
        first = True
        lo = 0.0
        hi = 0.0
        for j in range(k + 1):
            if j > da or k - j > db:
                continue
            plo, phi = I.mul(W[a, j, 0], W[a, j, 1], W[b, k - j, 0], W[b, k - j, 1])
            if first:
                lo, hi = plo, phi
                first = False
            else:
                lo, hi = I.add(lo, hi, plo, phi)
        W[i, k, 0] = lo
        W[i, k, 1] = hi


@njit(cache=True)
def copy_series(W, i, a, K, sign):
    """Row ``i`` = row ``a`` (``sign > 0``) or its negation, coefficients 0 to K."""
    for k in range(K + 1):
        if sign > 0:
            W[i, k, 0] = W[a, k, 0]
            W[i, k, 1] = W[a, k, 1]
        else:
            W[i, k, 0] = -W[a, k, 1]
            W[i, k, 1] = -W[a, k, 0]


@njit(cache=True)
def magnitude(lo, hi):
    """``max(|lo|, |hi|)``; NaN if a bound is NaN."""
    if lo != lo or hi != hi:
        return np.nan
    a = -lo if lo < 0.0 else lo
    b = -hi if hi < 0.0 else hi
    return a if a > b else b


@njit(cache=True)
def direction_monomial(dlo, dhi, j, k, l):
    """Enclosure of ``d_j d_k`` (``l < 0``) or ``d_j d_k d_l`` and the number of distinct index orders."""
    if l < 0:
        if j == k:
            lo, hi = I.sqr(dlo[j], dhi[j])
            return lo, hi, 1.0
        lo, hi = I.mul(dlo[j], dhi[j], dlo[k], dhi[k])
        return lo, hi, 2.0
    if j == k and k == l:
        lo, hi = I.pow(dlo[j], dhi[j], 3)
        return lo, hi, 1.0
    if j == k or k == l or j == l:
        a = j if (j == k or j == l) else k  # the repeated index
        b = l if j == k else (k if j == l else j)
        s = I.sqr(dlo[a], dhi[a])
        lo, hi = I.mul(s[0], s[1], dlo[b], dhi[b])
        return lo, hi, 3.0
    q = I.mul(dlo[j], dhi[j], dlo[k], dhi[k])
    lo, hi = I.mul(q[0], q[1], dlo[l], dhi[l])
    return lo, hi, 6.0
