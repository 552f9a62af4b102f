"""Lagrange remainders by interval Taylor mode (reachconf.tape + reachconf_kernels.taylor).

Soundness: the bound of ``lagrange_iv`` must contain the true remainder of
the linearisation ``f(p + d) - f(p) - J(p) d`` (order 2) and of the quadratic
expansion ``... - 1/2 H(p)[d, d]`` (order 3) at sampled points, evaluated
with the compiled point functions (which ``test_model.py`` checks against
sympy).  Tightness: the bound is not wildly above the sampled maximum, and it
is never above the older symbolic-tensor bound.
"""

import numpy as np
import pytest
import sympy as sp

import reachconf as rc
from reachconf.errors import ModelError, OptionsError
from reachconf.models import get_model
from reachconf.model.tape import build_tape
from reachconf_kernels import taylor as TM


def _box(model, rng, scale=0.05):
    """A random box around a valid operating point; inputs fixed (zero width)."""
    n, m, nz = model.n, model.m, model.nz
    c = rng.uniform(0.8, 1.2, nz)
    if model.name.startswith("bicycle"):
        c[3] = 10.0  # vx
    if model.name == "wind_turbine":
        c[n + 2] = 11.0  # wind speed above the tower velocity
    rad = rng.uniform(0.2, 1.0, nz) * scale * (np.abs(c) + 0.1)
    rad[n : n + m] = 0.0
    return c - rad, c + rad


def _true_remainders(comp, p, zp, D):
    """Remainders of order 2 and 3 at ``zp + d`` for each row ``d`` of D."""
    n, nz = comp.hess_pattern.shape[:2]
    f0, f1 = np.empty(n), np.empty(n)
    J = np.zeros((n, nz))
    H = np.zeros((n, nz, nz))
    comp.f(zp, p, f0)
    comp.jac(zp, p, J)
    comp.hess(zp, p, H)
    r2, r3 = [], []
    for d in D:
        comp.f(zp + d, p, f1)
        lin = f1 - f0 - J @ d
        r2.append(lin)
        r3.append(lin - 0.5 * np.einsum("ijk,j,k->i", H, d, d))
    return np.abs(r2), np.abs(r3)


def _check(model, comp, rng, boxes=12, samples=60, scale=0.05):
    """Sound on samples; returns the tightness ratios bound / sampled max per order."""
    p = model.param_vector
    ratios = {2: [], 3: []}
    for _ in range(boxes):
        zlo, zhi = _box(model, rng, scale)
        zp = rng.uniform(zlo, zhi)  # the linearisation point, anywhere in the box
        dlo, dhi = zlo - zp, zhi - zp
        corners = np.where(rng.random((samples // 2, model.nz)) < 0.5, dlo, dhi)
        D = np.vstack([rng.uniform(dlo, dhi, size=(samples // 2, model.nz)), corners])
        r2, r3 = _true_remainders(comp, p, zp, D)
        for K, r in ((2, r2), (3, r3)):
            bound = np.zeros(model.n)
            assert comp.lagrange_iv(zlo, zhi, dlo, dhi, p, K, bound) == 0
            # rounding of the float evaluation of f(p + d) - f(p) - J d itself (not part of the remainder)
            slack = 1e-12 * (1.0 + np.abs(D).max()) * (1.0 + np.abs(r2).max())
            assert np.all(r <= bound + slack), (model.name, K, r.max(axis=0), bound)
            big = r.max(axis=0) > 1e-9
            assert np.all(bound[~big] <= 1e-6), (K, bound)  # no remainder (e.g. a quadratic f at order 3)
            ratios[K].append(bound[big] / r.max(axis=0)[big])
    return {K: np.concatenate(v) for K, v in ratios.items()}


@pytest.mark.parametrize("name", ["vanderpol", "laub_loomis", "bicycle_closed_loop_actuated", "wind_turbine",
                                  "diff_drive", "bicycle_closed_loop_rate_limited"])  # fmt: skip
def test_remainder_bounds_contain_sampled_remainders_and_are_tight(name):
    model = get_model(name)
    comp = model.compiled()
    ratios = _check(model, comp, np.random.default_rng(3))
    for K in (2, 3):
        if ratios[K].size == 0:
            continue
        # a sampled maximum under-estimates the supremum, a bound over-estimates it: measured 1.0-1.2 in
        # the median on these boxes (an enclosure three times too large fails)
        assert np.median(ratios[K]) < 3.0, (K, np.median(ratios[K]))


def test_every_elementary_function_is_enclosed():
    """Every supported function (the Taylor rule of each), against sympy's derivatives evaluated with numpy.

    ``Abs``, ``Min`` and ``Max`` are used where one branch is active on the whole box (the reference
    expression takes that branch), so the remainder exists.
    """
    x, y, w = sp.symbols("x y w", real=True)
    common = [
        sp.exp(0.7 * x) * sp.sin(y) + sp.log(2 + x) * sp.cos(x * y) + sp.sqrt(3 + y) * w + sp.tan(0.3 * x)
        - sp.atan(x - y) + sp.tanh(2 * y) / (1.5 + x) + x**3 * w,
        (x + 2) ** -2 + (y + 3) ** sp.Rational(3, 2) + (1 + x**2) ** y + x * y * w,
    ]  # fmt: skip
    exprs = [common[0], common[1] + sp.Abs(x + 5) + sp.Min(x, y + 10) - sp.Max(x**2, y - 9)]
    reference = [common[0], common[1] + (x + 5) + x - x**2]
    z = (x, y, w)
    guards = []
    tape = build_tape(exprs, z, (), guards)
    f = sp.lambdify([z], reference, "numpy")
    J = sp.lambdify([z], sp.Matrix(reference).jacobian(z), "numpy")
    H = [sp.lambdify([z], sp.hessian(e, z), "numpy") for e in reference]
    rng = np.random.default_rng(5)
    for _ in range(30):
        c = rng.uniform(-0.5, 0.5, 3)
        rad = rng.uniform(0.01, 0.3, 3)
        zlo, zhi = c - rad, c + rad
        zp = rng.uniform(zlo, zhi)
        dlo, dhi = zlo - zp, zhi - zp
        b2, b3 = np.zeros(2), np.zeros(2)
        for K, b in ((2, b2), (3, b3)):
            assert TM.lagrange_bound(tape.ops, tape.consts, tape.outs, tape.tens, tape.segments, zlo, zhi, dlo, dhi,
                                     np.zeros(0), K, b) == 0  # fmt: skip
        f0, J0 = np.asarray(f(zp), float), np.asarray(J(zp), float)
        H0 = np.array([np.asarray(h(zp), float) for h in H])
        for d in np.vstack([rng.uniform(dlo, dhi, size=(40, 3)), np.where(rng.random((20, 3)) < 0.5, dlo, dhi)]):
            r2 = np.asarray(f(zp + d), float) - f0 - J0 @ d
            r3 = r2 - 0.5 * np.einsum("ijk,j,k->i", H0, d, d)
            assert np.all(np.abs(r2) <= b2 + 1e-12) and np.all(np.abs(r3) <= b3 + 1e-12), (r2, b2, r3, b3)


def test_taylor_bounds_are_never_above_the_tensor_bounds():
    """The older generator's interval Hessian / third-order tensor bound (same boxes) is never tighter."""
    rng = np.random.default_rng(11)
    for name in ("vanderpol", "bicycle", "wind_turbine"):
        model = get_model(name)
        new, old = model.compiled(order=3), model.compiled(order=3, remainder="tensor")
        p = model.param_vector
        tighter = 0
        for _ in range(20):
            zlo, zhi = _box(model, rng)
            zp = rng.uniform(zlo, zhi)
            for K in (2, 3):
                a, b = np.zeros(model.n), np.zeros(model.n)
                assert new.lagrange_iv(zlo, zhi, zlo - zp, zhi - zp, p, K, a) == 0
                assert old.lagrange_iv(zlo, zhi, zlo - zp, zhi - zp, p, K, b) == 0
                assert np.all(a <= b * (1 + 1e-12)), (name, K, a, b)
                tighter += np.sum(a < 0.99 * b)
        if name != "vanderpol":
            assert tighter > 0, name  # and it is strictly tighter on some boxes


def test_reach_taylor_matches_tensor_on_van_der_pol():
    model = get_model("vanderpol")
    X0 = rc.Interval([1.25, 2.35], [1.55, 2.45])
    tubes = [rc.reach(model, X0, 2.0, options=rc.ReachOptions(tensor_order=3, time_step=0.02, remainder=r))
             for r in ("taylor", "tensor")]  # fmt: skip
    a, b = (t.bounds()[-1] for t in tubes)
    width_a, width_b = a[1] - a[0], b[1] - b[0]
    assert np.all(width_a <= width_b * (1 + 1e-9)) and np.all(width_a >= 0.999 * width_b)


def test_guards_name_the_failed_operation():
    x = sp.Symbol("x", real=True)
    guards = []
    tape = build_tape([sp.log(x) + sp.sqrt(x) + 1 / x], (x,), (), guards)
    out = np.zeros(1)
    status = TM.lagrange_bound(tape.ops, tape.consts, tape.outs, tape.tens, tape.segments, np.array([-1.0]),
                               np.array([1.0]), np.array([-1.0]), np.array([1.0]), np.zeros(0), 2, out)  # fmt: skip
    assert status > 0 and any(w in guards[status - 1] for w in ("logarithm", "square root", "division"))
    # Abs is differentiable only away from 0
    guards = []
    tape = build_tape([sp.Abs(x)], (x,), (), guards)
    status = TM.lagrange_bound(tape.ops, tape.consts, tape.outs, tape.tens, tape.segments, np.array([-1.0]),
                               np.array([1.0]), np.array([-1.0]), np.array([1.0]), np.zeros(0), 2, out)  # fmt: skip
    assert status > 0 and "Abs" in guards[status - 1]


def test_bad_remainder_option_raises():
    with pytest.raises(OptionsError):
        rc.ReachOptions(remainder="mean-value")
    from reachconf.model.codegen import compile_model

    with pytest.raises(ModelError):
        compile_model(get_model("vanderpol"), remainder="nope")
    with pytest.raises(ModelError):
        build_tape([sp.sign(sp.Symbol("x", real=True))], (sp.Symbol("x", real=True),), (), [])
