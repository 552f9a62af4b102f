"""Options of :func:`reachconf.reach`: :class:`ReachOptions` and the reach algorithms as option types.

As in ReachabilityAnalysis.jl, an algorithm is a small type naming its paper:
:class:`ConservativeLinearization` (``"lin"``, Althoff et al. 2008) and
:class:`ConservativePolynomialization` (``"poly"``, Althoff 2013).  The
strings are shorthands: ``ReachOptions(algorithm="lin")`` and
``ReachOptions(algorithm=ConservativeLinearization())`` are the same reach;
``options.alg`` is the algorithm as an instance either way.  Order-reduction
methods are types too (:mod:`reachconf.sets.reduction`: ``Girard``, ``PCA``).

Adding an algorithm is local: a frozen dataclass subclass of
:class:`ReachAlgorithm` with a ``name``, the paper in its docstring, its own
fields (with defaults) and, if it needs them, ``tensor_orders`` and
:meth:`~ReachAlgorithm.validate`; decorate it with :func:`register_algorithm`
so that its name works as a shorthand.  :func:`reachconf.reach.reach_run`
dispatches on ``options.alg``: algorithms of the compiled loop by their
``kernel_code``, others by their type.  Making one the default is the default
of :attr:`ReachOptions.algorithm`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import ClassVar

import numpy as np

from reachconf.checks import check_field_types
from reachconf.errors import OptionsError
from reachconf.registry import NamedTypes
from reachconf.sets.reduction import ReductionMethod, reduction_method

__all__ = ["ReachOptions", "ReachAlgorithm", "ConservativeLinearization", "ConservativePolynomialization",
           "AdaptiveReach", "ALGORITHM_TYPES", "reach_algorithm", "register_algorithm", "SPLIT_METHODS", "MAX_ORDER",
           "REMAINDERS"]  # fmt: skip

#: how a set is split when its abstraction error cannot be bounded
SPLIT_METHODS = ("generator", "box")
#: largest zonotope order accepted (the reach stores ``order * n`` generators per step: 1000 at n = 6 is
#: 48 kB per set; CORA's examples use 10-200)
MAX_ORDER = 1000
#: how the Lagrange remainders are bounded (:mod:`reachconf.model.codegen`)
REMAINDERS = ("taylor", "tensor")
#: default ``max_splits`` of the adaptive algorithm (Van der Pol mu = 2, T = 8 needs about 256 pieces through its
#: fast phases to stay below y = 4.0: max y 4.155 with 64 splits, 3.894 with 256)
ADAPTIVE_MAX_SPLITS = 256


class ReachAlgorithm:
    """Base of the reach algorithms (see the module docstring)."""

    #: the shorthand accepted in place of an instance
    name: ClassVar[str] = ""
    #: the algorithm's number in the compiled reach loop (None: it runs its own loop)
    kernel_code: ClassVar[int | None] = None
    #: tensor orders of the Lagrange remainder the algorithm supports
    tensor_orders: ClassVar[tuple] = (2, 3)
    #: the tensor order used when ``ReachOptions.tensor_order`` is None
    default_tensor_order: ClassVar[int] = 2

    def validate(self, options: "ReachOptions") -> None:
        """Raise :class:`OptionsError` if ``options`` do not fit the algorithm (here: the tensor order)."""
        order = options.effective_tensor_order
        if order not in self.tensor_orders:
            need = f"={self.tensor_orders[0]}" if len(self.tensor_orders) == 1 else f" in {self.tensor_orders}"
            raise OptionsError(f"ReachOptions: algorithm {self.name!r} needs tensor_order{need}")

    def __str__(self):
        return self.name


@dataclass(frozen=True)
class ConservativeLinearization(ReachAlgorithm):
    """Conservative linearisation (shorthand ``"lin"``).

    Each step linearises ``f`` at the centre of the set, propagates the linear
    system with uncertain inputs exactly (Taylor series of the exponential with
    remainder) and adds the abstraction error, a Lagrange remainder bounded
    over the set at second order (tensor order 2) or by the Hessian at the
    linearisation point plus a third-order bound over the set (tensor order 3),
    found by CORA's iterative fixed point.

    References
    ----------
    M. Althoff, O. Stursberg, M. Buss, "Reachability analysis of nonlinear
    systems with uncertain parameters using conservative linearization",
    IEEE CDC 2008, pp. 4042–4048.
    """

    name: ClassVar[str] = "lin"
    kernel_code: ClassVar[int | None] = 0
    tensor_orders: ClassVar[tuple] = (2, 3)
    default_tensor_order: ClassVar[int] = 2


@dataclass(frozen=True)
class ConservativePolynomialization(ReachAlgorithm):
    """Conservative polynomialisation (shorthand ``"poly"``; tensor order 3).

    The quadratic term of the Taylor expansion is kept as a static
    polynomial part (the ``quad_map`` of the Hessian over the start set of
    each step) instead of being bounded with the remainder, which keeps
    sets tighter where ``f`` is strongly nonlinear.

    References
    ----------
    M. Althoff, "Reachability analysis of nonlinear systems using
    conservative polynomialization and non-convex sets", HSCC 2013,
    pp. 173–182.
    """

    name: ClassVar[str] = "poly"
    kernel_code: ClassVar[int | None] = 1
    tensor_orders: ClassVar[tuple] = (3,)
    default_tensor_order: ClassVar[int] = 3


@dataclass(frozen=True)
class AdaptiveReach(ReachAlgorithm):
    """Conservative linearisation with its parameters chosen per step (shorthand ``"adaptive"``).

    The time step, the zonotope, intermediate and error orders (by an
    error-bounded reduction), the tensor order (2 or 3) and the Taylor terms
    are chosen step by step from the abstraction and reduction errors against
    an error budget, and the set is split when its error over the set itself
    is over budget and halving it lowers that error
    (:mod:`reachconf.reach_adaptive`, :mod:`reachconf_kernels.adaptive`).
    ``ReachOptions.time_step`` is then the largest step (``None``: a tenth of
    the horizon), ``tensor_order`` fixes the tensor order if given, and
    ``intermediate_order``/``error_order`` are the orders of the intermediate
    sets; ``zonotope_order`` is not used (``max_order`` caps the order).  What
    was chosen is in the tube's :attr:`~reachconf.tube.ReachTube.log`.

    Parameters
    ----------
    error_budget : float, default 0.7
        The abstraction error may widen the set, relative to its size
        (averaged over the states), by at most ``error_budget / horizon`` per
        unit time (the horizon is the span of the sample times, at most
        ``budget_horizon``).  Smaller: tighter sets, smaller steps, more
        splits.
    budget_horizon : float, default 100.0
        The span (s) the error budget is spread over when the reach is
        longer: over a recording of hours the budget per unit time stays
        ``error_budget / budget_horizon`` instead of falling with the
        recording's length (the smallest step, a fraction of this span,
        too).  An abstraction error does not pile up over hours in a
        system whose states forget their past (a closed loop).  Measured:
        the closed-loop bicycle's 10,000-s straight-road recording at 100 Hz
        is undecided at t = 0.057 s with the whole horizon and conformant
        with 100 s (the reach 4.3 min wall; with the reductions' outlier cap of
        :mod:`reachconf_kernels.reduce_adaptive`); a disturbed oscillator over 1,000 s fails
        at t = 1.7 s with the whole horizon and takes 4.2 s CPU with 20 s,
        24 s with 100 s.  Reaches of at most 100 s are unchanged.
        ``math.inf``: always the whole horizon.
    max_order : float, default 50
        Largest zonotope order (generators / dimension) the error-bounded
        reduction may keep.
    max_steps : int, default 500000
        Most accepted steps (over all pieces) before the analysis gives up
        with a :class:`~reachconf.errors.ReachError`; the kept sets may also
        use at most a share of the available memory
        (:data:`reachconf.reach_adaptive.MEMORY_SHARE`).  Both bound what an
        exploding set can allocate.
    budget_retries : int, default 2
        When the abstraction error cannot be bounded (the set explodes), the
        reach runs again from the start with half the error budget and a
        quarter of the splits (:data:`reachconf.reach_adaptive.RETRY_SPLITS`), up to
        this many times (0: no retry); the budgets tried are in
        ``tube.log.budgets_tried``.  Measured: the coupled Van der Pol (T = 7)
        fails at t = 6.6 s with 0.7 and is verified with 0.35.  When the
        last budget fails too, it runs once more holding the step over
        budget where smaller steps cannot lower the error rate (its budget
        then appears twice in ``budgets_tried``).
    rtol, atol : float, default 1e-3 and 1e-6
        The error rates are measured against the set's radius, but per state
        against at least ``rtol * |x_i| + atol`` (``x`` the set's centre),
        as an ODE solver's tolerances (these are scipy's ``solve_ivp``
        defaults).  On a point or a very thin initial set the abstraction
        error is then held to an absolute size instead of one relative to a
        radius near zero, which no step could meet: with 0 and 0 (the radius
        alone) a Lotka-Volterra system from a point failed at t = 0, as did
        the Roessler and Robertson systems, and from boxes of radius 1e-7
        the reach took up to 39,000 steps (radius 1e-9: 66,000) instead of
        200-3,100 (README, "From a point").  Sets wider than the floor are
        unaffected.  Smaller values: thinner tubes from points, more steps
        (``1e-4``/``1e-7``: about 8 times thinner for 2.5-3 times the
        steps).  ``atol`` is used as at most ``rtol`` times the initial
        set's largest ``|x_i|`` (:meth:`for_initial_set`): in units where the
        states are of order 1e-8, an absolute 1e-6 let the error grow the set
        to its own size, and Van der Pol, verified in units of 1, failed.

    References
    ----------
    M. Wetzlinger, A. Kochdumper, S. Bak, M. Althoff, "Adaptive parameter
    tuning for reachability analysis of nonlinear systems", HSCC 2021
    (CORA's ``lin-adaptive``; the step-size control and the splitting here
    are simpler and our own).
    """

    name: ClassVar[str] = "adaptive"
    kernel_code: ClassVar[int | None] = None
    tensor_orders: ClassVar[tuple] = (2, 3)
    default_tensor_order: ClassVar[int] = 2
    error_budget: float = 0.7
    max_order: float = 50.0
    max_steps: int = 500_000
    budget_retries: int = 2
    budget_horizon: float = 100.0
    rtol: float = 1e-3
    atol: float = 1e-6

    def for_initial_set(self, magnitude: float) -> "AdaptiveReach":
        """These parameters with ``atol`` at most ``rtol * magnitude`` (the initial set's largest ``|x_i|``).

        The floor is then relative to the problem's units as ``rtol`` is; it binds only where all states start below
        ``atol / rtol`` (1e-3 with the defaults); a set all at 0 keeps ``atol``.
        """
        cap = self.rtol * float(magnitude)
        return replace(self, atol=cap) if 0.0 < cap < self.atol else self

    def validate(self, options: "ReachOptions") -> None:
        """Check the budget and that a fixed tensor order is 2 or 3."""
        if options.tensor_order is not None:
            super().validate(options)
        b = self.error_budget
        if not (isinstance(b, (int, float, np.number)) and 0 < b < math.inf):
            raise OptionsError(f"AdaptiveReach.error_budget must be a positive number, got {b!r}")
        m = self.max_order
        if not (isinstance(m, (int, float, np.number)) and 1 <= m < math.inf):
            raise OptionsError(f"AdaptiveReach.max_order must be a number >= 1, got {m!r}")
        if m > MAX_ORDER:
            raise OptionsError(f"AdaptiveReach.max_order must be at most {MAX_ORDER}, got {m!r}")
        k = self.max_steps
        if not (isinstance(k, (int, np.integer)) and not isinstance(k, bool) and k >= 1):
            raise OptionsError(f"AdaptiveReach.max_steps must be an integer >= 1, got {k!r}")
        r = self.budget_retries
        if not (isinstance(r, (int, np.integer)) and not isinstance(r, bool) and 0 <= r <= 10):
            raise OptionsError(f"AdaptiveReach.budget_retries must be an integer in 0..10, got {r!r}")
        h = self.budget_horizon
        if not (isinstance(h, (int, float, np.number)) and not isinstance(h, bool) and h > 0):
            raise OptionsError(f"AdaptiveReach.budget_horizon must be a positive number of seconds (math.inf: the "
                               f"whole horizon), got {h!r}")  # fmt: skip
        for name in ("rtol", "atol"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float, np.number)) and not isinstance(v, bool) and 0 <= v < math.inf):
                raise OptionsError(f"AdaptiveReach.{name} must be a number >= 0, got {v!r}")


#: name -> algorithm type (``ALGORITHM_TYPES.register`` adds one)
ALGORITHM_TYPES = NamedTypes(ReachAlgorithm, "reach algorithm")


def register_algorithm(cls: type[ReachAlgorithm]) -> type[ReachAlgorithm]:
    """Make a :class:`ReachAlgorithm` subclass known by its ``name`` (usable as a decorator)."""
    return ALGORITHM_TYPES.register(cls)


def reach_algorithm(value) -> ReachAlgorithm:
    """The algorithm for a name (``"lin"``, ``"poly"``) or an instance (:class:`OptionsError` otherwise)."""
    return ALGORITHM_TYPES.resolve(value)


for _cls in (ConservativeLinearization, ConservativePolynomialization, AdaptiveReach):
    register_algorithm(_cls)


@dataclass(frozen=True)
class ReachOptions:
    """Options of :func:`reach` (CORA's reach options, typed).

    Parameters
    ----------
    algorithm : str or ReachAlgorithm, default "adaptive"
        :class:`AdaptiveReach` (``"adaptive"``, after Wetzlinger et al. 2021:
        step, orders and tensor order chosen per step, splits when that is
        cheaper; the default), or the fixed-parameter algorithms
        :class:`ConservativeLinearization` (``"lin"``, Althoff 2008) and
        :class:`ConservativePolynomialization` (``"poly"``, Althoff 2013),
        which use ``time_step``, ``zonotope_order`` and ``tensor_order`` as
        given; ``alg`` is it as an instance.
    time_step : float or None, default None
        "adaptive": the largest step (``None``: a tenth of the horizon; steps
        also end at every sample time).  "lin"/"poly": the integration step;
        ``None``: one hundredth of the horizon, capped by the spacing of the
        sample times.
    taylor_terms : int, default 4
        Taylor terms of the matrix exponential (``r``); the remainder is bounded.
    zonotope_order : float, default 20
        Order (generators / dimension) the reachable sets are reduced to;
        at most :data:`MAX_ORDER` (1000).  Not used by "adaptive" (see
        :class:`AdaptiveReach`).
    intermediate_order : float, default 20
        Order of intermediate sets (time-interval set before the error loop,
        error sets); at most 1000.
    error_order : float, default 5
        Order the set is reduced to before ``quad_map`` (tensor order 3); at
        most 1000.
    tensor_order : int or None, default None
        2 (interval Hessian) or 3 (Hessian at the point + interval third-order
        tensor).  ``None``: chosen per step by "adaptive", 2 for "lin", 3 for
        "poly".
    reduction : str or ReductionMethod, default "girard"
        Order-reduction method: :class:`~reachconf.sets.reduction.Girard`
        (``"girard"``, Girard 2005) or :class:`~reachconf.sets.reduction.PCA`
        (``"pca"``, Kopetzki 2017); ``reduction_method`` is it as an instance.
        Used by "lin" and "poly"; "adaptive" ignores it and reduces by its own
        error-bounded rule (:mod:`reachconf_kernels.reduce_adaptive`).
    max_splits : int or None, default None
        How many times a set may be split (``None``: 8 for "lin"/"poly",
        :data:`ADAPTIVE_MAX_SPLITS` for "adaptive", which also splits when
        that is cheaper than smaller steps).
    split_method : {"generator", "box"}, default "generator"
        "generator" halves the zonotope exactly along its generator of largest
        normalised length; "box" halves the interval hull along its widest
        normalised axis (CORA).
    max_error : float or sequence of float, default inf
        Abstraction-error bound per state above which the set is split, in
        the units of ``f`` (state per unit time, as CORA's ``maxError``: the
        error enters the linearised system as an input); in other time units
        it scales with them (time in ms: a thousandth of the value in s).
        ``"lin"`` and ``"poly"`` only: ``"adaptive"`` splits by its own error
        budget (:class:`AdaptiveReach`) and does not read it.
    max_error_iterations : int, default 25
        Iterations of the abstraction-error fixed point before giving up.
    rounding : float, default 1e-13
        Relative allowance added per step for floating-point rounding of the
        zonotope arithmetic.
    progress : bool or None, default None
        Show a tqdm bar; ``None``: when stderr is a terminal and the run is long.
    remainder : {"taylor", "tensor"}, default "taylor"
        How the Lagrange remainders are bounded over the set: interval
        Taylor-mode arithmetic along the direction box (builds in seconds for
        any model) or the symbolic interval Hessian / third-order tensor of
        the older generator (build time grows with ``nz^3``; kept to compare).
        See :mod:`reachconf.model.codegen`.
    """

    algorithm: str | ReachAlgorithm = "adaptive"
    time_step: float | None = None
    taylor_terms: int = 4
    zonotope_order: float = 20.0
    intermediate_order: float = 20.0
    error_order: float = 5.0
    tensor_order: int | None = None
    reduction: str | ReductionMethod = "girard"
    max_splits: int | None = None
    split_method: str = "generator"
    max_error: float | tuple = math.inf
    max_error_iterations: int = 25
    rounding: float = 1e-13
    progress: bool | None = None
    remainder: str = "taylor"

    def __post_init__(self):
        check_field_types(self)
        alg = reach_algorithm(self.algorithm)
        if self.time_step is not None and not (math.isfinite(self.time_step) and self.time_step > 0):
            raise OptionsError(f"ReachOptions.time_step must be a positive number, got {self.time_step!r}")
        if not (isinstance(self.taylor_terms, (int, np.integer)) and 1 <= self.taylor_terms <= 20):
            raise OptionsError(f"ReachOptions.taylor_terms must be an integer in 1..20, got {self.taylor_terms!r}")
        for name in ("zonotope_order", "intermediate_order", "error_order"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float, np.number)) and 1 <= value <= MAX_ORDER):
                raise OptionsError(f"ReachOptions.{name} must be a number in [1, {MAX_ORDER}], got {value!r}")
        to = self.effective_tensor_order
        if to not in (2, 3):
            raise OptionsError(f"ReachOptions.tensor_order must be 2 or 3, got {self.tensor_order!r}")
        alg.validate(self)
        try:
            reduction = reduction_method(self.reduction)
        except OptionsError as exc:
            raise OptionsError(f"ReachOptions.reduction: {exc}") from None
        if reduction.kernel_code is None:
            raise OptionsError(f"ReachOptions.reduction: {reduction.name!r} is not available in the compiled reach loop")
        if self.split_method not in SPLIT_METHODS:
            raise OptionsError(f"ReachOptions.split_method must be one of {SPLIT_METHODS}, got {self.split_method!r}")
        if self.max_splits is not None and not (isinstance(self.max_splits, (int, np.integer)) and self.max_splits >= 0):
            raise OptionsError(f"ReachOptions.max_splits must be a non-negative integer, got {self.max_splits!r}")
        if not (isinstance(self.max_error_iterations, (int, np.integer)) and self.max_error_iterations >= 2):
            raise OptionsError("ReachOptions.max_error_iterations must be an integer >= 2")
        me = np.atleast_1d(np.asarray(self.max_error, dtype=float))
        if me.ndim != 1:
            raise OptionsError(f"ReachOptions.max_error must be a number or one per state, got shape {me.shape}")
        if np.any(np.isnan(me)) or np.any(me <= 0):
            raise OptionsError("ReachOptions.max_error must be positive (inf allowed)")
        if not (0 <= self.rounding < 1e-6):
            raise OptionsError("ReachOptions.rounding must be in [0, 1e-6)")
        if self.remainder not in REMAINDERS:
            raise OptionsError(f"ReachOptions.remainder must be one of {REMAINDERS}, got {self.remainder!r}")

    @property
    def alg(self) -> ReachAlgorithm:
        """The reach algorithm as an instance (``algorithm`` may be its name)."""
        return reach_algorithm(self.algorithm)

    @property
    def reduction_method(self) -> ReductionMethod:
        """The order-reduction method as an instance (``reduction`` may be its name)."""
        return reduction_method(self.reduction)

    @property
    def effective_max_splits(self) -> int:
        """``max_splits``, or its default for the algorithm when it is None."""
        if self.max_splits is None:
            return ADAPTIVE_MAX_SPLITS if isinstance(self.alg, AdaptiveReach) else 8
        return int(self.max_splits)

    @property
    def effective_tensor_order(self) -> int:
        """``tensor_order``, or the algorithm's default when it is None."""
        if self.tensor_order is None:
            return reach_algorithm(self.algorithm).default_tensor_order
        return int(self.tensor_order)
