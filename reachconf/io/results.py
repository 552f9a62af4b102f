"""Results as JSON files: the save/load protocol every result of reachconf shares.

A result class implements ``to_dict()`` (JSON-able) and ``from_dict(d)``;
:class:`JsonResult` adds ``to_json(path=None)``, ``save(path)`` and
``load(path)``.  The file holds ``"result": <class name>`` next to the fields,
so a reader (``reachconf plot FILE``) can tell which result it is.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from reachconf.checks import require_file
from reachconf.errors import DataError
from reachconf.io.atomic import atomic_write
from reachconf.io.jsonfile import json_text

__all__ = ["JsonResult", "jsonable", "read_json"]


def jsonable(value):
    """``json.dumps`` fallback: arrays as lists, numpy scalars as numbers, sets by ``to_list()``."""
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, (np.floating, np.integer, np.bool_)):
        return value.item()
    if hasattr(value, "to_list"):
        return value.to_list()
    return float(value)


def read_json(path) -> dict:
    """The JSON object in ``path`` (:class:`DataError` naming the file if it is missing or not a JSON object)."""
    path = Path(path)
    require_file(path, "result file")
    try:
        data = json.loads(path.read_bytes().decode("utf-8-sig"))
    except UnicodeDecodeError:
        raise DataError(f"{path}: not a JSON text file (not UTF-8)") from None
    except (json.JSONDecodeError, RecursionError) as exc:
        raise DataError(f"{path}: not valid JSON: {str(exc)[:200]}") from None
    except OSError as exc:
        raise DataError(f"{path}: cannot read the file: {exc.strerror or exc}") from None
    if not isinstance(data, dict):
        raise DataError(f"{path}: a result file holds a JSON object, got {type(data).__name__}")
    return data


class JsonResult:
    """Mixin of the result classes: JSON text, atomic saving and loading (see the module docstring)."""

    def to_dict(self) -> dict:  # pragma: no cover - every result implements it
        """The result as a JSON-able dict."""
        raise NotImplementedError

    @classmethod
    def from_dict(cls, d: dict):  # pragma: no cover - every result implements it
        """The result from :meth:`to_dict`'s dict."""
        raise NotImplementedError

    def to_json(self, path=None, indent: int = 2) -> str:
        """Strict JSON text of the result (with its class name under ``"result"``; numbers that are not finite
        become ``null``, see :func:`reachconf.io.jsonfile.json_text`); written atomically to ``path`` if given."""
        text = json_text({"result": type(self).__name__, **self.to_dict()}, indent=indent)
        if path is not None:
            atomic_write(path, text)
        return text

    def save(self, path) -> Path:
        """Write the result as JSON to ``path`` (atomically); returns the path."""
        self.to_json(path)
        return Path(path)

    @classmethod
    def load(cls, path):
        """Read a result written by :meth:`save` (:class:`DataError` naming the file on any problem)."""
        data = read_json(path)
        kind = data.pop("result", cls.__name__)
        if kind != cls.__name__:
            raise DataError(f"{path}: holds a {kind}, not a {cls.__name__}")
        try:
            return cls.from_dict(data)
        except (KeyError, TypeError, ValueError, IndexError, AttributeError) as exc:  # a part of another shape
            raise DataError(f"{path}: not a {cls.__name__} file ({type(exc).__name__}: {exc})") from None
