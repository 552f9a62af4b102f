"""The validation protocol of the gap diagnosis: tuning and test suites made differently (docs/diagnosis-validation.md).

A suite is made by :func:`make_suite` from a :class:`SuiteSpec`: the
multi-body "real vehicle" with ideal actuators, sensor noise scaled by
``noise`` and the withheld effects ``changes`` (fields of
:class:`~reachconf.datasets.vehicle_campaign.PlantEffects`) drives the listed
maneuvers under the tracking controller; the suite records the controller's
*commands* as the inputs ``ax, delta`` and the measured rear-axle states.
``truth`` gives the withheld effects in the diagnosis library's terms.

* :func:`tuning_specs` — the suites every threshold and rule is chosen on:
  maneuvers made for the diagnosis (lateral chirps and single-frequency
  weaves, at constant or swinging speed), effect values on a fixed grid,
  the campaign's noise level and (since 3 Dec) a block at 0.5, 0.7, 1.4 and
  2 times it;
* :func:`test_specs` — the suites the result is reported on: the eight
  standard maneuvers (lane change, swerve, double lane change, slalom at 2 and
  4 m/s²; six of them per suite, three runs each), effect values drawn at
  random from wide ranges, one or two effects at once, clean suites, noise 0.5
  to 2 times the campaign's, other seeds.  ``test_specs(seed=...)`` with
  another seed makes another test set the same way.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from reachconf.datasets.vehicle_campaign import (
    NO_EFFECTS,
    PlantEffects,
    excitation_path,
    reference_path,
    simulate_maneuver,
)
from reachconf.io import TestCase, TestSuite

__all__ = ["SuiteSpec", "tuning_specs", "test_specs", "case_names", "make_suite", "judge", "STANDARD_GROUPS", "TUNING_MANEUVERS"]

#: the eight standard maneuvers of the campaign (kind, peak lateral acceleration m/s²)
STANDARD_GROUPS = tuple((k, a) for k in ("LC", "SW", "DLC", "SL") for a in (2.0, 4.0))

#: maneuvers of the tuning suites (none of them standard): code -> excitation_path keyword arguments
TUNING_MANEUVERS = {
    "EX": {"a_lat": 3.0},  # lateral chirp 0.25-2 Hz at a speed swinging 8-12 m/s
    "CH": {"a_lat": 3.0, "dv": 0.0},  # the same chirp at constant speed
    "WV20": {"a_lat": 2.5, "dv": 0.0, "wavelengths": (20.0, 20.0), "duration": 12.0},  # 0.5 Hz weave
    "WV12": {"a_lat": 3.0, "dv": 2.0, "wavelengths": (12.0, 12.0), "duration": 12.0},  # 0.8 Hz, swinging speed
    "WV50": {"a_lat": 4.0, "dv": 0.0, "wavelengths": (50.0, 50.0), "duration": 16.0, "steer_rate": 0.4},  # 0.2 Hz
}


@dataclass(frozen=True)
class SuiteSpec:
    """How one protocol suite is made (deterministic)."""

    name: str
    role: str  # "tuning" or "test"
    category: str  # e.g. "steering lag", "clean", "two effects"
    maneuvers: tuple  # ((kind, a_lat) or (tuning code, None), ...)
    changes: dict = field(default_factory=dict)  # PlantEffects fields
    truth: tuple = ()  # ({"effect", "target", "params"}, ...)
    noise: float = 1.0
    repetitions: int = 3
    seed: int = 0

    def to_dict(self) -> dict:
        return {"name": self.name, "role": self.role, "category": self.category,
                "maneuvers": [list(m) for m in self.maneuvers], "changes": dict(self.changes),
                "truth": [dict(t) for t in self.truth], "noise": self.noise, "repetitions": self.repetitions,
                "seed": self.seed}  # fmt: skip


# --------------------------------------------------------------------------- effects in plant and library terms
def steering_lag(tau):
    return {"k_delta": 1.0 / tau}, [{"effect": "actuator_lag", "target": "delta", "params": {"tau": tau}}]


def steering_dead_time(T):
    T = round(T * 100) / 100  # the plant delays by whole controller periods (10 ms)
    return {"steer_delay": T}, [{"effect": "dead_time", "target": "delta", "params": {"T": T}}]


def steering_offset(deg):
    c = math.radians(deg)
    return {"delta_off": c}, [{"effect": "input_offset", "target": "delta", "params": {"c": c}}]


def yaw_offset(deg):
    c = math.radians(deg)
    return {"yaw_offset": c}, [{"effect": "output_offset", "target": "psi", "params": {"c": c}}]


def accel_scale_offset(k, c):
    return {"ax_s": k, "ax_off": c}, [{"effect": "input_scale", "target": "ax", "params": {"k": k}},
                                      {"effect": "input_offset", "target": "ax", "params": {"c": c}}]  # fmt: skip


def accel_offset(c):
    return {"ax_off": c}, [{"effect": "input_offset", "target": "ax", "params": {"c": c}}]


def _combine(*effects):
    changes, truth = {}, []
    for ch, tr in effects:
        changes.update(ch)
        truth += tr
    return changes, truth


def _spec(role, i, category, maneuvers, effect, noise, seed, repetitions=3):
    changes, truth = effect if effect else ({}, [])
    name = f"{role}-{i:02d}-{category.replace(' ', '_').replace('+', 'and')}"
    return SuiteSpec(name, role, category, tuple(maneuvers), dict(changes), tuple(truth), float(noise), repetitions,
                     int(seed))  # fmt: skip


def tuning_specs(seed: int = 1) -> list:
    """The tuning suites: a fixed effect grid on the tuning maneuvers, 24 at the campaign's noise and 13 at
    0.5-2 times it (the noise block)."""
    M = [(code, None) for code in TUNING_MANEUVERS]
    grid = [
        ("clean", None), ("clean", None), ("clean", None), ("clean", None),
        ("steering lag", steering_lag(0.08)), ("steering lag", steering_lag(0.12)), ("steering lag", steering_lag(0.2)),
        ("steering dead time", steering_dead_time(0.06)), ("steering dead time", steering_dead_time(0.1)),
        ("steering dead time", steering_dead_time(0.15)),
        ("steering offset", steering_offset(0.8)), ("steering offset", steering_offset(-1.5)),
        ("yaw offset", yaw_offset(0.5)), ("yaw offset", yaw_offset(-1.2)),
        ("accel scale+offset", accel_scale_offset(0.7, 0.2)), ("accel scale+offset", accel_scale_offset(0.85, -0.3)),
        ("accel offset", accel_offset(0.3)),
        ("two effects", _combine(steering_lag(0.1), yaw_offset(1.0))),
        ("two effects", _combine(steering_dead_time(0.08), accel_offset(-0.25))),
        ("two effects", _combine(steering_offset(1.0), accel_scale_offset(0.75, 0.15))),
        # a second, weaker effect next to a large first one (added with the consistency route of the naming rule)
        ("two effects", _combine(steering_offset(-1.8), yaw_offset(0.9))),
        ("two effects", _combine(steering_offset(1.2), accel_offset(-0.2))),
        ("two effects", _combine(steering_lag(0.15), accel_offset(0.15))),
        ("two effects", _combine(steering_dead_time(0.12), yaw_offset(-0.8))),
    ]  # fmt: skip
    # the noise block (added 3 Dec): the test sets' noise range, 0.5-2x, on a fixed grid of levels, with clean
    # suites at both ends and each category's weak values, where the naming threshold matters
    noisy = [
        ("clean", None, 0.5), ("clean", None, 1.4), ("clean", None, 2.0),
        ("steering lag", steering_lag(0.06), 1.4), ("steering lag", steering_lag(0.22), 0.7),
        ("steering dead time", steering_dead_time(0.05), 2.0), ("steering dead time", steering_dead_time(0.18), 1.4),
        ("steering offset", steering_offset(0.6), 1.4),
        ("yaw offset", yaw_offset(0.35), 0.7), ("yaw offset", yaw_offset(-0.6), 2.0),
        ("accel offset", accel_offset(0.18), 2.0),
        ("two effects", _combine(steering_dead_time(0.1), yaw_offset(0.5)), 1.4),
        ("two effects", _combine(steering_lag(0.1), accel_offset(-0.2)), 2.0),
    ]  # fmt: skip
    rng = np.random.default_rng(seed)
    out = []
    for i, (cat, eff, noise) in enumerate([(c, e, 1.0) for c, e in grid] + noisy):
        chosen = [M[j] for j in sorted(rng.choice(len(M), size=4, replace=False))]
        out.append(_spec("tuning", i, cat, chosen, eff, noise, seed * 100_000 + 1000 * i))
    return out


def test_specs(seed: int = 2) -> list:
    """The test suites: standard maneuvers, random effect values and noise levels (another seed: another set)."""
    rng = np.random.default_rng(seed)
    u = rng.uniform
    sign = lambda: float(rng.choice([-1.0, 1.0]))  # noqa: E731
    draws = {
        "steering lag": lambda: steering_lag(u(0.05, 0.25)),
        "steering dead time": lambda: steering_dead_time(u(0.04, 0.2)),
        "steering offset": lambda: steering_offset(sign() * u(0.5, 2.0)),
        "yaw offset": lambda: yaw_offset(sign() * u(0.3, 1.5)),
        "accel scale+offset": lambda: accel_scale_offset(u(0.6, 0.9), sign() * u(0.1, 0.4)),
        "accel offset": lambda: accel_offset(sign() * u(0.15, 0.4)),
    }
    pairs = [("steering lag", "yaw offset"), ("steering dead time", "yaw offset"), ("steering lag", "accel offset"),
             ("steering dead time", "accel offset"), ("steering offset", "yaw offset"),
             ("steering offset", "accel offset")]  # fmt: skip
    plan = (["clean"] * 5 + ["steering lag"] * 5 + ["steering dead time"] * 5 + ["steering offset"] * 3
            + ["yaw offset"] * 3 + ["accel scale+offset"] * 3 + ["accel offset"] * 2 + ["two effects"] * 6)  # fmt: skip
    out = []
    for i, cat in enumerate(plan):
        if cat == "clean":
            eff = None
        elif cat == "two effects":
            a, b = pairs[(i + int(rng.integers(len(pairs)))) % len(pairs)]
            eff = _combine(draws[a](), draws[b]())
        else:
            eff = draws[cat]()
        groups = [STANDARD_GROUPS[j] for j in sorted(rng.choice(len(STANDARD_GROUPS), size=6, replace=False))]
        noise = float(np.exp(u(np.log(0.5), np.log(2.0))))
        out.append(_spec("test", i, cat, groups, eff, noise, seed * 100_000 + 1000 * i + 7))
    return out


# --------------------------------------------------------------------------- making a suite
def _reference(kind, a_lat):
    if kind in TUNING_MANEUVERS:
        return excitation_path(**TUNING_MANEUVERS[kind])
    return reference_path(kind, a_lat)


def case_names(spec: SuiteSpec) -> list:
    """Names of the cases of ``spec``'s suite: ``<maneuver>_<acceleration>_<repetition>``."""
    groups = [kind if a is None else f"{kind}_{a:g}" for kind, a in spec.maneuvers]
    return [f"{g}_{r + 1}" for g in groups for r in range(spec.repetitions)]


def make_suite(spec: SuiteSpec) -> TestSuite:
    """Run the plant for every maneuver and repetition of ``spec`` (commands as inputs)."""
    d = PlantEffects()
    n = spec.noise
    effects = replace(NO_EFFECTS, noise_pos=n * d.noise_pos, noise_psi=n * d.noise_psi, noise_vel=n * d.noise_vel,
                      noise_omega=n * d.noise_omega, **spec.changes)  # fmt: skip
    cases = []
    for i, (kind, a) in enumerate(spec.maneuvers):
        group = kind if a is None else f"{kind}_{a:g}"
        ref = _reference(kind, a)
        for r in range(spec.repetitions):
            out = simulate_maneuver(ref, effects, seed=spec.seed + 10 * i + r)
            signals = {"ax": out["ax_req"], "delta": out["delta_req"] * effects.delta_s_nominal}
            signals.update({k: out[k] for k in ("X", "Y", "psi", "vx", "vy", "omega")})
            cases.append(TestCase.from_signals(f"{group}_{r + 1}", out["t"], signals, ("ax", "delta"),
                                               ("X", "Y", "psi", "vx", "vy", "omega"), group=group))  # fmt: skip
    return TestSuite(cases, name=spec.name)


# --------------------------------------------------------------------------- judging a verdict
def _key(e):
    return (e["effect"], e["target"])


def judge(decision: dict, truth) -> dict:
    """Compare a report's ``decision`` with the truth.

    Per true effect: ``"named"`` (in the chosen model of a "named" verdict, or
    shared by all explanations of an "indistinguishable" one),
    ``"indistinguishable"`` (among the explanations the verdict cannot
    separate) or ``"missed"``.  ``wrong``: named effects that are not true
    (for a clean suite, also every explanation of an "indistinguishable" one).
    """
    status = decision.get("status", "none")
    chosen = {tuple(p) for p in (decision.get("named_parts") or [[e["effect"], e["target"]]
                                                                  for e in decision.get("named", [])])}  # fmt: skip
    alts = [{tuple(p) for p in a["parts"]} for a in decision.get("alternatives", [])]
    shared = set(chosen)
    for a in alts:
        shared &= a
    union = set(chosen).union(*alts) if alts else set(chosen)
    true_keys = {_key(t) for t in truth}
    per = {}
    for t in truth:
        k = _key(t)
        if status == "named" and k in chosen or status == "indistinguishable" and k in shared:
            per[f"{k[0]}({k[1]})"] = "named"
        elif status == "indistinguishable" and k in union:
            per[f"{k[0]}({k[1]})"] = "indistinguishable"
        else:
            per[f"{k[0]}({k[1]})"] = "missed"
    if status == "named":
        wrong = sorted(f"{e}({t})" for e, t in chosen - true_keys)
    elif status == "indistinguishable":
        wrong = sorted(f"{e}({t})" for e, t in (union if not truth else shared) - true_keys)
    else:
        wrong = []
    # parameters of the named true effects: relative errors and interval coverage per method
    params = []
    for e in decision.get("named", []):
        t = next((t for t in truth if _key(t) == _key(e)), None)
        if t is None:
            continue
        for p, v in t["params"].items():
            est = e["params"][p]
            cover = {m: bool(iv[p][0] <= v <= iv[p][1]) for m, iv in e.get("interval_by_method", {}).items()
                     if np.all(np.isfinite(iv[p]))}  # fmt: skip
            params.append({"effect": f"{e['effect']}({e['target']})", "param": p, "truth": v, "estimate": est,
                           "relative_error": (est - v) / abs(v), "std": e["params_std"][p],
                           "interval": e["interval"][p], "covered": cover})  # fmt: skip
    if not truth:
        outcome = "correct: none" if status == "none" else "WRONG: claims an effect"
    elif wrong:
        outcome = "WRONG name"
    elif all(v == "named" for v in per.values()):
        outcome = "all named"
    elif all(v in ("named", "indistinguishable") for v in per.values()):
        outcome = "indistinguishable"
    elif any(v != "missed" for v in per.values()):
        outcome = "partly named"
    else:
        outcome = "none named"
    return {"status": status, "effects": per, "wrong": wrong, "params": params, "outcome": outcome}
