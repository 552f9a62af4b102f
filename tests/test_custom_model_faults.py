"""Faults an engineer bringing their own model met (a third new-user pass, 2 Dec): each test says what happened before."""

import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest
import sympy as sp

import reachconf as rc


def test_a_time_near_a_sample_gets_sets_that_hold_the_state_then():
    """Was: ReachTube.at(t) gave the sample's time-point set within 1e-9 of the tube's span (1e-5 s on a 10,000-s
    tube), where a state moving at 1000 units/s had left it: a true state reported outside."""
    m = rc.Model(name="qa_drift", states=("x", "y"), dynamics=["1000.0 + 0*y", "-y"])
    tube = rc.reach(m, rc.Interval([0.0, 1.0], [0.0, 1.0]), np.linspace(0.0, 10000.0, 11))
    for dt in (-9e-6, -2e-6, 2e-6, 5e-6, 9e-6, 2e-5):
        t = 5000.0 + dt
        assert tube.at(t).contains([1000.0 * t, np.exp(-t)]), dt
        assert tube.contains([t], [[1000.0 * t, 0.0]], output=False).conformant, dt
    assert tube.at(5000.0) is tube.time_point_sets[5]
    # and no looser than needed: just after a sample, the one step's time-interval set (x spans that step's 1e6)
    assert tube.at(5000.0 + 2e-6) is tube.time_interval_sets[int(np.searchsorted(tube.time_intervals[:, 1], 5000.0 + 2e-6))]
    width = np.ptp(tube.bounds()[:, :, 0], axis=1)
    assert width.max() < 1.01e6 and np.ptp([tube.time_point_sets[5].interval().lo[0], tube.time_point_sets[5].interval().hi[0]]) < 1e-2
    assert tube.at(np.nextafter(5000.0, 6000.0)) is tube.time_point_sets[5]  # a stamp's rounding is the sample
    with pytest.raises(rc.ReachError, match="outside the tube"):
        tube.at(10000.0 + 1e-6)


def test_outputs_that_depend_on_inputs_need_the_inputs():
    """Was: contains(times, Y) without inputs= used u = 0 for h(x, u) = x + u: every true measurement outside, and
    an impossible one conformant."""
    m = rc.Model(name="qa_feedthrough", states=("x",), inputs=("u",), dynamics=["-x + u"], outputs={"y": "x + u"})
    t = np.linspace(0, 1, 11)
    U = np.ones((t.size, 1))
    tube = rc.reach(m, rc.Interval([-0.01], [0.01]), t, inputs=U)
    y = (1 - np.exp(-t) + 1.0)[:, None]
    assert tube.contains(t, y, inputs=U).conformant
    assert not tube.contains(t, y - 1.0, inputs=U).conformant
    for call in (lambda: tube.contains(t, y), lambda: tube.output_sets()):
        with pytest.raises(rc.DataError, match=r"outputs of model 'qa_feedthrough' depend on the inputs \['u'\]"):
            call()
    # outputs without inputs need none
    m2 = rc.Model(name="qa_no_feedthrough", states=("x",), inputs=("u",), dynamics=["-x + u"], outputs={"y": "2*x"})
    tube2 = rc.reach(m2, rc.Interval([-0.01], [0.01]), t, inputs=U)
    assert tube2.contains(t, 2 * (1 - np.exp(-t))[:, None]).conformant


def test_a_loaded_tube_checks_states_and_says_why_not_outputs(tmp_path):
    """Was: contains() on a tube loaded from .npz stopped with AttributeError: 'NoneType' object has no attribute 'm'."""
    m = rc.Model(name="qa_decay", states=("x",), dynamics=["-x"])
    t = np.linspace(0, 1, 11)
    loaded = rc.ReachTube.load(rc.reach(m, rc.Interval([0.9], [1.1]), t).save(tmp_path / "tube.npz"))
    assert loaded.contains(t, np.exp(-t)[:, None], output=False).conformant
    with pytest.raises(rc.ReachError, match="no model attached .* check states \\(output=False\\)"):
        loaded.contains(t, np.exp(-t)[:, None])


def test_a_damaged_cache_entry_is_generated_again(tmp_path):
    """Was: a cut-off generated module or an empty metadata file in $REACHCONF_CACHE/models stopped every later build
    of the model with SyntaxError / EOFError / BadZipFile."""
    env = {**os.environ, "REACHCONF_CACHE": str(tmp_path), "PYTHONWARNINGS": "default"}
    script = textwrap.dedent("""
        import reachconf as rc
        m = rc.Model(name="qa_cc", states=("x",), dynamics=["-x"])
        print(m.f([1.0])[0], m.compiled().loaded_from_cache)
    """)
    run = lambda: subprocess.run([sys.executable, "-c", script], env=env, capture_output=True, text=True, timeout=300)  # noqa: E731
    assert run().stdout.split() == ["-1.0", "False"]
    folder = tmp_path / "models"
    (src,) = folder.glob("reachconf_gen_qa_cc_*.py")
    src.write_text(src.read_text()[:300])
    out = run()
    assert out.returncode == 0 and out.stdout.split() == ["-1.0", "False"], out.stderr
    assert "cached code" in out.stderr and "damaged" in out.stderr
    (meta,) = folder.glob("reachconf_gen_qa_cc_*.npz")
    meta.write_bytes(b"")
    out = run()
    assert out.returncode == 0 and out.stdout.split() == ["-1.0", "False"], out.stderr
    assert run().stdout.split() == ["-1.0", "True"]


@pytest.mark.parametrize("text, message", [
    ("-E*x", r"uses 'E', which sympy reads as E = 2.71828; declare 'E' .* \(or write exp\(1\)\)"),
    ("-GoldenRatio*x", r"uses 'GoldenRatio', which sympy reads as GoldenRatio"),
    ("-I*x", r"uses 'I', which sympy reads as I"),
    ("-beta*x", r"uses 'beta' without a call, which sympy reads as its function beta\(\)"),
])
def test_undeclared_names_sympy_knows_are_refused_in_text(text, message):
    """Was: x' = -E*x ran as x' = -2.718 x (E, I, GoldenRatio, Catalan taken as sympy's constants), and -beta*x
    failed with "bad operand type for unary -: 'FunctionClass'"."""
    with pytest.raises(rc.ModelError, match=message):
        rc.Model(name="qa_names", states=("x",), dynamics=[text])
    m = rc.Model(name="qa_names_ok", states=("x",), params={"E": 2.0}, dynamics=["-E*x + pi*0 + exp(1)*0 + 1e-3*sin(x)"])
    assert m.f([1.0])[0] == pytest.approx(-2.0 + 1e-3 * np.sin(1.0))


def test_symbols_with_sign_assumptions_are_refused():
    """Was: sp.Symbol("x", positive=True) let sympy turn -sqrt(x**2) - |x| into -2x before the model saw it:
    f(-1) = +2 instead of -2."""
    xp = sp.Symbol("x", positive=True)
    with pytest.raises(rc.ModelError, match=r"the variable 'x' created with assumptions \(.*positive.*\)"):
        rc.Model(name="qa_pos", states=("x",), dynamics=[-sp.sqrt(xp**2) - sp.Abs(xp)])
    m = rc.Model(name="qa_real", states=("x",), dynamics=[-sp.sqrt(sp.Symbol("x", real=True) ** 2) - sp.Abs(sp.Symbol("x"))])
    assert m.f([-1.0])[0] == pytest.approx(-2.0)
    k = sp.Symbol("k", positive=True)  # a parameter's assumption is a statement about its value: accepted
    assert rc.Model(name="qa_kpos", states=("x",), params={"k": 2.0}, dynamics=[-k * sp.Symbol("x")]).f([1.0])[0] == -2.0


def test_model_functions_and_names_that_cannot_work_say_why():
    """Was: np.sin on a symbol escaped as a bare TypeError; an output named t was accepted and clashed with the time
    column of test cases later; sign in an output told the user to use remainder='taylor', the default; the
    generator's internal names (s_x) in its messages."""
    with pytest.raises(rc.ModelError, match=r"model 'qa_np': dynamics\(symbols\) raised TypeError.*sympy's functions"):
        rc.Model(name="qa_np", states=("x",), dynamics=lambda s: [np.sin(s.x)])
    with pytest.raises(rc.ModelError, match=r"outputs: 't' is the time column"):
        rc.Model(name="qa_t", states=("t",), dynamics=["-t"])
    with pytest.raises(rc.ModelError, match=r"outputs: 't' is the time column"):
        rc.Model(name="qa_t2", states=("x",), dynamics=["-x"], outputs={"t": "x"})
    assert rc.Model(name="qa_t3", states=("t", "x"), dynamics=["1", "-x"], outputs=["x"]).output_names == ("x",)
    sign = rc.Model(name="qa_sign_out", states=("x",), dynamics=["-x"], outputs={"y": "sign(x)"})
    with pytest.raises(rc.ModelError, match=r"model 'qa_sign_out': .*DiracDelta\(x\) \(a derivative of sign or Heaviside"):
        sign.compiled()
    pw = rc.Model(name="qa_pw", states=("x",), dynamics=["Piecewise((-x, x > 0), (-2*x, True))"])
    with pytest.raises(rc.ModelError, match=r"model 'qa_pw': .*Piecewise \(in Piecewise\(\(-x, x > 0\)"):
        pw.compiled()


def test_a_simulation_that_leaves_the_models_domain_is_an_error():
    """Was: rc.simulate returned NaN rows without a word (cbrt of a negative state, a finite escape time)."""
    m = rc.Model(name="qa_cbrt2", states=("x", "v"), dynamics=lambda s: [s.v, -sp.cbrt(s.x) - 0.5 * s.v])
    with pytest.raises(rc.ModelError, match=r"model 'qa_cbrt2': the simulation is not finite from t = 1.95 on \(state 'x'"):
        rc.simulate(m, [0.6, 0.45], np.linspace(0, 4, 81))
    b = rc.Model(name="qa_blowup", states=("x",), dynamics=["x**2"])
    with pytest.raises(rc.ModelError, match="escapes to infinity"):
        rc.simulate(b, [2.0], np.linspace(0, 1, 6))
    assert np.all(np.isfinite(rc.simulate(b, [2.0], np.linspace(0, 0.4, 5))))
    assert not np.all(np.isfinite(rc.simulate(b, np.array([2.0]), np.linspace(0, 1, 6), inputs=np.zeros((6, 0)),
                                              disturbances=np.zeros((6, 0)), check=False)))  # the library's own loops


def test_threads_share_one_build_of_a_model(tmp_path):
    """Was: two threads calling Model.compiled() on the same model: one took the other's half-imported module from
    sys.modules and stopped on "has no attribute 'f_iv'" (the vehicle example's --quick --workers 2, 5 runs of 6)."""
    script = textwrap.dedent("""
        import threading
        import reachconf as rc
        errors = []
        for k in range(3):  # warm cache after the first round: the import itself is the window
            m = rc.models.bicycle(c_f=17.1 + k)
            def go():
                try:
                    m.compiled()
                except Exception as exc:
                    errors.append(repr(exc))
            threads = [threading.Thread(target=go) for _ in range(3)]
            [t.start() for t in threads]
            [t.join() for t in threads]
        print(errors or "ok")
    """)
    env = {**os.environ, "REACHCONF_CACHE": str(tmp_path)}
    for _ in range(2):  # cold cache, then warm
        out = subprocess.run([sys.executable, "-c", script], env=env, capture_output=True, text=True, timeout=600)
        assert out.returncode == 0 and out.stdout.strip() == "ok", (out.stdout, out.stderr[-2000:])


def test_signals_no_expression_uses_are_warned_about():
    """Was: a declared disturbance the dynamics never use got no word, and synthesis returned a box of about
    ±5e-10 for it (most often a typo in a name)."""
    with pytest.warns(UserWarning, match=r"disturbances \['w2'\] appear in no dynamics; inputs \['u2'\] appear in no "):
        rc.Model(name="qa_unused", states=("x",), inputs=("u", "u2"), disturbances=("w", "w2"), dynamics=["-x + u + w"])
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error")  # an input used only by the outputs is used
        rc.Model(name="qa_used", states=("x",), inputs=("u",), disturbances=("w",), dynamics=["-x + w"],
                 outputs={"y": "x + u"})  # fmt: skip


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="fork")
def test_a_forked_child_builds_while_a_parent_thread_holds_the_build_lock():
    """The build lock of a thread is not inherited locked by a forked child (the diagnosis forks its fit workers)."""
    import multiprocessing as mp
    import threading

    from reachconf.model import generated

    held, release = threading.Event(), threading.Event()

    def hold():
        with generated.BUILD_LOCK:
            held.set()
            release.wait(60)

    t = threading.Thread(target=hold)
    t.start()
    held.wait(10)
    try:
        ctx = mp.get_context("fork")
        q = ctx.Queue()
        p = ctx.Process(target=_child_build, args=(q,))
        p.start()
        p.join(120)
        assert p.exitcode == 0 and q.get(timeout=5) == -1.0
    finally:
        release.set()
        t.join()


def _child_build(q):
    q.put(float(rc.Model(name="qa_fork_child", states=("x",), dynamics=["-x"]).f([1.0])[0]))


def test_a_badly_scaled_linear_model_is_told_to_rescale():
    """Was: a linear model whose states differ by 1e9 in scale failed at t = 0 with advice for nonlinear models
    (tensor_order=3, splitting), which cannot help; in rescaled units it reaches."""
    m = rc.Model(name="qa_scaled_lin", states=["a", "b"], dynamics=["-a + 1e-9*b", "-0.5*b + 1e9*a"])
    X0 = rc.Interval([1e-6, 999.0], [1.1e-6, 1001.0])
    for algorithm in ("adaptive", "lin"):
        with pytest.raises(rc.ReachError, match=r"The model is linear.*an entry of 1e\+09 .* Rescale the states"):
            rc.reach(m, X0, np.linspace(0, 1, 6), options=rc.ReachOptions(algorithm=algorithm))
    units = rc.Model(name="qa_scaled_lin_units", states=["A", "b"], dynamics=["-A + 1e-3*b", "-0.5*b + 1e3*A"])
    assert rc.reach(units, rc.Interval([1.0, 999.0], [1.1, 1001.0]), np.linspace(0, 1, 6)).final_set().dim == 2
