"""*How far* at the data's own rate (DiagnoseOptions.box_rate=None, the default since 27 Nov).

Found by a new-user audit: with the held-out cases decimated to 20 Hz, a DC motor with a 50-ms electrical
time constant, driven by steps at 100 Hz, reported its exactly modelled input offset as "W shrinks 0.95x":
the input held for 50 ms needs a large W whatever the model.  Here: 30x at 100 Hz, 1.04x at 20 Hz.
"""

import numpy as np
import pytest

import reachconf as rc

PARAMS = {"R": 2.0, "L": 0.05, "K": 0.5, "J": 0.02, "b": 0.05}


@pytest.fixture(scope="module")
def motor_suite():
    model = rc.Model(name="dc_motor_box_rate", states=("om", "i"), inputs=("u",), disturbances=("w_load", "w_el"),
                     params=PARAMS, dynamics=lambda s: [(s.K * s.i - s.b * s.om) / s.J + s.w_load,
                                                        (s.u - s.R * s.i - s.K * s.om) / s.L + s.w_el])  # fmt: skip
    t = np.round(np.arange(0.0, 4.0 + 1e-9, 0.01), 10)
    cases = []
    for j in range(6):
        rng = np.random.default_rng(40 + j)
        u = np.zeros_like(t)
        tk = 0.0
        while tk < t[-1]:
            u[t >= tk] = rng.uniform(-6, 6)
            tk += rng.uniform(0.3, 0.9)
        X = rc.simulate(model, [0.0, 0.0], t, inputs=(u + 0.3)[:, None], substeps=8)  # a 0.3-V offset
        Y = X + np.column_stack([rng.normal(0, 0.02, t.size), rng.normal(0, 0.005, t.size)]).clip(-0.05, 0.05)
        cases.append(rc.TestCase(f"c{j}", f"g{j % 2}", t, u[:, None], Y, ("u",), ("om", "i")))
    return model, rc.TestSuite(cases)


def test_how_far_of_an_exact_effect_is_measured_at_the_datas_rate(motor_suite):
    model, suite = motor_suite
    rep = rc.diagnose(model, suite, effects=["input_offset"], progress=False)
    assert rep.named and rep.named[0]["effect"] == "input_offset"
    shrink = rep.before_after["W_volume_shrink"]
    assert shrink > 5.0, rep.before_after
    coarse = rc.diagnose(model, suite, effects=["input_offset"], progress=False, options=rc.DiagnoseOptions(box_rate=20.0))
    assert coarse.before_after["W_volume_shrink"] < shrink / 3


def test_a_failed_reach_tube_is_said_not_left_out(motor_suite):
    """tubes.png drew only the tube whose reach worked, without a word (found by a new-user audit)."""
    model, suite = motor_suite
    rep = rc.diagnose(model, suite, effects=["input_offset"], progress=False)
    assert [tb["label"] for tb in rep.tubes] == ["base", "with effect"] and all("tube" in tb for tb in rep.tubes)
    rep.tubes[0] = {"label": "base", "error": "the set exploded at t = 1 s"}
    assert "Reach tube (base) of the held-out case: not drawn, the reach failed: the set exploded" in rep.summary()
    ax = rep.plot(kind="tubes")
    assert "base: the reach failed" in ax.get_title()
