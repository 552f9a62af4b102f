"""The α-search of eq. 68: the smallest scaling ``c + α g`` of a box that passes a check.

Used by synthesis step 3 (per case, :mod:`reachconf.conformance.synthesis`),
the merge per maneuver (:mod:`reachconf.conformance.merge`) and the Pareto
front (:mod:`reachconf.conformance.pareto`), with the check of
:func:`reachset_check`.
"""

from __future__ import annotations

from reachconf.conformance.reachset import reachset_conformance
from reachconf.errors import OptionsError
from reachconf.sets.convert import as_zonotope
from reachconf.sets.core import Interval
from reachconf.verdict import Verdict

__all__ = ["alpha_search", "scaled_box", "reachset_check", "check_initial_sets"]


def scaled_box(c, g, alpha) -> Interval:
    """The box ``c ± α g`` (eq. 68)."""
    return Interval(c - alpha * g, c + alpha * g)


def alpha_search(check, W: Interval, iterations: int = 10, alpha_max: float = 1.0, below_failed_reach: bool = False):
    """Binary search (eq. 68) for the smallest α with ``check(c + α g)`` true.

    ``check(Interval)`` returns a bool, a :class:`~reachconf.verdict.Verdict` or a result with a ``verdict``;
    ``c, g`` are the centre and radius of ``W``.  α = 1 is tried first; if it is not conformant, α is
    doubled up to ``alpha_max`` (see :class:`~reachconf.conformance.synthesis.SynthesisOptions`) — but not
    after an *undecided* check (the reach failed: a larger box cannot make it succeed).  The
    bisection then runs between the largest failing and the smallest
    conformant α (``[0, 1]`` when α = 1 passes).

    ``below_failed_reach``: when a check is undecided before any α passed, bisect (at most
    ``iterations`` checks) between the largest α whose check was not conformant (0 at first) and the
    undecided one: a check that passes opens a *window* (its box is small enough for the reach and
    the reach still contains the measurements), which the bisection then narrows as above; an
    undecided check moves the upper end down, a not conformant one the lower end up.  Reachset
    conformance (eq. 43) is a property of the computed over-approximation, so it is not monotone in
    α where the reach is near failing: the window can be narrow, and is not searched for by default.

    Returns ``(alpha, box, conformant, trials)``; if no α passes, ``conformant``
    is False and α is the last one tried (with ``below_failed_reach``: the first undecided one).
    """
    c, g = W.center, W.radius
    trials = []
    lo, hi = 0.0, 1.0
    while True:
        ok, undecided = _outcome(check(scaled_box(c, g, hi)))
        trials.append((hi, ok))
        if ok:
            break
        if undecided and below_failed_reach:
            window = _window(check, c, g, lo, hi, iterations, trials)
            if window is None:
                return hi, scaled_box(c, g, hi), False, trials
            lo, hi = window
            break
        if hi >= alpha_max or undecided:
            return hi, scaled_box(c, g, hi), False, trials
        lo, hi = hi, min(2.0 * hi, alpha_max)
    for _ in range(iterations):
        mid = 0.5 * (lo + hi)
        ok, _ = _outcome(check(scaled_box(c, g, mid)))
        trials.append((mid, ok))
        if ok:
            hi = mid
        else:
            lo = mid
    return hi, scaled_box(c, g, hi), True, trials


def _window(check, c, g, lo, hi, iterations, trials):
    """``(lo, α)`` with ``check`` passing at α in ``(lo, hi)`` (``lo`` not conformant, ``hi`` undecided), or None."""
    for _ in range(iterations):
        mid = 0.5 * (lo + hi)
        ok, undecided = _outcome(check(scaled_box(c, g, mid)))
        trials.append((mid, ok))
        if ok:
            return lo, mid
        if undecided:
            hi = mid
        else:
            lo = mid
    return None


def _outcome(result) -> tuple[bool, bool]:
    """``(conformant, undecided)`` of a check's result (bool, Verdict, or an object with ``verdict``)."""
    verdict = result if isinstance(result, Verdict) else getattr(result, "verdict", None)
    if isinstance(verdict, Verdict):
        return verdict is Verdict.CONFORMANT, verdict is Verdict.UNDECIDED
    return bool(result), False


def reachset_check(model, case, W, V, options):
    """The reachset-conformance check of the α-searches: eq. 43 from ``options.X0`` (per case) or eq. 67.

    Stops at the first violation; when the reach with ``options.reach``
    fails (the set explodes), tries ``options.reach_fallback`` if given.

    Parameters
    ----------
    model : Model
    case : TestCase
    W, V : Interval
    options : SynthesisOptions

    Returns
    -------
    ReachsetResult
    """
    X0 = case_initial_set(options, case)
    res = reachset_conformance(model, case, W, V, X0=X0, options=options.reach, keep_tube=False,
                               violation_distance=False, stop_at_first_violation=True)  # fmt: skip
    if res.verdict is Verdict.UNDECIDED and options.reach_fallback is not None:  # the reach failed: the precise one
        res = reachset_conformance(model, case, W, V, X0=X0, options=options.reach_fallback, keep_tube=False,
                                   violation_distance=False, stop_at_first_violation=True)  # fmt: skip
    return res


def case_initial_set(options, case):
    """``options.X0`` for ``case``: the one set, the case's entry of a per-case mapping, or None (eq. 67)."""
    X0 = options.X0
    if isinstance(X0, dict):
        if case.name not in X0:
            raise OptionsError(f"SynthesisOptions.X0 has no initial set for case {case.name!r} (a mapping needs "
                               f"every case checked)")  # fmt: skip
        return X0[case.name]
    return X0


def check_initial_sets(X0, cases, n: int, where: str) -> None:
    """Raise before any work if ``SynthesisOptions.X0`` lacks a case's set or has a set of another dimension.

    ``X0``: None, one Interval/Zonotope, or a mapping of case names to them; ``n``: the model's state dimension.
    """
    missing = missing_initial_sets(X0, cases)
    if missing:
        raise OptionsError(f"{where}: SynthesisOptions.X0 has no initial set for case(s) {missing} (a mapping "
                           f"needs every case of the suite)")  # fmt: skip
    sets = X0.items() if isinstance(X0, dict) else ([] if X0 is None else [(None, X0)])
    for name, S in sets:
        label = "SynthesisOptions.X0" + ("" if name is None else f"[{name!r}]")
        as_zonotope(S, n, f"{where}: {label}")


def missing_initial_sets(X0, cases) -> str:
    """The names of ``cases`` that a per-case ``X0`` mapping lacks, as text for an error (the first five), or ""."""
    missing = [c.name for c in cases if c.name not in X0] if isinstance(X0, dict) else []
    return f"{missing[:5]}{' ...' if len(missing) > 5 else ''}" if missing else ""
