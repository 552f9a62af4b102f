"""Pure, numba-compiled kernels of reachconf: the only place with hot loops.

Every function here is ``@numba.njit(cache=True)`` and works on plain float64
arrays: no classes, no I/O, no Python objects.  The user-facing classes in
:mod:`reachconf.sets` validate their input and call these kernels.

Array conventions (decided once, used everywhere)
-------------------------------------------------
Intervals
    Two separate float64 arrays ``lo`` and ``hi`` of equal shape, ``lo <= hi``.
    Scalar interval kernels (:mod:`reachconf_kernels.interval`) take the bounds
    of each operand as separate scalars and return a tuple ``(lo, hi)``::

        lo, hi = interval.mul(alo, ahi, blo, bhi)

    This is the calling convention of generated model code (one pair of local
    variables per sub-expression).  Results are outward rounded: the exact real
    result of the operation on any reals in the operands lies in ``[lo, hi]``.
Zonotopes
    A centre ``c`` of shape ``(n,)`` and a generator matrix ``G`` of shape
    ``(n, m)``, ``m >= 0``, both C-contiguous float64:
    ``Z = {c + G @ b | b in [-1, 1]^m}``.
Points
    Batches of points are ``(N, n)`` arrays, one point per row.
"""

from reachconf_kernels import cache_stamp

cache_stamp.drop_stale_caches()  # numba does not notice a changed callee in another module (see cache_stamp)
