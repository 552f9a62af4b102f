"""Suites with one withheld effect, for checking the gap diagnosis (``reachconf.diagnose``).

The multi-body "real vehicle" of :mod:`reachconf.datasets.vehicle_campaign.plant` runs with
ideal actuators and no offsets, INS-like sensor noise on, plus exactly one
effect from the list below.  The suites record what a test driver's logger
would give a modeller who has not measured the actuators: the controller's
*requests* as the inputs ``ax, delta`` (wheel angle, m/s²) and the measured
rear-axle states; the realised actuator signals are left out.  The base model
(``bicycle`` driven by these inputs) therefore lacks the effect.

The truth is given in the diagnosis library's terms (effect, target, params).
"""

from __future__ import annotations

import math
from dataclasses import replace


from reachconf.datasets.vehicle_campaign import (
    NO_EFFECTS,
    PlantEffects,
    excitation_path,
    reference_path,
    simulate_maneuver,
)
from reachconf.diagnose.options import DiagnoseOptions
from reachconf.diagnose.identify import identify
from reachconf.errors import OptionsError
from reachconf.io import TestCase, TestSuite
from reachconf.models import bicycle

__all__ = ["WITHHELD", "noisy_ideal_plant", "withheld_suite", "DIAGNOSIS_MANEUVERS", "data_sheet", "nominal_bicycle_params"]

#: name -> (plant changes, truth: list of {effect, target, params} in the library's terms)
WITHHELD = {
    "steering_lag": ({"k_delta": 10.0}, [{"effect": "actuator_lag", "target": "delta", "params": {"tau": 0.1}}]),
    "steering_dead_time": ({"steer_delay": 0.08}, [{"effect": "dead_time", "target": "delta", "params": {"T": 0.08}}]),
    "accel_scale_offset": ({"ax_s": 0.64, "ax_off": 0.32},
                           [{"effect": "input_scale", "target": "ax", "params": {"k": 0.64}},
                            {"effect": "input_offset", "target": "ax", "params": {"c": 0.32}}]),
    "yaw_offset": ({"yaw_offset": math.radians(1.0)},
                   [{"effect": "output_offset", "target": "psi", "params": {"c": math.radians(1.0)}}]),
    "steering_offset": ({"delta_off": math.radians(1.09)},
                        [{"effect": "input_offset", "target": "delta", "params": {"c": math.radians(1.09)}}]),
    "none": ({}, []),
}  # fmt: skip

#: (kind, peak lateral acceleration) of the diagnosis runs: the excitation maneuver and a slalom
DIAGNOSIS_MANEUVERS = (("EX", 3.0), ("SL", 4.0))


def noisy_ideal_plant() -> PlantEffects:
    """Ideal actuators, no delays/offsets/scales; the campaign's default sensor noise."""
    d = PlantEffects()
    return replace(NO_EFFECTS, noise_pos=d.noise_pos, noise_psi=d.noise_psi, noise_vel=d.noise_vel,
                   noise_omega=d.noise_omega)  # fmt: skip


def withheld_suite(name: str, repetitions: int = 3, maneuvers=DIAGNOSIS_MANEUVERS, seed: int = 0, progress=False):
    """The suite of one withheld effect (``WITHHELD`` key); deterministic for a seed.

    Returns ``(suite, truth)``.
    """
    from tqdm.auto import tqdm

    if name not in WITHHELD:
        raise OptionsError(f"unknown withheld effect {name!r}; known: {sorted(WITHHELD)}")
    changes, truth = WITHHELD[name]
    effects = replace(noisy_ideal_plant(), **changes)
    cases = []
    jobs = [(kind, a, r) for kind, a in maneuvers for r in range(repetitions)]
    for i, (kind, a, r) in enumerate(tqdm(jobs, desc=f"suite {name}", disable=not progress, leave=False)):
        ref = excitation_path(a_lat=a) if kind == "EX" else reference_path(kind, a)
        out = simulate_maneuver(ref, effects, seed=seed * 100_003 + 1000 * i + 17)
        signals = {k: out[k] for k in ("X", "Y", "psi", "vx", "vy", "omega", "ax", "delta", "ax_req", "delta_req")}
        case = TestCase.from_signals(f"{kind}_{a:g}_{r + 1}", out["t"], signals, ("ax", "delta"),
                                     ("X", "Y", "psi", "vx", "vy", "omega"), group=f"{kind}_{a:g}")  # fmt: skip
        # what the logger gives: the requests (wheel angle) as the inputs, the realised signals left out
        cases.append(case.with_requests({"delta": (effects.delta_s_nominal, 0.0)}))
    return TestSuite(cases, name=f"withheld {name}"), [dict(tr) for tr in truth]


def data_sheet() -> dict:
    """The plant vehicle's data sheet in the bicycle's terms: wheelbase ``L``, ``b_L`` (CoG to rear axle over
    ``L``), ``J_m`` (yaw inertia over mass), and the tyres' normalised cornering stiffness ``|p_ky1|`` as the
    starting value of ``c_f, c_r`` (``commonroad-vehicle-models``' BMW 320i, ``parameters_vehicle2``)."""
    from vehiclemodels.parameters_vehicle2 import parameters_vehicle2

    p = parameters_vehicle2()
    L = p.a + p.b
    return {"L": L, "b_L": p.b / L, "J_m": p.I_z / p.m, "c_f": abs(p.tire.p_ky1), "c_r": abs(p.tire.p_ky1)}


def nominal_bicycle_params(repetitions: int = 2, seed: int = 99) -> dict:
    """Nominal parameters of the bicycle: the data sheet, with ``c_f, c_r`` identified on effect-free runs.

    Least squares by multi-step prediction (:func:`reachconf.diagnose.identify.identify`)
    on runs of the noisy ideal plant with *other* seeds than any diagnosis suite.
    (Until issue 18 the report's vehicle geometry, ``L = 2.7``, ``b/L = 0.57``, was
    used with ``J_m`` identified: a wrong wheelbase the joint fits then absorbed
    into the effects, e.g. steering lags 5-10 % too short.)
    """
    suite, _ = withheld_suite("none", repetitions=repetitions, seed=seed)
    sheet = data_sheet()
    res = identify(bicycle(**sheet), suite, ("c_f", "c_r"), method="prediction",
                   options=DiagnoseOptions(prior=10.0, param_bounds=0.9))  # fmt: skip
    return {**sheet, **res.params}
