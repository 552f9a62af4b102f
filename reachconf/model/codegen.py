"""Generate, compile and cache the numeric code of a :class:`~reachconf.model.Model`.

From the sympy expressions of ``f`` and ``h`` this module derives

* ``f``, its Jacobian with respect to ``z = (x, u, w)`` and its Hessians at a
  point (only the structurally non-zero entries are written, symmetric
  entries are computed once),
* the Lagrange remainders of the linearisation (source report section
  4.3.1) over a box, ``lagrange_iv`` (order 2: ``1/2 H(xi)[d, d]``, order 3:
  ``1/6 T(xi)[d, d, d]``), and ``f`` over a box (``f_iv``),
* ``h`` and its Jacobian (point and interval),

applies common-subexpression elimination, writes the result as a real Python module into a cache folder and
compiles it with ``numba.njit(cache=True)`` with the fixed signatures of :mod:`reachconf_kernels.signatures`.
The file name is a hash of the expressions, the names, the package version and this generator's version, so
a second process imports the module and loads numba's on-disk cache without recompiling.

Remainders (``remainder=``, :mod:`reachconf.model.remainders`):

* ``"taylor"`` (default): ``f`` is recorded once as a tape
  (:mod:`reachconf.model.tape`) that the compiled kernel
  :mod:`reachconf_kernels.taylor` evaluates in interval Taylor-mode
  arithmetic along the direction box, together with the symbolic second and
  third derivatives where they are small (the smaller bound is kept).  No
  interval derivative code is compiled per model, so the build grows with the
  model, not with ``nz^3``: the closed-loop vehicle with the rate-limited
  steering ``r tanh(k e / r)`` took 12 minutes before and takes seconds now
  (``benchmarks/bench_codegen.py``).  One build serves both orders.
* ``"tensor"``: the older path — the interval Hessian ``hess_iv`` and, with
  ``order=3``, the third-order tensor (``third``, ``third_iv``) as generated
  interval code, contracted by :mod:`reachconf_kernels.remainder`.  Kept to
  compare against; the Taylor bounds are never larger
  (``tests/model/test_taylor.py``).

The cache folder is ``$REACHCONF_CACHE`` if set, else the user cache folder
(``platformdirs.user_cache_dir("reachconf")``).
"""

from __future__ import annotations

import re
import time
import warnings
from dataclasses import dataclass, field
from functools import partial
from itertools import permutations
from pathlib import Path

import numpy as np
import sympy as sp

from reachconf.errors import ModelError
from reachconf.model import generated
from reachconf.model.generated import GENERATOR_VERSION, load_entry, model_hash, package_version, write_entry
from reachconf.model.printers import IntervalEmitter, point_code, real_diff
from reachconf.model.remainders import module_tape, taylor_section, tensor_section
from reachconf_kernels.taylor import range_enclosure
from reachconf.runner.caches import models_cache_dir

__all__ = ["CompiledModel", "compile_model", "cache_dir", "model_hash", "generate_source", "package_version",
           "GENERATOR_VERSION", "REMAINDERS"]  # fmt: skip

#: ways to bound the Lagrange remainders (see the module docstring)
REMAINDERS = ("taylor", "tensor")


def cache_dir() -> Path:
    """Folder of generated model modules (``$REACHCONF_CACHE/models`` or the user cache folder's ``models``)."""
    return models_cache_dir()


@dataclass
class CompiledModel:
    """Compiled functions of one model (see :mod:`reachconf_kernels.signatures`).

    Attributes
    ----------
    f, jac, h, jac_h, hess : numba dispatchers (point evaluation)
    f_iv, h_iv, jac_h_iv : interval evaluation (``f_iv(zlo, zhi, p, outlo, outhi)``, return a status);
        ``f_iv`` of a ``"taylor"`` build is a Python function calling the tape kernel; ``h_iv`` encloses
        ``h`` at a point with its rounding (an output set's centre)
    lagrange_iv : numba dispatcher
        Remainder bounds, signature ``IV_REMAINDER`` of
        :mod:`reachconf_kernels.signatures` (order 3 of a ``"tensor"`` build with
        ``order=2`` returns an error status).
    hess_iv : numba dispatcher or None (``"tensor"`` builds only)
    third, third_iv : numba dispatchers or None (``"tensor"`` builds with ``order=3``)
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
    generate_seconds, compile_seconds : float
        The two parts of ``seconds`` (generation is 0 when loaded from the cache).
    source_bytes : int
        Size of the generated module.
    remainder : str
        ``"taylor"`` or ``"tensor"``.
    tape : Tape or None
        The Taylor tape (``"taylor"`` builds).
    """

    f: object
    jac: object
    h: object
    jac_h: object
    hess: object
    f_iv: object
    hess_iv: object = None
    h_iv: object = None
    jac_h_iv: object = None
    lagrange_iv: object = None
    third: object = None
    third_iv: object = None
    hess_pattern: np.ndarray | None = None
    third_pattern: np.ndarray | None = None
    guards: list = field(default_factory=list)
    path: Path | None = None
    loaded_from_cache: bool = False
    seconds: float = 0.0
    module: object = None
    generate_seconds: float = 0.0
    compile_seconds: float = 0.0
    source_bytes: int = 0
    remainder: str = "taylor"
    tape: object = None

    def dispatchers(self):
        """All compiled dispatchers (for cache statistics)."""
        names = "f jac h jac_h hess f_iv hess_iv h_iv jac_h_iv third third_iv lagrange_iv".split()
        return {k: getattr(self, k) for k in names if hasattr(getattr(self, k), "stats")}


# ---------------------------------------------------------------------------
# public entry point
# ---------------------------------------------------------------------------
def compile_model(model, order: int = 2, remainder: str = "taylor") -> CompiledModel:
    """Generate (or find in the cache), import and compile the model's functions.

    Parameters
    ----------
    model : Model
    order : {2, 3}
        Highest remainder order needed.  Only the ``"tensor"`` path depends on
        it (3 adds the third-order tensors); a ``"taylor"`` build serves both.
    remainder : {"taylor", "tensor"}, default "taylor"
        How the Lagrange remainders are bounded (see the module docstring).

    Returns
    -------
    CompiledModel
    """
    with generated.BUILD_LOCK:  # one build at a time per process: threads share the generated module (generated.py)
        return _compile_model(model, order, remainder)


def _compile_model(model, order: int, remainder: str) -> CompiledModel:
    if order not in (2, 3):
        raise ModelError(f"order must be 2 or 3, got {order!r}")
    if remainder not in REMAINDERS:
        raise ModelError(f"remainder must be one of {REMAINDERS}, got {remainder!r}")
    if remainder == "taylor":
        order = 3  # one build for both orders
    t0 = time.perf_counter()
    digest = model_hash(model, order, remainder)
    safe = re.sub(r"[^A-Za-z0-9_]", "_", model.name)[:40]
    modname = f"reachconf_gen_{safe}_{digest}_{'taylor' if remainder == 'taylor' else f'o{order}'}"
    folder = cache_dir()
    path = folder / f"{modname}.py"
    meta_path = folder / f"{modname}.npz"
    from_cache = path.exists() and meta_path.exists()
    if not from_cache:
        _generate(model, order, remainder, path, meta_path)
    t_gen = time.perf_counter() - t0
    try:
        module, meta = load_entry(modname, path, meta_path)
    except Exception as exc:  # a damaged cache entry (cut off by a full disk, edited): generate it again, once
        if not from_cache:
            raise ModelError(f"model {model.name!r}: the generated code {path} does not load "
                             f"({type(exc).__name__}: {exc})"[:400]) from None  # fmt: skip
        warnings.warn(f"model {model.name!r}: the cached code {path.name} was damaged ({type(exc).__name__}); "
                      f"generating it again", RuntimeWarning, stacklevel=2)  # fmt: skip
        for f in (path, meta_path):
            f.unlink(missing_ok=True)
        return compile_model(model, order, remainder)
    guards = [str(g) for g in meta["guards"]] if "guards" in meta else []
    tape = module_tape(module)
    return CompiledModel(
        f=module.f,
        jac=module.jac,
        h=module.h,
        jac_h=module.jac_h,
        hess=module.hess,
        f_iv=module.f_iv if tape is None else partial(range_enclosure, tape.ops, tape.consts, tape.outs, tape.segments),
        hess_iv=getattr(module, "hess_iv", None),
        h_iv=module.h_iv,
        jac_h_iv=module.jac_h_iv,
        lagrange_iv=module.lagrange_iv,
        third=getattr(module, "third", None),
        third_iv=getattr(module, "third_iv", None),
        hess_pattern=meta["hess_pattern"],
        third_pattern=meta["third_pattern"] if "third_pattern" in meta else None,
        guards=guards,
        path=path,
        loaded_from_cache=from_cache,
        seconds=time.perf_counter() - t0,
        module=module,
        generate_seconds=t_gen if not from_cache else 0.0,
        compile_seconds=time.perf_counter() - t0 - t_gen,
        source_bytes=path.stat().st_size,
        remainder=remainder,
        tape=tape,
    )


def _generate(model, order: int, remainder: str, path: Path, meta_path: Path) -> None:
    """Write the model's generated source and its metadata (atomically) to the cache."""
    try:
        source, meta = generate_source(model, order, remainder)
    except ModelError as exc:  # in the user's names: the generator's symbols are s_<name>
        text = re.sub(r"\bs_(\w+)", r"\1", str(exc))
        raise ModelError(text if text.startswith("model ") else f"model {model.name!r}: {text}") from None
    except Exception as exc:  # e.g. sympy cannot print the derivative of floor: name the model, not the printer
        hint = ("a constant overflows float64 (|c| > 1.8e308): rescale the model" if isinstance(exc, OverflowError)
                else "write the dynamics with +, -, *, /, powers, sqrt, exp, log, sin, cos, tan, atan, tanh, Abs, Min, Max")
        raise ModelError(f"model {model.name!r}: cannot generate code for its derivatives "
                         f"({type(exc).__name__}: {str(exc).splitlines()[0] if str(exc) else ''}); {hint}") from None
    write_entry(path, meta_path, source, meta)


# ---------------------------------------------------------------------------
# derivatives
# ---------------------------------------------------------------------------
def _derivatives(model, order: int):
    z = model.z_symbols
    f = list(model.f_expr)
    n, nz = len(f), len(z)
    jac = [[real_diff(fi, zj) if zj in fi.free_symbols else sp.Integer(0) for zj in z] for fi in f]
    hess = {}  # (i, j, k) with j <= k -> expr
    for i in range(n):
        for j in range(nz):
            d1 = jac[i][j]
            if d1 == 0:
                continue
            for k in range(j, nz):
                if z[k] in d1.free_symbols:
                    d2 = real_diff(d1, z[k])
                    if d2 != 0:
                        hess[(i, j, k)] = d2
    third = {}
    if order >= 3:
        for (i, j, k), d2 in hess.items():
            for l in range(k, nz):
                if z[l] in d2.free_symbols:
                    d3 = real_diff(d2, z[l])
                    if d3 != 0:
                        third[(i, j, k, l)] = d3
    h = list(model.h_expr)
    jac_h = [[real_diff(hi, zj) if zj in hi.free_symbols else sp.Integer(0) for zj in z] for hi in h]
    return f, jac, hess, third, h, jac_h


def _permutations3(j, k):
    return {(j, k), (k, j)}


def _permutations4(j, k, l):
    return set(permutations((j, k, l)))


# ---------------------------------------------------------------------------
# source generation
# ---------------------------------------------------------------------------
_HEADER = '''"""Generated by reachconf.codegen (version {version}, remainder {remainder!r}) for model {name!r}."""
import math
import numba as nb
import numpy as np
from reachconf_kernels import interval as I
from reachconf_kernels import remainder as R
from reachconf_kernels import taylor as TM
from reachconf_kernels.signatures import (
    POINT_VEC, POINT_MAT, POINT_T3, POINT_T4, IV_VEC, IV_MAT, IV_T3, IV_T4, IV_REMAINDER,
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


def _point_function(name, sig, targets, model, z_index, p_index, opt="basic") -> str:
    """targets: list of (index-string, expr).

    ``opt="basic"`` (the tensor path) lets sympy factor terms before the
    elimination, which took most of the generation time of large models; the
    Taylor path passes ``None``.
    """
    exprs = [e for _, e in targets]
    reps, reduced = sp.cse(exprs, symbols=sp.numbered_symbols("c_"), optimizations=opt) if exprs else ([], [])
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
        self.m = model.m
        self.z_symbols = tuple(ren[s] for s in model.z_symbols)
        self.p_symbols = tuple(ren[s] for s in model.p_symbols)
        self.f_expr = tuple(e.xreplace(ren) for e in model.f_expr)
        self.h_expr = tuple(e.xreplace(ren) for e in model.h_expr)


def generate_source(model, order: int, remainder: str = "taylor"):
    """Python source of the compiled model module and its metadata arrays.

    Parameters
    ----------
    model : reachconf.Model
    order : {2, 3}
        Highest remainder order (the ``"tensor"`` path builds the third-order tensors for 3).
    remainder : {"taylor", "tensor"}

    Returns
    -------
    (str, dict of ndarray)
    """
    model = _Renamed(model)
    tensor = remainder == "tensor"
    opt = "basic" if tensor else None
    f, jac, hess, third, h, jac_h = _derivatives(model, order if tensor else 3)
    z = model.z_symbols
    n, nz, p_out = len(f), len(z), len(h)
    z_index = {s: i for i, s in enumerate(z)}
    p_index = {s: i for i, s in enumerate(model.p_symbols)}
    guards: list[str] = []

    def point(name, sig, targets):
        return _point_function(name, sig, targets, model, z_index, p_index, opt)

    def interval(name, sig, targets):
        return _interval_function(name, sig, targets, model, z_index, p_index, guards)

    def jacobian(rows, exprs):
        return [(f"{i}, {j}", e) for i in range(rows) for j in range(nz) if (e := exprs[i][j]) != 0]

    parts = [_HEADER.format(version=GENERATOR_VERSION, name=model.name, remainder=remainder)]
    parts.append(point("f", "POINT_VEC", [(str(i), e) for i, e in enumerate(f)]))
    parts.append(point("jac", "POINT_MAT", jacobian(n, jac)))
    parts.append(point("h", "POINT_VEC", [(str(i), e) for i, e in enumerate(h)]))
    parts.append(point("jac_h", "POINT_MAT", jacobian(p_out, jac_h)))
    hess_targets = []
    hess_pattern = np.zeros((n, nz, nz), dtype=bool)
    for (i, j, k), e in sorted(hess.items()):
        for a, b in _permutations3(j, k):
            hess_targets.append((f"{i}, {a}, {b}", e))
            hess_pattern[i, a, b] = True
    parts.append(point("hess", "POINT_T3", hess_targets))
    parts.append(interval("h_iv", "IV_VEC", [(str(i), e) for i, e in enumerate(h)]))
    parts.append(interval("jac_h_iv", "IV_MAT", jacobian(p_out, jac_h)))
    meta = {"hess_pattern": hess_pattern}
    if not tensor:
        moving = [j for j in range(nz) if not (n <= j < n + model.m)]  # the inputs are fixed within a step
        parts.append(taylor_section(f, z, model.p_symbols, moving, hess, third, guards)[0])
    else:
        parts.append(interval("f_iv", "IV_VEC", [(str(i), e) for i, e in enumerate(f)]))
        parts.append(interval("hess_iv", "IV_T3", hess_targets))
        if order >= 3:
            third_targets = []
            third_pattern = np.zeros((n, nz, nz, nz), dtype=bool)
            for (i, j, k, l), e in sorted(third.items()):
                for a, b, c in _permutations4(j, k, l):
                    third_targets.append((f"{i}, {a}, {b}, {c}", e))
                    third_pattern[i, a, b, c] = True
            parts.append(point("third", "POINT_T4", third_targets))
            parts.append(interval("third_iv", "IV_T4", third_targets))
            meta["third_pattern"] = third_pattern
        parts.append(tensor_section(order, guards))
    meta["guards"] = np.array(guards, dtype=str) if guards else np.array([], dtype=str)
    return "".join(parts), meta
