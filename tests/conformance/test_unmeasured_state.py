"""Synthesis and the Pareto front of a model with an unmeasured state (found by a new-user audit: synth and
pareto dropped the run file's X0 and stopped with "pass X0 explicitly", and step 1's "auto" asked for
method='optctrl', an option synthesis does not have)."""

import numpy as np
import pytest

import reachconf as rc


@pytest.fixture(scope="module")
def problem():
    # a damped oscillator whose velocity is not measured; the data have an input offset of 0.4 the model lacks
    model = rc.Model(name="osc_position_only", states=("p", "v"), inputs=("u",), disturbances=("w",),
                     params={"k": 4.0, "d": 0.8}, dynamics=lambda s: [s.v, -s.k * s.p - s.d * s.v + s.u + s.w],
                     outputs=("p",))  # fmt: skip
    t = np.round(np.arange(0.0, 3.0 + 1e-9, 0.02), 10)
    cases = []
    for j in range(4):
        rng = np.random.default_rng(7 + j)
        u = np.sin(2 * np.pi * rng.uniform(0.3, 1.0) * t + rng.uniform(0, 6))
        X = rc.simulate(model, [0.0, 0.0], t, inputs=(u + 0.4)[:, None], substeps=8)
        Y = X[:, :1] + rng.uniform(-0.002, 0.002, size=(t.size, 1))
        cases.append(rc.TestCase(f"c{j}", f"g{j % 2}", t, u[:, None], Y, ("u",), ("p",)))
    V = rc.Interval([-0.005], [0.005])
    X0 = rc.Interval([-0.01, -0.05], [0.01, 0.05])
    return model, rc.TestSuite(cases), V, X0


def test_synthesis_uses_the_given_initial_set(problem):
    model, suite, V, X0 = problem
    res = rc.synthesize_W(model, suite, V, rc.SynthesisOptions(X0=X0, alpha_iterations=4), progress=False)
    assert all(res.group_conformant.values()), res.table()
    for W in res.groups.values():  # the offset: w about 0.4
        assert W.lo[0] <= 0.4 <= W.hi[0] + 0.05 and W.hi[0] - W.lo[0] < 1.0
    assert all(c.message == "" or "alpha" in c.message for c in res.cases.values())


def test_without_an_initial_set_the_error_says_where_to_give_it(problem):
    model, suite, V, _ = problem
    with pytest.raises(rc.ConformanceError, match=r"SynthesisOptions\(X0=...\)"):
        rc.synthesize_W(model, suite, V, rc.SynthesisOptions(alpha_iterations=2), progress=False)


def test_diagnose_says_why_it_needs_every_state(problem):
    model, suite, V, _ = problem
    with pytest.raises(rc.ConformanceError, match="each state must be an output or computable from the outputs"):
        rc.diagnose(model, suite, progress=False)


def test_a_run_files_x0_reaches_the_synthesis(tmp_path):
    import shutil

    from reachconf.demo import demo_run_file
    from reachconf.runfile import load_run

    shutil.copytree(demo_run_file().parent, tmp_path / "demo")
    run = tmp_path / "demo" / "run.toml"
    text = run.read_text()
    spec = load_run(run)
    assert spec.synthesis_options.X0 is None
    box = ", ".join(["[-0.1, 0.1]"] * spec.model.n)
    run.write_text(text.replace("[sets]\n", f"[sets]\nX0 = [{box}]\n", 1))
    spec = load_run(run)
    assert spec.synthesis_options.X0 == spec.X0 and spec.X0.dim == spec.model.n
    run.write_text(text + "\n[synthesis]\nX0 = 1\n" if "[synthesis]" not in text else text.replace("[synthesis]\n", "[synthesis]\nX0 = 1\n"))
    with pytest.raises(rc.DataError, match=r"\[synthesis\] cannot hold"):
        load_run(run)
