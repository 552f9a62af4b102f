"""Generate, compile and cache the numeric code of a :class:`~reachconf.model.Model`.

From the sympy expressions of ``f`` and ``h`` this module derives

* ``f``, its Jacobian with respect to ``z = (x, u, w)``, its Hessians and
  third-order tensors (only the structurally non-zero entries are written,
  symmetric entries are computed once),
* interval versions of ``f``, of the Hessians and of the third-order tensors,
  evaluated over a box with the outward-rounded kernel
  :mod:`reachconf_kernels.interval` (these bound the Lagrange remainder of the
  linearisation, source report section 4.3.1),
* ``h`` and its Jacobian,

applies common-subexpression elimination, writes the result as a real Python
module into a cache folder and compiles it with ``numba.njit(cache=True)`` with
the fixed signatures of :mod:`reachconf_kernels.signatures`.  The file name is
a hash of the expressions, the names, the package version and this
generator's version, so a second process imports the module and loads numba's
on-disk cache without recompiling.

The cache folder is ``$REACHCONF_CACHE`` if set, else the user cache folder
(``platformdirs.user_cache_dir("reachconf")``).
"""

from __future__ import annotations

import hashlib
import importlib.metadata
import importlib.util
import io
import os
import re
import sys
import time
from dataclasses import dataclass, field
from itertools import permutations
from pathlib import Path

import numpy as np
import sympy as sp

import reachconf_kernels
from reachconf.errors import ModelError
from reachconf.io.atomic import atomic_write
from reachconf.model.printers import IntervalEmitter, point_code

__all__ = ["CompiledModel", "compile_model", "cache_dir", "model_hash", "generate_source", "package_version",
           "GENERATOR_VERSION"]  # fmt: skip

#: Bump when the generated code changes meaning: old cache entries are then ignored.
GENERATOR_VERSION = "1"


def cache_dir() -> Path:
    """Folder of generated model modules (``$REACHCONF_CACHE`` or the user cache folder)."""
    env = os.environ.get("REACHCONF_CACHE")
    if env:
        path = Path(env).expanduser()
    else:
        import platformdirs

        path = Path(platformdirs.user_cache_dir("reachconf"))
    path = path / "models"
    path.mkdir(parents=True, exist_ok=True)
    return path


@dataclass
class CompiledModel:
    """Compiled functions of one model (see :mod:`reachconf_kernels.signatures`).

    Attributes
    ----------
    f, jac, h, jac_h, hess : numba dispatchers (point evaluation)
    f_iv, hess_iv : numba dispatchers (interval evaluation, return a status)
    third, third_iv : numba dispatchers or None (only built with ``order=3``)
    hess_pattern : ndarray of bool, shape (n, nz, nz)
        Structurally non-zero Hessian entries.
    third_pattern : ndarray of bool or None, shape (n, nz, nz, nz)
    guards : list of str
        Description of each guarded interval operation (index = status - 1).
    path : Path
        The generated module file.
    loaded_from_cache : bool
        True if the module existed already (no code generation this time).
    seconds : float
        Time to generate (if needed), import and compile/load.
    """

    f: object
    jac: object
    h: object
    jac_h: object
    hess: object
    f_iv: object
    hess_iv: object
    jac_h_iv: object = None
    third: object = None
    third_iv: object = None
    hess_pattern: np.ndarray | None = None
    third_pattern: np.ndarray | None = None
    guards: list = field(default_factory=list)
    path: Path | None = None
    loaded_from_cache: bool = False
    seconds: float = 0.0
    module: object = None

    def dispatchers(self):
        """All compiled dispatchers (for cache statistics)."""
        names = ("f", "jac", "h", "jac_h", "hess", "f_iv", "hess_iv", "jac_h_iv", "third", "third_iv")
        return {k: getattr(self, k) for k in names if getattr(self, k) is not None}


# ---------------------------------------------------------------------------
# public entry point
# ---------------------------------------------------------------------------
def _kernel_fingerprint() -> str:
    """Hash of the kernel sources the generated code calls.

    numba's on-disk cache of the generated module links against the compiled
    interval kernel; when that kernel changes, the generated module must be
    rebuilt in a fresh folder or numba reports "unresolved symbol".
    """
    h = hashlib.sha256()
    folder = Path(reachconf_kernels.__file__).parent
    for name in ("interval.py", "__init__.py"):
        h.update((folder / name).read_bytes())
    return h.hexdigest()[:16]


def package_version() -> str:
    """The installed version of reachconf (from its metadata; ``"0+unknown"`` if it is not installed)."""
    try:
        return importlib.metadata.version("reachconf")
    except importlib.metadata.PackageNotFoundError:  # pragma: no cover - a plain source checkout
        return "0+unknown"


def model_hash(model, order: int) -> str:
    """Hash of what the generated code of ``model`` depends on (cache file name).

    Parameters
    ----------
    model : reachconf.Model
    order : {2, 3}

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


def compile_model(model, order: int = 2) -> CompiledModel:
    """Generate (or find in the cache), import and compile the model's functions.

    Parameters
    ----------
    model : Model
    order : {2, 3}
        Highest derivative order to build (3 adds the third-order tensors).

    Returns
    -------
    CompiledModel
    """
    if order not in (2, 3):
        raise ModelError(f"order must be 2 or 3, got {order!r}")
    t0 = time.perf_counter()
    digest = model_hash(model, order)
    safe = re.sub(r"[^A-Za-z0-9_]", "_", model.name)[:40]
    modname = f"reachconf_gen_{safe}_{digest}_o{order}"
    folder = cache_dir()
    path = folder / f"{modname}.py"
    meta_path = folder / f"{modname}.npz"
    from_cache = path.exists() and meta_path.exists()
    if not from_cache:
        source, meta = generate_source(model, order)
        atomic_write(path, source)
        buf = io.BytesIO()
        np.savez(buf, **meta)
        atomic_write(meta_path, buf.getvalue())
    module = sys.modules.get(modname)
    if module is None:
        spec = importlib.util.spec_from_file_location(modname, path)
        module = importlib.util.module_from_spec(spec)
        sys.modules[modname] = module
        try:
            spec.loader.exec_module(module)
        except Exception:
            sys.modules.pop(modname, None)
            raise
    meta = np.load(meta_path, allow_pickle=False)
    guards = [str(g) for g in meta["guards"]] if "guards" in meta else []
    return CompiledModel(
        f=module.f,
        jac=module.jac,
        h=module.h,
        jac_h=module.jac_h,
        hess=module.hess,
        f_iv=module.f_iv,
        hess_iv=module.hess_iv,
        jac_h_iv=module.jac_h_iv,
        third=getattr(module, "third", None),
        third_iv=getattr(module, "third_iv", None),
        hess_pattern=meta["hess_pattern"],
        third_pattern=meta["third_pattern"] if "third_pattern" in meta else None,
        guards=guards,
        path=path,
        loaded_from_cache=from_cache,
        seconds=time.perf_counter() - t0,
        module=module,
    )


# ---------------------------------------------------------------------------
# derivatives
# ---------------------------------------------------------------------------
def _derivatives(model, order: int):
    z = model.z_symbols
    f = list(model.f_expr)
    n, nz = len(f), len(z)
    jac = [[sp.diff(fi, zj) if zj in fi.free_symbols else sp.Integer(0) for zj in z] for fi in f]
    hess = {}  # (i, j, k) with j <= k -> expr
    for i in range(n):
        for j in range(nz):
            d1 = jac[i][j]
            if d1 == 0:
                continue
            for k in range(j, nz):
                if z[k] in d1.free_symbols:
                    d2 = sp.diff(d1, z[k])
                    if d2 != 0:
                        hess[(i, j, k)] = d2
    third = {}
    if order >= 3:
        for (i, j, k), d2 in hess.items():
            for l in range(k, nz):
                if z[l] in d2.free_symbols:
                    d3 = sp.diff(d2, z[l])
                    if d3 != 0:
                        third[(i, j, k, l)] = d3
    h = list(model.h_expr)
    jac_h = [[sp.diff(hi, zj) if zj in hi.free_symbols else sp.Integer(0) for zj in z] for hi in h]
    return f, jac, hess, third, h, jac_h


def _permutations3(j, k):
    return {(j, k), (k, j)}


def _permutations4(j, k, l):
    return set(permutations((j, k, l)))


# ---------------------------------------------------------------------------
# source generation
# ---------------------------------------------------------------------------
_HEADER = '''"""Generated by reachconf.codegen (version {version}) for model {name!r}. Do not edit."""
import math
import numba as nb
from reachconf_kernels import interval as I
from reachconf_kernels.signatures import (
    POINT_VEC, POINT_MAT, POINT_T3, POINT_T4, IV_VEC, IV_MAT, IV_T3, IV_T4,
)

'''


def _load_lines(symbols, z_index, p_index, used, point: bool) -> list[str]:
    lines = []
    for sym in symbols:
        if sym not in used:
            continue
        if sym in z_index:
            i = z_index[sym]
            if point:
                lines.append(f"    {sym.name} = z[{i}]")
            else:
                lines.append(f"    {sym.name}_lo = zlo[{i}]")
                lines.append(f"    {sym.name}_hi = zhi[{i}]")
        elif sym in p_index:
            lines.append(f"    {sym.name} = p[{p_index[sym]}]")
    return lines


def _point_function(name, sig, targets, model, z_index, p_index) -> str:
    """targets: list of (index-string, expr)."""
    exprs = [e for _, e in targets]
    reps, reduced = sp.cse(exprs, symbols=sp.numbered_symbols("c_"), optimizations="basic") if exprs else ([], [])
    used = set()
    for e in exprs:
        used |= e.free_symbols
    lines = [f"@nb.njit({sig}, cache=True, error_model='numpy', fastmath=False)", f"def {name}(z, p, out):"]
    lines += _load_lines(model.z_symbols + model.p_symbols, z_index, p_index, used, point=True)
    for sym, e in reps:
        lines.append(f"    {sym.name} = {point_code(e)}")
    for (idx, _), e in zip(targets, reduced):
        lines.append(f"    out[{idx}] = {point_code(e)}")
    lines.append("    return")
    return "\n".join(lines) + "\n\n"


def _interval_function(name, sig, targets, model, z_index, p_index, guards) -> str:
    exprs = [e for _, e in targets]
    reps, reduced = sp.cse(exprs, symbols=sp.numbered_symbols("c_"), optimizations="basic") if exprs else ([], [])
    used = set()
    for e in exprs:
        used |= e.free_symbols
    var_map = {}
    for sym in model.z_symbols:
        var_map[sym] = (f"{sym.name}_lo", f"{sym.name}_hi")
    for sym in model.p_symbols:
        var_map[sym] = (sym.name, sym.name)
    em = IntervalEmitter(var_map, guards)
    for sym, e in reps:
        lo, hi = em.emit(e)
        em.lines.append(f"    {sym.name}_lo = {lo}")
        em.lines.append(f"    {sym.name}_hi = {hi}")
        em.var_map[sym] = (f"{sym.name}_lo", f"{sym.name}_hi")
    outs = []
    for (idx, _), e in zip(targets, reduced):
        lo, hi = em.emit(e)
        outs.append((idx, lo, hi))
    lines = [f"@nb.njit({sig}, cache=True, error_model='numpy')", f"def {name}(zlo, zhi, p, outlo, outhi):"]
    lines += _load_lines(model.z_symbols + model.p_symbols, z_index, p_index, used, point=False)
    lines += em.lines
    for idx, lo, hi in outs:
        lines.append(f"    outlo[{idx}] = {lo}")
        lines.append(f"    outhi[{idx}] = {hi}")
    lines.append("    return 0")
    return "\n".join(lines) + "\n\n"


class _Renamed:
    """The model's expressions with every symbol renamed ``s_<name>`` (no clash with generated locals)."""

    def __init__(self, model):
        ren = {s: sp.Symbol(f"s_{s.name}", real=True) for s in model.z_symbols + model.p_symbols}
        self.name = model.name
        self.z_symbols = tuple(ren[s] for s in model.z_symbols)
        self.p_symbols = tuple(ren[s] for s in model.p_symbols)
        self.f_expr = tuple(e.xreplace(ren) for e in model.f_expr)
        self.h_expr = tuple(e.xreplace(ren) for e in model.h_expr)


def generate_source(model, order: int):
    """Python source of the compiled model module and its metadata arrays."""
    model = _Renamed(model)
    f, jac, hess, third, h, jac_h = _derivatives(model, order)
    z = model.z_symbols
    n, nz, p_out = len(f), len(z), len(h)
    z_index = {s: i for i, s in enumerate(z)}
    p_index = {s: i for i, s in enumerate(model.p_symbols)}
    guards: list[str] = []

    parts = [_HEADER.format(version=GENERATOR_VERSION, name=model.name)]
    parts.append(_point_function("f", "POINT_VEC", [(str(i), e) for i, e in enumerate(f)], model, z_index, p_index))
    parts.append(
        _point_function(
            "jac",
            "POINT_MAT",
            [(f"{i}, {j}", e) for i in range(n) for j in range(nz) if (e := jac[i][j]) != 0],
            model,
            z_index,
            p_index,
        )
    )
    parts.append(_point_function("h", "POINT_VEC", [(str(i), e) for i, e in enumerate(h)], model, z_index, p_index))
    parts.append(
        _point_function(
            "jac_h",
            "POINT_MAT",
            [(f"{i}, {j}", e) for i in range(p_out) for j in range(nz) if (e := jac_h[i][j]) != 0],
            model,
            z_index,
            p_index,
        )
    )
    hess_targets = []
    hess_pattern = np.zeros((n, nz, nz), dtype=bool)
    for (i, j, k), e in sorted(hess.items()):
        for a, b in _permutations3(j, k):
            hess_targets.append((f"{i}, {a}, {b}", e))
            hess_pattern[i, a, b] = True
    parts.append(_point_function("hess", "POINT_T3", hess_targets, model, z_index, p_index))
    parts.append(
        _interval_function("f_iv", "IV_VEC", [(str(i), e) for i, e in enumerate(f)], model, z_index, p_index, guards)
    )
    parts.append(_interval_function("hess_iv", "IV_T3", hess_targets, model, z_index, p_index, guards))
    parts.append(
        _interval_function(
            "jac_h_iv",
            "IV_MAT",
            [(f"{i}, {j}", e) for i in range(p_out) for j in range(nz) if (e := jac_h[i][j]) != 0],
            model,
            z_index,
            p_index,
            guards,
        )
    )
    meta = {"hess_pattern": hess_pattern}
    if order >= 3:
        third_targets = []
        third_pattern = np.zeros((n, nz, nz, nz), dtype=bool)
        for (i, j, k, l), e in sorted(third.items()):
            for a, b, c in _permutations4(j, k, l):
                third_targets.append((f"{i}, {a}, {b}, {c}", e))
                third_pattern[i, a, b, c] = True
        parts.append(_point_function("third", "POINT_T4", third_targets, model, z_index, p_index))
        parts.append(_interval_function("third_iv", "IV_T4", third_targets, model, z_index, p_index, guards))
        meta["third_pattern"] = third_pattern
    meta["guards"] = np.array(guards if guards else [""], dtype=str)[: len(guards)] if guards else np.array([], dtype=str)
    return "".join(parts), meta
