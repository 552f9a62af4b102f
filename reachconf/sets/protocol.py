"""The protocol every set type of reachconf follows.

:class:`Interval`, :class:`Zonotope`, :class:`SetUnion` and :class:`BoxDisk`
all have ``dim``, ``pieces``, ``interval()``, ``contains(points)``,
``linear_map(M)`` and ``plot(ax=None, dims=(0, 1), **style)``, so code that
handles sets calls these instead of asking for the type.
"""

from __future__ import annotations

from typing import Protocol, runtime_checkable

__all__ = ["ReachSet"]


@runtime_checkable
class ReachSet(Protocol):
    """A set of reachconf (a structural type: ``isinstance(S, ReachSet)`` checks the methods)."""

    @property
    def dim(self) -> int:
        """Dimension of the space the set lives in."""

    @property
    def pieces(self) -> tuple:
        """The convex sets whose union is the set (``(self,)`` for a convex set)."""

    def interval(self):
        """Interval hull (an :class:`~reachconf.sets.Interval`)."""

    def contains(self, points, tol=...):
        """Membership of one point (bool) or of the rows of ``points`` (boolean array)."""

    def linear_map(self, M):
        """The image ``{M x | x in S}`` (or an enclosure of it, for types not closed under maps)."""

    def plot(self, ax=None, dims=(0, 1), **style):
        """Draw the projection on two dimensions; returns the axes."""
