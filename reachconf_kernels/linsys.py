"""One step of linear reachability with uncertain inputs (CORA's ``linearSys``).

For ``x' = A x + u_c + u(t)``, ``u(t) in U`` over a step ``dt`` with ``r``
Taylor terms (notation of ``../shared/research/cora.md`` section 1):

* ``e^{A dt}`` truncated after ``r`` terms plus an entry-wise remainder
  ``E = [-Wr, Wr]``, ``Wr = |e^{|A| dt} - sum_{i<=r} (|A| dt)^i / i!|``;
* the state correction ``F`` (curvature of trajectories inside the step) and
  the input correction ``G``, both interval matrices;
* particular solutions for the constant input ``u_c`` and the time-varying
  input set ``U``.

Interval matrices are returned as a centre/radius pair ``(M, R)`` meaning
``[M - R, M + R]``.  All bounds that enter a set are inflated by a relative
``ROUND`` to cover floating-point rounding of the float computations (the
matrices are small and well scaled; the inflation is many orders of
magnitude above the accumulated rounding of ``r <= 10`` terms).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from reachconf_kernels.small_linalg import abs_terms_times, mat_mat, mat_vec

#: Relative inflation applied to computed remainder bounds (rounding allowance).
ROUND = 1e-12


@njit(cache=True)
def _factorial(k):
    out = 1.0
    for i in range(2, k + 1):
        out *= i
    return out


@njit(cache=True)
def taylor_powers(A, dt, r):
    """Powers ``A^i dt^i / i!`` for ``i = 0..r+1`` as an array (r+2, n, n)."""
    n = A.shape[0]
    P = np.empty((r + 2, n, n))
    P[0] = np.eye(n)
    for i in range(1, r + 2):
        s = dt / i
        for a in range(n):
            for b in range(n):
                acc = 0.0
                for k in range(n):
                    acc += P[i - 1, a, k] * A[k, b]
                P[i, a, b] = acc * s
    return P


@njit(cache=True)
def _next_term(term, absA, i, out):
    """``out = (term @ absA) / i``."""
    n = term.shape[0]
    for a in range(n):
        for b in range(n):
            acc = 0.0
            for k in range(n):
                acc += term[a, k] * absA[k, b]
            out[a, b] = acc / i


@njit(cache=True)
def exp_remainder(A, dt, r):
    """Entry-wise bound ``Wr >= |e^{A dt} - sum_{i<=r} (A dt)^i / i!|`` (CORA's ``E``).

    Computed as ``sum_{i>r} (|A| dt)^i / i!`` by summing 40 more terms and
    bounding the tail geometrically.
    """
    n = A.shape[0]
    absA = np.abs(A) * dt
    term = np.eye(n)
    nxt = np.empty((n, n))
    for i in range(1, r + 1):
        _next_term(term, absA, i, nxt)
        term, nxt = nxt, term
    W = np.zeros((n, n))
    # an entry of term @ absA is at most max(term) times a column sum of absA: the larger of the column and row
    # norms bounds the ratio of consecutive terms' largest entries
    norm = 0.0
    for i in range(n):
        s = 0.0
        sc = 0.0
        for j in range(n):
            s += absA[i, j]
            sc += absA[j, i]
        norm = max(norm, s, sc)
    for i in range(r + 1, r + 41):
        _next_term(term, absA, i, nxt)
        term, nxt = nxt, term
        for a in range(n):
            for b in range(n):
                W[a, b] += term[a, b]
    # tail i > r + 40: geometric bound with ratio norm / (r + 42)
    ratio = norm / (r + 42)
    tmax = 0.0
    for i in range(n):
        for j in range(n):
            tmax = max(tmax, term[i, j])
    if ratio < 1.0:
        W += tmax * norm / (r + 41) / (1.0 - ratio)
    else:
        W[:, :] = np.inf
    return W * (1.0 + ROUND) + 1e-300


@njit(cache=True)
def linear_step_matrices(A, dt, r):
    """Matrices of one linear step.

    Returns
    -------
    eAt : (n, n) truncated exponential ``sum_{i<=r} (A dt)^i / i!``
    E : (n, n) remainder radius (``e^{A dt} in eAt + [-E, E]``)
    T : (r+1, n, n) ``A^i dt^(i+1) / (i+1)!`` for the particular solutions
    F_c, F_r : centre/radius of the state correction interval matrix
    G_c, G_r : centre/radius of the input correction interval matrix
    """
    n = A.shape[0]
    P = taylor_powers(A, dt, r)  # P[i] = A^i dt^i / i!
    eAt = np.zeros((n, n))
    for i in range(r + 1):
        eAt += P[i]
    E = exp_remainder(A, dt, r)
    T = np.empty((r + 1, n, n))
    for i in range(r + 1):
        T[i] = P[i] * (dt / (i + 1))
    # F = sum_{i=2..r} [(i^{-i/(i-1)} - i^{-1/(i-1)}) dt^i / i!, 0] A^i + E
    F_lo = -E.copy()
    F_hi = E.copy()
    for i in range(2, r + 1):
        a = i ** (-i / (i - 1.0)) - i ** (-1.0 / (i - 1.0))  # negative
        for j in range(n):
            for k in range(n):
                v = a * P[i, j, k]
                if v < 0.0:
                    F_lo[j, k] += v
                else:
                    F_hi[j, k] += v
    # G = sum_{i=2..r+1} [(...) dt^i / i!, 0] A^{i-1} + E dt
    G_lo = -E * dt
    G_hi = E * dt
    for i in range(2, r + 2):
        a = i ** (-i / (i - 1.0)) - i ** (-1.0 / (i - 1.0))
        # A^{i-1} dt^i / i! = P[i-1] * dt / i
        for j in range(n):
            for k in range(n):
                v = a * P[i - 1, j, k] * dt / i
                if v < 0.0:
                    G_lo[j, k] += v
                else:
                    G_hi[j, k] += v
    F_c = 0.5 * (F_lo + F_hi)
    F_r = (0.5 * (F_hi - F_lo)) * (1.0 + ROUND)
    G_c = 0.5 * (G_lo + G_hi)
    G_r = (0.5 * (G_hi - G_lo)) * (1.0 + ROUND)
    return eAt, E, T, F_c, F_r, G_c, G_r


@njit(cache=True)
def interval_matrix_times_zonotope(M_c, M_r, c, G):
    """Enclosure of ``[M_c - M_r, M_c + M_r] Z`` as ``(c', G', box_radius)``.

    The result is ``M_c Z`` plus a box of radius ``M_r (|c| + sum|g|)``.
    """
    n = c.shape[0]
    cc = mat_vec(M_c, c)
    GG = mat_mat(M_c, G)
    absz = np.abs(c).copy()
    for j in range(G.shape[1]):
        for i in range(n):
            absz[i] += abs(G[i, j])
    rad = mat_vec(M_r, absz) * (1.0 + ROUND)
    # rounding of the float products M_c Z
    for i in range(n):
        s = 0.0
        for k in range(M_c.shape[1]):
            s += abs(M_c[i, k]) * absz[k]
        rad[i] += s * 4e-16 * (M_c.shape[1] + 1)
    return cc, GG, rad


@njit(cache=True)
def interval_matrix_times_vector(M_c, M_r, v):
    """Box ``(centre, radius)`` enclosing ``[M_c - M_r, M_c + M_r] v``."""
    cc = mat_vec(M_c, v)
    rad = mat_vec(M_r, np.abs(v))
    n = cc.shape[0]
    for i in range(n):
        s = 0.0
        for k in range(v.shape[0]):
            s += abs(M_c[i, k] * v[k])
        rad[i] = rad[i] * (1.0 + ROUND) + s * 4e-16 * (v.shape[0] + 1)
    return cc, rad


@njit(cache=True)
def particular_constant(T, E, dt, u):
    """Particular solution for a constant input ``u``: ``(centre, box radius)``.

    ``P^u = sum_i T_i u + [-E dt, E dt] u``.
    """
    n = T.shape[1]
    c = np.zeros(n)
    absu = np.abs(u)
    for i in range(T.shape[0]):
        c += mat_vec(T[i], u)
    rad = mat_vec(E * dt, absu)
    s = abs_terms_times(T, absu)
    rad = rad * (1.0 + ROUND) + s * 4e-16 * (T.shape[0] * n + 1)
    return c, rad


@njit(cache=True)
def particular_varying(T, E, dt, c, G, keep_terms=-1):
    """Particular solution for a time-varying input ``u(t) in Z(c, G)``.

    ``P^U = (+)_i T_i Z  (+)  [-E dt, E dt] Z`` term by term (never factored).
    ``keep_terms >= 0``: the generators of the terms ``i >= keep_terms`` are
    boxed at once (their per-axis absolute sums join the box radius) instead
    of being returned; ``-1`` keeps every term's generators.
    Returns ``(centre, generators, box radius)``.
    """
    n = T.shape[1]
    m = G.shape[1]
    terms = T.shape[0]
    kept = terms if keep_terms < 0 else min(terms, keep_terms)
    cc = np.zeros(n)
    GG = np.empty((n, kept * m))
    boxed = np.zeros(n)
    for i in range(terms):
        cc += mat_vec(T[i], c)
        TG = mat_mat(T[i], G)
        if i < kept:
            GG[:, i * m : (i + 1) * m] = TG
        else:
            for j in range(m):
                for r in range(n):
                    boxed[r] += abs(TG[r, j])
    absz = np.abs(c).copy()
    for j in range(m):
        for i in range(n):
            absz[i] += abs(G[i, j])
    rad = mat_vec(E * dt, absz)
    s = abs_terms_times(T, absz)
    # the boxed sums carry the summation's rounding (m + n terms) on top of the products' (the s term)
    rad = rad * (1.0 + ROUND) + boxed * (1.0 + 4e-16 * (m + n + 2)) + s * 4e-16 * (n + 2)
    return cc, GG, rad
