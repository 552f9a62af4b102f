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


def test_reach_and_simulate_arguments():
    with pytest.raises(rc.ReachError, match="1-D array of sample times"):
        rc.reach(vanderpol(), X0, [[0, 0.1, 0.2], [0.3, 0.4, 0.5]])
    with pytest.raises(rc.ReachError, match="array of sample times, got 'abc'"):
        rc.reach(vanderpol(), X0, "abc")
    with pytest.raises(rc.OptionsError, match="max_error has 3 entries, model 'vanderpol' has 2 states"):
        rc.reach(vanderpol(), X0, 0.1, options=rc.ReachOptions(algorithm="lin", max_error=[0.1, 0.1, 0.1]))
    with pytest.raises(rc.OptionsError, match="max_error must be a number or one per state"):
        rc.ReachOptions(max_error=[[0.1, 0.1]])
    with pytest.raises(rc.DataError, match="substeps must be a positive integer"):
        rc.simulate(vanderpol(), [1.0, 2.0], [0.0, 1.0], substeps=0)


def test_test_cases_and_suites():
    t = np.linspace(0.0, 1.0, 11)
    sig = (t, np.zeros((11, 1)), np.zeros((11, 1)))
    ok = rc.TestCase("c", "g", *sig, ("u",), ("y",))
    for name in ("../escaped", "a/b", "", None, ".."):
        with pytest.raises(rc.DataError, match="test case name must be a non-empty string"):
            rc.TestCase(name, "g", *sig, ("u",), ("y",))
    with pytest.raises(rc.DataError, match="input_names must be a sequence of names"):
        rc.TestCase("c", "g", *sig, "u", ("y",))
    with pytest.raises(rc.DataError, match="got a single TestCase"):
        rc.TestSuite(ok)
    with pytest.raises(rc.DataError, match="item 0 is a int"):
        rc.TestSuite([1, 2])
    suite = rc.TestSuite([ok])
    with pytest.raises(rc.DataError, match="has no case 'zz'; cases: \\['c'\\]"):
        suite["zz"]
    with pytest.raises(KeyError):  # still a KeyError for dict-like code
        suite["zz"]
    assert suite["c"] is ok


def test_diagnosis_and_bounds_arguments():
    spec = load_run(demo_run_file())
    suite = spec.suite()
    with pytest.raises(rc.ModelError, match="diagnose: model must be a reachconf Model"):
        rc.diagnose("bicycle_closed_loop", suite)
    with pytest.raises(rc.DataError, match="diagnose: suite must be a TestSuite"):
        rc.diagnose(spec.model, None)
    with pytest.raises(rc.OptionsError, match="seed must be a non-negative integer"):
        rc.diagnose(spec.model, suite, seed=-1)
    with pytest.raises(rc.OptionsError, match="options must be a DiagnoseOptions"):
        rc.diagnose(spec.model, suite, options={})
    with pytest.raises(rc.OptionsError, match="locate_gap: envelope out of range"):
        rc.locate_gap(spec.model, suite, spec.V, envelope=float("nan"))
    with pytest.raises(rc.OptionsError, match="locate_gap: group_share out of range"):
        rc.locate_gap(spec.model, suite, spec.V, group_share=2.0)
    with pytest.raises(rc.OptionsError, match="case_box: solve_for must be 'W' or 'V'"):
        rc.case_box(spec.model, suite[0], spec.V, solve_for="foo")
    with pytest.raises(rc.OptionsError, match="case_box: method must be one of"):
        rc.case_box(spec.model, suite[0], spec.V, method="foo")
    with pytest.raises(rc.OptionsError, match="options must be a TraceOptions"):
        rc.case_box(spec.model, suite[0], spec.V, options={})


def test_a_truncated_tube_file_is_a_data_error(tmp_path):
    (tmp_path / "empty.npz").write_bytes(b"")
    (tmp_path / "cut.npz").write_bytes(b"PK\x03\x04garbage")
    for name in ("empty.npz", "cut.npz"):
        with pytest.raises(rc.DataError):
            rc.ReachTube.load(tmp_path / name)


def test_model_names_that_cannot_be_used_are_refused():
    dyn = lambda s: [-s.x]  # noqa: E731
    with pytest.raises(rc.ModelError, match="starts with '_', which is reserved"):
        rc.Model(name="m", states=("_symbols",), dynamics=lambda s: [0])
    with pytest.raises(rc.ModelError, match="params must be a mapping"):
        rc.Model(name="m", states=("x",), params=["k"], dynamics=dyn)
    with pytest.raises(rc.ModelError, match=r"outputs \['u'\] have the name of an input"):
        rc.Model(name="m", states=("x",), inputs=("u",), outputs={"u": "x"}, dynamics=dyn)


def test_load_suite_names_files_of_the_same_stem_and_checks_its_model(tmp_path):
    import shutil

    shutil.copytree(demo_run_file().parent / "suite", tmp_path / "s")
    shutil.copy(tmp_path / "s" / "lane_change_01.csv", tmp_path / "s" / "lane_change_01.npz.csv")  # another stem: fine
    assert len(rc.load_suite(tmp_path / "s")) == 4
    shutil.copy(tmp_path / "s" / "lane_change_01.csv", tmp_path / "s" / "lane_change_01.CSV")
    with pytest.raises(rc.DataError, match=r"files \['lane_change_01.CSV', 'lane_change_01.csv'\] would give cases"):
        rc.load_suite(tmp_path / "s")
    with pytest.raises(rc.ModelError, match="load_suite: model must be a reachconf Model"):
        rc.load_suite(demo_run_file().parent / "suite", model="bicycle_closed_loop")


def test_conformance_keyword_types():
    spec = load_run(demo_run_file())
    case = spec.suite()[0]
    with pytest.raises(rc.OptionsError, match="max_distance_samples must be a non-negative integer"):
        rc.reachset_conformance(spec.model, case, spec.W, spec.V, max_distance_samples=-1)
    with pytest.raises(rc.OptionsError, match="progress must be True, False or None"):
        rc.reachset_conformance(spec.model, case, spec.W, spec.V, progress="x")
    with pytest.raises(rc.OptionsError, match="progress must be True, False or None"):
        rc.trace_conformance(spec.model, case, spec.W, spec.V, progress="x")


def test_containment_prints_a_summary():
    from reachconf.tube import Containment

    c = Containment(np.array([True, False, True] * 300), np.linspace(0, 9, 900), 1)
    assert repr(c) == "Containment(not conformant: 300 of 900 samples outside, first outside at t = 0.0100111 s)"


def test_second_audit_of_27_nov():
    """Times as text, a matrix as a box bound, a suite index past its end: reachconf errors naming the argument."""
    with pytest.raises(rc.ReachError, match="times must be a final time or an array of sample times"):
        rc.reach(vanderpol(), X0, "1")
    with pytest.raises(rc.SetError, match="lo must be a vector, got an array of shape"):
        rc.Interval(np.zeros((2, 2)), np.ones((2, 2)))
    assert rc.Interval([[0.0], [1.0]], [[1.0], [2.0]]).dim == 2  # a column is a vector
    suite = load_run(demo_run_file()).suite()
    with pytest.raises(rc.DataError, match="has 3 cases: no case at index 10") as info:
        suite[10]
    assert isinstance(info.value, IndexError)
    with pytest.raises(rc.DataError, match="index by position"):
        suite[1.5]
