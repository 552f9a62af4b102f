"""One BLAS thread while reachconf computes.

The matrices reachconf hands to BLAS are small or tall and narrow (a step's
Jacobians, a fit's residual Jacobian of a few parameters): OpenBLAS's thread
pool gains nothing on them, and its threads busy-wait between calls, taking
a core from the work (or from the other worker process).  Measured with
``benchmarks/bench_diagnose.py`` (an 18-case suite, 2 cores): the diagnosis
took 24.3 s wall and 46.3 s CPU with the default two BLAS threads, 17.9 s and
17.9 s with one.  The worker processes of :mod:`reachconf.runner` already run
with one (environment variables set before they start); in the calling
process the libraries are loaded already, so :func:`one_blas_thread` sets
the OpenBLAS libraries loaded into it (numpy's and scipy's wheels bring one
each) through their own ``openblas_set_num_threads`` and restores them
afterwards.

Linux only (the loaded libraries are read from ``/proc/self/maps``); elsewhere,
or for another BLAS, nothing changes.  It never raises.  The setting is
process-wide: threads of the caller that use BLAS meanwhile get one thread too.
"""

from __future__ import annotations

import ctypes
import functools
import threading
from contextlib import contextmanager

__all__ = ["one_blas_thread", "with_one_blas_thread"]

# (get, set) symbol pairs: scipy-openblas wheels (64-bit integer build with its suffix), plain OpenBLAS
_SYMBOLS = (
    ("scipy_openblas_get_num_threads64_", "scipy_openblas_set_num_threads64_"),
    ("scipy_openblas_get_num_threads", "scipy_openblas_set_num_threads"),
    ("openblas_get_num_threads64_", "openblas_set_num_threads64_"),
    ("openblas_get_num_threads", "openblas_set_num_threads"),
)
_controls: dict[str, tuple] = {}  # library path -> (get, set) or () when it has neither
_lock = threading.Lock()
_depth = 0
_saved: list = []


def _loaded_openblas() -> list[str]:
    try:
        with open("/proc/self/maps") as fh:
            paths = {line.split(None, 5)[-1].strip() for line in fh if "openblas" in line.lower()}
    except OSError:
        return []
    return sorted(p for p in paths if p.startswith("/") and ".so" in p)


def _control(path: str) -> tuple:
    if path not in _controls:
        found = ()
        try:
            lib = ctypes.CDLL(path, mode=ctypes.RTLD_LOCAL)
            for get_name, set_name in _SYMBOLS:
                get, set_ = getattr(lib, get_name, None), getattr(lib, set_name, None)
                if get is not None and set_ is not None:
                    get.restype, get.argtypes = ctypes.c_int, []
                    set_.restype, set_.argtypes = None, [ctypes.c_int]
                    found = (get, set_)
                    break
        except OSError:
            pass
        _controls[path] = found
    return _controls[path]


@contextmanager
def one_blas_thread():
    """Run the block with one OpenBLAS thread in every loaded OpenBLAS library (restored afterwards; nests)."""
    global _depth, _saved
    with _lock:
        if _depth == 0:
            _saved = []
            for path in _loaded_openblas():
                control = _control(path)
                if control:
                    get, set_ = control
                    try:
                        _saved.append((set_, int(get())))
                        set_(1)
                    except Exception:  # pragma: no cover - a library without a usable setter
                        pass
        _depth += 1
    try:
        yield
    finally:
        with _lock:
            _depth -= 1
            if _depth == 0:
                for set_, n in _saved:
                    try:
                        set_(n)
                    except Exception:  # pragma: no cover
                        pass
                _saved = []


def with_one_blas_thread(fn):
    """Decorator: ``fn`` runs inside :func:`one_blas_thread`."""

    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        with one_blas_thread():
            return fn(*args, **kwargs)

    return wrapper
