"""The α-search of eq. 68: the smallest scaling ``c + α g`` of a box that passes a check.

Used by synthesis step 3 (per case) and the merge per maneuver
(:mod:`reachconf.conformance.synthesis`).
"""

from __future__ import annotations

from reachconf.sets.core import Interval

__all__ = ["alpha_search", "scaled_box"]


def scaled_box(c, g, alpha) -> Interval:
    """The box ``c ± α g`` (eq. 68)."""
    return Interval(c - alpha * g, c + alpha * g)


def alpha_search(check, W: Interval, iterations: int = 10, alpha_max: float = 1.0):
    """Binary search (eq. 68) for the smallest α with ``check(c + α g)`` true.

    ``check(Interval) -> bool``; ``c, g`` are the centre and radius of ``W``.
    α = 1 is tried first; if it fails, α is doubled up to ``alpha_max`` (see
    :class:`~reachconf.conformance.synthesis.SynthesisOptions`).  The
    bisection then runs between the largest failing and the smallest
    conformant α (``[0, 1]`` when α = 1 passes).  Returns ``(alpha, box,
    conformant, trials)``; if no α up to ``alpha_max`` passes, ``conformant``
    is False and α is the last one tried.
    """
    c, g = W.center, W.radius
    trials = []
    lo, hi = 0.0, 1.0
    while True:
        ok = check(scaled_box(c, g, hi))
        trials.append((hi, bool(ok)))
        if ok:
            break
        if hi >= alpha_max:
            return hi, scaled_box(c, g, hi), False, trials
        lo, hi = hi, min(2.0 * hi, alpha_max)
    for _ in range(iterations):
        mid = 0.5 * (lo + hi)
        ok = check(scaled_box(c, g, mid))
        trials.append((mid, bool(ok)))
        if ok:
            hi = mid
        else:
            lo = mid
    return hi, scaled_box(c, g, hi), True, trials
