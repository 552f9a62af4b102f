"""Checks of the arrays that sets are built from or tested against (one message style for all set types)."""

from __future__ import annotations

import numpy as np

from reachconf.errors import SetError

__all__ = ["as_vector", "as_points"]


def as_vector(value, name: str, allow_empty: bool = False) -> np.ndarray:
    """A finite float64 vector, read-only and contiguous (:class:`SetError` naming ``name`` otherwise).

    Parameters
    ----------
    value : array_like
        Flattened.
    name : str
        For the message.
    allow_empty : bool
        Accept a vector of length 0.
    """
    try:
        arr = np.array(value, dtype=np.float64).reshape(-1)
    except (TypeError, ValueError):
        raise SetError(f"{name} must be numeric, got {value!r}") from None
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
