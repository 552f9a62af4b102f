"""Faults a new user's first session found (2 Dec): each raised a bare error, gave a wrong answer or a wrong message.

One test per finding; each fails on the code before the fix (noted in its docstring).
"""

import json
import sys

import numpy as np
import pytest

import reachconf as rc
from reachconf import cli
from reachconf.budget import TimeBudget
from reachconf.demo import demo_run_file
from reachconf.errors import OutputError
from reachconf.io import load_case
from reachconf.runfile import load_run


@pytest.fixture(scope="module")
def demo():
    spec = load_run(demo_run_file())
    return spec, spec.suite()


def decay_model():
    return rc.Model(name="decay_one_state", states=("th",), disturbances=("w",), params={"a": 1.0},
                    dynamics=lambda s: [-s.a * s.th + s.w])  # fmt: skip


def decay_case(name="c0", x0=1.0, seed=0, duration=1.0):
    model = decay_model()
    t = np.round(np.arange(0.0, duration + 1e-9, 0.05), 10)
    rng = np.random.default_rng(seed)
    X = rc.simulate(model, [x0], t, disturbances=rng.uniform(-0.05, 0.05, size=(t.size, 1)))
    return rc.TestCase(name, "g", t, np.zeros((t.size, 0)), X, (), ("th",))


@pytest.fixture()
def decay_run(tmp_path, monkeypatch):
    """A run file of the one-state model (a module of the test's own) and a suite of a short and a long case."""
    (tmp_path / "decay_mod.py").write_text(
        "import reachconf as rc\n"
        "def make():\n"
        "    return rc.Model(name='decay_one_state', states=('th',), disturbances=('w',), params={'a': 1.0},\n"
        "                    dynamics=lambda s: [-s.a * s.th + s.w])\n")  # fmt: skip
    monkeypatch.syspath_prepend(str(tmp_path))
    sys.modules.pop("decay_mod", None)
    suite = rc.TestSuite([decay_case("c0"), decay_case("long", 1.1, 1, duration=60.0)], name="decay")
    rc.save_suite(suite, tmp_path / "suite")
    run = tmp_path / "run.toml"
    run.write_text('model = "decay_mod:make"\nsuite = "suite"\n[sets]\nW = [[-0.05, 0.05]]\nV = [[-0.01, 0.01]]\n')
    return run


def test_an_initial_set_of_the_wrong_size_is_an_error_not_a_verdict(demo):
    """Was: reachset_conformance(keep_tube=False) and synthesize_W answered "not conformant at t = 0"."""
    spec, suite = demo
    bad = rc.Interval([0.0], [1.0])
    for keep in (True, False):
        with pytest.raises(rc.SetArgumentError, match="X0 has dimension 1, the model needs 6"):
            rc.reachset_conformance(spec.model, suite[0], spec.W, spec.V, X0=bad, keep_tube=keep)
    with pytest.raises(rc.SetArgumentError, match="X0 must be a reachconf Interval or Zonotope"):
        rc.reachset_conformance(spec.model, suite[0], spec.W, spec.V, X0=[[0, 1]] * 6, keep_tube=False)
    with pytest.raises(rc.SetArgumentError, match=r"synthesize_W: SynthesisOptions.X0 has dimension 1"):
        rc.synthesize_W(spec.model, suite, spec.V, options=rc.SynthesisOptions(X0=bad))
    per_case = {c.name: bad for c in suite}
    with pytest.raises(rc.SetArgumentError, match=r"SynthesisOptions.X0\['lane_change_01'\] has dimension 1"):
        rc.synthesize_W(spec.model, suite, spec.V, options=rc.SynthesisOptions(X0=per_case))
    with pytest.raises(rc.SetArgumentError, match="pareto_front: SynthesisOptions.X0 has dimension 1"):
        rc.pareto_front(spec.model, suite, spec.V, spec.W, options=rc.SynthesisOptions(X0=bad))


def test_a_model_without_disturbances_has_no_W_to_synthesize():
    """Was: a result with an empty table that could be neither reloaded nor plotted."""
    model = rc.Model(name="decay_no_w", states=("th",), dynamics=lambda s: [-s.th])
    t = np.linspace(0.0, 1.0, 11)
    case = rc.TestCase("c", "g", t, np.zeros((11, 0)), np.exp(-t)[:, None], (), ("th",))
    V = rc.Interval([-0.01], [0.01])
    with pytest.raises(rc.OptionsError, match="has no disturbance inputs w"):
        rc.synthesize_W(model, rc.TestSuite([case]), V)
    with pytest.raises(rc.OptionsError, match="has no disturbance inputs w"):
        rc.pareto_front(model, rc.TestSuite([case]), V, rc.Interval(np.zeros(0), np.zeros(0)))


def test_pareto_orders_and_iterations_are_checked(demo):
    """Was: a repeated channel accepted (another never explored); None, 'a', 'abc' gave bare Type/ValueErrors."""
    spec, suite = demo
    for orders in ([[0, 0, 1, 2, 3, 4]], "abc", [[0, 9]], [[]], [[0.5]], 3):
        with pytest.raises(rc.OptionsError, match="orders must be a list of sequences of distinct channels"):
            rc.pareto_front(spec.model, suite, spec.V, spec.W, orders=orders)
    for it in (None, "a", 0, 2.5, True):
        with pytest.raises(rc.OptionsError, match="iterations must be a positive integer"):
            rc.pareto_front(spec.model, suite, spec.V, spec.W, iterations=it)


def test_one_state_tube_is_drawn_against_time(tmp_path):
    """Was: "plot needs two dimensions" from ReachTube.plot and from `reachconf reach` (which stopped, exit 2)."""
    import matplotlib

    matplotlib.use("Agg")
    model = decay_model()
    tube = rc.reach(model, rc.Interval([0.9], [1.1]), 1.0, W=rc.Interval([-0.05], [0.05]))
    ax = tube.plot(measured=decay_case())
    assert ax.get_xlabel() == "t" and ax.get_ylabel() == "th"
    lo, hi = ax.get_ylim()
    b = tube.bounds()
    assert lo <= b[:, 0, 0].min() and hi >= b[:, 1, 0].max()
    assert ax.lines and ax.lines[0].get_xydata().shape == (21, 2)  # the measured samples, against time
    vdp = rc.reach(rc.models.vanderpol(), rc.Interval([1.4, 2.3], [1.5, 2.4]), 0.1)
    assert vdp.plot(dims="y").get_xlabel() == "t"  # one state of a larger tube, by name
    assert vdp.plot().get_xlabel() == "x"  # two states: unchanged


def test_reach_command_on_a_one_state_model(decay_run, capsys):
    out = decay_run.parent / "out"
    assert cli.main(["reach", str(decay_run), "--case", "c0", "--out", str(out)]) == 0, capsys.readouterr().err
    res = json.loads((out / "reach.json").read_text())
    assert list(res) == ["c0"] and not res["c0"]["failed"] and (out / "c0_tube.png").stat().st_size > 0


def test_time_limit_only_where_it_acts(demo, tmp_path, capsys):
    """Was: accepted and ignored by synth, pareto, diagnose; conform's message rounded 0.4 s to "0 s"."""
    for command in ("synth", "pareto", "diagnose"):
        status = cli.main([command, str(demo_run_file()), "--out", str(tmp_path / command), "--time-limit", "1"])
        err = capsys.readouterr().err.strip().splitlines()
        assert status == 2 and len(err) == 1 and "--time-limit" in err[0], (command, err)
    budget = TimeBudget("a run", 1e-9)
    budget.check(200, 200)  # all the work done: kept, whatever it took
    budget = TimeBudget("a run", 1e-9)
    with pytest.raises(rc.ResourceError, match=r"exceeds the time limit of 1e-09 s"):
        budget.check(1, 200)


def test_reach_command_streams_under_a_time_limit(decay_run, capsys):
    """Was: `reachconf reach --time-limit` ignored for tubes small enough to keep (the long case's 1,200 samples
    are six chunks of the streamed adaptive reach: the limit stops it after the first)."""
    out = decay_run.parent / "out"
    assert cli.main(["reach", str(decay_run), "--case", "c0", "--out", str(out), "--time-limit", "1e-6"]) == 0
    assert not json.loads((out / "reach.json").read_text())["c0"]["failed"]  # one chunk: done, kept
    status = cli.main(["reach", str(decay_run), "--case", "long", "--out", str(out), "--time-limit", "1e-6"])
    err = capsys.readouterr().err.strip().splitlines()
    assert status == 2 and len(err) == 1, err
    assert "for 1,200 samples" in err[0] and "exceeds the time limit of 1e-06 s" in err[0], err


def test_save_suite_refuses_cases_with_other_extras(tmp_path):
    """Was: written, then load_suite failed on the case without the extra column."""
    a, b = decay_case("a"), decay_case("b")
    a = rc.TestCase("a", "g", a.t, a.U, a.Y, (), ("th",), extras={"e": a.t})
    with pytest.raises(rc.DataError, match=r"case 'b' has the extra signals \[\], case 'a' \['e'\]"):
        rc.save_suite(rc.TestSuite([a, b]), tmp_path / "d")
    assert not (tmp_path / "d").exists()


def test_a_damaged_result_file_is_a_data_error(demo, tmp_path, capsys):
    """Was: AttributeError from SynthesisResult.load and a traceback with exit 1 from `reachconf plot`."""
    spec, suite = demo
    res = rc.synthesize_W(spec.model, rc.TestSuite([suite[0]]), spec.V,
                          options=rc.SynthesisOptions(alpha_iterations=1, merge_iterations=1))  # fmt: skip
    path = res.save(tmp_path / "synthesis.json")
    d = json.loads(path.read_text())
    d["groups"] = 5
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps(d))
    with pytest.raises(rc.DataError, match="bad.json: not a SynthesisResult file"):
        rc.SynthesisResult.load(bad)
    status = cli.main(["plot", str(bad)])
    err = capsys.readouterr().err.strip().splitlines()
    assert status == 2 and len(err) == 1 and "bad.json" in err[0], err


def test_segments_shorter_than_the_sampling_interval():
    """Was: [] from TestCase.segments, and a message about partial=False and short cases from the suite's."""
    case = decay_case()
    with pytest.raises(rc.DataError, match=r"segment length 0.01 s is shorter than the sampling interval \(0.05 s\)"):
        case.segments(0.01)
    with pytest.raises(rc.DataError, match="shorter than the sampling interval"):
        rc.TestSuite([case]).segments(0.01)
    assert len(case.segments(0.05)) == 20


def test_worst_case_takes_a_state_name(demo):
    """Was: ValueError "could not convert string to float"."""
    model = decay_model()
    t = np.linspace(0.0, 1.0, 11)
    X0, W = rc.Interval([0.9], [1.1]), rc.Interval([-0.05], [0.05])
    top = rc.worst_case(model, X0, t, "th", W=W)
    bottom = rc.worst_case(model, X0, t, "-th", W=W)
    assert top.value == pytest.approx(rc.worst_case(model, X0, t, [1.0], W=W).value)
    assert -bottom.value < top.value
    with pytest.raises(rc.DataError, match="value 'vx' is not a state of model 'decay_one_state'"):
        rc.worst_case(model, X0, t, "vx", W=W)
    with pytest.raises(rc.DataError, match="value must be a callable"):
        rc.worst_case(model, X0, t, [{"a": 1}], W=W)


def test_file_names_too_long_and_paths_that_are_not_files(tmp_path):
    """Was: a bare OSError for a 300-character name; "does not exist" / "no such file" for folders and devices."""
    with pytest.raises(OutputError, match="File name too long"):
        rc.atomic_write(tmp_path / ("z" * 300 + ".txt"), "hi")
    with pytest.raises(rc.DataError, match="is a folder, expected a run file"):
        load_run(tmp_path)
    with pytest.raises(rc.DataError, match="is not a regular file, expected a run file"):
        load_run("/dev/null")
    with pytest.raises(rc.DataError, match="is a folder, expected a result file"):
        rc.TraceResult.load(tmp_path)
    with pytest.raises(rc.DataError, match="is a folder, expected a file"):
        load_case(tmp_path)
    (tmp_path / "f.csv").write_text("t,x\n0,1\n")
    with pytest.raises(rc.DataError, match="is a file, expected a test suite folder"):
        rc.load_suite(tmp_path / "f.csv")


def test_small_argument_checks():
    """Was: decimate(1.5) silently every sample; Interval(None, None) "contains NaN or inf"."""
    case = decay_case()
    for k in (1.5, "2", 0, True):
        with pytest.raises(rc.DataError, match="decimation factor must be an integer >= 1"):
            case.decimate(k)
    assert case.decimate(np.int64(2)).t.size == 11
    for lo in (None, [None], ["a"]):
        with pytest.raises(rc.SetError, match="lo must be numeric"):
            rc.Interval(lo, [1.0])


def test_python_dash_m_reachconf(tmp_path):
    """Was: "No module named reachconf.__main__"."""
    import subprocess

    run = subprocess.run([sys.executable, "-m", "reachconf", "conform", str(tmp_path / "missing.toml")],
                         capture_output=True, text=True, timeout=120)  # fmt: skip
    assert run.returncode == 2, run.stderr
    assert run.stderr.strip().splitlines() == [f"reachconf: error: {tmp_path / 'missing.toml'}: no such run file"]


@pytest.mark.parametrize("start", ["", 'start_state = "past"\nsubsteps = 1\n'])
def test_a_reference_holding_the_same_data_is_no_change(tmp_path, capsys, start):
    """Was: `input_scale on kappa_ref (k = 0.9997 [0.9533, 1.046]) explains the gap` — 88 % of the numerical
    difference of two fits of the same recordings."""
    import shutil

    shutil.copytree(demo_run_file().parent, tmp_path / "demo")
    run = tmp_path / "demo" / "run.toml"
    run.write_text(run.read_text() + '\n[diagnose]\nreference = "suite"\n' + start)
    assert cli.main(["diagnose", str(run), "--json", str(tmp_path / "report.json")]) == 0
    out = capsys.readouterr().out
    assert "no change against the reference run" in out and "explains the gap" not in out, out
    report = rc.GapReport.load(tmp_path / "report.json")
    ref = report.decision["reference"]
    # no change: either no effect is chosen at all (the change test, z < z_name: since 3 Dec, with the 50-Hz demo's
    # "prefix" start states), or the one chosen is recognised as the two fits' numerical difference
    assert report.decision["status"] == "none" and (ref.get("same_data") or ref["z"] < 3.0), ref
    if start:  # "past" with one RK4 step per sample (the defaults until 3 Dec at the demo's 50 Hz) chooses an effect:
        assert ref["same_data"], ref  # the numerical difference (with the default two steps at 50 Hz it chooses none)
    # a saved report holds NaN and inf as None: its summary shows them as "—" (was: TypeError from format)
    d = json.loads((tmp_path / "report.json").read_text())

    def nones(x):
        if isinstance(x, dict):
            return {k: nones(v) for k, v in x.items()}
        if isinstance(x, list):
            return [nones(v) for v in x]
        return None if isinstance(x, float) else x

    for key in ("ranked_effects", "where", "before_after", "base", "features"):
        d[key] = nones(d[key])
    (tmp_path / "nones.json").write_text(json.dumps(d))
    text = rc.GapReport.load(tmp_path / "nones.json").summary()
    assert "| - | base (refitted) | | — |" in text and "nan" not in text


# ---------------------------------------------------------------- a second session (2 Dec): diagnosis, data, tubes
def test_tube_times_and_shapes_are_checked():
    """Was: at(inf) returned the initial set (contains at inf: "conformant"); bare Type/ValueErrors otherwise."""
    tube = rc.reach(rc.models.vanderpol(), rc.Interval([1.25, 2.35], [1.55, 2.45]), 0.5)
    for t in (np.inf, -np.inf):
        with pytest.raises(rc.ReachError, match="outside the tube"):
            tube.at(t)
    with pytest.raises(rc.ReachError, match="outside the tube"):
        tube.contains([np.inf], [[1.4, 2.4]], output=False)
    for t in (np.array([0.1, 0.2]), None, "x"):
        with pytest.raises(rc.DataError, match="t must be one time"):
            tube.at(t)
    with pytest.raises(rc.DataError, match=r"Y must be an array \(K, p\)"):
        tube.contains([0.0], np.zeros((1, 2, 2)))
    with pytest.raises(rc.SetError, match="dims must be state names or indices"):
        tube.project([None])
    assert tuple(tube.project(1).state_names) == ("y",)


def test_diagnose_arguments_are_checked(tmp_path):
    """Was: TypeErrors for effects=None / 5 and fit_params=3, "kd" split into 'k' and 'd', a repeated effect
    ranked twice, a window shorter than a sample or a box rate that leaves one sample failing after the fits."""
    model, suite = decay_model(), rc.TestSuite([decay_case(f"c{i}", x0, i, duration=3.0) for i, x0 in enumerate((1.0, 1.1, 0.9))])
    for effects in (None, 5):
        with pytest.raises(rc.OptionsError, match="effects must be 'all'"):
            rc.diagnose(model, suite, effects=effects, progress=False)
    with pytest.raises(rc.OptionsError, match="fit_params must be True, False, None or parameter names"):
        rc.diagnose(model, suite, fit_params=3, progress=False)
    with pytest.raises(rc.OptionsError, match=r"has no parameters \['kd'\]"):
        rc.diagnose(model, suite, fit_params="kd", progress=False)
    with pytest.raises(rc.OptionsError, match=r"window 0.01 s is shorter than the data's sampling interval"):
        rc.diagnose(model, suite, options=rc.DiagnoseOptions(window=0.01), progress=False)
    with pytest.raises(rc.OptionsError, match="box_rate 0.1 Hz keeps one sample"):
        rc.diagnose(model, suite, options=rc.DiagnoseOptions(box_rate=0.1), progress=False)
    from reachconf.diagnose.pipeline import resolve_effects

    assert len(resolve_effects(model, ["output_offset", "output_offset", ("output_offset", "th")])) == 1


def test_reference_cases_are_paired_by_name():
    """Was: paired by position (a reversed reference paired c0 with c2; other names were accepted)."""
    model, suite = decay_model(), rc.TestSuite([decay_case(f"c{i}", x0, i, duration=3.0) for i, x0 in enumerate((1.0, 1.1, 0.9))])
    renamed = [rc.TestCase("x" + c.name, c.group, c.t, c.U, c.Y, c.input_names, c.output_names) for c in suite]
    with pytest.raises(rc.OptionsError, match=r"reference: it has no case named \['c0', 'c1', 'c2'\]"):
        rc.diagnose(model, suite, reference=renamed, progress=False)
    from reachconf.diagnose.options import DiagnoseOptions
    from reachconf.diagnose.fit import prepare
    from reachconf.diagnose.reference import prepare_reference

    opts = DiagnoseOptions()
    prepared = [prepare(model, c, opts) for c in suite]
    ref = prepare_reference(model, list(suite)[::-1], prepared, opts)
    assert [r.name for r in ref] == ["c0", "c1", "c2"]


def test_results_and_options_refuse_what_they_cannot_show(demo, tmp_path):
    """Was: table(digits=-1) a bare ValueError; plot(dims=) of unknown outputs an empty picture; step2_decimate=0
    accepted; a run file's max_error of the wrong length an error that named neither the file nor the table."""
    spec, suite = demo
    res = rc.synthesize_W(spec.model, rc.TestSuite([suite[0]]), spec.V,
                          options=rc.SynthesisOptions(alpha_iterations=1, merge_iterations=1))  # fmt: skip
    for digits in (-1, None, 2.5):
        with pytest.raises(rc.OptionsError, match="digits must be an integer from 1 to 17"):
            res.table(digits=digits)
    rs = rc.reachset_conformance(spec.model, suite[0], spec.W, spec.V, keep_tube=False)
    with pytest.raises(rc.SetError, match="dims must be two of the outputs"):
        rs.plot(dims=("X", "zz"))
    for bad in (0, -3):
        with pytest.raises(rc.OptionsError, match="step2_decimate must be an integer >= 1"):
            rc.SynthesisOptions(step2_decimate=bad)
    import shutil

    shutil.copytree(demo_run_file().parent, tmp_path / "demo")
    run = tmp_path / "demo" / "run.toml"
    run.write_text(run.read_text().replace("[reach]\n", "[reach]\nmax_error = [0.5, 0.5, 0.5]\n"))
    with pytest.raises(rc.DataError, match=r"run.toml: \[reach\] max_error has 3 entries, model .* has 6 states"):
        load_run(run)


def test_damaged_real_data_files(data_root, tmp_path):
    """Was: NaN in the aero table, a missing units row of an OpenFAST CSV and a fractional BIWI id were read."""
    from reachconf.datasets.aero import read_performance_table
    from reachconf.datasets.biwi import read_obsmat
    from reachconf.datasets.openfast import read_csv

    table = data_root / "windturbine" / "Cp_Ct_Cq.NREL5MW.txt"
    if not table.is_file():
        pytest.skip(f"no {table}")
    lines = table.read_text(encoding="latin-1").splitlines()
    no = next(i for i, ln in enumerate(lines) if ln.strip() and not ln.lstrip().startswith("#") and i > 10)
    cells = lines[no].split()
    lines[no] = " ".join(["nan"] + cells[1:])
    bad = tmp_path / "cp.txt"
    bad.write_text("\n".join(lines) + "\n", encoding="latin-1")
    with pytest.raises(rc.DataError, match=rf"cp.txt: line {no + 1}: NaN or inf"):
        read_performance_table(bad)
    csv = tmp_path / "out.csv"
    csv.write_text("Time,RotSpeed\n0.0,9.0\n0.1,9.1\n0.2,9.2\n")
    with pytest.raises(rc.DataError, match="the second row must give the channels' units"):
        read_csv(csv)
    obs = tmp_path / "obsmat.txt"
    obs.write_text("1 1 0 0 0 0 0 0\n7 1.5 0 0 0 0 0 0\n")
    with pytest.raises(rc.DataError, match=r"row 2, column 2: the pedestrian id must be a whole number"):
        read_obsmat(obs)


def test_an_empty_effects_list_in_a_run_file(tmp_path, capsys):
    """Was: `effects = []` in a run file gave "no candidate effect applies to this model" without the file."""
    import shutil

    shutil.copytree(demo_run_file().parent, tmp_path / "demo")
    run = tmp_path / "demo" / "run.toml"
    run.write_text(run.read_text() + "\n[diagnose]\neffects = []\n")
    assert cli.main(["diagnose", str(run)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "run.toml: [diagnose]" in err[0] and "no candidate effect applies" in err[0], err


def test_a_run_file_sets_the_fallback_reach(tmp_path):
    """Was: SynthesisOptions.reach_fallback could not be set from a run file ("unknown keys ['reach_fallback']")."""
    import shutil

    shutil.copytree(demo_run_file().parent, tmp_path / "demo")
    run = tmp_path / "demo" / "run.toml"
    base = run.read_text()
    assert load_run(run).synthesis_options.reach_fallback is None
    run.write_text(base + '\n[reach_fallback]\nalgorithm = "lin"\ntensor_order = 3\ntime_step = 0.01\n')
    fb = load_run(run).synthesis_options.reach_fallback
    assert isinstance(fb, rc.ReachOptions) and (fb.algorithm, fb.tensor_order, fb.time_step) == ("lin", 3, 0.01)
    run.write_text(base + "\n[reach_fallback]\nmax_error = [0.5, 0.5]\n")
    with pytest.raises(rc.DataError, match=r"run.toml: \[reach_fallback\] max_error has 2 entries"):
        load_run(run)
    run.write_text(base + "\n[reach_fallback]\nstep = 0.1\n")
    with pytest.raises(rc.DataError, match=r"run.toml: \[reach_fallback\]: unknown options \['step'\]"):
        load_run(run)
    run.write_text(base.replace("[synthesis]\n", "[synthesis]\nreach_fallback = 1\n"))
    with pytest.raises(rc.DataError, match=r"\[synthesis\] cannot hold .*use the \[reach\], \[reach_fallback\]"):
        load_run(run)
