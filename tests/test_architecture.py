"""The package's architecture, read from its source: imports, private names, module sizes, layers.

Every import counts, at module level or inside a function (a function-level
import is still a dependency).  ``from a.b import c`` depends on the module
``a.b.c`` if it exists, else on ``a.b``; importing a submodule is not counted
as depending on its parent package's ``__init__``.
"""

import ast
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("reachconf", "reachconf_kernels")
MAX_LINES = 500

#: layers from the bottom up; a module may import its own layer and those below
LAYERS = (
    ("kernels, errors, registries, argument checks, verdicts, time stamps",
     ("reachconf_kernels", "reachconf.errors", "reachconf.registry", "reachconf.checks", "reachconf.verdict",
      "reachconf.timestamps")),
    ("sets, test suites, process pools, resource checks", ("reachconf.sets", "reachconf.io", "reachconf.runner",
                                                            "reachconf.budget", "reachconf.blas_threads")),
    ("model, drawing", ("reachconf.model", "reachconf.plot")),
    ("reachability, built-in models", ("reachconf.reach", "reachconf.reach_options", "reachconf.reach_stream",
                                       "reachconf.reach_adaptive", "reachconf.reach_adaptive_stream",
                                       "reachconf.reach_errors", "reachconf.reach_log", "reachconf.tube_pieces",
                                       "reachconf.tube", "reachconf.models")),
    ("conformance, data sets", ("reachconf.conformance", "reachconf.datasets")),
    ("gap diagnosis", ("reachconf.diagnose",)),
    ("run files, demo, warm-up", ("reachconf.runfile", "reachconf.demo", "reachconf.warmup")),
    ("command line, example scripts", ("reachconf.cli", "reachconf.cli_cases", "reachconf.commands", "reachconf.drawable",
                                       "reachconf.script")),
    ("the package face", ("reachconf",)),
)
#: (importer, imported) pairs allowed to run against the layering: at most one, each with its reason
UPWARD_ALLOWED = {}


def _modules():
    mods = {}
    for pkg in PACKAGES:
        for path in sorted((ROOT / pkg).rglob("*.py")):
            parts = list(path.relative_to(ROOT).with_suffix("").parts)
            if parts[-1] == "__init__":
                parts = parts[:-1]
            mods[".".join(parts)] = path
    return mods


MODULES = _modules()
TREES = {m: ast.parse(p.read_text(encoding="utf-8")) for m, p in MODULES.items()}


def _resolve(name):
    while name and name not in MODULES:
        name = name.rpartition(".")[0]
    return name or None


def _imports(module):
    """(line, imported module, names) of every import of a package module."""
    out = []
    is_pkg = MODULES[module].name == "__init__.py"
    for node in ast.walk(TREES[module]):
        if isinstance(node, ast.Import):
            for a in node.names:
                if a.name.split(".")[0] in PACKAGES:
                    out.append((node.lineno, _resolve(a.name), ()))
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                pkg = module if is_pkg else module.rpartition(".")[0]
                for _ in range(node.level - 1):
                    pkg = pkg.rpartition(".")[0]
                base = pkg + ("." + base if base else "")
            if base.split(".")[0] not in PACKAGES:
                continue
            for a in node.names:
                full = f"{base}.{a.name}"
                out.append((node.lineno, full if full in MODULES else _resolve(base), (a.name,)))
    return out


GRAPH = {m: {imp for _, imp, _ in _imports(m) if imp and imp != m} for m in MODULES}


def _cycles(graph):
    index, low, stack, on, found = {}, {}, [], set(), []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in graph[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                found.append(sorted(comp))

    sys.setrecursionlimit(max(sys.getrecursionlimit(), 10_000))
    for v in graph:
        if v not in index:
            visit(v)
    return found


def _layer(module):
    best, level = -1, None
    for i, (_, prefixes) in enumerate(LAYERS):
        for p in prefixes:
            if (module == p or module.startswith(p + ".")) and len(p) > best:
                best, level = len(p), i
    return level


def test_no_import_cycles():
    assert _cycles(GRAPH) == []


def test_every_module_has_a_layer():
    assert [m for m in MODULES if _layer(m) is None] == []


def test_at_most_one_import_against_the_layering():
    upward = sorted((m, imp) for m, deps in GRAPH.items() for imp in deps if _layer(imp) > _layer(m))
    assert len(UPWARD_ALLOWED) <= 1
    assert [u for u in upward if u not in UPWARD_ALLOWED] == []


def test_no_module_imports_the_package_face():
    """Library code imports from the defining modules; ``reachconf/__init__`` is for users and stays lazy."""
    assert sorted(m for m, deps in GRAPH.items() if "reachconf" in deps) == []


def _defined_names(tree):
    names = set()
    for node in ast.walk(tree):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            names.add(node.name)
        elif isinstance(node, ast.Name) and isinstance(node.ctx, ast.Store):
            names.add(node.id)
        elif isinstance(node, ast.Attribute) and isinstance(node.ctx, ast.Store):
            names.add(node.attr)
        elif isinstance(node, ast.arg):
            names.add(node.arg)
    return names


def _private(name):
    return name.startswith("_") and not (name.startswith("__") and name.endswith("__"))


def _private_uses(path, tree):
    """Imports of another module's underscore names, and ``obj._name`` where ``_name`` is not this module's."""
    own = _defined_names(tree)
    bad = []
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and (node.module or "").split(".")[0] in PACKAGES:
            bad += [f"{path}:{node.lineno}: from {node.module} import {a.name}" for a in node.names if _private(a.name)]
        elif isinstance(node, ast.Attribute) and _private(node.attr) and node.attr not in own:
            if not (isinstance(node.value, ast.Name) and node.value.id in ("self", "cls")):
                bad.append(f"{path}:{node.lineno}: {ast.unparse(node)}")
    return bad


def test_no_module_uses_another_modules_private_names():
    files = [p for pkg in (*PACKAGES, "examples", "benchmarks") for p in sorted((ROOT / pkg).rglob("*.py"))]
    bad = []
    for path in files:
        bad += _private_uses(path.relative_to(ROOT), ast.parse(path.read_text(encoding="utf-8")))
    assert bad == []


def test_no_module_over_500_lines():
    sizes = {m: len(p.read_text(encoding="utf-8").splitlines()) for m, p in MODULES.items()}
    assert {m: n for m, n in sizes.items() if n > MAX_LINES} == {}


def test_import_reachconf_is_lazy():
    code = ("import sys, reachconf; print(sorted(m for m in sys.modules if m.startswith('reachconf')));"
            "print(sorted(m for m in ('numpy', 'sympy', 'numba', 'scipy', 'cvxpy') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.split("\n")
    assert out[0] == "['reachconf', 'reachconf.errors']"
    assert out[1] == "[]"


def test_face_names_and_old_module_paths_resolve():
    code = """
import reachconf as rc
import reachconf.reach, reachconf.diagnose.pipeline
assert callable(rc.reach) and callable(rc.diagnose)
from reachconf.reach import ReachOptions
assert rc.ReachOptions is ReachOptions
for name in rc.__all__:
    getattr(rc, name)
import importlib
for old, new in rc.MOVED_MODULES.items():
    assert importlib.import_module(old) is importlib.import_module(new), old
from reachconf.simulate import simulate
from reachconf.campaign.plant import PlantEffects
import sys
assert sys.modules["reachconf.model.simulate"].__spec__.name == "reachconf.model.simulate"
assert simulate is sys.modules["reachconf.model.simulate"].simulate
print("ok")
"""
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert res.stdout.strip() == "ok", res.stderr


def test_every_module_imports():
    """All modules import in one fresh interpreter, the higher layers first (no hidden order dependence)."""
    order = sorted((m for m in MODULES if m.startswith("reachconf.")), key=lambda m: (-_layer(m), m))
    code = "import importlib\nfor m in %r:\n    importlib.import_module(m)\nprint('ok')" % (order,)
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert res.stdout.strip() == "ok", res.stderr[-3000:]
