"""Converters for set arguments: :func:`as_box` and :func:`as_zonotope`.

Every function that takes a set (an initial set ``X0``, a disturbance set
``W``, a measurement-error set ``V``) converts it with one of these, so the
checks and the messages are the same everywhere: a wrong type or dimension
raises :class:`~reachconf.errors.SetArgumentError` naming the argument.
"""

from __future__ import annotations

import numpy as np

from reachconf.errors import SetArgumentError
from reachconf.sets.core import Interval, Zonotope

__all__ = ["as_box", "as_zonotope"]


def as_box(S, dim: int | None = None, name: str = "set", exact: bool = False) -> Interval:
    """The interval hull of a set argument, checked against the dimension the caller needs.

    Parameters
    ----------
    S : Interval, Zonotope or None
        ``None`` is the point ``{0}`` (needs ``dim``).
    dim : int, optional
        Required dimension.
    name : str
        Argument name for messages (``"W"``, ``"V"``).
    exact : bool
        The caller needs the set itself, not a hull (a trace within the hull
        need not lie in the set): a zonotope that is not a box (a generator
        with more than one non-zero entry) is an error.

    Returns
    -------
    Interval
        ``S`` itself if it is an Interval.

    Raises
    ------
    SetArgumentError
        If ``S`` is not a reachconf set or has another dimension, or with
        ``exact`` if it is a zonotope that is not a box.
    """
    if S is None:
        if dim is None:
            raise SetArgumentError(f"{name} is None and no dimension is given")
        return Interval(np.zeros(dim), np.zeros(dim))
    if isinstance(S, Zonotope):
        if exact and np.any(np.count_nonzero(S.generators, axis=0) > 1):
            raise SetArgumentError(f"{name} is a zonotope that is not a box: its interval hull would accept traces "
                                   f"outside it; pass {name}.interval() to check against the hull")  # fmt: skip
        S = S.interval()
    if not isinstance(S, Interval):
        raise SetArgumentError(f"{name} must be a reachconf Interval or Zonotope, got {type(S).__name__}")
    if dim is not None and S.dim != dim:
        raise SetArgumentError(f"{name} has dimension {S.dim}, the model needs {dim}")
    return S


def as_zonotope(S, dim: int | None = None, name: str = "set") -> Zonotope:
    """A set argument as a Zonotope (an Interval is converted exactly), checked against a dimension.

    Parameters
    ----------
    S : Interval or Zonotope
    dim : int, optional
        Required dimension.
    name : str
        Argument name for messages (``"X0"``, ``"W"``).

    Returns
    -------
    Zonotope

    Raises
    ------
    SetArgumentError
        If ``S`` is not an Interval or Zonotope or has another dimension.
    """
    if isinstance(S, Zonotope):
        Z = S
    elif isinstance(S, Interval):
        Z = S.to_zonotope()
    else:
        raise SetArgumentError(f"{name} must be a reachconf Interval or Zonotope, got {type(S).__name__}")
    if dim is not None and Z.dim != dim:
        raise SetArgumentError(f"{name} has dimension {Z.dim}, the model needs {dim}")
    return Z
