"""A stiff, non-normal linear system: its set explodes by the wrapping effect, and the error says so.

Found by the linear-reach fuzz (27 Nov): eigenvalues -1e-3 ... -1e4 behind a random non-orthogonal basis
(logarithmic norm 3.3e4 1/s) made every algorithm's set NaN/inf within a fraction of a second — the order
reduction boxes part of the set in the state axes every step, and under ``e^{A dt}`` a box grows at up to
the logarithmic norm although every eigenvalue is stable.  The error used to blame the abstraction error
(which a linear model does not have) and, with ``reduction="pca"``, was a bare ``LinAlgError`` from the
eigen-decomposition of the NaN/inf generators.  In its real modal form the same system is reached.
"""

import numpy as np
import pytest
import scipy.linalg as sla

import reachconf as rc
from reachconf.errors import ReachError
from reachconf.model import Model
from reachconf_kernels import zonotope as zk


def _stiff_matrix():
    rng = np.random.default_rng(40)
    lam = -np.logspace(-3, 4, 4)
    V = np.eye(4) + 0.5 * rng.normal(size=(4, 4))
    return V @ np.diag(lam) @ np.linalg.inv(V), V, lam


def _linear_model(A, b, name):
    n = A.shape[0]
    params = {f"a{i}{j}": float(A[i, j]) for i in range(n) for j in range(n)}
    params.update({f"b{i}": float(b[i]) for i in range(n)})

    def dynamics(s):
        return [sum(s[f"a{i}{j}"] * s[f"x{j}"] for j in range(n)) + s[f"b{i}"] * s.w for i in range(n)]

    return Model(name=name, states=tuple(f"x{i}" for i in range(n)), disturbances=("w",), params=params,
                 dynamics=dynamics)  # fmt: skip


@pytest.mark.parametrize("reduction", ["girard", "pca"])
def test_explosion_of_a_linear_model_is_reported_as_the_wrapping_effect(reduction):
    A, _, _ = _stiff_matrix()
    model = _linear_model(A, np.array([1.0, -0.5, 0.3, 0.2]), "stiff_nonnormal")
    X0 = rc.Interval(np.full(4, 0.9), np.full(4, 1.1))
    W = rc.Interval([-0.1], [0.1])
    opts = rc.ReachOptions(algorithm="lin", time_step=1e-4, reduction=reduction)
    with pytest.raises(ReachError) as err:
        rc.reach(model, X0, 0.05, W=W, options=opts)
    msg = str(err.value)
    assert "wrapping effect" in msg and "logarithmic norm" in msg and "modal form" in msg, msg
    assert "tensor_order=3" not in msg  # no advice about an abstraction error a linear model does not have


def test_the_modal_form_of_the_same_system_is_reached_soundly():
    A, V, lam = _stiff_matrix()
    b = np.array([1.0, -0.5, 0.3, 0.2])
    Vi = np.linalg.inv(V)
    model = _linear_model(np.diag(lam), Vi @ b, "stiff_modal")  # z = V^-1 x: z' = diag(lam) z + V^-1 b w
    Z0 = rc.Zonotope(Vi @ np.ones(4), Vi * 0.1)
    tube = rc.reach(model, Z0, np.linspace(0.0, 0.05, 6), W=rc.Interval([-0.1], [0.1]),
                    options=rc.ReachOptions(algorithm="lin", time_step=1e-4))  # fmt: skip
    rng = np.random.default_rng(1)
    for k, t in enumerate(np.linspace(0.0, 0.05, 6)):
        S = tube.time_point_sets[k]
        # constant disturbances: z(t) = e^{Lt} z0 + (e^{Lt} - 1)/L (V^-1 b) w, per mode
        for _ in range(40):
            z0 = Vi @ (np.ones(4) + rng.uniform(-0.1, 0.1, 4))
            w = rng.choice([-0.1, 0.1])
            zt = np.exp(lam * t) * z0 + np.expm1(lam * t) / lam * (Vi @ b) * w
            assert S.contains(zt, tol=1e-9), (t, zt)
        assert np.all(np.isfinite(S.interval().hi))
    # and tight: the final set's radius is within 10 % of the exact one (homogeneous image plus the input's reach;
    # for the fastest mode, lam dt = -1 per step, within 3 times: the step's input enclosure)
    iv = tube.time_point_sets[-1].interval()
    exact = np.abs(sla.expm(np.diag(lam) * 0.05)) @ np.abs(Vi * 0.1).sum(axis=1) + np.abs(
        np.expm1(lam * 0.05) / lam * (Vi @ b)) * 0.1  # fmt: skip
    assert np.all((iv.hi - iv.lo)[:3] / 2 <= 1.1 * exact[:3]) and (iv.hi - iv.lo)[3] / 2 <= 3.0 * exact[3]


def test_pca_reduction_of_nan_or_inf_generators_does_not_raise():
    G = np.array([[1.0, 2.0, np.inf, 0.5, 0.1, 0.2], [0.0, 1.0, 1.0, np.nan, 0.3, 0.1]])
    c, Gr = zk.reduce_pca(np.zeros(2), G, 1.0)
    assert Gr.shape[0] == 2 and not np.all(np.isfinite(Gr))  # the caller's finiteness check sees it


def test_the_wrapping_diagnosis_speaks_only_for_linear_models_that_wrap():
    from reachconf.reach_errors import wrapping_diagnosis

    A, _, _ = _stiff_matrix()
    stiff = _linear_model(A, np.zeros(4), "stiff_nonnormal")
    assert "wrapping effect" in wrapping_diagnosis(stiff, 0.02)  # mu_inf t = 3.3e4 * 0.02 >> 30
    assert wrapping_diagnosis(stiff, 1e-4) == ""  # too early for boxes of rounding size to explode
    assert wrapping_diagnosis(rc.models.get_model("vanderpol"), 100.0) == ""  # nonlinear: the abstraction error
    assert wrapping_diagnosis(rc.models.get_model("pedestrian_acc"), 10.0) == ""  # linear, mu_inf t small
