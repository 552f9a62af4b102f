"""`modal_form`: a linear model in real modal coordinates z = V^-1 x (block-diagonal state matrix)."""

import numpy as np
import pytest

import reachconf as rc
from reachconf.errors import ModelError
from reachconf.model import Model


def _model(A, B, name="lin"):
    n = A.shape[0]
    params = {f"a{i}{j}": float(A[i, j]) for i in range(n) for j in range(n)}
    params.update({f"b{i}": float(B[i, 0]) for i in range(n)})
    params.update({f"e{i}": float(B[i, 1]) for i in range(n)})
    return Model(name=name, states=tuple(f"x{i}" for i in range(n)), inputs=("u",), disturbances=("w",),
                 params=params, outputs=lambda s: {"y": s.x0 - 2 * s.x1, "v": s.x1 + s.u},
                 dynamics=lambda s: [sum(s[f"a{i}{j}"] * s[f"x{j}"] for j in range(n)) + s[f"b{i}"] * s.u
                                     + s[f"e{i}"] * s.w + 0.5 for i in range(n)])  # fmt: skip


@pytest.mark.parametrize("seed", range(4))
def test_modal_model_is_the_same_system_in_other_coordinates(seed):
    rng = np.random.default_rng(seed)
    n = 3 + seed % 2
    A = rng.normal(size=(n, n)) * 2.0  # real eigenvalues and complex pairs
    B = rng.normal(size=(n, 2))
    model = _model(A, B)
    modal = rc.modal_form(model)
    M = modal.model
    assert M.state_names == tuple(f"z{i}" for i in range(n)) and M.output_names == ("y", "v")
    assert M.input_names == ("u",) and M.disturbance_names == ("w",)
    assert np.allclose(modal.V @ modal.V_inv, np.eye(n), atol=1e-10)
    for _ in range(5):
        x, u, w = rng.normal(size=n), rng.normal(size=1), rng.normal(size=1)
        z = modal.V_inv @ x
        assert np.allclose(modal.V @ M.f(z, u, w), model.f(x, u, w), rtol=1e-9, atol=1e-9)
        assert np.allclose(M.h(z, u), model.h(x, u), rtol=1e-9, atol=1e-9)
    # block diagonal: z_i' depends on z_i (and its pair's partner) only
    J = np.zeros((n, M.nz))
    M.compiled().jac(np.zeros(M.nz), M.param_vector, J)
    Az = J[:, :n]
    assert np.allclose(np.sort_complex(np.linalg.eigvals(Az)), np.sort_complex(np.linalg.eigvals(A)), atol=1e-8)
    off = np.abs(Az) * (1 - np.eye(n))
    for i in range(n):
        partners = [j for j in range(n) if off[i, j] > 1e-8 * np.abs(Az).max()]
        assert len(partners) <= 1
    # sets map both ways
    X = rc.Interval(-np.ones(n), np.ones(n))
    back = modal.from_modal(modal.to_modal(X)).interval()
    assert np.all(back.lo <= -1 + 1e-9) and np.all(back.hi >= 1 - 1e-9) and np.all(back.hi <= 1 + 1e-6)


def test_modal_form_refuses_nonlinear_and_defective_models():
    with pytest.raises(ModelError, match="not linear"):
        rc.modal_form(rc.models.get_model("vanderpol"))
    with pytest.raises(ModelError, match="not diagonalisable"):
        rc.modal_form(rc.models.get_model("pedestrian_acc"))  # a double integrator: a Jordan block
    with pytest.raises(ModelError, match="state_prefix"):
        pair = Model(name="pair", states=("x0", "x1"), dynamics=lambda s: [-s.x0, s.x0 - 2 * s.x1])
        rc.modal_form(pair, state_prefix="x")  # the outputs are the original states x0, x1


def test_without_the_outputs_the_modal_states_are_the_outputs():
    A = np.array([[-1.0, 3.0], [0.0, -50.0]])
    modal = rc.modal_form(_model(A, np.ones((2, 2))), keep_outputs=False)
    assert modal.model.output_names == ("z0", "z1")
    assert np.allclose(np.sort(modal.eigenvalues.real), [-50.0, -1.0])


def test_modal_form_of_something_not_a_model_is_a_model_error():
    with pytest.raises(ModelError, match="needs a reachconf Model"):
        rc.modal_form(np.eye(2))
