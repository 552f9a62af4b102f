"""Strict JSON for every result file: plain types only, no ``NaN``/``Infinity``.

``json.dumps`` writes ``NaN`` and ``Infinity`` for non-finite floats, which
is not JSON (strict parsers reject it).  :func:`to_jsonable` turns a result
(dicts, lists, numpy arrays and scalars, sets, enums, objects with
``to_dict``/``to_list``) into plain JSON values and every non-finite number
into ``null``; the result classes put the reason next to it (``verdict``,
``message``).  :func:`json_text` then serialises with ``allow_nan=False``.
"""

from __future__ import annotations

import enum
import json
import math
from pathlib import PurePath

import numpy as np

__all__ = ["to_jsonable", "json_text", "finite_or_none"]


def finite_or_none(x):
    """``float(x)`` if finite, else ``None`` (JSON ``null``); ``None`` stays ``None``."""
    if x is None:
        return None
    x = float(x)
    return x if math.isfinite(x) else None


def to_jsonable(obj):
    """Plain JSON values (dict with str keys, list, str, int, float, bool, None); non-finite numbers -> None."""
    if obj is None or isinstance(obj, (bool, np.bool_)):
        return None if obj is None else bool(obj)
    if isinstance(obj, enum.Enum):
        return to_jsonable(obj.value)
    if isinstance(obj, str):
        return str(obj)
    if isinstance(obj, (int, np.integer)):
        return int(obj)
    if isinstance(obj, (float, np.floating)):
        return finite_or_none(obj)
    if isinstance(obj, dict):
        return {str(to_jsonable(k)) if not isinstance(k, str) else k: to_jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple, set, frozenset)):
        return [to_jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return to_jsonable(obj.tolist())
    if isinstance(obj, PurePath):
        return str(obj)
    if hasattr(obj, "to_dict"):
        return to_jsonable(obj.to_dict())
    if hasattr(obj, "to_list"):
        return to_jsonable(obj.to_list())
    if isinstance(obj, complex):
        return str(obj)
    return str(obj)


def json_text(obj, indent: int | None = 2) -> str:
    """Strict JSON text of ``obj`` (see :func:`to_jsonable`); never contains ``NaN`` or ``Infinity``."""
    return json.dumps(to_jsonable(obj), indent=indent, allow_nan=False)
