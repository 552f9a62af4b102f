"""One glitched sample (a sensor spike of 1e4) gives a verdict or a clear error, never numba's LinAlgError.

Found by a bad-input audit: the per-step fit's Gauss-Newton system went non-finite and ``trace_conformance``
(``"auto"``, ``"perstep"``) and ``synthesize_W`` raised ``numpy.linalg.LinAlgError`` from compiled code.
"""

import numpy as np
import pytest

import reachconf as rc
from reachconf.demo import demo_run_file
from reachconf.runfile import load_run
from reachconf.verdict import Verdict


@pytest.fixture(scope="module")
def glitched():
    spec = load_run(demo_run_file())
    case = spec.suite()[0]
    Y = np.array(case.Y)
    Y[100, 0] += 1e4
    return spec, rc.TestCase("glitch", case.group, case.t, case.U, Y, case.input_names, case.output_names)


@pytest.mark.parametrize("method", ["perstep", "auto"])
def test_trace_conformance_of_a_glitch_is_undecided(glitched, method):
    spec, case = glitched
    res = rc.trace_conformance(spec.model, case, spec.W, spec.V, method=method)
    assert res.verdict is Verdict.UNDECIDED and not res.conformant
    assert "diverged" in res.message or "no disturbance trace" in res.message, res.message


def test_synthesis_names_the_glitched_case(glitched):
    spec, case = glitched
    with pytest.raises(rc.ConformanceError, match="case 'glitch': synthesis step 1 found no disturbance trace"):
        rc.synthesize_W(spec.model, rc.TestSuite([case]), spec.V, options=spec.synthesis_options, progress=False)


def test_failed_alg2_search_reports_no_disturbance_margins(glitched):
    """Alg. 2 found no trace: its last guess is no certificate, so its W margins are NaN (null in JSON), not W's half-widths."""
    import json

    spec, case = glitched
    res = rc.trace_conformance(spec.model, case, spec.W, spec.V, method="optctrl")
    assert res.verdict is Verdict.UNDECIDED and "no disturbance trace" in res.message, res.message
    names = spec.model.disturbance_names
    assert all(np.isnan(res.margins[w]) for w in names) and not set(names) & set(res.margin_times)
    assert res.worst()[0] in spec.model.output_names  # the outputs' margins stay: where the last guess leaves V
    d = json.loads(res.to_json())
    assert all(d["margins"][w] is None for w in names)
