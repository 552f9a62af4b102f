"""Elementwise outward-rounded interval arithmetic on ``(lo, hi)`` arrays.

Each function applies the scalar kernel of :mod:`reachconf_kernels.interval`
to every element of equally shaped (1-D, contiguous) bound arrays and returns
``(lo, hi)`` arrays; the same soundness guarantees hold element by element::

    lo, hi = mul(alo, ahi, blo, bhi)
"""

from __future__ import annotations

import numpy as np
from numba import njit

from reachconf_kernels import interval as iv

__all__ = ["add", "sub", "mul", "div", "min", "max", "neg", "sqr", "sqrt", "exp", "log", "sin", "cos", "tan", "atan", "tanh", "abs", "pow"]


@njit(cache=True)
def add(alo, ahi, blo, bhi):
    """``[a] + [b]``, outward rounded (elementwise on ``lo, hi`` arrays)."""
    lo = np.empty_like(alo)
    hi = np.empty_like(alo)
    for i in range(alo.shape[0]):
        lo[i], hi[i] = iv.add(alo[i], ahi[i], blo[i], bhi[i])
    return lo, hi

@njit(cache=True)
def sub(alo, ahi, blo, bhi):
    """``[a] - [b]``, outward rounded (elementwise on ``lo, hi`` arrays)."""
    lo = np.empty_like(alo)
    hi = np.empty_like(alo)
    for i in range(alo.shape[0]):
        lo[i], hi[i] = iv.sub(alo[i], ahi[i], blo[i], bhi[i])
    return lo, hi

@njit(cache=True)
def mul(alo, ahi, blo, bhi):
    """``[a] * [b]``, outward rounded (``0 * inf = 0``) (elementwise on ``lo, hi`` arrays)."""
    lo = np.empty_like(alo)
    hi = np.empty_like(alo)
    for i in range(alo.shape[0]):
        lo[i], hi[i] = iv.mul(alo[i], ahi[i], blo[i], bhi[i])
    return lo, hi

@njit(cache=True)
def div(alo, ahi, blo, bhi):
    """``[a] / [b]``, outward rounded; ``ZeroDivisionError`` if ``[b]`` contains 0 (elementwise on ``lo, hi`` arrays)."""
    lo = np.empty_like(alo)
    hi = np.empty_like(alo)
    for i in range(alo.shape[0]):
        lo[i], hi[i] = iv.div(alo[i], ahi[i], blo[i], bhi[i])
    return lo, hi

@njit(cache=True)
def min(alo, ahi, blo, bhi):
    """Elementwise minimum ``min([a], [b])`` (exact) (elementwise on ``lo, hi`` arrays)."""
    lo = np.empty_like(alo)
    hi = np.empty_like(alo)
    for i in range(alo.shape[0]):
        lo[i], hi[i] = iv.min(alo[i], ahi[i], blo[i], bhi[i])
    return lo, hi

@njit(cache=True)
def max(alo, ahi, blo, bhi):
    """Elementwise maximum ``max([a], [b])`` (exact) (elementwise on ``lo, hi`` arrays)."""
    lo = np.empty_like(alo)
    hi = np.empty_like(alo)
    for i in range(alo.shape[0]):
        lo[i], hi[i] = iv.max(alo[i], ahi[i], blo[i], bhi[i])
    return lo, hi

@njit(cache=True)
def neg(alo, ahi):
    """``-[a]`` (exact) (elementwise on ``lo, hi`` arrays)."""
    lo = np.empty_like(alo)
    hi = np.empty_like(alo)
    for i in range(alo.shape[0]):
        lo[i], hi[i] = iv.neg(alo[i], ahi[i])
    return lo, hi

@njit(cache=True)
def sqr(alo, ahi):
    """``[a]^2`` (tighter than ``[a] * [a]`` when ``[a]`` contains 0), outward rounded (elementwise on ``lo, hi`` arrays)."""
    lo = np.empty_like(alo)
    hi = np.empty_like(alo)
    for i in range(alo.shape[0]):
        lo[i], hi[i] = iv.sqr(alo[i], ahi[i])
    return lo, hi

@njit(cache=True)
def sqrt(alo, ahi):
    """``sqrt([a])``, outward rounded; ``ValueError`` below 0 (elementwise on ``lo, hi`` arrays)."""
    lo = np.empty_like(alo)
    hi = np.empty_like(alo)
    for i in range(alo.shape[0]):
        lo[i], hi[i] = iv.sqrt(alo[i], ahi[i])
    return lo, hi

@njit(cache=True)
def exp(alo, ahi):
    """``exp([a])``, widened for the C library's rounding (elementwise on ``lo, hi`` arrays)."""
    lo = np.empty_like(alo)
    hi = np.empty_like(alo)
    for i in range(alo.shape[0]):
        lo[i], hi[i] = iv.exp(alo[i], ahi[i])
    return lo, hi

@njit(cache=True)
def log(alo, ahi):
    """``log([a])``, widened for the C library's rounding; ``ValueError`` for ``lo <= 0`` (elementwise on ``lo, hi`` arrays)."""
    lo = np.empty_like(alo)
    hi = np.empty_like(alo)
    for i in range(alo.shape[0]):
        lo[i], hi[i] = iv.log(alo[i], ahi[i])
    return lo, hi

@njit(cache=True)
def sin(alo, ahi):
    """``sin([a])`` with its extrema inside the interval, widened and clamped to ``[-1, 1]`` (elementwise on ``lo, hi`` arrays)."""
    lo = np.empty_like(alo)
    hi = np.empty_like(alo)
    for i in range(alo.shape[0]):
        lo[i], hi[i] = iv.sin(alo[i], ahi[i])
    return lo, hi

@njit(cache=True)
def cos(alo, ahi):
    """``cos([a])`` with its extrema inside the interval, widened and clamped to ``[-1, 1]`` (elementwise on ``lo, hi`` arrays)."""
    lo = np.empty_like(alo)
    hi = np.empty_like(alo)
    for i in range(alo.shape[0]):
        lo[i], hi[i] = iv.cos(alo[i], ahi[i])
    return lo, hi

@njit(cache=True)
def tan(alo, ahi):
    """``tan([a])``, widened; ``ValueError`` across a pole (elementwise on ``lo, hi`` arrays)."""
    lo = np.empty_like(alo)
    hi = np.empty_like(alo)
    for i in range(alo.shape[0]):
        lo[i], hi[i] = iv.tan(alo[i], ahi[i])
    return lo, hi

@njit(cache=True)
def atan(alo, ahi):
    """``atan([a])``, widened for the C library's rounding (elementwise on ``lo, hi`` arrays)."""
    lo = np.empty_like(alo)
    hi = np.empty_like(alo)
    for i in range(alo.shape[0]):
        lo[i], hi[i] = iv.atan(alo[i], ahi[i])
    return lo, hi


@njit(cache=True)
def tanh(alo, ahi):
    """``tanh([a])``, widened for the C library's rounding and clamped to ``[-1, 1]`` (elementwise on ``lo, hi`` arrays)."""
    lo = np.empty_like(alo)
    hi = np.empty_like(alo)
    for i in range(alo.shape[0]):
        lo[i], hi[i] = iv.tanh(alo[i], ahi[i])
    return lo, hi

@njit(cache=True)
def abs(alo, ahi):
    """``|[a]|`` (exact) (elementwise on ``lo, hi`` arrays)."""
    lo = np.empty_like(alo)
    hi = np.empty_like(alo)
    for i in range(alo.shape[0]):
        lo[i], hi[i] = iv.abs(alo[i], ahi[i])
    return lo, hi

@njit(cache=True)
def pow(alo, ahi, k):
    """Integer power ``k`` of every element."""
    lo = np.empty_like(alo)
    hi = np.empty_like(alo)
    for i in range(alo.shape[0]):
        lo[i], hi[i] = iv.pow(alo[i], ahi[i], k)
    return lo, hi
