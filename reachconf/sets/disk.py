"""Disks and box ⊕ disk sets: the reachable positions of the pedestrian models (eqs. 73/74).

A pedestrian whose acceleration or speed is bounded in norm reaches, at time
``t``, a box (the initial uncertainty) Minkowski-added to a disk (``a_max t²/2``
or ``v_max t``).  :class:`BoxDisk` is that set with its exact membership test;
:func:`box_disk_distance` is the same test vectorised over many sets at once
(the pedestrian and robot use cases evaluate thousands per call);
:func:`disk_zonotope` encloses a disk by a zonotope as CORA does.
"""

from __future__ import annotations

import math

import numpy as np

from reachconf.errors import SetError
from reachconf.sets.core import Interval, Zonotope
from reachconf.sets.validate import as_tolerance

__all__ = ["BoxDisk", "box_disk_distance", "disk_zonotope"]


def box_disk_distance(d, half_widths, radius=0.0):
    """Euclidean distance of points from box ⊕ disk sets centred at 0, minus the disk radius.

    Parameters
    ----------
    d : array_like (..., n)
        Points relative to the centres of their sets.
    half_widths : array_like, broadcastable to ``d``
        Half-widths of the boxes (per axis, or one per set as ``r[..., None]``).
    radius : float or array_like, broadcastable to ``d[..., 0]``
        Disk radii (0: the box alone).

    Returns
    -------
    ndarray (...)
        ``dist(d, box) - radius``: at most 0 exactly for the points of the
        set (negative inside the rounded box, ``-radius`` inside the box).
    """
    e = np.maximum(np.abs(d) - half_widths, 0.0)
    return np.sqrt(np.sum(e * e, axis=-1)) - radius


def disk_zonotope(radius: float, n_generators: int = 8, center=(0.0, 0.0)) -> Zonotope:
    """A zonotope enclosing the disk of the given radius: a circumscribed regular ``2k``-gon.

    ``k`` generators of length ``r tan(pi / 2k)`` at angles ``i pi / k``; the
    polygon's apothem is ``r``, so it contains the disk and exceeds it by a
    factor ``1 / cos(pi / 2k)`` at its corners.

    Parameters
    ----------
    radius : float
        Radius ``r >= 0``.
    n_generators : int, default 8
        ``k >= 2``.
    center : array_like (2,), default (0, 0)

    Returns
    -------
    Zonotope
    """
    if not (math.isfinite(radius) and radius >= 0):
        raise SetError(f"radius must be a finite non-negative number, got {radius!r}")
    k = int(n_generators)
    if k < 2:
        raise SetError(f"n_generators must be at least 2, got {n_generators!r}")
    length = radius * math.tan(math.pi / (2 * k)) * (1 + 1e-12)
    angles = np.arange(k) * math.pi / k
    G = length * np.vstack([np.cos(angles), np.sin(angles)])
    return Zonotope(np.asarray(center, dtype=float), G)


class BoxDisk:
    """The set ``box(center, half_widths) ⊕ disk(radius)`` (a box with rounded corners).

    Parameters
    ----------
    center : array_like (n,)
    half_widths : float or array_like (n,)
        Non-negative half-widths of the box.
    radius : float
        Non-negative radius of the Euclidean ball added to the box.
    """

    def __init__(self, center, half_widths, radius=0.0):
        c = np.array(center, dtype=float).reshape(-1)
        b = np.broadcast_to(np.asarray(half_widths, dtype=float), c.shape).copy()
        r = float(radius)
        if not (np.all(np.isfinite(c)) and np.all(np.isfinite(b)) and math.isfinite(r)):
            raise SetError("BoxDisk: center, half_widths and radius must be finite")
        if np.any(b < 0) or r < 0:
            raise SetError(f"BoxDisk: half_widths and radius must be non-negative, got {b.tolist()} and {r}")
        self.center, self.half_widths, self.radius = c, b, r

    @property
    def dim(self) -> int:
        """Dimension of the set."""
        return self.center.size

    @property
    def pieces(self) -> tuple:
        """The convex sets whose union is this set: ``(self,)``."""
        return (self,)

    def distance(self, points) -> np.ndarray:
        """Euclidean distance of points (..., n) from the box minus the radius (<= 0 inside the set)."""
        return box_disk_distance(np.asarray(points, dtype=float) - self.center, self.half_widths, self.radius)

    def contains(self, points, tol: float = 0.0):
        """Exact membership: bool for one point, a boolean array for several (..., n)."""
        res = self.distance(points) <= as_tolerance(tol)
        return bool(res) if np.ndim(res) == 0 else res

    def interval(self) -> Interval:
        """Interval hull: the box grown by the radius."""
        return Interval(self.center - self.half_widths - self.radius, self.center + self.half_widths + self.radius)

    def to_zonotope(self, n_generators: int = 8) -> Zonotope:
        """An enclosing zonotope: the disk by :func:`disk_zonotope` (2-D), then the box generators."""
        if self.dim != 2:
            raise SetError(f"BoxDisk.to_zonotope needs a 2-D set, this one has dimension {self.dim}")
        return disk_zonotope(self.radius, n_generators, self.center) + Zonotope([0.0, 0.0], np.diag(self.half_widths))

    def linear_map(self, M) -> Zonotope:
        """An enclosure of ``M @ self``: the map of :meth:`to_zonotope` (exact maps of a rounded box are not boxes)."""
        return np.asarray(M, dtype=float) @ self.to_zonotope()

    def boundary(self, n: int = 72) -> np.ndarray:
        """``n`` points on the boundary of a 2-D set, counter-clockwise from angle 0, shape (n, 2)."""
        if self.dim != 2:
            raise SetError(f"BoxDisk.boundary needs a 2-D set, this one has dimension {self.dim}")
        a = np.linspace(0, 2 * np.pi, n)
        c, b, r = self.center, self.half_widths, self.radius
        return np.column_stack([c[0] + np.sign(np.cos(a)) * b[0] + r * np.cos(a),
                                c[1] + np.sign(np.sin(a)) * b[1] + r * np.sin(a)])  # fmt: skip

    def plot(self, ax=None, dims=(0, 1), **style):
        """Draw the (2-D) set as a filled patch; returns the axes."""
        import matplotlib.pyplot as plt
        from matplotlib.patches import Polygon

        if tuple(dims) != (0, 1):
            raise SetError("BoxDisk.plot draws 2-D sets (dims=(0, 1))")
        if ax is None:
            _, ax = plt.subplots()
        V = self.boundary()
        style.setdefault("alpha", 0.4)
        color = style.pop("color", "C0")
        ax.add_patch(Polygon(V, closed=True, facecolor=color, edgecolor=color, **style))
        ax.update_datalim(V)
        ax.autoscale()
        return ax

    def __repr__(self):
        return f"BoxDisk(center={self.center.tolist()}, half_widths={self.half_widths.tolist()}, radius={self.radius:g})"
