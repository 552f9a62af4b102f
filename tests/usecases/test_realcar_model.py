"""The built-in model ``single_track`` (issue 17): names, equations, steady-state cornering, real data."""

import gzip

import numpy as np
import pytest
from conftest import DATA_ROOT

from reachconf.model.simulate import simulate
from reachconf.models import get_model, single_track

DATA = DATA_ROOT / "realcar" / "stanford_track_100hz.csv.gz"
README_VALUES = {"m": 982.0, "l_f": 1.33, "l_r": 1.07, "J_z": 1605.0, "c_f": 0.7e5, "c_r": 1.2e5}


def _reference_f(x, u, w, p):
    """The equations of the docstring, written again with numpy (ISO 8855 signs)."""
    vx, vy, om = x
    ax, d = u
    a_f = d - np.arctan((vy + p["l_f"] * om) / vx)
    a_r = -np.arctan((vy - p["l_r"] * om) / vx)
    f_f, f_r = p["c_f"] * a_f, p["c_r"] * a_r
    return np.array([ax + vy * om + w[0],
                     (f_f * np.cos(d) + f_r) / p["m"] - vx * om + w[1],
                     (p["l_f"] * f_f * np.cos(d) - p["l_r"] * f_r) / p["J_z"] + w[2]])  # fmt: skip


def test_names_and_defaults_are_the_contract():
    car = single_track()
    assert car.state_names == ("vx", "vy", "omega")
    assert car.output_names == ("vx", "vy", "omega")
    assert car.input_names == ("ax", "delta")
    assert car.disturbance_names == ("w_vx", "w_vy", "w_omega")
    assert dict(car.params) == README_VALUES
    assert get_model("single_track", c_f=8e4).params["c_f"] == 8e4


def test_equations_match_an_independent_implementation():
    rng = np.random.default_rng(17)
    p = {k: v * rng.uniform(0.7, 1.3) for k, v in README_VALUES.items()}
    car = single_track(**p)
    for _ in range(20):
        x = np.array([rng.uniform(10, 60), rng.uniform(-2, 2), rng.uniform(-0.6, 0.6)])
        u = np.array([rng.uniform(-10, 7), rng.uniform(-0.15, 0.5)])
        w = rng.normal(size=3)
        np.testing.assert_allclose(car.f(x, u, w), _reference_f(x, u, w, p), rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(car.h(x, u), x)


def test_signs_left_steer_turns_left_and_the_car_understeers():
    """Steady state of the linear model: omega = vx delta / (L + K vx^2), K = m (l_r/c_f - l_f/c_r) / L > 0."""
    car = single_track()
    p = car.params
    L = p["l_f"] + p["l_r"]
    K = p["m"] * (p["l_r"] / p["c_f"] - p["l_f"] / p["c_r"]) / L
    assert K > 0  # the README's values make an understeering car
    vx, delta = 20.0, 0.02
    t = np.arange(0.0, 8.0, 0.01)
    X = simulate(car, [vx, 0.0, 0.0], t, inputs=[0.0, delta])
    assert X[-1, 2] > 0  # steering to the left yaws to the left
    # the small-angle steady state (the model has atan and cos: 1 % agreement)
    np.testing.assert_allclose(X[-1, 2], vx * delta / (L + K * vx**2), rtol=0.01)
    assert X[-1, 1] < 0  # at speed the rear slides out: vy < 0 in a left turn, so vx' = vy omega < 0 with ax = 0
    assert vx * 0.98 < X[-1, 0] < vx


@pytest.mark.skipif(not DATA.exists(), reason="real-car data not available")
def test_one_second_predictions_on_the_real_run_are_close_in_the_linear_range():
    """README check: 1-s open-loop yaw-rate predictions with the nominal values err ~0.02 rad/s for |ay| < 8."""
    with gzip.open(DATA, "rt") as fh:
        names = fh.readline().strip().split(",")
        D = np.loadtxt(fh, delimiter=",")
    col = {n: D[:, i] for i, n in enumerate(names)}
    car = single_track()
    errs, n = [], 100
    for k in range(0, 20000, 1000):  # 20 one-second windows
        sl = slice(k, k + n + 1)
        if np.max(np.abs(col["ay"][sl])) >= 8:
            continue
        X = simulate(car, [col["vx"][k], col["vy"][k], col["omega"][k]], col["t"][sl],
                     inputs=np.c_[col["ax"][sl], col["delta"][sl]])  # fmt: skip
        errs.append(X[:, 2] - col["omega"][sl])
    rms = float(np.sqrt(np.mean(np.concatenate(errs) ** 2)))
    assert len(errs) >= 5
    assert rms < 0.04, rms
