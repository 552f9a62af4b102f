"""Union of zonotopes: the pieces of a split reachable set at one time."""

from __future__ import annotations

import numpy as np

from reachconf.errors import SetError
from reachconf.sets.core import Interval

__all__ = ["SetUnion"]


class SetUnion:
    """Union of zonotopes (the pieces of a split reachable set at one time).

    Parameters
    ----------
    pieces : iterable of Zonotope
        At least one set, all of the same dimension.
    """

    def __init__(self, pieces):
        from reachconf.sets.core import Zonotope

        if pieces is None or isinstance(pieces, (str, bytes)):
            raise SetError(f"SetUnion: pieces must be an iterable of zonotopes, got {pieces!r}")
        try:
            pieces = tuple(pieces)
        except TypeError:
            raise SetError(f"SetUnion: pieces must be an iterable of zonotopes, got {type(pieces).__name__}") from None
        if not pieces:
            raise SetError("SetUnion needs at least one set")
        conv = []
        for i, piece in enumerate(pieces):
            if isinstance(piece, Interval):
                piece = piece.to_zonotope()
            if not isinstance(piece, Zonotope):
                raise SetError(f"SetUnion: piece {i} is a {type(piece).__name__}, not a Zonotope or Interval")
            if conv and piece.dim != conv[0].dim:
                raise SetError(f"SetUnion: piece {i} has dimension {piece.dim}, piece 0 {conv[0].dim}")
            conv.append(piece)
        #: the zonotopes whose union is the set
        self.pieces = tuple(conv)

    @property
    def dim(self) -> int:
        """Dimension of the pieces."""
        return self.pieces[0].dim

    def interval(self) -> Interval:
        """Interval hull of the union."""
        lo = np.min([p.interval().lo for p in self.pieces], axis=0)
        hi = np.max([p.interval().hi for p in self.pieces], axis=0)
        return Interval(lo, hi)

    def contains(self, points, tol=1e-9):
        """Point containment in any piece (bool for one point, boolean array for several)."""
        result = None
        for p in self.pieces:
            r = np.asarray(p.contains(points, tol=tol))
            result = r if result is None else (result | r)
        return result if result.ndim else bool(result)

    def project(self, dims):
        """The union of the projected pieces."""
        return SetUnion([p.project(dims) for p in self.pieces])

    def linear_map(self, M):
        """The union of the mapped pieces ``M @ piece``."""
        return SetUnion([M @ p for p in self.pieces])

    def __add__(self, other):
        return SetUnion([p + other for p in self.pieces])

    def plot(self, ax=None, dims=(0, 1), **style):
        """Draw every piece (see :meth:`Zonotope.plot`); returns the axes."""
        for p in self.pieces:
            ax = p.plot(ax, dims=dims, **style)
        return ax

    def __iter__(self):
        return iter(self.pieces)

    def __len__(self):
        return len(self.pieces)

    def __repr__(self):
        return f"SetUnion({len(self.pieces)} zonotopes of dimension {self.dim})"
