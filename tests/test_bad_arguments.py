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
