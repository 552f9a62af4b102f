"""A user's own effects: their start and bounds are checked before any fit, and a signal that is not finite is an
error naming the effect (it was scored with a placeholder residual of 1e6 and printed as a loss of
"+11785260347584712 % above base"); small numerical cases of where and how far that warned or divided by zero."""

import dataclasses
import warnings

import numpy as np
import pytest

import reachconf as rc
from reachconf.diagnose.effects import Effect
from reachconf.conformance.trace import trace_disturbances
from reachconf.diagnose.locate import locate_gap
from reachconf.errors import OptionsError

from test_diagnose import _oscillator_suite


def _offset(name, guess=(0.0,), bounds=((-1.0,), (1.0,)), signal=lambda t, u, th: u + th[0]):
    return Effect(name, "input", ("c",), lambda x: guess, lambda x: bounds, signal=signal)


@pytest.fixture(scope="module")
def oscillator():
    return _oscillator_suite(lag=0.1, n=4)


@pytest.mark.parametrize("effect, message", [
    (_offset("two_guesses", guess=(0.0, 1.0)), r"guess gives 2 values and bounds 1 and 1 for its 1 parameter"),
    (_offset("reversed", bounds=((1.0,), (-1.0,))), r"lower bound of 'c' must be below the upper, got \[1.0, -1.0\]"),
    (_offset("open", bounds=((-np.inf,), (1.0,))), r"guess and bounds must be finite"),
    (_offset("text", guess=("a",)), r"guess\(signal\) must give 1 numbers"),
    (_offset("nan_signal", signal=lambda t, u, th: u + np.nan), r"'nan_signal' on 'u': its signal gives NaN or inf"),
    (_offset("short", signal=lambda t, u, th: u[:-1]), r"one value per sample \(\(801,\)\), got an array of shape \(800,\)"),
])
def test_a_custom_effect_is_checked_before_it_is_fitted(oscillator, effect, message):
    m, suite = oscillator
    with pytest.raises(OptionsError, match=message):
        rc.diagnose(m, suite, effects=[effect], progress=False, workers=1)


def test_a_sound_custom_effect_is_fitted_and_its_start_clipped_into_its_bounds(oscillator):
    m, suite = oscillator
    e = _offset("far_start", guess=(5.0,))  # outside its bounds: clipped, as before
    g, lo, hi = e.start_values("u", np.zeros(3))
    assert (g, lo, hi) == ((5.0,), (-1.0,), (1.0,))
    rep = rc.diagnose(m, suite, effects=[e], progress=False, workers=1)
    row = next(r for r in rep.ranked_effects if r["label"] == "far_start(u)")
    assert -1.0 <= row["params"]["c"] <= 1.0 and np.isfinite(row["held_out_loss"])


def test_where_on_traces_that_need_no_disturbance_gives_zero_shares(oscillator):
    m, suite = oscillator
    traces = [dataclasses.replace(r, W_trace=np.zeros_like(r.W_trace))
              for r in (trace_disturbances(m, c) for c in suite)]  # fmt: skip
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)  # was: invalid value in divide (0 / 0)
        loc = locate_gap(m, suite, traces=traces)
    assert loc.shares == {"w": 0.0}


def test_a_constant_request_maps_by_its_offset_without_a_rank_warning():
    m, suite = _oscillator_suite(lag=0.1, n=4)
    cases = [dataclasses.replace(c, extras={"u_req": np.full(c.t.size, 0.5)}) for c in suite]
    with warnings.catch_warnings():
        warnings.simplefilter("error", np.exceptions.RankWarning)  # was: polyfit may be poorly conditioned
        rep = rc.diagnose(m, rc.TestSuite(cases), effects=["input_offset"], progress=False, workers=1)
    k, c = rep.where["actuator_vs_process"]["request_map"]["u"]
    assert k == 1.0 and np.isfinite(c)


def test_a_custom_effects_targets_must_be_names(oscillator):
    """Was: targets(model) giving numbers or None ended in a TypeError deep in the candidate list."""
    m, suite = oscillator
    for targets, message in ((lambda model: [0], r"targets\(model\) must give names \(str\), got \[0\]"),
                             (lambda model: None, r"targets\(model\) must give a list of names")):  # fmt: skip
        e = Effect("odd_targets", "input", ("c",), lambda x: (0.0,), lambda x: ((-1.0,), (1.0,)),
                   signal=lambda t, u, th: u + th[0], targets=targets)  # fmt: skip
        with pytest.raises(OptionsError, match=message):
            rc.diagnose(m, suite, effects=[e], progress=False, workers=1)
