"""Argument checks shared by the options classes and the entry points (each error names the argument).

:func:`check_field_types` checks every field of an options dataclass against
its annotation *before* the values are used, so that ``time_step = "fast"``
raises ``OptionsError("ReachOptions.time_step must be a number, got 'fast'")``
instead of a ``TypeError`` from deep inside.  :func:`check_workers` is the
one check of a ``workers`` argument (an integer >= 1, or None).
"""

from __future__ import annotations

import numbers
import types
import typing
from functools import lru_cache
from pathlib import Path

from reachconf.errors import DataError, OptionsError

__all__ = ["check_field_types", "check_workers", "check_options", "describe_type", "value_has_type"]


def _is_int(value) -> bool:
    return isinstance(value, numbers.Integral) and not isinstance(value, bool)


def _is_real(value) -> bool:
    return isinstance(value, numbers.Real) and not isinstance(value, bool)


def value_has_type(value, tp) -> bool:
    """Does ``value`` fit the annotation ``tp``?  Numbers are not bools; an int is a float; a list is a tuple."""
    if tp is typing.Any or tp is object:
        return True
    if tp is None or tp is type(None):
        return value is None
    origin = typing.get_origin(tp)
    if origin in (typing.Union, types.UnionType):
        return any(value_has_type(value, t) for t in typing.get_args(tp))
    if origin is typing.Literal:
        return value in typing.get_args(tp)
    if origin is not None:  # list[str], tuple[float, ...], dict[...]: check the container only
        tp = origin
    if tp is float:
        return _is_real(value)
    if tp is int:
        return _is_int(value)
    if tp is bool:
        return isinstance(value, bool)
    if tp is tuple:
        import numpy as np

        return isinstance(value, (tuple, list, np.ndarray))
    if isinstance(tp, type):
        return isinstance(value, tp)
    return True  # an annotation this check does not understand: the class's own checks decide


def describe_type(tp) -> str:
    """``float | None`` -> ``"a number or None"`` (for messages)."""
    names = {float: "a number", int: "an integer", bool: "true or false", str: "a string", tuple: "a list",
             type(None): "None", list: "a list", dict: "a table"}  # fmt: skip
    origin = typing.get_origin(tp)
    if origin in (typing.Union, types.UnionType):
        return " or ".join(describe_type(t) for t in typing.get_args(tp))
    if origin is typing.Literal:
        return " or ".join(repr(a) for a in typing.get_args(tp))
    if origin is not None:
        tp = origin
    if tp in names:
        return names[tp]
    return f"a {getattr(tp, '__name__', str(tp))}"


@lru_cache(maxsize=None)
def _hints(cls):
    return typing.get_type_hints(cls)


def check_field_types(obj) -> None:
    """Raise :class:`OptionsError` naming the first field of dataclass ``obj`` whose value has the wrong type.

    Call it first in ``__post_init__``; the class's own checks (ranges,
    choices) follow.  Annotations are resolved with ``typing.get_type_hints``.
    """
    import dataclasses

    cls = type(obj)
    hints = _hints(cls)
    for f in dataclasses.fields(obj):
        tp = hints.get(f.name)
        if tp is None:
            continue
        value = getattr(obj, f.name)
        if not value_has_type(value, tp):
            raise OptionsError(f"{cls.__name__}.{f.name} must be {describe_type(tp)}, got {value!r}")


def check_workers(workers, name: str = "workers"):
    """``workers`` as an int >= 1, or None; raise :class:`OptionsError` naming ``name`` otherwise.

    ``"2"``, ``2.0``, ``0``, ``-3`` and ``True`` are all errors: a number of
    processes is a positive integer.
    """
    if workers is None:
        return None
    if not _is_int(workers) or workers < 1:
        raise OptionsError(f"{name} must be a positive integer (number of worker processes), got {workers!r}")
    return int(workers)


def check_options(options, cls, where: str, name: str = "options"):
    """``cls()`` if ``options`` is None, ``options`` if it is a ``cls``, else :class:`OptionsError` naming it.

    Catches e.g. ``trace_conformance(..., options=ReachOptions())``, which
    would otherwise fail later with an ``AttributeError``.
    """
    if options is None:
        return cls()
    if not isinstance(options, cls):
        raise OptionsError(f"{where}: {name} must be a {cls.__name__} (or None for the defaults), "
                           f"got {type(options).__name__}")  # fmt: skip
    return options


def require_file(path, what: str = "file") -> None:
    """Raise :class:`DataError` naming ``path`` unless it is a regular file: no such file, a folder, or another kind
    (a device, a pipe); ``what`` names the file in the message (``"run file"``, ``"result file"``)."""
    path = Path(path)
    if path.is_file():
        return
    if path.is_dir():
        raise DataError(f"{path}: is a folder, expected a {what}")
    if path.exists():
        raise DataError(f"{path}: is not a regular file, expected a {what}")
    raise DataError(f"{path}: no such {what}")


def is_number_text(text: str) -> bool:
    """Whether ``text`` parses as a float (a data file's cell: "1.5", "nan", "1e3")."""
    try:
        float(text)
    except ValueError:
        return False
    return True
