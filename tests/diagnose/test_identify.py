"""Parameter identification: both methods recover the parameters of data made with known ones."""

import numpy as np
import pytest

import reachconf as rc
from reachconf.diagnose import identify
from reachconf.io import TestCase, TestSuite
from reachconf.model.simulate import simulate


def _suite(k=3.0, c=0.4, n=3):
    m = rc.Model(name="spring", states=("x", "v"), inputs=("u",), disturbances=("w",), params={"k": 2.0, "c": 0.5},
                 dynamics=lambda s: [s.v, -s.k * s.x - s.c * s.v + s.u + s.w])  # fmt: skip
    truth = m.with_params(k=k, c=c)
    rng = np.random.default_rng(0)
    cases = []
    for i in range(n):
        t = np.round(np.arange(0, 8 + 1e-9, 0.01), 10)
        u = np.sin((1 + 0.3 * i) * t) + 0.5 * np.sign(np.sin(0.5 * t + i))
        X = simulate(truth, [0.1 * i, 0.0], t, inputs=u[:, None], substeps=10)
        Y = X + rng.normal(scale=1e-4, size=X.shape)
        cases.append(TestCase(f"c{i}", "g", t, u[:, None], Y, ("u",), ("x", "v")))
    return m, TestSuite(cases)


@pytest.mark.parametrize("method", ["prediction", "equation_error"])
def test_identify_recovers_the_parameters(method):
    m, suite = _suite()
    res = identify(m, suite, ("k", "c"), method=method, prior=1e-4,
                   options=rc.DiagnoseOptions(prior=10.0, param_bounds=0.9))  # fmt: skip
    assert res.start == {"k": 2.0, "c": 0.5}
    assert abs(res.params["k"] - 3.0) < 0.03 and abs(res.params["c"] - 0.4) < 0.03, res.params
    assert res.method == method and res.samples > 0


def test_identify_rejects_bad_arguments():
    m, suite = _suite(n=1)
    with pytest.raises(rc.OptionsError, match="no parameters"):
        identify(m, suite, ("k", "nope"))
    with pytest.raises(rc.OptionsError, match="method"):
        identify(m, suite, ("k",), method="magic")
    with pytest.raises(rc.OptionsError, match="no states"):
        identify(m, suite, ("k",), method="equation_error", equations=("z",))
