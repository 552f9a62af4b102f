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
    A, _, _ = _stiff_matrix()
    b = np.array([1.0, -0.5, 0.3, 0.2])
    modal = rc.modal_form(_linear_model(A, b, "stiff_nonnormal"))
    times = np.linspace(0.0, 0.05, 6)
    tube = rc.reach(modal.model, modal.to_modal(rc.Interval(np.full(4, 0.9), np.full(4, 1.1))), times,
                    W=rc.Interval([-0.1], [0.1]), options=rc.ReachOptions(algorithm="lin", time_step=1e-4))  # fmt: skip
    rng = np.random.default_rng(1)
    for k, t in enumerate(times):
        S = tube.time_point_sets[k]
        assert np.all(np.isfinite(S.interval().hi))
        # exact solutions of the original system, constant disturbances: x(t) = e^{At} x0 + A^-1 (e^{At} - I) b w
        eA = sla.expm(A * t)
        for _ in range(40):
            x0 = rng.uniform(0.9, 1.1, 4)
            w = rng.choice([-0.1, 0.1])
            xt = eA @ x0 + np.linalg.solve(A, (eA - np.eye(4)) @ b) * w
            assert S.contains(modal.V_inv @ xt, tol=1e-9), (t, xt)
    # tight: the final set's radius, in the modal states, within 10 % of the exact one (the fastest mode, lam dt =
    # -1 per step, within 3 times: the step's input enclosure)
    lam = modal.eigenvalues.real
    Vi = modal.V_inv
    exact = np.exp(lam * 0.05) * np.abs(Vi * 0.1).sum(axis=1) + np.abs(np.expm1(lam * 0.05) / lam * (Vi @ b)) * 0.1
    rad = (tube.time_point_sets[-1].interval().hi - tube.time_point_sets[-1].interval().lo) / 2
    slow = lam > -1e3
    assert np.all(rad[slow] <= 1.1 * exact[slow]) and np.all(rad <= 3.0 * exact)


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
