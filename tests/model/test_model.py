"""Models, code generation, compiled derivatives and their cache."""

import json
import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest
import sympy as sp

import reachconf as rc
from reachconf.models import get_model


def _vdp():
    return rc.Model(
        name="vdp_test",
        states=("x", "y"),
        params={"mu": 1.0},
        dynamics=lambda s: [s.y, s.mu * (1 - s.x**2) * s.y - s.x],
    )


# ---------------------------------------------------------------- definition
def test_model_forms_agree():
    x, y, mu = sp.symbols("x y mu")
    as_exprs = rc.Model(states=("x", "y"), params={"mu": 1.0}, dynamics=[y, mu * (1 - x**2) * y - x])
    as_dict = rc.Model(states=("x", "y"), params={"mu": 1.0}, dynamics=lambda s: {"y": s.mu * (1 - s.x**2) * s.y - s.x, "x": s.y})

    class VdP(rc.Model):
        states = ("x", "y")
        params = {"mu": 1.0}

        def dynamics(self, s):
            return [s.y, s.mu * (1 - s.x**2) * s.y - s.x]

    for model in (as_exprs, as_dict, VdP()):
        assert np.allclose(model.f([1.0, 2.0]), [2.0, -1.0])
    assert as_exprs.output_names == ("x", "y")


def test_with_params_returns_new_model_without_recompiling():
    m = _vdp()
    m2 = m.with_params(mu=2.0)
    assert m.params["mu"] == 1.0 and m2.params["mu"] == 2.0
    assert np.allclose(m.f([0.5, 1.0]), [1.0, 0.25])
    assert np.allclose(m2.f([0.5, 1.0]), [1.0, 1.0])
    assert m2.compiled().path == m.compiled().path


@pytest.mark.parametrize(
    "kwargs, match",
    [
        (dict(states=("x",), dynamics=lambda s: [s.z]), "unknown name 'z'"),
        (dict(states=("x", "y"), dynamics=lambda s: [s.x]), "1 expressions for 2 states"),
        (dict(states=("x", "x"), dynamics=lambda s: [s.x, s.x]), "duplicate"),
        (dict(states=("x",), inputs=("x",), dynamics=lambda s: [s.x]), "twice"),
        (dict(states=("x",), params={"k": float("nan")}, dynamics=lambda s: [s.k * s.x]), "finite"),
        (dict(states=("x",), disturbances=("w",), dynamics=lambda s: [s.w], outputs=lambda s: {"y": s.w}), "additive"),
        (dict(states=("1x",), dynamics=lambda s: [0]), "not a valid signal name"),
        (dict(states=("x",), dynamics=[sp.Symbol("q")]), "unknown symbol 'q'"),
        (dict(states=("x",), dynamics=lambda s: {"y": s.x}), "unknown states"),
    ],
)
def test_model_errors(kwargs, match):
    with pytest.raises(rc.ModelError, match=match):
        rc.Model(**kwargs)


def test_with_params_unknown_name():
    with pytest.raises(rc.ModelError, match="no parameters"):
        _vdp().with_params(nu=1.0)


def test_get_model_unknown():
    with pytest.raises(rc.ModelError, match="unknown model"):
        get_model("no_such_model")


# ------------------------------------------------------ compiled derivatives
def _lambdified(model):
    z = model.z_symbols
    p = model.p_symbols
    f = sp.Matrix(model.f_expr)
    J = f.jacobian(z)
    H = [sp.hessian(fi, z) for fi in model.f_expr]
    return (
        sp.lambdify([z, p], f, "numpy"),
        sp.lambdify([z, p], J, "numpy"),
        [sp.lambdify([z, p], h, "numpy") for h in H],
    )


@pytest.mark.parametrize("name", ["vanderpol", "bicycle", "wind_turbine", "diff_drive"])
def test_compiled_derivatives_match_sympy(name):
    model = get_model(name)
    comp = model.compiled(order=3)
    f_ref, J_ref, H_ref = _lambdified(model)
    rng = np.random.default_rng(1)
    p = model.param_vector
    for _ in range(5):
        z = rng.uniform(0.5, 1.5, model.nz)
        if name == "wind_turbine":
            z[model.n + 2] = 10.0  # wind speed well above the tower velocity
        out = np.empty(model.n)
        comp.f(z, p, out)
        assert np.allclose(out, np.asarray(f_ref(z, p), float).ravel(), rtol=1e-12, atol=1e-12)
        J = np.zeros((model.n, model.nz))
        comp.jac(z, p, J)
        assert np.allclose(J, np.asarray(J_ref(z, p), float), rtol=1e-11, atol=1e-11)
        H = np.zeros((model.n, model.nz, model.nz))
        comp.hess(z, p, H)
        for i in range(model.n):
            assert np.allclose(H[i], np.asarray(H_ref[i](z, p), float), rtol=1e-10, atol=1e-10)


@pytest.mark.parametrize("name", ["vanderpol", "bicycle", "bicycle_actuated", "wind_turbine", "diff_drive"])
def test_interval_derivatives_enclose_point_values(name):
    """Sound: every sampled point value lies in the interval evaluation over the box (and it is tight).

    The symbolic interval tensors of the ``remainder="tensor"`` generator (the
    default Taylor-mode remainders are tested in ``test_taylor.py``).
    """
    model = get_model(name)
    comp = model.compiled(order=3, remainder="tensor")
    p = model.param_vector
    rng = np.random.default_rng(7)
    center = rng.uniform(0.8, 1.2, model.nz)
    if name == "wind_turbine":
        center[model.n + 2] = 11.0
    rad = 0.05 * np.abs(center) + 0.01
    zlo, zhi = center - rad, center + rad
    n, nz = model.n, model.nz
    Flo, Fhi = np.empty(n), np.empty(n)
    Hlo, Hhi = np.zeros((n, nz, nz)), np.zeros((n, nz, nz))
    Tlo, Thi = np.zeros((n, nz, nz, nz)), np.zeros((n, nz, nz, nz))
    assert comp.f_iv(zlo, zhi, p, Flo, Fhi) == 0
    assert comp.hess_iv(zlo, zhi, p, Hlo, Hhi) == 0
    assert comp.third_iv(zlo, zhi, p, Tlo, Thi) == 0
    samples = rng.uniform(zlo, zhi, size=(300, nz))
    corners = np.where(rng.random((50, nz)) < 0.5, zlo, zhi)
    f = np.empty(n)
    H = np.zeros((n, nz, nz))
    T = np.zeros((n, nz, nz, nz))
    fmin = np.full(n, np.inf)
    fmax = np.full(n, -np.inf)
    for z in np.vstack([samples, corners]):
        comp.f(z, p, f)
        comp.hess(z, p, H)
        comp.third(z, p, T)
        assert np.all(Flo <= f) and np.all(f <= Fhi)
        assert np.all(Hlo <= H) and np.all(H <= Hhi)
        assert np.all(Tlo <= T) and np.all(T <= Thi)
        fmin, fmax = np.minimum(fmin, f), np.maximum(fmax, f)
    # tightness: the enclosure is not wildly larger than the sampled range
    width = Fhi - Flo
    assert np.all(width <= 20 * (fmax - fmin) + 1e-6 * (1 + np.abs(fmax)))


@pytest.mark.parametrize("remainder", ["taylor", "tensor"])
def test_interval_guard_reports_domain_error(remainder):
    model = get_model("bicycle")
    comp = model.compiled(remainder=remainder)
    nz = model.nz
    zlo = np.full(nz, -1.0)
    zhi = np.full(nz, 1.0)  # vx box contains 0: division guarded
    out = np.zeros(model.n)
    zp = np.zeros(nz)
    status = comp.lagrange_iv(zlo, zhi, zlo - zp, zhi - zp, zp, zp, np.zeros((nz, 0)), model.param_vector, 2, out)
    assert status > 0
    assert "division" in comp.guards[status - 1]


def test_cache_second_process_does_not_recompile(tmp_path):
    """A second process imports the generated module and loads numba's cache: no compilation."""
    script = textwrap.dedent(
        """
        import json, sys
        import reachconf as rc
        m = rc.Model(name="cache_probe", states=("x", "y"), params={"k": 3.0},
                     dynamics=lambda s: [s.y, -s.k * s.x + s.x**3])
        comp = m.compiled()
        misses = sum(sum(d.stats.cache_misses.values()) for d in comp.dispatchers().values())
        hits = sum(sum(d.stats.cache_hits.values()) for d in comp.dispatchers().values())
        print(json.dumps({"from_cache": comp.loaded_from_cache, "misses": misses, "hits": hits,
                          "seconds": comp.seconds}))
        """
    )
    env = dict(os.environ, REACHCONF_CACHE=str(tmp_path))
    runs = []
    for _ in range(2):
        out = subprocess.run([sys.executable, "-c", script], env=env, capture_output=True, text=True, timeout=600)
        assert out.returncode == 0, out.stderr
        runs.append(json.loads(out.stdout.strip().splitlines()[-1]))
    first, second = runs
    assert not first["from_cache"] and first["misses"] > 0
    assert second["from_cache"] and second["misses"] == 0 and second["hits"] > 0


def test_output_enclosure_holds_h_at_the_centre_despite_cancellation():
    """``h = x^2 - y^2`` at points x, y ~ 1e4 of 1e-12 apart: the float h(c) is 1e-4 of the result off.

    The enclosure allowed 1e-14 of the result for the rounding of h(c); every one of these points' exact
    outputs was outside its own output set.
    """
    from fractions import Fraction

    from reachconf.model.outputs import output_enclosure

    m = rc.Model(name="hq", states=("x", "y"), dynamics=lambda s: [0 * s.x, 0 * s.y],
                 outputs=lambda s: {"h": s.x**2 - s.y**2})  # fmt: skip
    rng = np.random.default_rng(0)
    for _ in range(50):
        x = 1e4 * (1 + rng.random())
        y = x * (1 - 1e-12 * rng.random())
        O = output_enclosure(m, rc.Zonotope(np.array([x, y]), np.zeros((2, 0))))
        exact = Fraction(x) ** 2 - Fraction(y) ** 2
        assert abs(Fraction(O.center[0]) - exact) <= Fraction(np.abs(O.generators).sum())
        assert np.abs(O.generators).sum() <= 4 * np.finfo(float).eps * x * x  # and tight: a few ulps of the squares


def test_affine_output_enclosure_holds_the_exact_output_despite_cancellation():
    """``y = 0.1 x - 0.3 z + 0.7 u + 0.2`` near 0 from terms of 1e6: the float ``C c + D u + e`` is ulps of the
    terms off, and the affine path added no allowance: the exact outputs of point sets were outside their sets."""
    from fractions import Fraction

    from reachconf.model.outputs import output_enclosure

    m = rc.Model(name="aff_cancel", states=("x", "z"), inputs=("u",), dynamics=lambda s: [0 * s.x, 0 * s.z],
                 outputs=lambda s: {"y": 0.1 * s.x - 0.3 * s.z + 0.7 * s.u + 0.2})  # fmt: skip
    C, D, e = (Fraction(0.1), Fraction(-0.3)), Fraction(0.7), Fraction(0.2)
    rng = np.random.default_rng(20261127)
    for _ in range(50):
        x, z = rng.uniform(1e6, 2e6), rng.uniform(1e6, 2e6)
        u = float((-(C[0] * Fraction(x) + C[1] * Fraction(z)) - e) / D) * (1 + 1e-15 * rng.normal())
        for S in (rc.Zonotope([x, z], np.zeros((2, 0))), rc.Interval([x, z], [x, z])):
            O = output_enclosure(m, S, [u])
            exact = C[0] * Fraction(x) + C[1] * Fraction(z) + D * Fraction(u) + e
            assert Fraction(O.interval().lo[0]) <= exact <= Fraction(O.interval().hi[0])
            assert O.contains([float(exact)], tol=0.0)
            assert O.interval().hi[0] - O.interval().lo[0] <= 1e-14 * 1e6  # a few ulps of the terms
