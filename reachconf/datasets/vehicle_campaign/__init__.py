"""The vehicle test campaign of section 4, generated: reference maneuvers and a multi-body "real vehicle".

The DLR measurements of the report are not public, so the campaign is
generated (seeded, deterministic):

* :mod:`.maneuvers` — reference paths (lane change, swerve, double lane
  change, slalom, and the excitation maneuver of the diagnosis) with
  continuous curvature;
* :mod:`.plant` — the multi-body plant of ``commonroad-vehicle-models`` in
  closed loop with the tracking controller
  (:mod:`reachconf.models.vehicle_controller`), with actuator lags, delays,
  offsets and sensor noise (:class:`PlantEffects`);
* :mod:`.generate` — the campaign as a :class:`~reachconf.TestSuite`
  (:func:`make_campaign`, :func:`make_case`).
"""

from reachconf.datasets.vehicle_campaign.generate import (
    CAMPAIGN_ACCELERATIONS,
    CAMPAIGN_MANEUVERS,
    make_campaign,
    make_case,
)
from reachconf.datasets.vehicle_campaign.maneuvers import MANEUVERS, excitation_path, lane_change, reference_path
from reachconf.datasets.vehicle_campaign.plant import NO_EFFECTS, PlantEffects, simulate_maneuver

__all__ = ["MANEUVERS", "reference_path", "excitation_path", "lane_change", "PlantEffects", "NO_EFFECTS",
           "simulate_maneuver", "make_campaign", "make_case", "CAMPAIGN_MANEUVERS", "CAMPAIGN_ACCELERATIONS"]  # fmt: skip
