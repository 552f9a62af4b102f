"""Numba signatures of generated model functions.

Generated model code (:mod:`reachconf.codegen`) compiles every function with one
of these explicit signatures, and the reachability kernels take them as
first-class function arguments (:class:`numba.types.FunctionType`).  Because
the kernel signature does not depend on the model, one compiled (and
disk-cached) reach loop serves every model.

Conventions: ``z = (x, u, w)`` stacked, ``p`` the parameter vector.  Point
functions write into ``out``; interval functions take ``zlo, zhi`` and write
``outlo, outhi``, returning an ``int64`` status (0 = ok, k > 0 = a domain error
in the k-th guarded operation, e.g. a division by an interval containing 0).
Tensor outputs must be zero-initialised by the caller: generated code writes
only the structurally non-zero entries.

The reach kernels call the model's remainder function ``lagrange_iv``
(:data:`IV_REMAINDER`): for a box ``Z = [zlo, zhi]`` of points, a box
``D = [dlo, dhi]`` of directions and an order ``K`` (2 or 3: the Lagrange
remainders of conservative linearisation and of tensor order 3) it writes,
per state, a bound of ``|D^K f(xi)[d, ..., d]| / K!`` over ``d`` in ``D`` and
``xi`` on the segments from the expansion point ``zp`` to ``zp + d``, which
``Z`` must contain.  ``dc + dG [-1, 1]``, a zonotope within ``D`` holding every
direction (``dG`` may have no columns), keeps the correlations of the set.
The known inputs are fixed (their direction is not read).
"""

from numba import types

f8_1 = types.float64[::1]
f8_2 = types.float64[:, ::1]
f8_3 = types.float64[:, :, ::1]
f8_4 = types.float64[:, :, :, ::1]

#: ``f(z, p, out)``, ``h(z, p, out)``
POINT_VEC = types.void(f8_1, f8_1, f8_1)
#: ``jac(z, p, out)`` with ``out`` of shape (rows, nz)
POINT_MAT = types.void(f8_1, f8_1, f8_2)
#: ``hess(z, p, out)`` with ``out`` of shape (rows, nz, nz)
POINT_T3 = types.void(f8_1, f8_1, f8_3)
#: ``third(z, p, out)`` with ``out`` of shape (rows, nz, nz, nz)
POINT_T4 = types.void(f8_1, f8_1, f8_4)
#: ``f_iv(zlo, zhi, p, outlo, outhi) -> status``
IV_VEC = types.int64(f8_1, f8_1, f8_1, f8_1, f8_1)
#: ``jac_h_iv(zlo, zhi, p, outlo, outhi) -> status`` (matrix output)
IV_MAT = types.int64(f8_1, f8_1, f8_1, f8_2, f8_2)
#: ``hess_iv(zlo, zhi, p, outlo, outhi) -> status``
IV_T3 = types.int64(f8_1, f8_1, f8_1, f8_3, f8_3)
#: ``third_iv(zlo, zhi, p, outlo, outhi) -> status``
IV_T4 = types.int64(f8_1, f8_1, f8_1, f8_4, f8_4)

#: ``lagrange_iv(zlo, zhi, dlo, dhi, zp, dc, dG, p, order, out) -> status``
IV_REMAINDER = types.int64(f8_1, f8_1, f8_1, f8_1, f8_1, f8_1, f8_2, f8_1, types.int64, f8_1)

FN_POINT_VEC = types.FunctionType(POINT_VEC)
FN_POINT_MAT = types.FunctionType(POINT_MAT)
FN_POINT_T3 = types.FunctionType(POINT_T3)
FN_POINT_T4 = types.FunctionType(POINT_T4)
FN_IV_VEC = types.FunctionType(IV_VEC)
FN_IV_MAT = types.FunctionType(IV_MAT)
FN_IV_T3 = types.FunctionType(IV_T3)
FN_IV_T4 = types.FunctionType(IV_T4)
FN_IV_REMAINDER = types.FunctionType(IV_REMAINDER)
