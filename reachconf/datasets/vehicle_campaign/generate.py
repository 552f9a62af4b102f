"""The vehicle test campaign of section 4: 4 maneuvers x 2 lateral accelerations x 5 repetitions.

:func:`make_campaign` runs :func:`reachconf.datasets.vehicle_campaign.plant.simulate_maneuver`
for lane change, swerve, double lane change and slalom at 10 m/s with peak
lateral accelerations 2 and 4 m/s^2 (groups ``LC_2 ... SL_4``), seeded and
deterministic, and returns (and optionally saves) the suite.  Each case has
the measured actuator outputs ``ax, delta`` as inputs and the rear-axle states
as outputs (the ``bicycle`` model's signals); the requests ``ax_req,
delta_req`` and the reference ``X_ref ... kappa_ref`` are extras, so
``case.select(...)`` serves ``bicycle_actuated`` and ``bicycle_closed_loop`` too.
"""

from __future__ import annotations

from tqdm.auto import tqdm

from reachconf.datasets.vehicle_campaign.maneuvers import reference_path
from reachconf.datasets.vehicle_campaign.plant import PlantEffects, simulate_maneuver
from reachconf.errors import OptionsError
from reachconf.io.cases import TestCase, TestSuite
from reachconf.io.files import save_suite
from reachconf.runner.pool import Pool

__all__ = ["CAMPAIGN_MANEUVERS", "CAMPAIGN_ACCELERATIONS", "make_campaign", "make_case"]

CAMPAIGN_MANEUVERS = ("LC", "SW", "DLC", "SL")
CAMPAIGN_ACCELERATIONS = (2.0, 4.0)
_OUTPUTS = ("X", "Y", "psi", "vx", "vy", "omega")
_EXTRAS = ("ax_req", "delta_req", "X_ref", "Y_ref", "psi_ref", "v_ref", "kappa_ref")


def make_case(kind, a_lat, rep, effects=PlantEffects(), seed=0, v=10.0, feedforward_only=False, name=None):
    """One campaign run as a :class:`reachconf.io.TestCase` (group ``f"{kind}_{a_lat:g}"``)."""
    ref = reference_path(kind, a_lat, v)
    # a distinct, reproducible noise seed per (seed, maneuver, acceleration, repetition)
    kind_index = CAMPAIGN_MANEUVERS.index(kind) if kind in CAMPAIGN_MANEUVERS else 9
    case_seed = seed * 1_000_000 + kind_index * 10_000 + int(round(10 * a_lat)) * 100 + int(rep)
    out = simulate_maneuver(ref, effects, seed=case_seed, feedforward_only=feedforward_only)
    group = f"{kind}_{a_lat:g}"
    signals = {k: out[k] for k in (*_OUTPUTS, "ax", "delta", *_EXTRAS)}
    return TestCase.from_signals(name or f"{group}_{rep + 1}", out["t"], signals, ("ax", "delta"), _OUTPUTS, group=group)


def _case_job(job):
    """:func:`make_case` of one ``(kind, a_lat, rep, effects, seed, feedforward_only)`` job (a pool task)."""
    kind, a_lat, rep, effects, seed, feedforward_only = job
    return make_case(kind, a_lat, rep, effects, seed, feedforward_only=feedforward_only)


def make_campaign(folder=None, effects=PlantEffects(), seed=0, repetitions=5, maneuvers=CAMPAIGN_MANEUVERS,
                  accelerations=CAMPAIGN_ACCELERATIONS, feedforward_only=False, progress=True, pool=None):  # fmt: skip
    """Generate the campaign suite (40 cases by default); save it to ``folder`` if given.

    ``pool`` (a :class:`reachconf.runner.Pool`) simulates the runs on its workers; every run has its own seed, so the
    suite is the same with or without it.
    """
    if pool is not None and not isinstance(pool, Pool):
        raise OptionsError(f"make_campaign: pool must be a reachconf.runner.Pool or None, got {type(pool).__name__}")
    jobs = [(k, a, r, effects, seed, feedforward_only) for k in maneuvers for a in accelerations for r in range(repetitions)]
    if pool is not None and pool.parallel:
        cases = pool.map(_case_job, jobs, desc="campaign", progress=progress)
    else:
        cases = [_case_job(job) for job in tqdm(jobs, desc="campaign", disable=not progress, leave=False)]
    suite = TestSuite(cases, name="vehicle campaign")
    if folder is not None:
        save_suite(suite, folder)
    return suite
