"""Compiled code shipped to workers: the generated model modules and numba's caches.

Building a model (sympy derivatives, code generation) and compiling it and
the kernels with numba takes minutes on a fresh machine; a worker that gets
the files instead loads them in about a second.  A *bundle* holds

* the generated model modules (``.py`` and ``.npz``) of
  ``$REACHCONF_CACHE/models`` (:func:`models_cache_dir`), with their
  modification times, and
* numba's cache files (``.nbi`` index, ``.nbc`` data) of those modules and of
  the :mod:`reachconf_kernels` modules, each taken from and written to the
  folder numba itself uses for that source file (:func:`numba_cache_dir`:
  ``NUMBA_CACHE_DIR``, the ``__pycache__`` next to the source, or the user
  cache folder).

:func:`install_cache_bundle` writes a bundle on a worker (only files that
are missing or differ).  numba checks its cache entries itself (the source
file's contents, the numba version, the CPU): an entry that does not fit the
worker is ignored and compiled there, so a bundle is never wrong, at worst
useless.  This module imports no kernel module (importing some of them compiles
them: the files must be in place first).
"""

from __future__ import annotations

import hashlib
import importlib.util
import os
from pathlib import Path

from reachconf.io.atomic import atomic_write

__all__ = ["reachconf_cache_root", "models_cache_dir", "kernels_source_dir", "numba_cache_dir",
           "model_cache_bundle", "kernel_cache_bundle", "install_cache_bundle", "bundle_digest",
           "bundle_size"]  # fmt: skip

_NUMBA_SUFFIXES = (".nbi", ".nbc")


def reachconf_cache_root() -> Path:
    """``$REACHCONF_CACHE`` if set, else the user cache folder (``platformdirs.user_cache_dir("reachconf")``)."""
    env = os.environ.get("REACHCONF_CACHE")
    if env:
        return Path(env).expanduser()
    import platformdirs

    return Path(platformdirs.user_cache_dir("reachconf"))


def models_cache_dir() -> Path:
    """Folder of the generated model modules (``<cache root>/models``), created if needed."""
    path = reachconf_cache_root() / "models"
    path.mkdir(parents=True, exist_ok=True)
    return path


def kernels_source_dir() -> Path:
    """Folder of the :mod:`reachconf_kernels` sources (found without importing any kernel)."""
    spec = importlib.util.find_spec("reachconf_kernels")
    return Path(list(spec.submodule_search_locations)[0])


def numba_cache_dir(source) -> Path | None:
    """The folder numba caches the compiled functions of the Python file ``source`` in (None: no cache).

    The locators are tried in numba's own order: ``NUMBA_CACHE_DIR``, the
    ``__pycache__`` folder next to the source when it is writable, the user
    cache folder (:func:`reachconf_kernels.cache_stamp.cache_folder`, the one
    place that asks numba).  Importing the kernel package checks its cache
    stamp but compiles nothing.
    """
    from reachconf_kernels.cache_stamp import cache_folder

    return cache_folder(Path(source))


def _numba_files(source: Path):
    folder = numba_cache_dir(source)
    if folder is None or not folder.is_dir():
        return []
    prefix = source.stem + "."
    return sorted(p for p in folder.iterdir() if p.name.startswith(prefix) and p.suffix in _NUMBA_SUFFIXES)


def model_cache_bundle(paths) -> dict:
    """The bundle of generated model modules (paths of their ``.py`` files) and their numba caches."""
    models, numba = [], []
    for path in paths:
        path = Path(path)
        for f in (path, path.with_suffix(".npz")):
            if f.is_file():
                models.append((f.name, f.read_bytes(), f.stat().st_mtime))
        numba += [("models", path.name, f.name, f.read_bytes()) for f in _numba_files(path)]
    return {"models": models, "numba": numba}


def kernel_cache_bundle() -> dict:
    """The bundle of numba's caches of every :mod:`reachconf_kernels` module compiled on this machine."""
    from reachconf_kernels.cache_stamp import STAMP_NAME

    numba = []
    for source in sorted(kernels_source_dir().glob("*.py")):
        numba += [("kernels", source.name, f.name, f.read_bytes()) for f in _numba_files(source)]
    init = kernels_source_dir() / "__init__.py"
    folder = numba_cache_dir(init)
    if folder is not None and (folder / STAMP_NAME).is_file():
        # the stamp of the sources these caches were compiled from: without it, a worker that
        # imports the kernels after installing the bundle would drop the caches as stale
        numba.append(("kernels", init.name, STAMP_NAME, (folder / STAMP_NAME).read_bytes()))
    return {"models": [], "numba": numba}


def bundle_digest(bundle: dict) -> str:
    """Hash of a bundle's names and contents (names the worker plugin that installs it)."""
    h = hashlib.sha256()
    for name, data, _ in bundle["models"]:
        h.update(name.encode() + b"\0" + hashlib.sha256(data).digest())
    for root, source, name, data in bundle["numba"]:
        h.update(f"{root}/{source}/{name}".encode() + b"\0" + hashlib.sha256(data).digest())
    return h.hexdigest()[:16]


def bundle_size(bundle: dict) -> int:
    """Bytes of file contents in a bundle."""
    return sum(len(e[1]) for e in bundle["models"]) + sum(len(e[3]) for e in bundle["numba"])


def _put(path: Path, data: bytes, mtime=None) -> bool:
    try:
        if path.is_file() and path.stat().st_size == len(data) and path.read_bytes() == data:
            return False
    except OSError:
        pass
    atomic_write(path, data)
    if mtime is not None:
        os.utime(path, (mtime, mtime))  # older numba versions stamp the cache with the source's mtime
    return True


def install_cache_bundle(bundle: dict) -> dict:
    """Write a bundle into this machine's caches (files that are missing or differ).

    Returns ``{"written": n, "kept": m}``.  Runs on a worker, before it
    builds or loads anything (see :mod:`reachconf.runner.dask`).
    """
    written = kept = 0
    models = models_cache_dir()
    for name, data, mtime in bundle["models"]:
        if _put(models / name, data, mtime):
            written += 1
        else:
            kept += 1
    roots = {"models": models, "kernels": kernels_source_dir()}
    folders = {}
    for root, source, name, data in bundle["numba"]:
        key = (root, source)
        if key not in folders:
            folders[key] = numba_cache_dir(roots[root] / source)
        if folders[key] is None:
            continue
        if _put(folders[key] / name, data):
            written += 1
        else:
            kept += 1
    return {"written": written, "kept": kept}
