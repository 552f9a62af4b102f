"""Test campaigns: the vehicle tracking controller and reference maneuvers.

:mod:`reachconf.campaign.controller` holds the tracking law shared by the
closed-loop model (sympy) and the campaign simulation (numpy).
"""

from reachconf.campaign.maneuvers import MANEUVERS, reference_path  # noqa: E402

__all__ = ["MANEUVERS", "reference_path"]
