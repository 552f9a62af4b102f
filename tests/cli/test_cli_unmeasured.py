"""Run files for a model with a state that is not measured: ``[sets] unmeasured`` (eq. 67 for the measured states of
each case, bounds for the others) and ``[sets.X0]`` as a table of per-case initial sets."""

import json
import subprocess
import sys

import numpy as np
import pytest

import reachconf as rc
from reachconf.runfile import load_run

MODEL = """import reachconf as rc
model = rc.Model(name="osc_position_only", states=("p", "v"), inputs=("u",), disturbances=("w",),
                 params={"k": 4.0, "d": 0.8}, dynamics=lambda s: [s.v, -s.k * s.p - s.d * s.v + s.u + s.w],
                 outputs=("p",))
"""
STARTS = ((0.0, 0.2), (0.6, -0.3), (-0.5, 0.1))  # (p, v) at t = 0: every run starts elsewhere


def cli(*args, timeout=300):
    return subprocess.run([sys.executable, "-m", "reachconf.cli", *map(str, args)], capture_output=True, text=True,
                          timeout=timeout)  # fmt: skip


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    """A model file, a suite whose runs start at different positions and velocities (an input offset of 0.4 the
    model lacks), and a run file with ``[sets] unmeasured``."""
    root = tmp_path_factory.mktemp("unmeasured")
    (root / "osc_model.py").write_text(MODEL)
    namespace = {}
    exec(MODEL, namespace)  # the same model as the run file's
    model = namespace["model"]
    t = np.round(np.arange(0.0, 3.0 + 1e-9, 0.02), 10)
    cases = []
    for j, x0 in enumerate(STARTS):
        rng = np.random.default_rng(11 + j)
        u = np.sin(2 * np.pi * rng.uniform(0.3, 1.0) * t + rng.uniform(0, 6))
        X = rc.simulate(model, list(x0), t, inputs=(u + 0.4)[:, None], substeps=8)
        Y = X[:, :1] + rng.uniform(-0.002, 0.002, size=(t.size, 1))
        cases.append(rc.TestCase(f"c{j}", "g", t, u[:, None], Y, ("u",), ("p",)))
    rc.save_suite(rc.TestSuite(cases), root / "suite")
    head = 'model = "osc_model:model"\nsuite = "suite"\n[sets]\nW = [[0.3, 0.5]]\nV = [[-0.005, 0.005]]\n'
    (root / "run.toml").write_text(head + "[sets.unmeasured]\nv = [-0.4, 0.4]\n[synthesis]\nalpha_iterations = 4\n")
    return root, model, rc.TestSuite(cases)


def test_unmeasured_gives_each_case_its_own_start(folder):
    root, model, suite = folder
    spec = load_run(root / "run.toml")
    sets = spec.initial_sets(suite)
    for case in suite:
        X0 = sets[case.name]
        p1 = case.Y[0, 0]
        assert X0.lo == pytest.approx([p1 - 0.005, -0.4]) and X0.hi == pytest.approx([p1 + 0.005, 0.4])
    assert spec.synthesis_options_for(suite).X0["c1"] is not None
    # the whole chain: each case's own start (one X0 for all would miss the runs that start elsewhere)
    out = root / "out_conform"
    proc = cli("conform", root / "run.toml", "--kind", "reachset", "--json", out / "c.json")
    assert proc.returncode == 0, proc.stderr
    verdicts = json.loads((out / "c.json").read_text())
    assert sorted(verdicts) == ["c0", "c1", "c2"]
    assert all(v["reachset"]["conformant"] is True for v in verdicts.values()), verdicts
    one = rc.Interval([-0.005, -0.4], [0.005, 0.4])  # c0's start for every case: c1 and c2 leave its reach
    W, V = rc.Interval([0.3], [0.5]), rc.Interval([-0.005], [0.005])
    assert not rc.reachset_conformance(model, suite.cases[1], W, V, X0=one).conformant


def test_synth_and_reach_with_unmeasured(folder):
    root, _, suite = folder
    out = root / "out_synth"
    proc = cli("synth", root / "run.toml", "--json", out / "s.json", "--out", out)
    assert proc.returncode == 0, proc.stderr
    res = json.loads((out / "s.json").read_text())
    assert all(c["conformant"] is True for c in res["cases"].values()), res["cases"]
    (lo, hi), = res["groups"]["g"]
    assert abs(0.5 * (lo + hi) - 0.4) < 0.05 and hi - lo < 0.2  # the input offset
    proc = cli("reach", root / "run.toml", "--case", "c2", "--out", out)
    assert proc.returncode == 0, proc.stderr
    (p_lo, p_hi), (v_lo, v_hi) = json.loads((out / "reach.json").read_text())["c2"]["bounds"][0]  # first step
    p1 = suite.cases[2].Y[0, 0]  # about -0.5: c2's own start
    assert p_lo <= p1 - 0.005 and p1 + 0.005 <= p_hi < p1 + 0.2 and v_lo <= -0.4 and 0.4 <= v_hi


def test_x0_table_per_case(folder):
    root, _, suite = folder
    boxes = "\n".join(f"{c.name} = [[{x0[0] - 0.01}, {x0[0] + 0.01}], [{x0[1] - 0.05}, {x0[1] + 0.05}]]"
                      for c, x0 in zip(suite, STARTS))  # fmt: skip
    text = (root / "run.toml").read_text().split("[sets.unmeasured]")[0] + f"[sets.X0]\n{boxes}\n"
    (root / "table.toml").write_text(text)
    spec = load_run(root / "table.toml")
    assert spec.initial_sets(suite)["c1"].lo == pytest.approx([0.59, -0.35])
    out = root / "out_table"
    proc = cli("conform", root / "table.toml", "--kind", "reachset", "--json", out / "c.json")
    assert proc.returncode == 0, proc.stderr
    assert all(v["reachset"]["conformant"] for v in json.loads((out / "c.json").read_text()).values())
    (root / "short.toml").write_text(text.replace(boxes.splitlines()[2], ""))
    proc = cli("conform", root / "short.toml", "--kind", "reachset")
    assert proc.returncode == 2 and "[sets.X0] has no initial set for the cases ['c2']" in proc.stderr, proc.stderr


@pytest.mark.parametrize(("sets", "message"), [
    ("[sets.unmeasured]\np = [0, 1]\n", "outputs given: ['p']"),
    ("[sets.unmeasured]\nspeed = [0, 1]\n", "['speed'] are not states"),
    ("[sets.unmeasured]\nv = [1, 0]\n", "lo <= hi"),
    ("[sets.unmeasured]\nv = [0, true]\n", "sets.unmeasured.v: must be a pair [lo, hi] of numbers"),
    ("[sets]\nunmeasured = [0, 1]\n", "sets.unmeasured: must be a table"),
    ("[sets]\nX0 = [[0, 1], [0, 1]]\nunmeasured = {v = [0, 1]}\n", "gives both X0 and unmeasured"),
    ("[sets.X0]\nc0 = [[0, 1]]\n", "sets.X0.c0: has 1 intervals, the model needs 2"),
    ("[sets]\nX0 = {}\n", "sets.X0: the table of per-case initial sets is empty"),
])  # fmt: skip
def test_bad_sets_are_named(folder, sets, message):
    root = folder[0]
    path = root / "bad.toml"
    path.write_text('model = "osc_model:model"\nsuite = "suite"\n' + sets)
    with pytest.raises(rc.DataError, match="bad.toml") as info:
        load_run(path)
    assert message in str(info.value)


def test_unmeasured_needs_V_and_no_X0_with_segments(folder):
    root, _, suite = folder
    path = root / "noV.toml"
    path.write_text('model = "osc_model:model"\nsuite = "suite"\n[sets.unmeasured]\nv = [0, 1]\n')
    with pytest.raises(rc.DataError, match="unmeasured needs sets.V"):
        load_run(path).initial_sets(suite)
    path.write_text('model = "osc_model:model"\nsuite = "suite"\nsegment_length = 1.0\n'
                    '[sets.X0]\nc0 = [[0, 1], [0, 1]]\n')  # fmt: skip
    with pytest.raises(rc.DataError, match="segments start from their own first sample"):
        load_run(path)
