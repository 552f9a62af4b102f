"""The Fiala tyre effect ``tire_fiala`` (issue 17): the force law, the rewritten model, its targets."""

import numpy as np
import pytest
import sympy as sp

from reachconf.diagnose import EFFECTS
from reachconf.diagnose.tyres import fiala_force
from reachconf.errors import ModelError
from reachconf.models import bicycle, single_track


def _fiala_exact(c, alpha, fmax):
    u = c * alpha / fmax
    return np.where(np.abs(u) <= 3, fmax * (u - u * np.abs(u) / 3 + u**3 / 27), fmax * np.sign(u))


def _f(model):
    """``f(x, u)`` with ``w = 0`` by sympy (no code generation: these tests stay quick)."""
    fn = sp.lambdify((model.z_symbols, model.p_symbols), list(model.f_expr), "numpy")
    return lambda x, u: np.array(fn(np.r_[x, u, np.zeros(model.q)], model.param_vector), float)


def test_smoothed_force_is_the_brush_model_within_a_tenth_of_a_percent_of_the_limit():
    c, a, f = sp.symbols("c a f", real=True)
    force = sp.lambdify((c, a, f), fiala_force(c, a, f), "numpy")
    rng = np.random.default_rng(3)
    for _ in range(20):
        cc, ff = rng.uniform(2e4, 2e5), rng.uniform(1e3, 8e3)
        alpha = np.linspace(-0.3, 0.3, 2001)
        got, want = force(cc, alpha, ff), _fiala_exact(cc, alpha, ff)
        assert np.max(np.abs(got - want)) <= 1e-3 * ff
        assert np.all(np.diff(got) >= -1e-9 * ff)  # monotone
        assert np.max(np.abs(got)) <= ff * (1 + 1e-9)
        slope = (force(cc, 1e-6, ff) - force(cc, -1e-6, ff)) / 2e-6
        assert slope == pytest.approx(cc, rel=1e-4)  # the linear tyre's cornering stiffness at zero slip


def test_effect_targets_and_large_friction_gives_the_linear_model():
    car = single_track()
    eff = EFFECTS["tire_fiala"]
    assert eff.applicable(car) == ["c_f", "c_r", "axles"]
    assert eff.applicable(bicycle()) == []
    rng = np.random.default_rng(0)
    for target in ("c_f", "c_r", "axles"):
        m = eff.apply_model(car, target, (1e4,))
        assert m.state_names == car.state_names and m.param_names[-1] == f"tire_fiala_mu_{target}"
        fm, fc = _f(m), _f(car)
        for _ in range(10):
            x = np.array([rng.uniform(10, 50), rng.uniform(-1, 1), rng.uniform(-0.5, 0.5)])
            u = np.array([0.0, rng.uniform(-0.1, 0.1)])
            np.testing.assert_allclose(fm(x, u), fc(x, u), rtol=1e-3, atol=1e-3)


def test_low_friction_limits_the_lateral_acceleration():
    """With mu = 0.5 on both axles the tyre forces cannot give more than mu g of lateral acceleration."""
    car = single_track()
    m = EFFECTS["tire_fiala"].apply_model(car, "axles", (0.5,))
    x = np.array([30.0, 0.0, 0.0])
    fm, fc = _f(m), _f(car)
    for delta in (0.05, 0.2, 0.4):
        ay = fm(x, np.array([0.0, delta]))[1] + x[0] * x[2]  # vy' + vx omega
        assert abs(ay) <= 0.5 * 9.81 * 1.001
    lin = fc(x, np.array([0.0, 0.4]))[1] + x[0] * x[2]
    assert abs(lin) > 4 * 0.5 * 9.81  # the linear tyre does not saturate


def test_model_outside_the_convention_is_refused():
    with pytest.raises(ModelError, match="single-track convention"):
        EFFECTS["tire_fiala"].apply_model(bicycle(), "c_f", (1.0,))


def test_a_second_tyre_effect_leaves_an_already_saturated_axle_alone():
    """Pairs of the diagnosis (axles + c_r) must not fail: the second mu does not act on the saturated axle."""
    car = single_track()
    eff = EFFECTS["tire_fiala"]
    both = eff.apply_model(car, "axles", (0.8,))
    again = eff.apply_model(both, "c_r", (0.3,))
    x, u = np.array([25.0, 0.4, 0.3]), np.array([0.0, 0.08])
    np.testing.assert_allclose(_f(again)(x, u), _f(both)(x, u), rtol=1e-12)
