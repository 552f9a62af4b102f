"""Every public name of reachconf and reachconf_kernels has a docstring (the API reference is built from them).

Public: a module whose name has no leading underscore; in it, the names of
``__all__`` and every function and class defined there without a leading
underscore; of a class, every method and property defined in the class body
without a leading underscore.  Dunder methods and inherited members are left
out; a dataclass's generated signature does not count as a docstring.
"""

import dataclasses
import importlib
import inspect
import pkgutil

import pytest

import reachconf
import reachconf_kernels


def _modules():
    names = []
    for pkg in (reachconf, reachconf_kernels):
        names.append(pkg.__name__)
        for info in pkgutil.walk_packages(pkg.__path__, pkg.__name__ + "."):
            if not any(part.startswith("_") for part in info.name.split(".")):
                names.append(info.name)
    return sorted(names)


def _doc(obj):
    doc = getattr(getattr(obj, "py_func", obj), "__doc__", None)  # numba dispatchers keep the Python function's
    return (doc or "").strip()


def _class_doc_missing(cls):
    doc = _doc(cls)
    generated = dataclasses.is_dataclass(cls) and doc.startswith(f"{cls.__name__}(")
    return not doc or generated


def _missing(module_name):
    module = importlib.import_module(module_name)
    missing = [module_name] if not _doc(module) else []
    defined = [n for n, v in vars(module).items() if not n.startswith("_") and (inspect.isfunction(v) or
               inspect.isclass(v) or hasattr(v, "py_func"))]  # fmt: skip
    for name in dict.fromkeys([*getattr(module, "__all__", ()), *defined]):
        obj = getattr(module, name)
        if getattr(obj, "__module__", module_name) != module_name:
            continue  # a re-export: checked where it is defined
        if inspect.isclass(obj):
            if _class_doc_missing(obj):
                missing.append(f"{module_name}.{name}")
            for attr, value in vars(obj).items():
                if attr.startswith("_"):
                    continue
                if isinstance(value, (staticmethod, classmethod)):
                    value = value.__func__
                if isinstance(value, property) or inspect.isfunction(value):
                    if not _doc(value):
                        missing.append(f"{module_name}.{name}.{attr}")
        elif callable(obj) and not _doc(obj):
            missing.append(f"{module_name}.{name}")
    return missing


@pytest.mark.parametrize("module_name", _modules())
def test_public_names_have_docstrings(module_name):
    assert _missing(module_name) == []
