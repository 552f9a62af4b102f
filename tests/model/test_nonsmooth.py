"""Abs, Min and Max in a model's dynamics (found by a bad-input audit: their derivatives, sympy's sign,
Heaviside and DiracDelta, failed code generation with a printer error, although the generator's own message
lists them as supported).

The point derivatives take their values where the function is differentiable; the remainder over a set
comes from Taylor mode, whose guards stop a reach whose set crosses a kink (a ReachError naming the
operation) — sound by construction, checked here against simulated trajectories.
"""

import numpy as np
import pytest
import sympy as sp
from scipy.integrate import solve_ivp

import reachconf as rc


def _model():
    return rc.Model(name="nonsmooth_drag", states=("x", "y"), inputs=("u",),
                    dynamics=lambda s: [-s.x * sp.Abs(s.x) + s.u,
                                        -sp.Max(s.y, 0.2 * s.y) + sp.Min(s.x, 2.0)])  # fmt: skip


def _rhs(t, z, u):
    x, y = z
    return [-x * abs(x) + u, -max(y, 0.2 * y) + min(x, 2.0)]


def test_point_functions_and_derivatives():
    m = _model()
    np.testing.assert_allclose(m.f([0.5, 0.3], [0.1]), [-0.25 + 0.1, -0.3 + 0.5])
    np.testing.assert_allclose(m.f([-0.5, -0.3], [0.0]), [0.25, 0.06 - 0.5])
    comp = m.compiled()
    z, J = np.array([-0.5, -0.3, 0.0]), np.zeros((2, 3))
    comp.jac(z, m.param_vector, J)
    np.testing.assert_allclose(J, [[-1.0, 0.0, 1.0], [1.0, -0.2, 0.0]])  # d(-x|x|)/dx = -2|x|; y < 0: Max = 0.2 y


def test_reach_is_sound_away_from_the_kinks():
    m = _model()
    lo, hi = np.array([0.5, 0.5]), np.array([0.6, 0.6])
    times = np.linspace(0.0, 3.0, 61)
    tube = rc.reach(m, rc.Interval(lo, hi), times, inputs=np.full((times.size, 1), 0.5))
    rng = np.random.default_rng(20261127)
    corners = np.array(np.meshgrid(*zip(lo, hi))).reshape(2, -1).T
    for p in np.vstack([corners, rng.uniform(lo, hi, size=(196, 2))]):
        X = solve_ivp(_rhs, (0.0, 3.0), p, t_eval=times, args=(0.5,), rtol=1e-10, atol=1e-12).y.T
        assert all(tube.time_point_sets[k].contains(X[k], tol=1e-9) for k in range(times.size))
    width = tube.final_set().interval()
    assert np.all(width.hi - width.lo < 0.2)


def test_a_set_across_a_kink_stops_with_the_operation_named():
    m = _model()
    with pytest.raises(rc.ReachError, match=r"Abs of an interval containing 0 \(not differentiable there\) in Abs\(x\)"):
        rc.reach(m, rc.Interval([-0.1, 0.5], [0.1, 0.6]), 1.0, inputs=[0.5])


@pytest.mark.parametrize("dyn, needle", [
    (lambda s: [s.x + sp.oo], "is not finite"),
    (lambda s: [sp.nan * s.x], "is not finite"),
    (lambda s: [sp.Float("1e400") * s.x], r"is not finite \(as float64\)"),
    (lambda s: [sp.Integer(10) ** 400 * s.x], r"is not finite \(as float64\)"),
    (lambda s: [sp.Function("g")(s.x)], r"undefined function\(s\) \['g'\]"),
    (lambda s: [sp.Derivative(s.x**2, s.x)], "unevaluated derivative"),
])
def test_expressions_that_cannot_be_a_model_are_refused_when_built(dyn, needle):
    with pytest.raises(rc.ModelError, match=needle):
        rc.Model(name="bad_expr", states=("x",), dynamics=dyn)


def test_the_legacy_tensor_remainder_points_to_taylor_mode():
    """The legacy ``remainder="tensor"`` path prints the derivatives symbolically; a second derivative of Abs is a
    DiracDelta, which it cannot bound: the error says which remainder can."""
    m = _model()
    opts = rc.ReachOptions(algorithm="lin", tensor_order=3, remainder="tensor")
    with pytest.raises(rc.ModelError, match=r"DiracDelta.*second derivative of Abs, Min or Max.*remainder='taylor'"):
        rc.reach(m, rc.Interval([0.9, 0.5], [1.1, 0.6]), np.linspace(0.0, 0.1, 3), inputs=np.zeros((3, 1)),
                 options=opts)  # fmt: skip


def test_code_that_cannot_be_generated_names_the_model():
    m = rc.Model(name="floor_model", states=("x",), dynamics=lambda s: [-sp.floor(s.x)])
    with pytest.raises(rc.ModelError, match="model 'floor_model': cannot generate code"):
        m.f([0.5])
    # finite constants whose derivatives overflow float64 (the Hessian of 1e306 x^1000 holds 9.99e311): named as such
    m = rc.Model(name="overflow_model", states=("x",), dynamics=lambda s: [-sp.Float("1e306") * s.x**1000])
    with pytest.raises(rc.ModelError, match=r"cannot generate code .*a constant overflows float64"):
        m.f([0.5])


def test_outputs_with_abs_min_max_compile_and_their_enclosures_hold_across_the_kinks():
    """An output with Abs, Min or Max: the interval Jacobian of ``h`` holds sympy's sign and Heaviside, which the
    interval code generator refused ("does not support sign"), so the model did not build (found by a codegen fuzz
    audit).  Over a set across a kink they enclose the generalised gradients: the output set holds every sample."""
    from reachconf.model.outputs import output_enclosure

    m = rc.Model(name="nonsmooth_outputs", states=("x", "y"), dynamics=lambda s: [s.y, -s.x],
                 outputs=lambda s: {"a": sp.Abs(s.x - s.y) + s.y, "b": sp.Max(s.x, 2 * s.y - 1) * s.x,
                                    "c": sp.Min(s.x ** 2, s.y)})  # fmt: skip
    rng = np.random.default_rng(11)
    for c, r in (([0.1, 0.1], [0.3, 0.2]), ([1.0, 1.0], [0.05, 0.5]), ([0.0, 0.0], [0.0, 0.4]), ([2.0, -1.0], [0.1, 0.1])):
        S = rc.Zonotope(c, np.diag(r) @ np.array([[1.0, 0.5], [-0.2, 1.0]]))
        Y = output_enclosure(m, S)
        X = np.array(c) + rng.uniform(-1, 1, size=(400, 2)) @ np.array(S.generators).T
        X = np.vstack([X, np.array(c) + np.array([[1, 1], [1, -1], [-1, 1], [-1, -1]]) @ np.array(S.generators).T])
        H = np.array([[abs(x - y) + y, max(x, 2 * y - 1) * x, min(x * x, y)] for x, y in X])
        assert np.all(Y.contains(H, tol=1e-12)), c


def test_abs_of_arguments_sympy_cannot_prove_real_compiles_with_real_derivatives():
    """``Abs(log(x + 3))``, ``Abs((x + 3) ** y)``: sympy differentiates them as complex moduli (``re``, ``im``,
    ``arg``, unevaluated derivatives of ``sign``), which the printer refused — the model did not build (found by a
    codegen fuzz audit).  They are differentiated as real functions now: the Jacobian and Hessian match differences."""
    m = rc.Model(name="abs_of_log", states=("x", "y"),
                 dynamics=lambda s: [-sp.Abs(sp.log(s.x + 3)) * s.y, sp.Abs((s.x + 3) ** s.y) - sp.Abs(sp.sqrt(s.x + 3))])  # fmt: skip
    comp = m.compiled()
    p = m.param_vector
    for z in ([0.5, 0.7], [-2.5, 1.2], [1.0, -0.4]):  # log(x + 3) > 0 and < 0
        z = np.array(z)
        J, H = np.zeros((2, 2)), np.zeros((2, 2, 2))
        comp.jac(z, p, J)
        comp.hess(z, p, H)
        for j in range(2):
            e = np.eye(2)[j] * 1e-6
            np.testing.assert_allclose(J[:, j], (m.f(z + e) - m.f(z - e)) / 2e-6, rtol=1e-6, atol=1e-8)
            Jp, Jm = np.zeros((2, 2)), np.zeros((2, 2))
            comp.jac(z + e, p, Jp)
            comp.jac(z - e, p, Jm)
            np.testing.assert_allclose(H[:, :, j], (Jp - Jm) / 2e-6, rtol=1e-5, atol=1e-7)
