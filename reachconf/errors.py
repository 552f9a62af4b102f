"""Exceptions raised by reachconf.

Every error a user can cause is a subclass of :class:`ReachconfError`, and its
message names the argument, file, row or column that is wrong.  The command-line
interface prints such errors as one line and exits with status 2.
"""

from __future__ import annotations

__all__ = [
    "ReachconfError",
    "SetError",
    "ModelError",
    "ReachError",
    "DataError",
    "ConformanceError",
    "SolverError",
    "OptionsError",
    "SetArgumentError",
    "OutputError",
    "ResourceError",
]


class ReachconfError(Exception):
    """Base class of every error reachconf raises on purpose."""


class SetError(ReachconfError, ValueError):
    """A set (interval, zonotope) was built or used with invalid data."""


class ModelError(ReachconfError, ValueError):
    """A model definition, parameter or signal name is invalid."""


class ReachError(ReachconfError, RuntimeError):
    """Reachability analysis failed (e.g. the set exploded).

    Attributes
    ----------
    time : float or None
        Time at which the failure happened.
    state : str or None
        Name of the state whose error bound exploded.
    term : str or None
        Which error term exploded (e.g. ``"lagrange"``).
    tried : dict or None
        What an adaptive reach tried before it gave up (``smallest_step``,
        ``highest_tensor_order``, ``max_order``, ``splits``, ``max_splits``,
        ``steps``), else None.
    """

    def __init__(self, message, *, time=None, state=None, term=None, tried=None):
        super().__init__(message)
        self.time = time
        self.state = state
        self.term = term
        self.tried = tried


class DataError(ReachconfError, ValueError):
    """A data file or array (test case, suite, run file) is malformed."""


class ConformanceError(ReachconfError, RuntimeError):
    """A conformance computation could not be carried out."""


class SolverError(ReachconfError, RuntimeError):
    """An optimisation solver failed or returned an infeasible/inaccurate result."""


class OptionsError(ReachconfError, ValueError):
    """An options object (reach, conformance, synthesis) has an invalid value."""


class SetArgumentError(SetError, OptionsError):
    """A set passed as an argument (``X0``, ``W``, ``V``) has the wrong type or dimension.

    Both a :class:`SetError` and an :class:`OptionsError`: the set is bad, and
    so is the argument.
    """


class OutputError(ReachconfError, OSError):
    """An output file or folder cannot be written (not writable, a file where a folder is expected, locked).

    Also an :class:`OSError`, so ``except OSError`` around file writing keeps
    working; the message names the path the user gave, never a temporary file.
    """


class ResourceError(ReachconfError, MemoryError):
    """A computation would need more memory or time than is available (raised before it starts)."""
