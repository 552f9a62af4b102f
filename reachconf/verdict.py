"""Three-valued conformance verdicts: conformant, not conformant, undecided.

A check is *undecided* when it could not be carried out to the end — the
reachable set exploded or left the model's domain, the simulated trace
diverged, the optimiser found no disturbance trace — so that neither answer
is shown.  An undecided check is never counted as conformant (``conformant``
is False) and never reported as "not conformant" either: the result's
``message`` says why it is undecided.

In JSON, a verdict is the string ``"conformant"``, ``"not_conformant"`` or
``"undecided"`` (key ``verdict``), and ``conformant`` is ``true``, ``false``
or ``null`` (undecided).
"""

from __future__ import annotations

from enum import Enum

__all__ = ["Verdict", "overall_verdict"]


class Verdict(str, Enum):
    """Outcome of a conformance check.

    The members are strings (``Verdict.UNDECIDED == "undecided"``), so they
    serialise to JSON as they are.  ``bool(verdict)`` is not defined on
    purpose; use ``verdict is Verdict.CONFORMANT`` or the result's
    ``conformant`` flag.
    """

    CONFORMANT = "conformant"
    NOT_CONFORMANT = "not_conformant"
    UNDECIDED = "undecided"

    @classmethod
    def of(cls, conformant: bool, undecided: bool = False) -> "Verdict":
        """``UNDECIDED`` if ``undecided``, else ``CONFORMANT`` or ``NOT_CONFORMANT`` by ``conformant``."""
        if undecided:
            return cls.UNDECIDED
        return cls.CONFORMANT if conformant else cls.NOT_CONFORMANT

    @property
    def label(self) -> str:
        """Text for summaries: ``"conformant"``, ``"NOT conformant"``, ``"undecided"``."""
        return {"conformant": "conformant", "not_conformant": "NOT conformant", "undecided": "undecided"}[self.value]

    @property
    def json_conformant(self):
        """``True``, ``False`` or ``None`` (undecided): the ``conformant`` value of the JSON files."""
        return None if self is Verdict.UNDECIDED else self is Verdict.CONFORMANT

    def __bool__(self):
        raise TypeError("a Verdict has three values; compare it (verdict is Verdict.CONFORMANT) instead of bool()")

    def __str__(self):
        return self.value


def overall_verdict(verdicts) -> Verdict:
    """One verdict for several checks: undecided if any is, else not conformant if any is, else conformant.

    An empty collection is ``CONFORMANT`` (nothing failed).
    """
    verdicts = [Verdict(v) for v in verdicts]
    if Verdict.UNDECIDED in verdicts:
        return Verdict.UNDECIDED
    if Verdict.NOT_CONFORMANT in verdicts:
        return Verdict.NOT_CONFORMANT
    return Verdict.CONFORMANT
