"""Reach algorithms and reduction methods as option types; the strings stay shorthands for them."""

from dataclasses import dataclass
from typing import ClassVar

import numpy as np
import pytest

import reachconf as rc
from reachconf.models import vanderpol
from reachconf.reach_options import (
    ALGORITHM_TYPES,
    AdaptiveReach,
    ConservativeLinearization,
    ConservativePolynomialization,
    ReachAlgorithm,
    reach_algorithm,
    register_algorithm,
)
from reachconf.sets import PCA, Girard


def test_strings_are_shorthands_for_the_types():
    assert isinstance(rc.ReachOptions().alg, AdaptiveReach)  # the default (issue 16)
    assert isinstance(rc.ReachOptions(algorithm="lin").alg, ConservativeLinearization)
    assert isinstance(rc.ReachOptions(algorithm="poly").alg, ConservativePolynomialization)
    assert rc.ReachOptions(algorithm="poly").effective_tensor_order == 3
    assert rc.ReachOptions(algorithm=ConservativePolynomialization()).effective_tensor_order == 3
    assert isinstance(rc.ReachOptions(reduction="pca").reduction_method, PCA)
    assert isinstance(rc.ReachOptions(reduction=Girard()).reduction_method, Girard)
    with pytest.raises(rc.OptionsError, match="tensor_order=3"):
        rc.ReachOptions(algorithm=ConservativePolynomialization(), tensor_order=2)
    with pytest.raises(rc.OptionsError, match="algorithm"):
        rc.ReachOptions(algorithm=Girard())
    with pytest.raises(rc.OptionsError, match="reduction"):
        rc.ReachOptions(reduction=ConservativeLinearization())


def test_a_type_and_its_shorthand_give_the_same_tube():
    X0 = rc.Interval([1.25, 2.35], [1.55, 2.45])
    common = dict(time_step=0.05, zonotope_order=10)
    by_name = rc.reach(vanderpol(), X0, 1.0, options=rc.ReachOptions(algorithm="lin", reduction="pca", **common))
    by_type = rc.reach(vanderpol(), X0, 1.0,
                       options=rc.ReachOptions(algorithm=ConservativeLinearization(), reduction=PCA(), **common))
    np.testing.assert_array_equal(by_name.bounds(), by_type.bounds())
    assert by_type.meta["options"]["algorithm"] == "lin" and by_type.meta["options"]["reduction"] == "pca"


def test_adding_an_algorithm_is_local():
    @dataclass(frozen=True)
    class EvenOrders(ReachAlgorithm):
        """A test algorithm: the linearisation kernel, tensor order 3 only."""

        name: ClassVar[str] = "test_even"
        kernel_code: ClassVar[int] = 0
        tensor_orders: ClassVar[tuple] = (3,)
        default_tensor_order: ClassVar[int] = 3
        factor: float = 1.0

    try:
        register_algorithm(EvenOrders)
        opts = rc.ReachOptions(algorithm="test_even")
        assert isinstance(opts.alg, EvenOrders) and opts.effective_tensor_order == 3
        assert reach_algorithm(EvenOrders(factor=2.0)).factor == 2.0
        with pytest.raises(rc.OptionsError, match="tensor_order=3"):
            rc.ReachOptions(algorithm="test_even", tensor_order=2)
    finally:
        ALGORITHM_TYPES.pop("test_even", None)
    with pytest.raises(rc.OptionsError):
        rc.ReachOptions(algorithm="test_even")


def test_model_builds_of_the_default_and_of_fixed_orders():
    """The builds a run's workers get: "adaptive" with tensor remainders may ask for order 3 at any step."""
    from reachconf.model.shipping import model_builds

    assert model_builds([rc.ReachOptions()]) == [(2, "taylor")]  # a Taylor-mode build serves both orders
    assert model_builds([rc.ReachOptions(remainder="tensor")]) == [(2, "taylor"), (2, "tensor"), (3, "tensor")]
    assert model_builds([rc.ReachOptions(algorithm="lin", remainder="tensor")]) == [(2, "taylor"), (2, "tensor")]
    assert model_builds([rc.ReachOptions(remainder="tensor", tensor_order=2)]) == [(2, "taylor"), (2, "tensor")]


def test_a_division_by_zero_in_the_compiled_loop_is_a_reach_error():
    """The compiled loops divide by zero once a bound overflowed and NaN slipped past the interval guards (a reach
    of y' = log x from x near 1e-8, found by a numerical audit): a ReachError saying what to change, not a bare
    ZeroDivisionError."""
    from reachconf.errors import ReachError
    from reachconf.reach_errors import float_failure

    class _M:
        name = "tiny_log"

    with pytest.raises(ReachError, match=r"reach tiny_log: the sets' bounds overflowed .* rescale the states"):
        with float_failure(_M()):
            1.0 / 0.0
