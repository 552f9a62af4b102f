"""Checks of the arrays that sets are built from or tested against (one message style for all set types)."""

from __future__ import annotations

import numpy as np

from reachconf.checks import value_has_type
from reachconf.errors import SetError

__all__ = ["as_vector", "as_points", "as_count", "as_tolerance", "as_rng", "is_finite_number"]


def as_vector(value, name: str, allow_empty: bool = False) -> np.ndarray:
    """A finite float64 vector, read-only and contiguous (:class:`SetError` naming ``name`` otherwise).

    Parameters
    ----------
    value : array_like
        A vector, or an array with one non-singleton axis (flattened).
    name : str
        For the message.
    allow_empty : bool
        Accept a vector of length 0.
    """
    try:
        kind = np.asarray(value).dtype.kind
        arr = np.array(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise SetError(f"{name} must be numeric, got {value!r}"[:200]) from None
    if kind not in "biuf":  # None (read as NaN), text, objects
        raise SetError(f"{name} must be numeric, got {value!r}"[:200])
    if sum(d > 1 for d in arr.shape) > 1:  # a row or column vector is a vector; a matrix is not
        raise SetError(f"{name} must be a vector, got an array of shape {arr.shape}")
    arr = arr.reshape(-1)
    if arr.size == 0 and not allow_empty:
        raise SetError(f"{name} is empty")
    if not np.all(np.isfinite(arr)):
        raise SetError(f"{name} contains NaN or inf (unbounded sets are not allowed)")
    arr = np.ascontiguousarray(arr)
    arr.flags.writeable = False
    return arr


def as_points(points, dim: int, name="points"):
    """Points as a finite (N, dim) float64 array, and whether a single point (1-D) was given.

    Returns
    -------
    P : ndarray (N, dim)
    single : bool
    """
    P = np.asarray(points, dtype=np.float64)
    single = P.ndim == 1
    P = np.atleast_2d(P)
    if P.shape[-1] != dim:
        raise SetError(f"{name} must have {dim} columns, got shape {np.shape(points)}")
    if not np.all(np.isfinite(P)):
        raise SetError(f"{name} contains NaN or inf")
    return np.ascontiguousarray(P), single


def as_count(value, name: str) -> int:
    """A number of points: a non-negative integer (:class:`SetError` naming ``name`` otherwise)."""
    if not value_has_type(value, int) or value < 0:
        raise SetError(f"{name} must be a non-negative integer, got {value!r}")
    return int(value)


def as_tolerance(value, name: str = "tol") -> float:
    """A tolerance: a finite number >= 0 (:class:`SetError` naming ``name`` otherwise)."""
    if not is_finite_number(value) or value < 0:
        raise SetError(f"{name} must be a finite number >= 0, got {value!r}")
    return float(value)


def as_rng(rng) -> np.random.Generator:
    """``numpy.random.default_rng(rng)``: a seed, a SeedSequence, a Generator or None (:class:`SetError` otherwise)."""
    try:
        return np.random.default_rng(rng)
    except (TypeError, ValueError) as exc:
        raise SetError(f"rng must be a seed (non-negative integer), a numpy Generator or None, got {rng!r}: "
                       f"{exc}") from None  # fmt: skip


def is_finite_number(value) -> bool:
    """A real number (not a bool, not text) that is finite."""
    return value_has_type(value, float) and np.isfinite(float(value))
