"""Models travel as build recipes: a process keeps what it built and reuses it for every job that carries it."""

import copy
import pickle

import numpy as np

import reachconf as rc
from reachconf.model.recipe import built_models


def oscillator(k=4.0):
    return rc.Model(name="osc_recipe", states=("p", "v"), inputs=("u",), disturbances=("w",), params={"k": k, "d": 0.5},
                    dynamics=lambda s: [s.v, -s.k * s.p - s.d * s.v + s.u + s.w])  # fmt: skip


def test_unpickled_models_are_kept_and_shared_per_process():
    m = oscillator()
    blob = pickle.dumps(m)
    assert len(blob) < 10_000
    a, b = pickle.loads(blob), pickle.loads(pickle.dumps(m))
    assert a is b  # the second job reuses the model built for the first (and what it compiled)
    assert built_models()[m.structure_key] is a
    x = np.array([0.3, -0.2])
    np.testing.assert_array_equal(a.f(x, [0.1], [0.0]), m.f(x, [0.1], [0.0]))
    a.compiled()
    c = pickle.loads(pickle.dumps(m.with_params(k=9.0)))  # other parameter values: a copy sharing the code
    assert c is not a and c.params["k"] == 9.0 and a.params["k"] == 4.0
    assert c.compiled() is a.compiled()
    np.testing.assert_allclose(c.f(x, [0.0], [0.0]), [-0.2, -9.0 * 0.3 + 0.1])


def test_structure_key_ignores_parameter_values_but_not_expressions():
    m = oscillator()
    assert m.with_params(k=1.0).structure_key == m.structure_key
    other = rc.Model(name="osc_recipe", states=("p", "v"), inputs=("u",), disturbances=("w",), params={"k": 4.0, "d": 0.5},
                     dynamics=lambda s: [s.v, -s.k * s.p**3 - s.d * s.v + s.u + s.w])  # fmt: skip
    assert other.structure_key != m.structure_key


def test_copies_are_independent_models():
    m = oscillator()
    d = copy.deepcopy(m)
    assert d is not m and d.structure_key == m.structure_key and dict(d.params) == dict(m.params)
    c = copy.copy(m)
    assert c is not m and c.params == m.params


class Scripted(rc.Model):
    """A model class defined in a script (``__main__``) travels as a plain Model."""

    states = ("x",)
    disturbances = ("w",)

    def dynamics(self, s):
        return [-s.x + s.w]


def test_a_class_from_the_script_travels_as_a_plain_model(monkeypatch):
    monkeypatch.setattr(Scripted, "__module__", "__main__")
    m = Scripted()
    back = pickle.loads(pickle.dumps(m))
    assert type(back) is rc.Model and back.f_expr == m.f_expr
