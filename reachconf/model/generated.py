"""Generated model modules on disk: an entry's name, written atomically, imported once per process under a lock.

An entry is ``<name>.py`` (the generated numba functions) and ``<name>.npz`` (their metadata); the name holds
:func:`model_hash`, a hash of everything the generated code depends on (the model's expressions and names,
the generator's and the kernels' sources, the package version), so a changed model never meets stale code.  Threads of
one process share the import: without the lock a second thread found the first one's half-executed module
in ``sys.modules`` and stopped on a missing ``f_iv`` (the vehicle example's ``--quick --workers 2``, whose
tables ran on threads).  Processes share the files, written atomically.
"""

from __future__ import annotations

import hashlib
import importlib.metadata
import importlib.util
import io
import os
import sys
import threading
from pathlib import Path

import numpy as np
import sympy as sp

import reachconf_kernels
from reachconf.io.atomic import atomic_write

__all__ = ["BUILD_LOCK", "GENERATOR_VERSION", "model_hash", "package_version", "write_entry", "load_entry"]

#: Bump when the generated code changes meaning: old cache entries are then ignored.
GENERATOR_VERSION = "5"

#: held while a model is generated, imported or compiled (re-entrant: a damaged entry is built again inside);
#: read it as ``generated.BUILD_LOCK``: a forked child gets a new one (the parent's may be held by another thread)
BUILD_LOCK = threading.RLock()


def _new_lock_in_child() -> None:
    global BUILD_LOCK
    BUILD_LOCK = threading.RLock()


if hasattr(os, "register_at_fork"):
    os.register_at_fork(after_in_child=_new_lock_in_child)

#: what every generated module defines
_FUNCTIONS = ("f", "jac", "h", "jac_h", "hess", "h_iv", "jac_h_iv", "lagrange_iv")


def _kernel_fingerprint() -> str:
    """Hash of the kernel sources the generated code calls and of the generator's own sources.

    numba's on-disk cache of the generated module links against the compiled
    interval and Taylor kernels; when they change, the generated module must be
    rebuilt in a fresh folder or numba reports "unresolved symbol".  A change
    of the generator or of the tape recorder changes the generated code.
    """
    h = hashlib.sha256()
    folder = Path(reachconf_kernels.__file__).parent
    for name in ("interval.py", "taylor.py", "taylor_rules.py", "remainder.py", "signatures.py", "__init__.py"):
        h.update((folder / name).read_bytes())
    for name in ("codegen.py", "tape.py", "remainders.py", "printers.py"):
        h.update((Path(__file__).parent / name).read_bytes())
    return h.hexdigest()[:16]


def package_version() -> str:
    """The installed version of reachconf (from its metadata; ``"0+unknown"`` if it is not installed)."""
    try:
        return importlib.metadata.version("reachconf")
    except importlib.metadata.PackageNotFoundError:  # pragma: no cover - a plain source checkout
        return "0+unknown"


def model_hash(model, order: int, remainder: str = "taylor") -> str:
    """Hash of what the generated code of ``model`` depends on (cache file name).

    Parameters
    ----------
    model : reachconf.Model
    order : {2, 3}
    remainder : {"taylor", "tensor"}

    Returns
    -------
    str
        20 hexadecimal digits.
    """
    h = hashlib.sha256()
    for part in (
        GENERATOR_VERSION,
        package_version(),
        _kernel_fingerprint(),
        str(order),
        remainder,
        repr(model.state_names),
        repr(model.input_names),
        repr(model.disturbance_names),
        repr(model.param_names),
        repr(model.output_names),
        *(sp.srepr(e) for e in model.f_expr),
        *(sp.srepr(e) for e in model.h_expr),
    ):
        h.update(part.encode())
        h.update(b"\0")
    return h.hexdigest()[:20]


def write_entry(path: Path, meta_path: Path, source: str, meta: dict) -> None:
    """Write the generated source and its metadata, each atomically."""
    atomic_write(path, source)
    buf = io.BytesIO()
    np.savez(buf, **meta)
    atomic_write(meta_path, buf.getvalue())


def load_entry(modname: str, path: Path, meta_path: Path):
    """The generated module (imported once per process) and its metadata, every array read now.

    Raises whatever a damaged entry raises (SyntaxError, EOFError, BadZipFile, AttributeError, KeyError ...):
    the caller builds it again.
    """
    with BUILD_LOCK:
        module = sys.modules.get(modname)
        if module is None:
            spec = importlib.util.spec_from_file_location(modname, path)
            module = importlib.util.module_from_spec(spec)
            sys.modules[modname] = module  # (under the lock: another thread never sees it half-executed)
            try:
                spec.loader.exec_module(module)
                for name in _FUNCTIONS:
                    getattr(module, name)
            except BaseException:
                sys.modules.pop(modname, None)
                raise
        with np.load(meta_path, allow_pickle=False) as data:
            meta = {k: data[k] for k in data.files}
    if "hess_pattern" not in meta:
        raise KeyError(f"{meta_path.name} has no hess_pattern")
    return module, meta
