"""The two concrete set types, :class:`Interval` (axis-aligned boxes) and :class:`Zonotope`.

They convert into each other (``Interval.to_zonotope``, ``Zonotope.interval``),
so they share this module.  Both are immutable (read-only numpy arrays) and validate their input; the
computations are done by the numba kernels in :mod:`reachconf_kernels.zonotope`.
"""

from __future__ import annotations

import math

import numpy as np

from reachconf.errors import OptionsError, SetError
from reachconf.sets.containment import contains_points
from reachconf.sets.reduction import reduction_method
from reachconf.sets.validate import as_count, as_points, as_rng, as_tolerance, as_vector, is_finite_number
from reachconf_kernels import quadmap as qk
from reachconf_kernels import zonotope as zk
from reachconf_kernels.zonotope_polygon import polygon as zonotope_polygon

__all__ = ["Interval", "Zonotope"]


def _dims(dims, n: int) -> list:
    """``dims`` as a list of indices 0..n-1 (SetError on anything else: negative, fractional, out of range)."""
    try:
        dims = list(dims)
    except TypeError:
        raise SetError(f"dims must be a sequence of dimension indices, got {dims!r}") from None
    out = []
    for d in dims:
        if isinstance(d, bool) or not isinstance(d, (int, np.integer)) or not 0 <= int(d) < n:
            raise SetError(f"dimension {d!r} out of range 0..{n - 1} (dims must be integer indices)")
        out.append(int(d))
    return out


class Interval:
    """Axis-aligned box ``[lo, hi]`` (the boxes of eqs. 62–66, the sets V and W).

    Parameters
    ----------
    lo, hi : array_like (n,) or scalars
        Bounds, ``lo <= hi``, finite.  A row or column vector (shape ``(1, n)`` or ``(n, 1)``) is read as
        a vector; a matrix is refused.  ``n = 0`` gives the zero-dimensional box (the ``W`` of a model
        without disturbances).

    Raises
    ------
    SetError
        On non-finite bounds, ``lo > hi`` or different lengths.
    """

    __slots__ = ("lo", "hi")
    __array_ufunc__ = None  # make ``A @ box`` call __rmatmul__ instead of numpy

    def __init__(self, lo, hi):
        lo = as_vector(lo, "lo", allow_empty=True)
        hi = as_vector(hi, "hi", allow_empty=True)
        if lo.shape != hi.shape:
            raise SetError(f"lo has {lo.size} entries but hi has {hi.size}")
        bad = np.nonzero(lo > hi)[0]
        if bad.size:
            i = int(bad[0])
            raise SetError(f"lo > hi in dimension {i}: {lo[i]} > {hi[i]} (empty interval)")
        with np.errstate(over="ignore"):
            wide = np.nonzero(~np.isfinite(hi - lo))[0]
        if wide.size:
            i = int(wide[0])
            raise SetError(f"the width hi - lo overflows in dimension {i} ([{lo[i]}, {hi[i]}]): unbounded sets are "
                           f"not allowed")  # fmt: skip
        object.__setattr__(self, "lo", lo)
        object.__setattr__(self, "hi", hi)

    def __setattr__(self, name, value):
        raise SetError("Interval is immutable")

    def __reduce__(self):
        return (Interval, (np.array(self.lo), np.array(self.hi)))

    @property
    def dim(self) -> int:
        """Dimension ``n``."""
        return self.lo.size

    @property
    def pieces(self) -> tuple:
        """The convex sets whose union is this set: ``(self,)``."""
        return (self,)

    @property
    def center(self) -> np.ndarray:
        """Midpoint ``(lo + hi) / 2``."""
        return 0.5 * (self.lo + self.hi)

    @property
    def radius(self) -> np.ndarray:
        """Half-widths ``(hi - lo) / 2``."""
        return 0.5 * (self.hi - self.lo)

    def volume(self) -> float:
        """Product of the widths."""
        return float(np.prod(self.hi - self.lo))

    def to_zonotope(self) -> "Zonotope":
        """The same box as a :class:`Zonotope` (one generator per non-degenerate dimension)."""
        c, G = zk.from_interval(np.asarray(self.lo), np.asarray(self.hi))
        return Zonotope.from_kernel(c, G)

    def interval(self) -> "Interval":
        """The interval hull: the box itself."""
        return self

    def linear_map(self, M) -> "Zonotope":
        """``M @ self``: a :class:`Zonotope` (the image of a box is not a box)."""
        return M @ self.to_zonotope()

    def contains(self, points, tol: float = 0.0):
        """Membership of one point (bool) or of the rows of ``points`` (boolean array), up to ``tol``."""
        P, single = as_points(points, self.dim)
        tol = as_tolerance(tol)
        r = np.all((P >= self.lo - tol) & (P <= self.hi + tol), axis=1)
        return bool(r[0]) if single else r

    def hull(self, other: "Interval") -> "Interval":
        """Smallest box containing both (``other``: any set, by its interval hull)."""
        other = self._same_dim(other, "hull")
        return Interval(np.minimum(self.lo, other.lo), np.maximum(self.hi, other.hi))

    def intersection(self, other: "Interval") -> "Interval":
        """Intersection with the interval hull of ``other`` (:class:`SetError` if empty)."""
        other = self._same_dim(other, "intersection")
        return Interval(np.maximum(self.lo, other.lo), np.minimum(self.hi, other.hi))

    def scale(self, alpha: float) -> "Interval":
        """Scale about the centre by ``alpha >= 0`` (eq. 68), rounded outward (``alpha = 1``: the box itself)."""
        if not is_finite_number(alpha) or alpha < 0:
            raise SetError(f"alpha must be a finite non-negative number, got {alpha!r}")
        if alpha == 1:
            return self
        return Interval(*zk.scale_box(self.lo, self.hi, float(alpha)))  # an overflow (inf) is refused as unbounded

    def is_subset(self, other: "Interval", tol: float = 0.0) -> bool:
        """Is the box inside the interval hull of ``other`` (up to ``tol``)?"""
        other = self._same_dim(other, "is_subset")
        tol = as_tolerance(tol)
        return bool(np.all(self.lo >= other.lo - tol) and np.all(self.hi <= other.hi + tol))

    def _same_dim(self, other, op: str) -> "Interval":
        if not hasattr(other, "interval"):
            raise SetError(f"{op}: other must be a set (Interval, Zonotope, ...), got {type(other).__name__}")
        other = other.interval()
        if other.dim != self.dim:
            raise SetError(f"{op}: the sets have dimensions {self.dim} and {other.dim}")
        return other

    def sample(self, n: int, rng=None) -> np.ndarray:
        """``n`` points of the box, shape (n, dim): a quarter corners, the rest uniform."""
        n, rng = as_count(n, "n"), as_rng(rng)
        if n == 0:
            return np.empty((0, self.dim))
        corners = np.where(rng.random((max(n // 4, 1), self.dim)) < 0.5, self.lo, self.hi)
        inner = rng.uniform(self.lo, self.hi, size=(n - corners.shape[0], self.dim))
        return np.vstack([corners, inner])[:n]

    def project(self, dims) -> "Interval":
        """The box on the dimensions ``dims`` (indices)."""
        dims = _dims(dims, self.dim)
        return Interval(self.lo[dims], self.hi[dims])

    def __add__(self, other):
        if isinstance(other, Interval):
            if other.dim != self.dim:
                raise SetError(f"cannot add intervals of dimensions {self.dim} and {other.dim}")
            return Interval(np.nextafter(self.lo + other.lo, -np.inf), np.nextafter(self.hi + other.hi, np.inf))
        if isinstance(other, Zonotope):
            return other + self
        v = as_vector(other, "point")
        if v.size != self.dim:
            raise SetError(f"point has {v.size} entries, the interval {self.dim}")
        return Interval(np.nextafter(self.lo + v, -np.inf), np.nextafter(self.hi + v, np.inf))

    __radd__ = __add__

    def __rmatmul__(self, M):
        return M @ self.to_zonotope()

    def __eq__(self, other):
        return isinstance(other, Interval) and np.array_equal(self.lo, other.lo) and np.array_equal(self.hi, other.hi)

    def __hash__(self):
        return hash((self.lo.tobytes(), self.hi.tobytes()))

    def plot(self, ax=None, dims=(0, 1), **style):
        """Draw the projection on ``dims`` (see :meth:`Zonotope.plot`); returns the axes."""
        return self.to_zonotope().plot(ax, dims=dims, **style)

    @classmethod
    def from_list(cls, pairs) -> "Interval":
        """The box of ``[[lo_0, hi_0], ...]`` (the inverse of :meth:`to_list`)."""
        try:
            arr = np.asarray(pairs, dtype=float)
        except (TypeError, ValueError):
            raise SetError(f"from_list: expected [[lo, hi], ...] pairs of numbers, got {pairs!r}") from None
        if arr.ndim != 2 or arr.shape[1] != 2:
            raise SetError(f"from_list: expected [[lo, hi], ...] (shape (n, 2)), got shape {arr.shape}")
        return cls(arr[:, 0], arr[:, 1])

    def to_list(self):
        """``[[lo_0, hi_0], ...]`` as plain floats (JSON, run files)."""
        return [[float(a), float(b)] for a, b in zip(self.lo, self.hi)]

    def __repr__(self):
        pairs = ", ".join(f"[{a:.6g}, {b:.6g}]" for a, b in zip(self.lo, self.hi))
        return f"Interval({pairs})"


class Zonotope:
    """Zonotope ``{c + G b | b in [-1, 1]^m}``.

    Operations that are exact in real arithmetic (linear map, Minkowski sum, ``+`` a vector, enclose, scale,
    compact) are computed in floating point and may miss a true point by a few ulps of the numbers' magnitude;
    those that make boxes (interval hull, reduction, ``quad_map``) round outward.  ``contains``' default
    tolerance covers the former; the reach algorithms add an allowance for them every step.

    Parameters
    ----------
    center : array_like (n,)
        ``c``.
    generators : array_like (n, m), m >= 0
        ``G``, one generator per column.

    Raises
    ------
    SetError
        On non-finite values or shapes that do not match.
    """

    __slots__ = ("center", "generators")
    __array_ufunc__ = None  # make ``A @ Z`` call __rmatmul__ instead of numpy

    def __init__(self, center, generators):
        # a 0-dimensional zonotope is allowed: it is R^0 = {()} (e.g. W of a model without disturbances)
        c = as_vector(center, "center", allow_empty=True)
        try:
            G = np.array(generators, dtype=np.float64)
        except (TypeError, ValueError):
            raise SetError("generators must be numeric") from None
        if G.ndim == 1 and c.size == 1:
            G = G.reshape(1, -1)
        if G.ndim == 1 and G.size == 0:
            G = G.reshape(c.size, 0)
        if G.ndim != 2:
            raise SetError(f"generators must be a 2-D array (n, m), got shape {G.shape}")
        if G.shape[0] != c.size:
            raise SetError(f"generators have {G.shape[0]} rows but the center has {c.size} entries")
        if not np.all(np.isfinite(G)):
            raise SetError("generators contain NaN or inf (unbounded sets are not allowed)")
        G = np.ascontiguousarray(G)
        G.flags.writeable = False
        object.__setattr__(self, "center", c)
        object.__setattr__(self, "generators", G)

    def __setattr__(self, name, value):
        raise SetError("Zonotope is immutable")

    def __reduce__(self):
        return (Zonotope, (np.array(self.center), np.array(self.generators)))

    @classmethod
    def from_kernel(cls, c, G) -> "Zonotope":
        """Wrap kernel output (float64 arrays of the right shapes) without re-validating it.

        The arrays are taken over (made read-only), not copied; only a
        non-finite result is rejected.  For user input use the constructor.
        """
        # a sum is non-finite if any entry is; only then (or on overflow of the sum) check properly
        if not math.isfinite(c.sum() + G.sum()) and not (np.isfinite(c).all() and np.isfinite(G).all()):
            raise SetError("result is unbounded (overflow to inf/NaN)")
        c.flags.writeable = False
        G.flags.writeable = False
        Z = object.__new__(cls)
        object.__setattr__(Z, "center", c)
        object.__setattr__(Z, "generators", G)
        return Z

    @classmethod
    def from_interval(cls, interval: Interval) -> "Zonotope":
        """The box ``interval`` as a zonotope."""
        return interval.to_zonotope()

    @property
    def dim(self) -> int:
        """Dimension ``n``."""
        return self.center.size

    @property
    def order(self) -> float:
        """Generators per dimension, ``m / n``."""
        return self.generators.shape[1] / self.dim

    @property
    def pieces(self) -> tuple:
        """The convex sets whose union is this set: ``(self,)``."""
        return (self,)

    def _cg(self):
        return self.center, self.generators

    def interval(self) -> Interval:
        """Interval hull (exact: ``c ± sum |G|``, outward rounded)."""
        lo, hi = zk.interval_hull(*self._cg())
        return Interval(lo, hi)

    def to_zonotope(self) -> "Zonotope":
        """The zonotope itself."""
        return self

    def linear_map(self, M) -> "Zonotope":
        """``M @ self``, for a matrix ``M`` (k, n): exact in real arithmetic, computed in floating point (the few-ulp
        rounding is not enclosed; the reach algorithms add an allowance for it)."""
        return M @ self

    def __rmatmul__(self, M):
        M = np.asarray(M, dtype=np.float64)
        if M.ndim != 2 or M.shape[1] != self.dim:
            raise SetError(f"matrix of shape {M.shape} cannot map a zonotope of dimension {self.dim}")
        if not np.all(np.isfinite(M)):
            raise SetError("matrix contains NaN or inf")
        c, G = zk.linear_map(np.ascontiguousarray(M), *self._cg())
        return Zonotope.from_kernel(c, G)

    def __add__(self, other):
        c, G = self._cg()
        if isinstance(other, Zonotope):
            if other.dim != self.dim:
                raise SetError(f"cannot add zonotopes of dimensions {self.dim} and {other.dim}")
            c2, G2 = zk.minkowski_sum(c, G, *other._cg())
            return Zonotope.from_kernel(c2, G2)
        if isinstance(other, Interval):
            if other.dim != self.dim:
                raise SetError(f"cannot add an interval of dimension {other.dim} to a zonotope of dimension {self.dim}")
            c2, G2 = zk.add_interval(c, G, np.asarray(other.lo), np.asarray(other.hi))
            return Zonotope.from_kernel(c2, G2)
        v = as_vector(other, "point")
        if v.size != self.dim:
            raise SetError(f"point has {v.size} entries, the zonotope {self.dim}")
        return Zonotope(c + v, G)

    __radd__ = __add__

    def reduce(self, order: float, method="girard") -> "Zonotope":
        """An enclosing zonotope with at most ``order * dim`` generators.

        Parameters
        ----------
        order : float
            At least 1.
        method : str or ReductionMethod, default "girard"
            :class:`~reachconf.sets.reduction.Girard` (``"girard"``) or
            :class:`~reachconf.sets.reduction.PCA` (``"pca"``).

        Returns
        -------
        Zonotope
        """
        if not is_finite_number(order) or order < 1:
            raise SetError(f"order must be a number >= 1, got {order!r}")
        try:
            reduction = reduction_method(method)
        except OptionsError as exc:
            raise SetError(str(exc)) from None
        c, G = reduction.reduce(*self._cg(), float(order))
        return Zonotope.from_kernel(c, G)

    def enclose(self, other: "Zonotope") -> "Zonotope":
        """A zonotope enclosing the convex hull of both (Girard's enclosure)."""
        other = other.to_zonotope()
        if other.dim != self.dim:
            raise SetError(f"cannot enclose zonotopes of dimensions {self.dim} and {other.dim}")
        c, G = zk.enclose(*self._cg(), *other._cg())
        return Zonotope.from_kernel(c, G)

    def cartesian(self, other) -> "Zonotope":
        """The Cartesian product ``self × other``."""
        other = other.to_zonotope()
        c, G = zk.cartesian_product(*self._cg(), *other._cg())
        return Zonotope.from_kernel(c, G)

    def quad_map(self, Q) -> "Zonotope":
        """A zonotope enclosing ``{(x^T Q_i x)_i | x in self}`` for matrices ``Q`` (k, n, n) (CORA's quadMap)."""
        Q = np.ascontiguousarray(np.asarray(Q, dtype=np.float64))
        if Q.ndim != 3 or Q.shape[1:] != (self.dim, self.dim):
            raise SetError(f"Q must have shape (k, {self.dim}, {self.dim}), got {Q.shape}")
        c, G = qk.quad_map(*self._cg(), Q)
        err = qk.quad_map_rounding(*self._cg(), *self._cg(), Q)  # outward rounding: a box of a few ulps per output
        return Zonotope.from_kernel(c, np.hstack([G, np.diag(err)[:, err > 0]]))

    def compact(self, tol: float = 0.0) -> "Zonotope":
        """The same set with parallel generators merged and generators of length <= ``tol`` dropped."""
        c, G = zk.compact(*self._cg(), as_tolerance(tol))
        return Zonotope.from_kernel(c, G)

    def support(self, direction) -> float:
        """Support function ``max_{x in Z} d^T x`` (outward rounded)."""
        d = as_vector(direction, "direction")
        if d.size != self.dim:
            raise SetError(f"direction has {d.size} entries, the zonotope {self.dim}")
        return float(zk.support(*self._cg(), np.ascontiguousarray(d)))

    def bounds_along(self, direction):
        """``(min, max)`` of ``d^T x`` over the zonotope (outward rounded)."""
        d = as_vector(direction, "direction")
        if d.size != self.dim:  # the compiled loop reads d[i] for every dimension
            raise SetError(f"direction has {d.size} entries, the zonotope {self.dim}")
        return tuple(float(v) for v in zk.bounds_along(*self._cg(), np.ascontiguousarray(d)))

    def project(self, dims) -> "Zonotope":
        """The zonotope on the dimensions ``dims`` (indices)."""
        dims = _dims(dims, self.dim)
        return Zonotope(self.center[dims], self.generators[dims])

    def scale(self, alpha: float) -> "Zonotope":
        """Scale about the centre by ``alpha >= 0``."""
        if not (np.isfinite(alpha) and alpha >= 0):
            raise SetError(f"alpha must be a finite non-negative number, got {alpha!r}")
        return Zonotope(self.center, alpha * self.generators)

    def polygon(self, dims=(0, 1)) -> np.ndarray:
        """Vertices (V, 2) of a convex polygon, counter-clockwise, that contains the 2-D projection (by ulps)."""
        Z = self.project(dims) if self.dim != 2 or tuple(dims) != (0, 1) else self
        Z = Z.compact(0.0)
        if Z.generators.shape[1] == 0:
            return Z.center.reshape(1, 2).copy()
        return zonotope_polygon(*Z._cg())

    def contains(self, points, tol: float = 1e-9):
        """Point containment: ``||p - c||_Z <= 1 + tol`` (zonotope norm), exact up to ``tol``.

        Points outside the interval hull are rejected at once; in 2-D the
        half-spaces normal to the generators decide; otherwise a compiled simplex whose every
        answer carries a checked certificate, and one LP (HiGHS) per point
        without one (:func:`reachconf.sets.containment.contains_points`).
        Returns a bool for one point, a boolean array for the rows of ``points``.
        A ``tol`` far below the default is not resolved where the LP decides:
        HiGHS's feasibility tolerance is 1e-10 in the problem's scaled units
        (measured: points at most 3.6 % of the default ``tol`` beyond the
        widened set were accepted there).
        """
        P, single = as_points(points, self.dim)
        res = contains_points(self.center, self.generators, P, as_tolerance(tol))
        return bool(res[0]) if single else res

    def sample(self, n: int, rng=None) -> np.ndarray:
        """``n`` points inside: random vertices (b in {-1, 1}^m) and random interior points."""
        n, rng = as_count(n, "n"), as_rng(rng)
        if n == 0:
            return np.empty((0, self.dim))
        m = self.generators.shape[1]
        k = max(n // 3, 1)
        B = np.vstack([np.where(rng.random((k, m)) < 0.5, -1.0, 1.0), rng.uniform(-1, 1, size=(n - k, m))])[:n]
        return self.center + B @ self.generators.T

    def vertices_sample(self, n: int, rng=None) -> np.ndarray:
        """``n`` random vertices (``b`` in {-1, 1}^m; possibly repeated or not extreme)."""
        n, rng = as_count(n, "n"), as_rng(rng)
        B = np.where(rng.random((n, self.generators.shape[1])) < 0.5, -1.0, 1.0)
        return self.center + B @ self.generators.T

    def plot(self, ax=None, dims=(0, 1), **style):
        """Draw the projection on ``dims`` as a filled polygon; returns the axes.

        Parameters
        ----------
        ax : matplotlib Axes, optional
            New axes if None.
        dims : pair of int
        **style
            Passed to the patch (``color`` for face and edge, ``alpha`` 0.4 by default).
        """
        import matplotlib.pyplot as plt
        from matplotlib.patches import Polygon

        if ax is None:
            _, ax = plt.subplots()
        V = self.polygon(dims)
        style.setdefault("alpha", 0.4)
        color = style.pop("color", "C0")
        ax.add_patch(Polygon(V, closed=True, facecolor=color, edgecolor=color, **style))
        ax.autoscale_view()
        ax.update_datalim(V)
        ax.autoscale()
        return ax

    def __repr__(self):
        return f"Zonotope(dim={self.dim}, generators={self.generators.shape[1]}, center={np.round(self.center, 6).tolist()})"
