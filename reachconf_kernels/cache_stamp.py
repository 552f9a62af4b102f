"""Drop numba's cached kernels when any kernel source changed.

numba keys a cached function on its own source file only (modification time
and size).  A kernel inlines the jitted functions it calls from other modules
(``interval.py`` into ``nonlinear.py``, for example), so after an update that
changes only the callee, the caller's cache entry would still be loaded, with
the old callee compiled into it.  That is a soundness hazard (an outward
rounding fixed in ``interval.py`` would silently stay unfixed), and it happens
in every editable install after ``git pull``.

:func:`drop_stale_caches` runs once when :mod:`reachconf_kernels` is imported:
it hashes the package's sources (with the numba version) and, when the hash
differs from the one stamped in numba's cache folder, removes the package's
cache files (``.nbi``/``.nbc``) so that every kernel is compiled afresh, then
writes the new stamp.  This is the package's only file access; it never
raises (a read-only installation simply keeps numba's own behaviour).
"""

from __future__ import annotations

import hashlib
import os
import tempfile
from pathlib import Path

__all__ = ["sources_digest", "cache_folder", "drop_stale_caches"]

STAMP_NAME = "reachconf_kernels.stamp"
_NUMBA_SUFFIXES = (".nbi", ".nbc")


def sources_digest(folder: Path) -> str:
    """SHA-256 of the names and contents of the ``*.py`` files in ``folder`` and the numba version."""
    import numba

    h = hashlib.sha256(numba.__version__.encode())
    for path in sorted(Path(folder).glob("*.py")):
        h.update(path.name.encode() + b"\0" + hashlib.sha256(path.read_bytes()).digest())
    return h.hexdigest()


def _probe():  # pragma: no cover - never called: numba's locators read its first line number only
    pass


def cache_folder(source: Path) -> Path | None:
    """The folder numba caches the functions of ``source`` in (its own locators, in its own order)."""
    from numba.core import caching

    for name in ("UserProvidedCacheLocator", "InTreeCacheLocator", "UserWideCacheLocator"):
        cls = getattr(caching, name, None) or getattr(caching, "_" + name, None)
        if cls is None:
            continue
        locator = cls.from_function(_probe, str(source))
        if locator is not None:
            return Path(locator.get_cache_path())
    return None


def drop_stale_caches(folder: Path | None = None) -> int:
    """Remove numba's cache files of the kernels in ``folder`` if any source changed since the last stamp.

    Parameters
    ----------
    folder : Path, optional
        The kernel package's folder (default: this package).

    Returns
    -------
    int
        The number of cache files removed (0 when the stamp is current or the
        cache folder cannot be written).
    """
    try:
        folder = Path(folder) if folder is not None else Path(__file__).resolve().parent
        sources = sorted(folder.glob("*.py"))
        cache = cache_folder(folder / "__init__.py")
        if cache is None:
            return 0
        digest = sources_digest(folder)
        stamp = cache / STAMP_NAME
        try:
            if stamp.read_text(encoding="ascii").strip() == digest:
                return 0
        except (OSError, UnicodeDecodeError):
            pass
        removed = 0
        for source in sources:
            where = cache_folder(source)
            if where is None or not where.is_dir():
                continue
            prefix = source.stem + "."
            for f in where.iterdir():
                if f.name.startswith(prefix) and f.suffix in _NUMBA_SUFFIXES:
                    try:
                        f.unlink()
                        removed += 1
                    except FileNotFoundError:
                        pass  # another process removed it first
        cache.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix="." + STAMP_NAME, dir=cache)
        with os.fdopen(fd, "w", encoding="ascii") as fh:
            fh.write(digest + "\n")
        os.replace(tmp, stamp)
        return removed
    except OSError:
        return 0
