"""The two concrete set types, :class:`Interval` (axis-aligned boxes) and :class:`Zonotope`.

They convert into each other (``Interval.to_zonotope``, ``Zonotope.interval``),
so they share this module.  Both are immutable (read-only numpy arrays) and validate their input; the
computations are done by the numba kernels in :mod:`reachconf_kernels.zonotope`.
"""

from __future__ import annotations

import math

import numpy as np

from reachconf.errors import SetError
from reachconf.sets.containment import contains_points
from reachconf_kernels import zonotope as zk

__all__ = ["Interval", "Zonotope"]


def _vector(value, name: str, allow_empty: bool = False) -> np.ndarray:
    try:
        arr = np.array(value, dtype=np.float64).reshape(-1)
    except (TypeError, ValueError):
        raise SetError(f"{name} must be numeric, got {value!r}") from None
    if arr.size == 0 and not allow_empty:
        raise SetError(f"{name} is empty")
    if not np.all(np.isfinite(arr)):
        raise SetError(f"{name} contains NaN or inf (unbounded sets are not allowed)")
    arr = np.ascontiguousarray(arr)
    arr.flags.writeable = False
    return arr


def _points(points, dim: int, name="points"):
    P = np.asarray(points, dtype=np.float64)
    single = P.ndim == 1
    P = np.atleast_2d(P)
    if P.shape[-1] != dim:
        raise SetError(f"{name} must have {dim} columns, got shape {np.shape(points)}")
    if not np.all(np.isfinite(P)):
        raise SetError(f"{name} contains NaN or inf")
    return np.ascontiguousarray(P), single


class Interval:
    """Axis-aligned box ``[lo, hi]`` (eq. 62–66 boxes, V and W sets).

    Parameters
    ----------
    lo, hi : array_like (n,) or scalars
    """

    __slots__ = ("lo", "hi")
    __array_ufunc__ = None  # make ``A @ box`` call __rmatmul__ instead of numpy

    def __init__(self, lo, hi):
        lo = _vector(lo, "lo", allow_empty=True)
        hi = _vector(hi, "hi", allow_empty=True)
        if lo.shape != hi.shape:
            raise SetError(f"lo has {lo.size} entries but hi has {hi.size}")
        bad = np.nonzero(lo > hi)[0]
        if bad.size:
            i = int(bad[0])
            raise SetError(f"lo > hi in dimension {i}: {lo[i]} > {hi[i]} (empty interval)")
        object.__setattr__(self, "lo", lo)
        object.__setattr__(self, "hi", hi)

    def __setattr__(self, name, value):
        raise SetError("Interval is immutable")

    def __reduce__(self):
        return (Interval, (np.array(self.lo), np.array(self.hi)))

    @property
    def dim(self) -> int:
        return self.lo.size

    @property
    def center(self) -> np.ndarray:
        return 0.5 * (self.lo + self.hi)

    @property
    def radius(self) -> np.ndarray:
        return 0.5 * (self.hi - self.lo)

    def volume(self) -> float:
        return float(np.prod(self.hi - self.lo))

    def to_zonotope(self) -> "Zonotope":
        c, G = zk.from_interval(np.asarray(self.lo), np.asarray(self.hi))
        return Zonotope.from_kernel(c, G)

    def interval(self) -> "Interval":
        return self

    def contains(self, points, tol: float = 0.0):
        P, single = _points(points, self.dim)
        r = np.all((P >= self.lo - tol) & (P <= self.hi + tol), axis=1)
        return bool(r[0]) if single else r

    def hull(self, other: "Interval") -> "Interval":
        other = _as_interval(other)
        return Interval(np.minimum(self.lo, other.lo), np.maximum(self.hi, other.hi))

    def intersection(self, other: "Interval") -> "Interval":
        other = _as_interval(other)
        return Interval(np.maximum(self.lo, other.lo), np.minimum(self.hi, other.hi))

    def scale(self, alpha: float) -> "Interval":
        """Scale about the centre by ``alpha >= 0`` (eq. 68)."""
        if not (np.isfinite(alpha) and alpha >= 0):
            raise SetError(f"alpha must be a finite non-negative number, got {alpha!r}")
        c, r = self.center, self.radius
        return Interval(c - alpha * r, c + alpha * r)

    def is_subset(self, other: "Interval", tol: float = 0.0) -> bool:
        other = _as_interval(other)
        return bool(np.all(self.lo >= other.lo - tol) and np.all(self.hi <= other.hi + tol))

    def sample(self, n: int, rng=None) -> np.ndarray:
        rng = np.random.default_rng(rng)
        corners = np.where(rng.random((max(n // 4, 1), self.dim)) < 0.5, self.lo, self.hi)
        inner = rng.uniform(self.lo, self.hi, size=(n - corners.shape[0], self.dim))
        return np.vstack([corners, inner])[:n]

    def project(self, dims) -> "Interval":
        dims = list(dims)
        return Interval(self.lo[dims], self.hi[dims])

    def __add__(self, other):
        if isinstance(other, Interval):
            if other.dim != self.dim:
                raise SetError(f"cannot add intervals of dimensions {self.dim} and {other.dim}")
            return Interval(np.nextafter(self.lo + other.lo, -np.inf), np.nextafter(self.hi + other.hi, np.inf))
        if isinstance(other, Zonotope):
            return other + self
        v = _vector(other, "point")
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
        return self.to_zonotope().plot(ax, dims=dims, **style)

    def to_list(self):
        return [[float(a), float(b)] for a, b in zip(self.lo, self.hi)]

    def __repr__(self):
        pairs = ", ".join(f"[{a:.6g}, {b:.6g}]" for a, b in zip(self.lo, self.hi))
        return f"Interval({pairs})"


def _as_interval(x) -> Interval:
    if isinstance(x, Interval):
        return x
    if isinstance(x, Zonotope):
        return x.interval()
    raise SetError(f"expected an Interval, got {type(x).__name__}")


class Zonotope:
    """Zonotope ``{c + G b | b in [-1, 1]^m}``.

    Parameters
    ----------
    center : array_like (n,)
    generators : array_like (n, m), m >= 0
    """

    __slots__ = ("center", "generators")
    __array_ufunc__ = None  # make ``A @ Z`` call __rmatmul__ instead of numpy

    def __init__(self, center, generators):
        # a 0-dimensional zonotope is allowed: it is R^0 = {()} (e.g. W of a model without disturbances)
        c = _vector(center, "center", allow_empty=True)
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
        return interval.to_zonotope()

    @property
    def dim(self) -> int:
        return self.center.size

    @property
    def order(self) -> float:
        return self.generators.shape[1] / self.dim

    def _cg(self):
        return self.center, self.generators

    def interval(self) -> Interval:
        lo, hi = zk.interval_hull(*self._cg())
        return Interval(lo, hi)

    def to_zonotope(self) -> "Zonotope":
        return self

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
        v = _vector(other, "point")
        if v.size != self.dim:
            raise SetError(f"point has {v.size} entries, the zonotope {self.dim}")
        return Zonotope(c + v, G)

    __radd__ = __add__

    def reduce(self, order: float, method: str = "girard") -> "Zonotope":
        if not (np.isfinite(order) and order >= 1):
            raise SetError(f"order must be >= 1, got {order!r}")
        if method == "girard":
            c, G = zk.reduce_girard(*self._cg(), float(order))
        elif method == "pca":
            c, G = zk.reduce_pca(*self._cg(), float(order))
        else:
            raise SetError(f"unknown reduction method {method!r}; use 'girard' or 'pca'")
        return Zonotope.from_kernel(c, G)

    def enclose(self, other: "Zonotope") -> "Zonotope":
        other = other.to_zonotope()
        if other.dim != self.dim:
            raise SetError(f"cannot enclose zonotopes of dimensions {self.dim} and {other.dim}")
        c, G = zk.enclose(*self._cg(), *other._cg())
        return Zonotope.from_kernel(c, G)

    def cartesian(self, other) -> "Zonotope":
        other = other.to_zonotope()
        c, G = zk.cartesian_product(*self._cg(), *other._cg())
        return Zonotope.from_kernel(c, G)

    def quad_map(self, Q) -> "Zonotope":
        Q = np.ascontiguousarray(np.asarray(Q, dtype=np.float64))
        if Q.ndim != 3 or Q.shape[1:] != (self.dim, self.dim):
            raise SetError(f"Q must have shape (k, {self.dim}, {self.dim}), got {Q.shape}")
        c, G = zk.quad_map(*self._cg(), Q)
        return Zonotope.from_kernel(c, G)

    def compact(self, tol: float = 0.0) -> "Zonotope":
        c, G = zk.compact(*self._cg(), float(tol))
        return Zonotope.from_kernel(c, G)

    def support(self, direction) -> float:
        d = _vector(direction, "direction")
        if d.size != self.dim:
            raise SetError(f"direction has {d.size} entries, the zonotope {self.dim}")
        return float(zk.support(*self._cg(), np.ascontiguousarray(d)))

    def bounds_along(self, direction):
        d = _vector(direction, "direction")
        return tuple(float(v) for v in zk.bounds_along(*self._cg(), np.ascontiguousarray(d)))

    def project(self, dims) -> "Zonotope":
        dims = [int(d) for d in dims]
        for d in dims:
            if not 0 <= d < self.dim:
                raise SetError(f"dimension {d} out of range 0..{self.dim - 1}")
        return Zonotope(self.center[dims], self.generators[dims])

    def scale(self, alpha: float) -> "Zonotope":
        if not (np.isfinite(alpha) and alpha >= 0):
            raise SetError(f"alpha must be a finite non-negative number, got {alpha!r}")
        return Zonotope(self.center, alpha * self.generators)

    def polygon(self, dims=(0, 1)) -> np.ndarray:
        """Vertices of the 2-D projection, counter-clockwise, shape (V, 2)."""
        Z = self.project(dims) if self.dim != 2 or tuple(dims) != (0, 1) else self
        Z = Z.compact(0.0)
        if Z.generators.shape[1] == 0:
            return Z.center.reshape(1, 2).copy()
        return zk.polygon(*Z._cg())

    def contains(self, points, tol: float = 1e-9):
        """Point containment: ``||p - c||_Z <= 1 + tol`` (zonotope norm), exact up to ``tol``.

        Points outside the interval hull are rejected at once; points with a
        least-norm coefficient vector in the unit box are accepted at once;
        the rest are decided by an LP (HiGHS) each.
        """
        P, single = _points(points, self.dim)
        res = contains_points(self.center, self.generators, P, tol)
        return bool(res[0]) if single else res

    def sample(self, n: int, rng=None) -> np.ndarray:
        """``n`` points inside: random vertices (b in {-1, 1}^m) and random interior points."""
        rng = np.random.default_rng(rng)
        m = self.generators.shape[1]
        k = max(n // 3, 1)
        B = np.vstack([np.where(rng.random((k, m)) < 0.5, -1.0, 1.0), rng.uniform(-1, 1, size=(n - k, m))])[:n]
        return self.center + B @ self.generators.T

    def vertices_sample(self, n: int, rng=None) -> np.ndarray:
        rng = np.random.default_rng(rng)
        B = np.where(rng.random((n, self.generators.shape[1])) < 0.5, -1.0, 1.0)
        return self.center + B @ self.generators.T

    def plot(self, ax=None, dims=(0, 1), **style):
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
