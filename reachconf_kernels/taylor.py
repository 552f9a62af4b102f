"""Interval Taylor-mode arithmetic on a tape: Lagrange remainders without derivative tensors.

A model's right-hand side ``f`` is recorded once as a *tape* (a list of
elementary operations, :mod:`reachconf.tape`).  This module evaluates the tape
in truncated Taylor arithmetic with interval coefficients: every variable
``z_j`` enters as the series ``[zlo_j, zhi_j] + [dlo_j, dhi_j] t`` and every
operation propagates the coefficients of ``t^0 .. t^K`` (``K <= 3``).  The
``K``-th coefficient of the output encloses

    g_K = D^K f_i(xi)[d, ..., d] / K!      for all xi in Z = [zlo, zhi], d in D = [dlo, dhi],

the coefficient of ``t^K`` in ``f_i(xi + t d)``.  With ``xi = p + tau d``
(``tau`` in [0, 1], so ``xi`` lies in ``Z`` whenever ``Z`` contains ``p`` and
``p + D``) this is the Lagrange remainder of the Taylor polynomial of degree
``K - 1`` of ``f`` at ``p``::

    f(p + d) = sum_{k < K} D^k f(p)[d, ..., d] / k!  +  D^K f(xi)[d, ..., d] / K!

``K = 2`` bounds the linearisation error (conservative linearisation,
source report section 4.3.1, ``1/2 dz^T H(xi) dz``) and ``K = 3`` the cubic
term of tensor order 3 (``1/6 sum T(xi) dz dz dz``) — without forming the
Hessian or the third-order tensor: the cost grows with the size of the
expression graph, not with ``nz^3``.

Rules: sums and products by coefficient (Cauchy products); a univariate
function ``phi(u)`` by Faa di Bruno's formula::

    y0 = phi(u0)
    y1 = phi'(u0) u1
    y2 = phi'(u0) u2 + phi''(u0) / 2 u1^2
    y3 = phi'(u0) u3 + phi''(u0) u1 u2 + phi'''(u0) / 6 u1^3

with tight enclosures of ``phi', phi'', phi'''`` over the interval ``u0``
(monotone pieces, extrema at the known critical points).  Every operation is
outward rounded (:mod:`reachconf_kernels.interval`), so the result is a sound
enclosure.  A domain error (division by an interval containing 0, ``log`` or
``sqrt`` at or below 0, ``tan`` across a pole, ``Abs``/``Min``/``Max`` switching
inside the set where derivatives are needed) returns the guard number stored
in the tape instead of raising.

Tape layout (``ops``, int64, one row per node, operands precede their users):
``[opcode, a, b, aux, deg, guard]``: operand rows ``a, b``; ``aux`` = constant
row, parameter index, variable index or integer exponent; ``deg`` = degree of
the node as a polynomial in ``t`` (3 = "3 or more"); ``guard`` = status to
return on a domain error (0: none).  ``consts`` (C, 2) holds outward-rounded
constant intervals; ``outs`` the node of each output.
"""

from __future__ import annotations


import numpy as np
from numba import njit, types

from reachconf_kernels import interval as I
from reachconf_kernels import taylor_rules as R

OP_CONST = 0
OP_PARAM = 1
OP_VAR = 2
OP_ADD = 3
OP_SUB = 4
OP_NEG = 5
OP_MUL = 6
OP_POWI = 7  # integer exponent in aux
OP_POWR = 8  # real exponent: interval consts[aux], base > 0
OP_SQRT = 9
OP_EXP = 10
OP_LOG = 11
OP_SIN = 12
OP_COS = 13
OP_TAN = 14
OP_ATAN = 15
OP_TANH = 16
OP_ABS = 17
OP_MIN = 18
OP_MAX = 19

#: columns of a tape row
COL_OP, COL_A, COL_B, COL_AUX, COL_DEG, COL_GUARD, COL_FLAG = 0, 1, 2, 3, 4, 5, 6
#: width of a tape row
TAPE_COLUMNS = 7
#: highest Taylor coefficient the kernel computes
MAX_ORDER = 3

# one signature for every caller (a literal order or start would compile the tape's interpreter again)
_RO = types.Array(types.int64, 2, "C", readonly=True), types.Array(types.float64, 2, "C", readonly=True)
_V, _M, _T = types.float64[::1], types.float64[:, ::1], types.float64[:, :, ::1]


@njit((*_RO, _V, _V, _V, _V, _V, types.int64, _T, _M, types.int64, types.int64, types.int64, _T), cache=True)
def evaluate(ops, consts, zlo, zhi, dlo, dhi, p, K, W, F, start, stop, max_deg, tight):
    """Fill ``W[node, k] = (lo, hi)`` of the nodes ``start`` to ``stop - 1``, coefficients ``k <= K``.

    Returns 0 or the guard number of a failed domain check.  ``W`` must be
    zero-initialised, shape (nodes, MAX_ORDER + 1, 2); ``F`` is scratch of
    shape (MAX_ORDER + 1, 2).  Operands must lie in the evaluated range.
    Nodes of a degree above ``max_deg`` are skipped.  ``tight`` (nodes, 2, 2),
    unless empty, holds enclosures of the coefficients 0 and 1 of the flagged
    nodes (:func:`affine_ranges`); they are intersected with the computed ones.
    """
    for i in range(start, stop):
        if ops[i, 4] > max_deg:
            continue
        op = ops[i, 0]
        a = ops[i, 1]
        b = ops[i, 2]
        aux = ops[i, 3]
        deg = ops[i, 4] if ops[i, 4] < K else K
        guard = ops[i, 5]
        da = ops[a, 4] if a >= 0 and ops[a, 4] < K else K
        db = ops[b, 4] if b >= 0 and ops[b, 4] < K else K
        if a < 0:
            da = 0
        if b < 0:
            db = 0
        if op == OP_CONST:
            W[i, 0, 0] = consts[aux, 0]
            W[i, 0, 1] = consts[aux, 1]
        elif op == OP_PARAM:
            W[i, 0, 0] = p[aux]
            W[i, 0, 1] = p[aux]
        elif op == OP_VAR:
            W[i, 0, 0] = zlo[aux]
            W[i, 0, 1] = zhi[aux]
            if deg >= 1:
                W[i, 1, 0] = dlo[aux]
                W[i, 1, 1] = dhi[aux]
        elif op == OP_ADD or op == OP_SUB:
            for k in range(deg + 1):
                blo = W[b, k, 0] if k <= db else 0.0
                bhi = W[b, k, 1] if k <= db else 0.0
                if k > da:
                    alo, ahi = 0.0, 0.0
                else:
                    alo, ahi = W[a, k, 0], W[a, k, 1]
                if op == OP_ADD:
                    if k > da:
                        W[i, k, 0], W[i, k, 1] = blo, bhi
                    elif k > db:
                        W[i, k, 0], W[i, k, 1] = alo, ahi
                    else:
                        W[i, k, 0], W[i, k, 1] = I.add(alo, ahi, blo, bhi)
                else:
                    if k > da:
                        W[i, k, 0], W[i, k, 1] = -bhi, -blo
                    elif k > db:
                        W[i, k, 0], W[i, k, 1] = alo, ahi
                    else:
                        W[i, k, 0], W[i, k, 1] = I.sub(alo, ahi, blo, bhi)
        elif op == OP_NEG:
            R.copy_series(W, i, a, deg, -1)
        elif op == OP_MUL:
            R.cauchy_product(W, i, a, b, da, db, deg)
        else:
            # univariate functions of row a: phi^(m)(u0) into F, then Faa di Bruno
            copied = False
            alo = W[a, 0, 0]
            ahi = W[a, 0, 1]
            smooth = deg >= 1  # derivatives needed
            if op == OP_POWI:
                if aux < 0 and alo <= 0.0 <= ahi:
                    return guard
                R.powi_derivatives(F, alo, ahi, aux, deg)
            elif op == OP_POWR:
                if alo <= 0.0:
                    return guard
                R.powr_derivatives(F, alo, ahi, consts[aux, 0], consts[aux, 1], deg)
            elif op == OP_SQRT:
                if alo < 0.0 or (smooth and alo <= 0.0):
                    return guard
                F[0, 0], F[0, 1] = I.sqrt(alo, ahi)
                if deg >= 1:
                    F[1, 0], F[1, 1] = I.div(0.5, 0.5, F[0, 0], F[0, 1])
                if deg >= 2:
                    sx = I.mul(F[0, 0], F[0, 1], alo, ahi)
                    q = I.div(0.25, 0.25, sx[0], sx[1])
                    F[2, 0], F[2, 1] = -q[1], -q[0]
                    if deg >= 3:
                        sxx = I.mul(sx[0], sx[1], alo, ahi)
                        F[3, 0], F[3, 1] = I.div(0.375, 0.375, sxx[0], sxx[1])
            elif op == OP_EXP:
                e = I.exp(alo, ahi)
                for m in range(deg + 1):
                    F[m, 0], F[m, 1] = e
            elif op == OP_LOG:
                if alo <= 0.0:
                    return guard
                F[0, 0], F[0, 1] = I.log(alo, ahi)
                if deg >= 1:
                    F[1, 0], F[1, 1] = I.div(1.0, 1.0, alo, ahi)
                if deg >= 2:
                    s = I.sqr(alo, ahi)
                    q = I.div(1.0, 1.0, s[0], s[1])
                    F[2, 0], F[2, 1] = -q[1], -q[0]
                if deg >= 3:
                    c = I.pow(alo, ahi, 3)
                    F[3, 0], F[3, 1] = I.div(2.0, 2.0, c[0], c[1])
            elif op == OP_SIN or op == OP_COS:
                s = I.sin(alo, ahi)
                c = I.cos(alo, ahi)
                # derivatives cycle sin -> cos -> -sin -> -cos
                for m in range(deg + 1):
                    phase = m if op == OP_SIN else m + 1
                    phase = phase % 4
                    if phase == 0:
                        F[m, 0], F[m, 1] = s
                    elif phase == 1:
                        F[m, 0], F[m, 1] = c
                    elif phase == 2:
                        F[m, 0], F[m, 1] = -s[1], -s[0]
                    else:
                        F[m, 0], F[m, 1] = -c[1], -c[0]
            elif op == OP_TAN:
                c = I.cos(alo, ahi)
                if c[0] <= 0.0 <= c[1]:
                    return guard
                s = I.sin(alo, ahi)
                tlo, thi = I.div(s[0], s[1], c[0], c[1])
                F[0, 0], F[0, 1] = tlo, thi
                q = I.sqr(tlo, thi)
                if deg >= 1:
                    F[1, 0], F[1, 1] = I.add(q[0], q[1], 1.0, 1.0)
                if deg >= 2:  # 2 t + 2 t^3, increasing in t
                    F[2, 0] = R.tan_second_derivative(tlo)[0]
                    F[2, 1] = R.tan_second_derivative(thi)[1]
                if deg >= 3:  # 2 + 8 s + 6 s^2, increasing in s = t^2 >= 0
                    q2 = I.sqr(q[0], q[1])
                    r1 = I.mul(8.0, 8.0, q[0], q[1])
                    r2 = I.mul(6.0, 6.0, q2[0], q2[1])
                    r = I.add(r1[0], r1[1], r2[0], r2[1])
                    F[3, 0], F[3, 1] = I.add(r[0], r[1], 2.0, 2.0)
            elif op == OP_ATAN:
                F[0, 0], F[0, 1] = I.atan(alo, ahi)
                if deg >= 1:
                    R.atan_derivatives(F, alo, ahi, deg)
            elif op == OP_TANH:
                tlo, thi = I.tanh(alo, ahi)
                F[0, 0], F[0, 1] = tlo, thi
                if deg >= 1:
                    R.tanh_derivatives(F, tlo, thi, deg)
            elif op == OP_ABS:
                if deg == 0:
                    F[0, 0], F[0, 1] = I.abs(alo, ahi)
                elif alo >= 0.0:
                    R.copy_series(W, i, a, deg, 1)
                    copied = True
                elif ahi <= 0.0:
                    R.copy_series(W, i, a, deg, -1)
                    copied = True
                else:
                    return guard
            elif op == OP_MIN or op == OP_MAX:
                blo = W[b, 0, 0]
                bhi = W[b, 0, 1]
                if deg == 0:
                    if op == OP_MIN:
                        F[0, 0], F[0, 1] = I.min(alo, ahi, blo, bhi)
                    else:
                        F[0, 0], F[0, 1] = I.max(alo, ahi, blo, bhi)
                else:
                    a_below = ahi <= blo
                    b_below = bhi <= alo
                    if not (a_below or b_below):
                        return guard
                    pick_a = a_below if op == OP_MIN else b_below
                    R.copy_series(W, i, a if pick_a else b, deg, 1)
                    copied = True
            if not copied:
                W[i, 0, 0] = F[0, 0]
                W[i, 0, 1] = F[0, 1]
                if deg >= 1:
                    R.faa_di_bruno(W, i, a, da, deg, F)
        if tight.shape[0] > 0 and ops[i, COL_FLAG] == 1:
            for k in range(2 if deg >= 1 else 1):
                if tight[i, k, 0] > W[i, k, 0]:
                    W[i, k, 0] = tight[i, k, 0]
                if tight[i, k, 1] < W[i, k, 1]:
                    W[i, k, 1] = tight[i, k, 1]
    return 0


@njit(cache=True)
def affine_ranges(ops, consts, stop, zp, dc, dG, p, W, F, tight):
    """Enclosures of the coefficients 0 and 1 of the flagged affine nodes over a zonotope.

    A flagged node is affine in the moving variables, ``y(z) = y(zp) + a . (z -
    zp)``, and feeds a nonlinear one.  Over the zonotope ``D = dc + dG [-1, 1]``
    of directions ``d = z - zp`` its coefficient 1, ``a . d``, lies in
    ``a . dc +- sum_g |a . dG_g|`` and its coefficient 0 (at ``zp + tau d``,
    ``tau`` in [0, 1]) in ``y(zp) + hull(that, 0)``: the correlations of the set
    are kept, where the box of ``D`` sums ``|a_j|`` times each coordinate's
    range.  The gradient ``a`` is propagated through the affine nodes with
    interval arithmetic; the sums over the generators are rounded with an a
    priori bound.  Writes ``tight[node, k] = (lo, hi)``; returns a status.
    """
    nz = zp.shape[0]
    ng = dG.shape[1]
    zero = np.zeros(nz)
    status = evaluate(ops, consts, zp, zp, zero, zero, p, 0, W, F, 0, stop, 1, np.zeros((0, 2, 2)))  # y(zp)
    if status != 0:
        return status
    A = np.zeros((stop, nz, 2))
    gamma = (nz + 2) * 2.220446049250313e-16
    for i in range(stop):
        if ops[i, 4] != 1:
            continue
        op = ops[i, 0]
        a = ops[i, 1]
        b = ops[i, 2]
        if op == OP_VAR:
            A[i, ops[i, 3], 0] = 1.0
            A[i, ops[i, 3], 1] = 1.0
        elif op == OP_NEG:
            for j in range(nz):
                A[i, j, 0], A[i, j, 1] = -A[a, j, 1], -A[a, j, 0]
        elif op == OP_ADD or op == OP_SUB:  # rows of degree-0 operands are zero
            for j in range(nz):
                if op == OP_ADD:
                    A[i, j, 0], A[i, j, 1] = I.add(A[a, j, 0], A[a, j, 1], A[b, j, 0], A[b, j, 1])
                else:
                    A[i, j, 0], A[i, j, 1] = I.sub(A[a, j, 0], A[a, j, 1], A[b, j, 0], A[b, j, 1])
        elif op == OP_MUL:  # one factor of degree 0, the other affine
            c, v = (a, b) if ops[a, 4] == 0 else (b, a)
            for j in range(nz):
                A[i, j, 0], A[i, j, 1] = I.mul(W[c, 0, 0], W[c, 0, 1], A[v, j, 0], A[v, j, 1])
        elif op == OP_ABS:
            sign = 1.0 if W[a, 0, 0] >= 0.0 else -1.0  # the branch at zp (the box pass checks it holds)
            for j in range(nz):
                if sign > 0:
                    A[i, j, 0], A[i, j, 1] = A[a, j, 0], A[a, j, 1]
                else:
                    A[i, j, 0], A[i, j, 1] = -A[a, j, 1], -A[a, j, 0]
        elif op == OP_MIN or op == OP_MAX:
            pick_a = (W[a, 0, 0] <= W[b, 0, 0]) == (op == OP_MIN)
            src = a if pick_a else b
            for j in range(nz):
                A[i, j, 0], A[i, j, 1] = A[src, j, 0], A[src, j, 1]
        else:
            return 0  # not an affine rule: leave the box enclosures alone
        if ops[i, COL_FLAG] != 1:
            continue
        # a . dc (interval) and R >= sum_g |a . dG_g| for every a in the interval gradient
        clo, chi = 0.0, 0.0
        am = np.empty(nz)
        ar = np.empty(nz)
        for j in range(nz):
            t = I.mul(A[i, j, 0], A[i, j, 1], dc[j], dc[j])
            clo, chi = I.add(clo, chi, t[0], t[1])
            am[j] = 0.5 * (A[i, j, 0] + A[i, j, 1])
            ar[j] = I.up(max(A[i, j, 1] - am[j], am[j] - A[i, j, 0]))
        radius = 0.0
        for g in range(ng):
            mid = 0.0
            mag = 0.0
            spread = 0.0
            for j in range(nz):
                v = am[j] * dG[j, g]
                mid += v
                mag += abs(v)
                spread += ar[j] * abs(dG[j, g])
            radius += abs(mid) + gamma * mag + spread  # float sum error of mid is below gamma * mag
        radius = I.up(radius * (1.0 + 2.0 * (ng + nz + 4) * 2.220446049250313e-16))
        lo1, hi1 = I.sub(clo, chi, radius, radius)
        hi1 = I.up(chi + radius)
        tight[i, 1, 0] = lo1
        tight[i, 1, 1] = hi1
        h0 = I.add(W[i, 0, 0], W[i, 0, 1], lo1 if lo1 < 0.0 else 0.0, hi1 if hi1 > 0.0 else 0.0)
        tight[i, 0, 0] = h0[0]
        tight[i, 0, 1] = h0[1]
    return 0


@njit(cache=True)
def lagrange_bound(ops, consts, outs, tens, segments, zlo, zhi, dlo, dhi, zp, dc, dG, p, K, out):
    """``out[i] >= |D^K f_i(xi)[d, ..., d]| / K!`` for all ``xi`` in [zlo, zhi], ``d`` in [dlo, dhi].

    ``zp`` is the expansion point and ``D = dc + dG [-1, 1]`` a zonotope of the
    directions ``d`` within the box (``dG`` with no columns: the box only);
    ``xi`` is taken from the segments ``zp + tau d``, which the box must
    contain.  The zonotope tightens the ranges of the affine sub-expressions
    that feed nonlinear ones (:func:`affine_ranges`).

    Two enclosures, the smaller kept per output:

    * Taylor mode: the ``t^K`` coefficient of the tape rows ``0 ..
      segments[0]-1``; ``outs`` (F, n) holds the node of each output in each
      of F recorded forms of the same function (each form is an enclosure);
    * the derivative tensor, where it was recorded: rows ``tens`` =
      ``[K, i, node, j, k, l]`` (``l = -1`` for K = 2) give the unique entries
      ``D_jk(l) f_i`` (evaluated over the box, rows ``segments[1] ..
      segments[2]-1`` for K = 2 and ``segments[3] .. segments[4]-1`` for K = 3)
      and ``sum mult * [D f_i] * [d_j][d_k]([d_l]) / K!`` encloses the same
      quantity; ``segments[5 + (K - 2) * n + i]`` is 1 when every non-zero
      entry of output ``i`` is recorded; ``segments[5 + 2 n]`` is 1 when the
      tape has flagged affine nodes.

    Returns 0 or the guard number of a failed domain check.
    """
    n = outs.shape[1]
    W = np.zeros((ops.shape[0], MAX_ORDER + 1, 2))
    F = np.zeros((MAX_ORDER + 1, 2))
    tight = np.zeros((0, 2, 2))
    if dG.shape[1] > 0 and segments[5 + 2 * n] == 1:
        tight = np.empty((segments[0], 2, 2))
        tight[:, :, 0] = -np.inf
        tight[:, :, 1] = np.inf
        status = affine_ranges(ops, consts, segments[0], zp, dc, dG, p, W, F, tight)
        if status != 0:
            return status
        W[:] = 0.0
    status = evaluate(ops, consts, zlo, zhi, dlo, dhi, p, K, W, F, 0, segments[0], MAX_ORDER, tight)
    if status != 0:
        return status
    for i in range(n):
        best = np.inf
        for f in range(outs.shape[0]):
            node = outs[f, i]
            m = 0.0 if ops[node, 4] < K else R.magnitude(W[node, K, 0], W[node, K, 1])
            if m != m:
                best = np.nan
                break
            if m < best:
                best = m
        out[i] = best
    start = segments[1] if K == 2 else segments[3]
    stop = segments[2] if K == 2 else segments[4]
    if stop > start:
        status = evaluate(ops, consts, zlo, zhi, dlo, dhi, p, 0, W, F, start, stop, MAX_ORDER, tight[:0])
        if status != 0:
            return status
        slo = np.zeros(n)
        shi = np.zeros(n)
        for e in range(tens.shape[0]):
            if tens[e, 0] != K:
                continue
            i = tens[e, 1]
            node = tens[e, 2]
            mlo, mhi, mult = R.direction_monomial(dlo, dhi, tens[e, 3], tens[e, 4], tens[e, 5])
            t = I.mul(W[node, 0, 0], W[node, 0, 1], mlo, mhi)
            t = I.mul(t[0], t[1], mult, mult)
            slo[i], shi[i] = I.add(slo[i], shi[i], t[0], t[1])
        scale = 0.5 if K == 2 else 1.0 / 6.0
        for i in range(n):
            if segments[5 + (K - 2) * n + i] == 1:
                m = R.magnitude(slo[i], shi[i])
                if m == m:
                    m = I.up(m * scale) if K == 2 else I.up(I.up(m / 6.0))
                    if m < out[i]:
                        out[i] = m
    return 0


@njit(cache=True)
def range_enclosure(ops, consts, outs, segments, zlo, zhi, p, outlo, outhi):
    """Interval evaluation of the outputs over the box ``[zlo, zhi]`` (the coefficient ``t^0``).

    The intersection of the enclosures of the recorded forms.
    """
    n = zlo.shape[0]
    W = np.zeros((ops.shape[0], MAX_ORDER + 1, 2))
    F = np.zeros((MAX_ORDER + 1, 2))
    zero = np.zeros(n)
    status = evaluate(ops, consts, zlo, zhi, zero, zero, p, 0, W, F, 0, segments[0], MAX_ORDER, np.zeros((0, 2, 2)))
    if status != 0:
        return status
    for i in range(outs.shape[1]):
        lo = -np.inf
        hi = np.inf
        for f in range(outs.shape[0]):
            node = outs[f, i]
            if W[node, 0, 0] > lo or W[node, 0, 0] != W[node, 0, 0]:
                lo = W[node, 0, 0]
            if W[node, 0, 1] < hi or W[node, 0, 1] != W[node, 0, 1]:
                hi = W[node, 0, 1]
        outlo[i] = lo
        outhi[i] = hi
    return 0


@njit(cache=True)
def coefficients(ops, consts, outs, segments, zlo, zhi, dlo, dhi, p, K, outlo, outhi):
    """Coefficients ``t^0`` to ``t^K`` of the outputs (first recorded form), shape (n, K + 1) each.

    For tests and diagnostics.
    """
    W = np.zeros((ops.shape[0], MAX_ORDER + 1, 2))
    F = np.zeros((MAX_ORDER + 1, 2))
    status = evaluate(ops, consts, zlo, zhi, dlo, dhi, p, K, W, F, 0, segments[0], MAX_ORDER, np.zeros((0, 2, 2)))
    if status != 0:
        return status
    for i in range(outs.shape[1]):
        for k in range(K + 1):
            outlo[i, k] = W[outs[0, i], k, 0]
            outhi[i, k] = W[outs[0, i], k, 1]
    return 0
