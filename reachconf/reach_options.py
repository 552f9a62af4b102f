"""Options of :func:`reachconf.reach`: :class:`ReachOptions` (CORA's reach options, typed)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from reachconf.errors import OptionsError

__all__ = ["ReachOptions", "ALGORITHMS", "REDUCTIONS", "SPLIT_METHODS"]

#: reach algorithms (kernel code = index): conservative linearisation, conservative polynomialisation
ALGORITHMS = ("lin", "poly")
#: zonotope order-reduction methods (kernel code = index)
REDUCTIONS = ("girard", "pca")
#: how a set is split when its abstraction error cannot be bounded
SPLIT_METHODS = ("generator", "box")


@dataclass(frozen=True)
class ReachOptions:
    """Options of :func:`reach` (CORA's reach options, typed).

    Parameters
    ----------
    algorithm : {"lin", "poly"}, default "lin"
        Conservative linearisation or polynomialisation (Althoff 2008/2013).
    time_step : float or None, default None
        Largest integration step.  ``None``: one hundredth of the horizon,
        capped by the spacing of the sample times.
    taylor_terms : int, default 4
        Taylor terms of the matrix exponential (``r``); the remainder is bounded.
    zonotope_order : float, default 20
        Order (generators / dimension) the reachable sets are reduced to.
    intermediate_order : float, default 20
        Order of intermediate sets (time-interval set before the error loop,
        error sets).
    error_order : float, default 5
        Order the set is reduced to before ``quad_map`` (tensor order 3).
    tensor_order : int or None, default None
        2 (interval Hessian) or 3 (Hessian at the point + interval third-order
        tensor).  ``None``: 2 for "lin", 3 for "poly".
    reduction : {"girard", "pca"}, default "girard"
        Order-reduction method.
    max_splits : int, default 8
        How many times a set may be split when its error cannot be bounded.
    split_method : {"generator", "box"}, default "generator"
        "generator" halves the zonotope exactly along its generator of largest
        normalised length; "box" halves the interval hull along its widest
        normalised axis (CORA).
    max_error : float or sequence of float, default inf
        Abstraction-error bound per state above which the set is split.
    max_error_iterations : int, default 25
        Iterations of the abstraction-error fixed point before giving up.
    rounding : float, default 1e-13
        Relative allowance added per step for floating-point rounding of the
        zonotope arithmetic.
    progress : bool or None, default None
        Show a tqdm bar; ``None``: when stderr is a terminal and the run is long.
    """

    algorithm: str = "lin"
    time_step: float | None = None
    taylor_terms: int = 4
    zonotope_order: float = 20.0
    intermediate_order: float = 20.0
    error_order: float = 5.0
    tensor_order: int | None = None
    reduction: str = "girard"
    max_splits: int = 8
    split_method: str = "generator"
    max_error: float | tuple = math.inf
    max_error_iterations: int = 25
    rounding: float = 1e-13
    progress: bool | None = None

    def __post_init__(self):
        if self.algorithm not in ALGORITHMS:
            raise OptionsError(f"ReachOptions.algorithm must be one of {ALGORITHMS}, got {self.algorithm!r}")
        if self.time_step is not None and not (math.isfinite(self.time_step) and self.time_step > 0):
            raise OptionsError(f"ReachOptions.time_step must be a positive number, got {self.time_step!r}")
        if not (isinstance(self.taylor_terms, (int, np.integer)) and 1 <= self.taylor_terms <= 20):
            raise OptionsError(f"ReachOptions.taylor_terms must be an integer in 1..20, got {self.taylor_terms!r}")
        for name in ("zonotope_order", "intermediate_order", "error_order"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float, np.number)) and value >= 1 and math.isfinite(value)):
                raise OptionsError(f"ReachOptions.{name} must be a number >= 1, got {value!r}")
        to = self.effective_tensor_order
        if to not in (2, 3):
            raise OptionsError(f"ReachOptions.tensor_order must be 2 or 3, got {self.tensor_order!r}")
        if self.algorithm == "poly" and to != 3:
            raise OptionsError("ReachOptions: algorithm 'poly' needs tensor_order=3")
        if self.reduction not in REDUCTIONS:
            raise OptionsError(f"ReachOptions.reduction must be one of {REDUCTIONS}, got {self.reduction!r}")
        if self.split_method not in SPLIT_METHODS:
            raise OptionsError(f"ReachOptions.split_method must be one of {SPLIT_METHODS}, got {self.split_method!r}")
        if not (isinstance(self.max_splits, (int, np.integer)) and self.max_splits >= 0):
            raise OptionsError(f"ReachOptions.max_splits must be a non-negative integer, got {self.max_splits!r}")
        if not (isinstance(self.max_error_iterations, (int, np.integer)) and self.max_error_iterations >= 2):
            raise OptionsError("ReachOptions.max_error_iterations must be an integer >= 2")
        me = np.atleast_1d(np.asarray(self.max_error, dtype=float))
        if np.any(np.isnan(me)) or np.any(me <= 0):
            raise OptionsError("ReachOptions.max_error must be positive (inf allowed)")
        if not (0 <= self.rounding < 1e-6):
            raise OptionsError("ReachOptions.rounding must be in [0, 1e-6)")

    @property
    def effective_tensor_order(self) -> int:
        if self.tensor_order is None:
            return 3 if self.algorithm == "poly" else 2
        return int(self.tensor_order)
