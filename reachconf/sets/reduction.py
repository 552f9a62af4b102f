"""Zonotope order-reduction methods as option types (as LazySets' ``GIR05()``, ``COMB03()``).

A reduction method encloses a zonotope by one of at most ``order`` times its
dimension generators.  Pass an instance or its name wherever a method is
asked for: ``Z.reduce(10, Girard())`` is ``Z.reduce(10, "girard")``;
``ReachOptions(reduction=PCA())`` is ``ReachOptions(reduction="pca")``.

To add a method: subclass :class:`ReductionMethod` with a frozen dataclass,
give it a ``name``, its paper in the docstring and a :meth:`~ReductionMethod.reduce`,
and register it with :func:`register_reduction`.  (The compiled reach loop
knows the methods by ``kernel_code``; a method without one reduces only
outside it.)
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

from reachconf.registry import NamedTypes
from reachconf_kernels import zonotope as zk

__all__ = ["ReductionMethod", "Girard", "PCA", "REDUCTION_METHODS", "reduction_method", "register_reduction"]


class ReductionMethod:
    """Base of the order-reduction methods (see the module docstring)."""

    #: the shorthand accepted in place of an instance
    name: ClassVar[str] = ""
    #: the method's number in the compiled reach loop (None: not available there)
    kernel_code: ClassVar[int | None] = None

    def reduce(self, c, G, order: float):
        """``(c, G)`` of an enclosing zonotope with at most ``order * n`` generators (kernel arrays)."""
        raise NotImplementedError

    def __str__(self):
        return self.name


@dataclass(frozen=True)
class Girard(ReductionMethod):
    """Girard's reduction: keep the longest generators, box the others.

    The generators with the largest ``||g||_1 - ||g||_inf`` are kept, the
    others are replaced by the interval hull of their sum (one generator per
    dimension), outward rounded.

    References
    ----------
    A. Girard, "Reachability of uncertain linear systems using zonotopes",
    HSCC 2005, LNCS 3414, pp. 291–305.
    """

    name: ClassVar[str] = "girard"
    kernel_code: ClassVar[int | None] = 0

    def reduce(self, c, G, order: float):
        """See :meth:`ReductionMethod.reduce`."""
        return zk.reduce_girard(c, G, float(order))


@dataclass(frozen=True)
class PCA(ReductionMethod):
    """Girard's choice of generators, boxed in the frame of their principal axes.

    The generators to be removed are enclosed by a box aligned with the
    eigenvectors of ``R R^T`` (``R`` the removed generators) instead of the
    coordinate axes, inflated for the rounding of the eigenvectors.

    References
    ----------
    A.-K. Kopetzki, B. Schürmann, M. Althoff, "Methods for order reduction of
    zonotopes", IEEE CDC 2017, pp. 5626–5633 (the PCA method).
    """

    name: ClassVar[str] = "pca"
    kernel_code: ClassVar[int | None] = 1

    def reduce(self, c, G, order: float):
        """See :meth:`ReductionMethod.reduce`."""
        return zk.reduce_pca(c, G, float(order))


#: name -> method type (``REDUCTION_METHODS.register`` adds one)
REDUCTION_METHODS = NamedTypes(ReductionMethod, "reduction method")


def register_reduction(cls: type[ReductionMethod]) -> type[ReductionMethod]:
    """Make a :class:`ReductionMethod` subclass known by its ``name`` (usable as a decorator)."""
    return REDUCTION_METHODS.register(cls)


def reduction_method(value) -> ReductionMethod:
    """The method for a name (``"girard"``, ``"pca"``) or an instance (:class:`OptionsError` otherwise)."""
    return REDUCTION_METHODS.resolve(value)


for _cls in (Girard, PCA):
    register_reduction(_cls)
