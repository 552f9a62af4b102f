"""Sets: every set type of reachconf and the operations on them.

* :mod:`reachconf.sets.core` — :class:`Interval` (axis-aligned boxes) and
  :class:`Zonotope`, immutable, computed by the kernels of
  :mod:`reachconf_kernels.zonotope`;
* :mod:`reachconf.sets.union` — :class:`SetUnion`, the pieces of a split
  reachable set;
* :mod:`reachconf.sets.disk` — :class:`BoxDisk` (box ⊕ disk, the pedestrian
  sets of eqs. 73/74) with its exact membership test
  :func:`box_disk_distance`, and :func:`disk_zonotope`;
* :mod:`reachconf.sets.containment` — certified batch point containment in
  zonotopes;
* :mod:`reachconf.sets.convert` — :func:`as_box`, :func:`as_zonotope` for set
  arguments;
* :mod:`reachconf.sets.reduction` — order-reduction methods as option types
  (:class:`Girard`, :class:`PCA`);
* :mod:`reachconf.sets.protocol` — :class:`ReachSet`, the protocol all set
  types follow (``dim``, ``pieces``, ``interval()``, ``contains``,
  ``linear_map``, ``plot``).
"""

from reachconf.sets.containment import contains_points, contains_points_lp
from reachconf.sets.convert import as_box, as_zonotope
from reachconf.sets.core import Interval, Zonotope
from reachconf.sets.disk import BoxDisk, box_disk_distance, disk_zonotope
from reachconf.sets.protocol import ReachSet
from reachconf.sets.reduction import PCA, Girard, ReductionMethod, reduction_method, register_reduction
from reachconf.sets.union import SetUnion

__all__ = ["Interval", "Zonotope", "SetUnion", "BoxDisk", "box_disk_distance", "disk_zonotope", "as_box",
           "as_zonotope", "contains_points", "contains_points_lp", "ReachSet", "ReductionMethod", "Girard", "PCA",
           "reduction_method", "register_reduction"]  # fmt: skip
