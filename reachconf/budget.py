"""Pre-flight checks of memory and time for long computations.

Long recordings are processed in windows, so what a run needs grows by a
known number of bytes per sample (what the result keeps) plus a fixed amount
per window.  :func:`check_memory` compares that estimate with the memory
available to this process (``MemAvailable`` of ``/proc/meminfo`` and, in a
container, the cgroup limit) *before* the work starts and raises
:class:`~reachconf.errors.ResourceError` naming the case, the estimate and
what to change — instead of an abort (``std::bad_alloc``, ``MemoryError``)
halfway through.  :class:`TimeBudget` does the same for a time limit: it
projects the whole run from the first window and stops before the rest.
"""

from __future__ import annotations

import math
import os
import sys
import time

from reachconf.errors import OptionsError, ResourceError

__all__ = ["available_memory", "check_memory", "check_time_limit", "TimeBudget", "format_bytes", "tube_bytes_per_step",
           "progress_bar", "peak_memory"]


def format_bytes(n: float) -> str:
    """``1536 -> '1.5 KB'`` (powers of 1024)."""
    n = float(n)
    for unit in ("B", "KB", "MB", "GB"):
        if abs(n) < 1024 or unit == "GB":
            return f"{n:.0f} {unit}" if unit == "B" else f"{n:.1f} {unit}"
        n /= 1024
    return f"{n:.1f} GB"  # pragma: no cover


def _cgroup_free() -> float | None:
    for limit, used in (("/sys/fs/cgroup/memory.max", "/sys/fs/cgroup/memory.current"),
                        ("/sys/fs/cgroup/memory/memory.limit_in_bytes", "/sys/fs/cgroup/memory/memory.usage_in_bytes")):  # fmt: skip
        try:
            with open(limit) as fh:
                text = fh.read().strip()
            if text == "max":
                return None
            with open(used) as fh:
                cur = float(fh.read().strip())
            lim = float(text)
            if lim > 2**60:  # "no limit" in cgroup v1
                return None
            return max(0.0, lim - cur)
        except (OSError, ValueError):
            continue
    return None


def available_memory() -> float:
    """Bytes this process can still allocate (``REACHCONF_MEMORY_LIMIT`` overrides, in bytes)."""
    env = os.environ.get("REACHCONF_MEMORY_LIMIT")
    if env:
        try:
            return float(env)
        except ValueError:
            raise ResourceError(f"REACHCONF_MEMORY_LIMIT must be a number of bytes, got {env!r}") from None
    free = None
    try:
        with open("/proc/meminfo") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    free = float(line.split()[1]) * 1024
                    break
    except OSError:
        pass
    if free is None:
        try:
            free = float(os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE"))
        except (ValueError, OSError, AttributeError):  # pragma: no cover - not POSIX
            free = float("inf")
    cg = _cgroup_free()
    return min(free, cg) if cg is not None else free


def peak_memory() -> float:
    """Peak resident memory of this process's own image so far, in bytes.

    Linux: ``VmHWM`` of ``/proc/self/status``.  Not ``getrusage(RUSAGE_SELF).ru_maxrss``:
    at ``exec`` Linux keeps the larger of its own peak and the peak of the
    memory image it replaces, which for a child started with ``vfork`` +
    ``exec`` (Python's ``subprocess``) is the *parent's* peak — a command
    started from a pytest or notebook process that once held 3 GB reports
    3 GB.  Elsewhere (no ``/proc``) ``ru_maxrss`` is the fallback (bytes on
    macOS, KB otherwise).

    Returns
    -------
    float
        Bytes.
    """
    try:
        with open("/proc/self/status") as fh:
            for line in fh:
                if line.startswith("VmHWM:"):
                    return float(line.split()[1]) * 1024
    except OSError:
        pass
    import resource

    peak = float(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss)
    return peak if sys.platform == "darwin" else peak * 1024


def check_memory(what: str, samples: int, per_sample: float, fixed: float = 0.0, hint: str = "") -> float:
    """Raise :class:`ResourceError` if ``samples * per_sample + fixed`` bytes exceed the available memory.

    Returns the estimate (bytes).  ``what`` names the job (``"trace conformance of case X"``).
    """
    need = float(samples) * float(per_sample) + float(fixed)
    free = available_memory()
    if need > 0.9 * free:
        raise ResourceError(
            f"{what}: {samples:,} samples need about {format_bytes(need)} ({format_bytes(per_sample)} per sample"
            f" + {format_bytes(fixed)}), but only {format_bytes(free)} is available; nothing was computed"
            + (f". {hint}" if hint else "")
        )
    return need


def tube_bytes_per_step(n: int, m: int, zonotope_order: float) -> tuple[float, float]:
    """Memory of a kept reach tube: ``(bytes per integration step, fixed bytes)``.

    Two zonotopes per step (time point and time interval) of at most
    ``n (order + 1) + 1`` generators, in the kernel's arrays and again as set
    objects, plus the step grid and inputs; fixed: 64 MB of working memory.
    """
    gmax = int(n * max(float(zonotope_order), 1.0)) + n + 1
    per_set = 8.0 * n * (gmax + 2)
    return 2 * 2 * per_set + 8 * (m + 4 * n), 64e6


def progress_bar(enabled, total: float, desc: str, unit: str, auto_above: float, terminal_only: bool = False):
    """A tqdm progress bar, or None.

    ``enabled`` True/False, or None: a bar when ``total`` exceeds
    ``auto_above`` (and, with ``terminal_only``, stderr is a terminal).
    """
    if enabled is None:
        enabled = total > auto_above and sys.stderr is not None and (not terminal_only or sys.stderr.isatty())
    if not enabled:
        return None
    from tqdm.auto import tqdm

    return tqdm(total=int(total), desc=desc, unit=unit, unit_scale=unit == "sample", leave=False, mininterval=0.5)


def check_time_limit(limit, name: str = "time_limit"):
    """``limit`` as a float > 0 (seconds), or None; :class:`OptionsError` naming ``name`` otherwise."""
    if limit is None:
        return None
    ok = isinstance(limit, (int, float)) and not isinstance(limit, bool) and math.isfinite(limit) and limit > 0
    if not ok:
        raise OptionsError(f"{name} must be a positive number of seconds (or None), got {limit!r}")
    return float(limit)


class TimeBudget:
    """Stop a windowed run early when its projected duration exceeds ``limit`` seconds.

    ``check(done, total)`` after each window: once at least ``min_fraction`` of
    the work (or the first window) is done, the duration so far is
    extrapolated linearly (the windows cost the same per sample) and a
    :class:`ResourceError` is raised if the projection exceeds the limit.
    """

    def __init__(self, what: str, limit: float | None, min_fraction: float = 0.0):
        self.what = what
        self.limit = check_time_limit(limit)
        self.start = time.perf_counter()
        self.min_fraction = float(min_fraction)
        self.checked = False

    def check(self, done: float, total: float):
        """Project the run from ``done`` of ``total`` units of work; raise ResourceError if over the limit."""
        if self.limit is None or self.checked or total <= 0 or done <= 0 or done >= total:
            return  # (all the work done: its result is kept, however long it took)
        if done / total < self.min_fraction and done < total:
            return
        self.checked = True
        spent = time.perf_counter() - self.start
        projected = spent * total / done
        if projected > self.limit:
            raise ResourceError(
                f"{self.what}: projected {_seconds(projected)} s for {total:,.0f} samples (measured {_seconds(spent)} s "
                f"on the first {done:,.0f}) exceeds the time limit of {_seconds(self.limit)} s; stopped before the rest"
            )


def _seconds(x: float) -> str:
    """Seconds for a message: three significant digits below 1000 s (0.000123, 0.4, 12.3), whole seconds above."""
    return f"{x:,.0f}" if x >= 1000 else f"{x:.3g}"
