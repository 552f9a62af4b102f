"""Source of the generated remainder function ``lagrange_iv`` (see :mod:`reachconf.model.codegen`).

Two ways to bound the Lagrange remainders of the linearisation (source
report section 4.3.1) over a box of points and a box of directions:

* :func:`taylor_section` (``remainder="taylor"``, the default): the tape of
  ``f`` (:mod:`reachconf.model.tape`) as module constants and a one-line
  ``lagrange_iv`` calling the Taylor-mode kernel
  :func:`reachconf_kernels.taylor.lagrange_bound`.  Only this wrapper is
  compiled per model, whatever the size of the derivative tensors.
* :func:`tensor_section` (``remainder="tensor"``): ``lagrange_iv`` contracting
  the generated interval Hessian ``hess_iv`` and third-order tensor
  ``third_iv`` (:mod:`reachconf_kernels.remainder`), the older path.
"""

from __future__ import annotations

from reachconf.model.tape import Tape, build_tape

__all__ = ["taylor_section", "tensor_section", "module_tape"]

_TAYLOR = '''TAPE_OPS = np.array({ops}, dtype=np.int64).reshape(({n_ops}, 7))
TAPE_CONSTS = np.array({consts}, dtype=np.float64).reshape(({n_consts}, 2))
TAPE_OUTS = np.array({outs}, dtype=np.int64).reshape(({n_forms}, {n}))
TAPE_TENS = np.array({tens}, dtype=np.int64).reshape(({n_tens}, 6))
TAPE_SEGMENTS = np.array({segments}, dtype=np.int64)


@nb.njit(IV_REMAINDER, cache=True)
def lagrange_iv(zlo, zhi, dlo, dhi, zp, dc, dG, p, order, out):
    return TM.lagrange_bound(TAPE_OPS, TAPE_CONSTS, TAPE_OUTS, TAPE_TENS, TAPE_SEGMENTS, zlo, zhi, dlo, dhi, zp, dc, dG,
                             p, order, out)

'''

_TENSOR = '''@nb.njit(IV_REMAINDER, cache=True)
def lagrange_iv(zlo, zhi, dlo, dhi, zp, dc, dG, p, order, out):
    n, nz = out.shape[0], zlo.shape[0]
    if order == 2:
        Hlo = np.zeros((n, nz, nz))
        Hhi = np.zeros((n, nz, nz))
        status = hess_iv(zlo, zhi, p, Hlo, Hhi)
        if status != 0:
            return status
        R.hessian_remainder(Hlo, Hhi, dlo, dhi, out)
        return 0
{third_body}
'''

_THIRD = '''    Tlo = np.zeros((n, nz, nz, nz))
    Thi = np.zeros((n, nz, nz, nz))
    status = third_iv(zlo, zhi, p, Tlo, Thi)
    if status != 0:
        return status
    R.third_order_remainder(Tlo, Thi, dlo, dhi, out)
    return 0'''


def taylor_section(f, z_symbols, p_symbols, moving, hess, third, guards: list) -> tuple[str, Tape]:
    """Module source holding the tape of ``f`` and its ``lagrange_iv``; and the tape.

    Parameters
    ----------
    f : sequence of sympy expressions
    z_symbols, p_symbols : the variables and parameters of ``f``
    moving : list of int
        Variables whose direction can be non-zero (not the known inputs).
    hess, third : dict
        Unique non-zero second and third derivatives (``(i, j, k)`` and
        ``(i, j, k, l)`` keys), recorded on the tape where they are small.
    guards : list of str
        Guard messages (appended to).
    """
    tape = build_tape(f, z_symbols, p_symbols, guards, directional=moving, tensors={2: hess, 3: third})
    source = _TAYLOR.format(
        ops=tape.ops.ravel().tolist(), n_ops=tape.size, consts=[float(v) for v in tape.consts.ravel()],
        n_consts=tape.consts.shape[0], outs=tape.outs.ravel().tolist(), n_forms=tape.outs.shape[0],
        n=tape.outs.shape[1], tens=tape.tens.ravel().tolist(), n_tens=tape.tens.shape[0],
        segments=tape.segments.tolist(),
    )  # fmt: skip
    return source, tape


def tensor_section(order: int, guards: list) -> str:
    """Module source of ``lagrange_iv`` over the generated ``hess_iv`` (and ``third_iv`` for ``order=3``)."""
    if order >= 3:
        return _TENSOR.format(third_body=_THIRD)
    guards.append("the third-order tensors were not built (compile_model(..., order=2, remainder='tensor'))")
    return _TENSOR.format(third_body=f"    return {len(guards)}")


def module_tape(module) -> Tape | None:
    """The tape a generated module holds (``None`` for a ``"tensor"`` build)."""
    if not hasattr(module, "TAPE_OPS"):
        return None
    return Tape(module.TAPE_OPS, module.TAPE_CONSTS, module.TAPE_OUTS, module.TAPE_TENS, module.TAPE_SEGMENTS)
