"""Tasks of the real-car example that run on the pool's worker processes.

They live in an importable module, not in ``run.py``: the run's one pool
starts its workers for the first task (a library job, with the script hidden
from the workers), so a task defined in the script (``__main__``) could not
be unpickled by them later.
"""

from __future__ import annotations


def reachset_job(job):
    """Reachset conformance (eq. 43) of one window: ``(model, case, W, V)`` -> a JSON-able dict."""
    model, case, W, V = job
    from reachconf.conformance import reachset_conformance

    r = reachset_conformance(model, case, W, V, keep_tube=False, progress=False)
    return {"case": case.name, "verdict": r.verdict.value, "first_violation_time": r.first_violation_time,
            "seconds": r.seconds, "message": r.message}  # fmt: skip
