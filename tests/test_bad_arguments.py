"""Bad arguments found by the bad-input audit of 27 Nov: each raises a reachconf error naming the argument."""

import numpy as np
import pytest

import reachconf as rc
from reachconf.demo import demo_run_file
from reachconf.models import vanderpol
from reachconf.runfile import load_run

X0 = rc.Interval([1.0, 2.0], [1.1, 2.1])


def test_reach_streamed_takes_the_default_options():
    tube = rc.reach_streamed(vanderpol(), X0, 0.5)  # options=None raised AttributeError
    assert tube.bounds().shape[0] >= 2
    with pytest.raises(rc.OptionsError, match="options must be a ReachOptions"):
        rc.reach_streamed(vanderpol(), X0, 0.5, options={})
    with pytest.raises(rc.OptionsError, match="max_sets must be an integer >= 2"):
        rc.reach_streamed(vanderpol(), X0, 0.5, max_sets=0)
    with pytest.raises(rc.ModelError):
        rc.reach_streamed("vanderpol", X0, 0.5)


@pytest.mark.parametrize("bad", [-1, 0, float("nan"), float("inf"), "a", True])
def test_time_limit_must_be_positive_seconds(bad):
    spec = load_run(demo_run_file())
    case = spec.suite()[0]
    with pytest.raises(rc.OptionsError, match="time_limit must be a positive number of seconds"):
        rc.trace_conformance(spec.model, case, spec.W, spec.V, time_limit=bad)
    with pytest.raises(rc.OptionsError, match="time_limit must be a positive number of seconds"):
        rc.reachset_conformance(spec.model, case, spec.W, spec.V, time_limit=bad)
    with pytest.raises(rc.OptionsError, match="time_limit must be a positive number of seconds"):
        rc.reach_streamed(vanderpol(), X0, 0.5, time_limit=bad)
    assert np.isfinite(rc.reach_streamed(vanderpol(), X0, 0.5, time_limit=60.0).bounds()).all()


def test_set_methods_check_dimensions_and_indices():
    from reachconf.sets import SetUnion

    I2, Z5 = rc.Interval([0, 0], [1, 1]), rc.Zonotope(np.ones(5), np.eye(5))
    for call, needle in [(lambda: I2.hull(rc.Interval([0], [1])), "hull: the sets have dimensions 2 and 1"),
                         (lambda: I2.intersection(rc.Interval([0], [1])), "intersection: the sets have dimensions"),
                         (lambda: I2.is_subset(3), "is_subset: other must be a set"),
                         (lambda: I2.project([-1]), "dimension -1 out of range"),
                         (lambda: Z5.project([0.7]), "dimension 0.7 out of range"),
                         (lambda: rc.Interval.from_list([[0, 1, 2], [3, 4, 5]]), r"shape \(n, 2\)"),
                         (lambda: Z5.bounds_along([1.0]), "direction has 1 entries, the zonotope 5"),
                         (lambda: SetUnion([I2, Z5]), "piece 1 has dimension 5, piece 0 2"),
                         (lambda: SetUnion([1, 2]), "piece 0 is a int"),
                         (lambda: SetUnion("ab"), "iterable of zonotopes")]:  # fmt: skip
        with pytest.raises(rc.SetError, match=needle):
            call()
    # the bounds along a direction are those of the support function, every call the same
    d = np.arange(5.0)
    assert Z5.bounds_along(d) == (-Z5.support(-d), Z5.support(d)) == Z5.bounds_along(d)
    assert I2.project(np.array([1])) == rc.Interval([0], [1])
