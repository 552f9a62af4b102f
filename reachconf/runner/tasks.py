"""Tasks of a :class:`~reachconf.runner.pool.Pool` and the ways a run on it can end early."""

from __future__ import annotations

from reachconf.errors import ReachconfError

__all__ = ["Task", "Interrupted", "WorkersLost", "Stopped"]


class Interrupted(ReachconfError, KeyboardInterrupt):
    """Raised on Ctrl-C; ``.partial`` holds the results finished so far (``None`` for the rest)."""

    def __init__(self, partial):
        done = sum(r is not None for r in partial)
        super().__init__(f"interrupted: {done} of {len(partial)} jobs finished")
        self.partial = partial


class WorkersLost(ReachconfError, RuntimeError):
    """No worker left for the timeout, or a job keeps killing its workers.

    ``.partial`` holds the results finished so far (``None`` for the rest), as
    with :class:`Interrupted`.
    """

    def __init__(self, message, partial=None):
        super().__init__(message)
        self.partial = partial


class Stopped(ReachconfError):
    """A wait was given up because the run is stopping (Ctrl-C or an error in another thread)."""


class Task:
    """One job submitted to a :class:`Pool`: ``fn(job)``; ``value`` once ``done``."""

    __slots__ = ("fn", "job", "inner", "generation", "done", "value", "index")

    def __init__(self, fn, job, index=None):
        self.fn, self.job, self.index = fn, job, index
        self.inner = None
        self.generation = 0
        self.done = False
        self.value = None
