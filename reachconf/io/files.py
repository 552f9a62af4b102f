"""Test suites on disk: reading and writing folders of measured test cases ⟨U, Y, T⟩ (section 3.1).

A test suite is a folder with one test case per file (``.csv`` or ``.npz``):

* CSV: a header row, then one row per sample.  Column ``t`` (seconds,
  strictly increasing), then columns named after the model's inputs and
  outputs (SI units, radians), and optionally extra signals (e.g. requested
  actuator values).
* NPZ: one array per column, with the same names.

An optional ``suite.toml`` in the folder says which columns are inputs,
outputs and extras, gives a group (maneuver) per file, renames columns and
converts units::

    name = "lane changes"
    inputs = ["delta", "a"]
    outputs = ["x", "y", "psi"]
    extras = ["delta_req"]
    [groups]
    "lc_01.csv" = "lane_change_2"
    [rename]            # column in file -> name used
    steer = "delta"
    [units]             # column (after renaming) -> unit it is stored in
    delta = "deg"

A rename onto a name that another column of the file has (or gets) is an
error, never a silent choice of one of them.  The readers are strict
(:mod:`reachconf.io.readers`): plain decimal numbers, UTF-8 with or without a
byte-order mark, real-valued 1-D arrays in an NPZ.  Every problem raises
:class:`reachconf.DataError` naming the file, row (the file's line number)
and column; a suite is either loaded completely or not at all.
"""

from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np

from reachconf.checks import require_file
from reachconf.errors import DataError, ModelError
from reachconf.io.atomic import atomic_write
from reachconf.io.cases import TestCase, TestSuite, check_signals
from reachconf.io.readers import read_csv_columns, read_npz_columns, read_suite_toml

__all__ = ["load_suite", "save_suite", "load_case", "save_case", "UNITS"]

#: unit name -> factor to SI (value_SI = factor * value); ``rad``/``m``/``s`` are 1.
UNITS = {
    "": 1.0, "1": 1.0, "si": 1.0, "rad": 1.0, "m": 1.0, "s": 1.0, "m/s": 1.0, "m/s^2": 1.0, "rad/s": 1.0,
    "n": 1.0, "nm": 1.0, "n*m": 1.0,
    "deg": math.pi / 180.0, "deg/s": math.pi / 180.0, "rpm": 2.0 * math.pi / 60.0,
    "km/h": 1.0 / 3.6, "kn": 1000.0, "knm": 1000.0, "kn*m": 1000.0, "kn·m": 1000.0, "g": 9.80665,
    "ms": 1e-3, "mm": 1e-3, "cm": 1e-2,
}  # fmt: skip


# --------------------------------------------------------------------------- reading


def _path_argument(path, what: str) -> Path:
    if not isinstance(path, (str, os.PathLike)) or (isinstance(path, str) and not path):
        raise DataError(f"{what} must be a path (str or pathlib.Path), got {path!r}")
    return Path(path)


def _renamed(cols: dict, rename: dict, path) -> dict:
    """Columns after ``rename``; a rename onto a name another column has (or gets) is an error."""
    out = {}
    origin = {}
    for k, v in cols.items():
        new = rename.get(k, k)
        if not isinstance(new, str) or not new:
            raise DataError(f"{path}: rename of column {k!r} must give a non-empty name, got {new!r}")
        if new in out:
            first, second = sorted((origin[new], k), key=lambda c: c in rename)
            raise DataError(f"{path}: rename {second!r} -> {new!r} collides with the column {first!r} of the file "
                            f"(which is {'also renamed to' if first in rename else 'already'} {new!r}); "
                            "drop or rename one of them")  # fmt: skip
        out[new] = v
        origin[new] = k
    return out


def load_case(path, inputs=None, outputs=None, extras=None, group="default", rename=None, units=None,
              model=None) -> TestCase:  # fmt: skip
    """Read one test case file (``.csv`` or ``.npz``).

    Parameters
    ----------
    path : path-like
    inputs, outputs : sequence of str, optional
        Column names of the inputs and outputs.  Default: the model's, else
        every column but ``t`` (and the extras) is an output.
    extras : sequence of str, optional
        Further columns to keep.  With ``inputs``/``outputs`` given, any other
        column is an error ("unknown column").
    rename : dict, optional
        Column renames applied first (file name -> name used).
    units : dict, optional
        Column -> unit the file stores it in (see :data:`UNITS`); converted to SI.
    model : reachconf.Model, optional
        Supplies ``inputs`` and ``outputs``.
    """
    path = _path_argument(path, "load_case: path")
    require_file(path)
    suffix = path.suffix.lower()
    rows = None  # file line of each sample (CSV)
    if suffix == ".csv":
        cols, rows = read_csv_columns(path)
    elif suffix == ".npz":
        cols = read_npz_columns(path)
    else:
        raise DataError(f"{path}: unsupported file type {suffix!r} (use .csv or .npz)")
    cols = _renamed(cols, dict(rename or {}), path)
    if "t" not in cols:
        raise DataError(f"{path}: missing column 't' (time in seconds); columns: {list(cols)}")
    for name, unit in dict(units or {}).items():
        key = str(unit).strip().lower().replace(" ", "")
        if key not in UNITS:
            raise DataError(f"{path}: column {name!r}: unknown unit {unit!r}; known: {sorted(u for u in UNITS if u)}")
        if name not in cols:
            raise DataError(f"{path}: units given for column {name!r}, which the file does not have")
        cols[name] = cols[name] * UNITS[key]
    if model is not None:
        inputs = inputs if inputs is not None else model.input_names
        outputs = outputs if outputs is not None else model.output_names
    extras = list(extras or [])
    if outputs is None:
        outputs = [k for k in cols if k != "t" and k not in extras and k not in (inputs or ())]
    inputs = list(inputs or [])
    outputs = list(outputs)
    wanted = ["t", *inputs, *outputs, *extras]
    twice = sorted({k for k in wanted if wanted.count(k) > 1})
    if twice:
        raise DataError(f"{path}: columns {twice} have more than one role (time t, input, output, extra)")
    missing = [k for k in wanted if k not in cols]
    if missing:
        raise DataError(f"{path}: missing columns {missing}; the file has {list(cols)}")
    unknown = [k for k in cols if k not in wanted]
    if unknown:
        raise DataError(f"{path}: unknown columns {unknown}; expected {wanted} (declare extras in suite.toml)")
    K = cols["t"].size
    where = str(path)
    U = np.column_stack([cols[k] for k in inputs]) if inputs else np.zeros((K, 0))
    Y = np.column_stack([cols[k] for k in outputs]) if outputs else np.zeros((K, 0))
    t, U, Y = check_signals(where, cols["t"], U, Y, inputs, outputs, row_numbers=rows)
    for k in extras:
        bad = ~np.isfinite(cols[k])
        if bad.any():
            i = int(np.argmax(bad))
            raise DataError(f"{path}: row {i + 1 if rows is None else rows[i]}, column {k!r}: NaN/inf not allowed")
    return TestCase(path.stem, group, t, U, Y, tuple(inputs), tuple(outputs), {k: cols[k] for k in extras})


def load_suite(path, model=None) -> TestSuite:
    """Load every ``.csv``/``.npz`` file of a folder as a :class:`TestSuite` (see module docstring).

    Raises :class:`reachconf.DataError` on the first bad file, naming it; nothing is half-loaded.
    """
    folder = _path_argument(path, "load_suite: path")
    if not folder.is_dir():
        raise DataError(f"{folder}: " + ("is a file, expected a test suite folder" if folder.exists()
                                         else "test suite folder does not exist"))  # fmt: skip
    cfg = read_suite_toml(folder)
    try:
        files = sorted(p for p in folder.iterdir()
                       if p.suffix.lower() in (".csv", ".npz") and not p.name.startswith(".") and p.is_file())  # fmt: skip
    except OSError as exc:
        raise DataError(f"{folder}: cannot list the folder: {exc.strerror or exc}") from None
    if not files:
        raise DataError(f"{folder}: no .csv or .npz test case files")
    stems = [p.stem for p in files]
    same = sorted(p.name for p in files if stems.count(p.stem) > 1)
    if same:  # a case is named by its file's stem
        raise DataError(f"{folder}: files {same} would give cases of the same name; keep one of each")
    if model is not None and not all(hasattr(model, a) for a in ("state_names", "input_names", "output_names")):
        raise ModelError(f"load_suite: model must be a reachconf Model, got {type(model).__name__}")
    groups = cfg.get("groups", {})
    unknown = set(groups) - {p.name for p in files} - {p.stem for p in files}
    if unknown:
        raise DataError(f"{folder / 'suite.toml'}: [groups] names files that do not exist: {sorted(unknown)}")
    cases = [
        load_case(p, inputs=cfg.get("inputs"), outputs=cfg.get("outputs"), extras=cfg.get("extras"),
                  group=str(groups.get(p.name, groups.get(p.stem, "default"))), rename=cfg.get("rename"),
                  units=cfg.get("units"), model=model)
        for p in files
    ]  # fmt: skip
    return TestSuite(cases, name=cfg.get("name", folder.name))


# --------------------------------------------------------------------------- writing


def _case_csv(case: TestCase) -> str:
    names = ["t", *case.input_names, *case.output_names, *case.extras]
    data = np.column_stack([case.t, case.U, case.Y, *[v[:, None] for v in case.extras.values()]])
    lines = [",".join(names)]
    lines += [",".join(repr(float(v)) for v in row) for row in data]
    return "\n".join(lines) + "\n"


def _npz_bytes(arrays: dict) -> bytes:
    """An ``.npz`` archive of ``arrays`` (as ``np.savez``, which cannot take a signal named ``file``)."""
    import io as _io
    import zipfile

    buf = _io.BytesIO()
    with zipfile.ZipFile(buf, "w", zipfile.ZIP_STORED) as zf:
        for name, value in arrays.items():
            with zf.open(f"{name}.npy", "w", force_zip64=True) as f:
                np.lib.format.write_array(f, np.asanyarray(value), allow_pickle=False)
    return buf.getvalue()


def save_case(case: TestCase, path) -> Path:
    """Write one case as ``.csv`` or ``.npz`` (by the suffix of ``path``), atomically."""
    path = Path(path)
    if path.suffix.lower() == ".npz":
        atomic_write(path, _npz_bytes({"t": case.t, **case.signals}))
    else:
        atomic_write(path, _case_csv(case))
    return path


def _toml_str(s: str) -> str:
    return '"' + s.replace("\\", "\\\\").replace('"', '\\"') + '"'


def save_suite(suite: TestSuite, path, fmt: str = "csv", replace: bool = False) -> Path:
    """Write a suite as a folder of ``.csv`` (or ``.npz``) files plus ``suite.toml``.

    Parameters
    ----------
    suite : TestSuite
    path : path-like
        The folder (created if missing).
    fmt : {"csv", "npz"}
    replace : bool, default False
        The folder may already hold test case files that are not cases of
        ``suite`` (e.g. an earlier suite saved there).  :func:`load_suite`
        reads every case file of a folder, so they would silently join this
        suite: without ``replace`` that is an error (nothing is deleted);
        with it, they are deleted after the new cases are written.

    Raises
    ------
    DataError
        Bad ``fmt``, cases with different signals, or (without ``replace``)
        other case files in the folder, named.
    """
    if fmt not in ("csv", "npz"):
        raise DataError(f"fmt must be 'csv' or 'npz', got {fmt!r}")
    folder = Path(path)
    if folder.exists() and not folder.is_dir():
        raise DataError(f"{folder}: is a file, not a folder: save_suite writes a folder of case files")
    first = suite[0]
    for case in suite:
        if case.input_names != first.input_names or case.output_names != first.output_names:
            raise DataError(f"suite {suite.name!r}: case {case.name!r} has other signals than {first.name!r}")
        if set(case.extras) != set(first.extras):  # suite.toml lists one set of extra columns for every file
            raise DataError(f"suite {suite.name!r}: case {case.name!r} has the extra signals {sorted(case.extras)}, "
                            f"case {first.name!r} {sorted(first.extras)}; a suite folder needs the same in every "
                            f"case (nothing was written)")  # fmt: skip
    names = {f"{case.name}.{fmt}" for case in suite}
    stale = sorted(p for p in folder.iterdir() if p.is_file() and not p.name.startswith(".")
                   and p.suffix.lower() in (".csv", ".npz") and p.name not in names) if folder.is_dir() else []  # fmt: skip
    if stale and not replace:
        shown = ", ".join(p.name for p in stale[:5]) + (f" and {len(stale) - 5} more" if len(stale) > 5 else "")
        raise DataError(f"{folder}: holds test case files that are not in suite {suite.name!r} ({shown}); "
                        "load_suite would read them as part of it: save into an empty folder or pass replace=True")  # fmt: skip
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise DataError(f"{folder}: cannot create the suite folder: {exc.strerror or exc}") from None
    for case in suite:
        save_case(case, folder / f"{case.name}.{fmt}")
    for p in stale:
        p.unlink()
    lines = [f"name = {_toml_str(suite.name)}",
             "inputs = [" + ", ".join(_toml_str(s) for s in first.input_names) + "]",
             "outputs = [" + ", ".join(_toml_str(s) for s in first.output_names) + "]",
             "extras = [" + ", ".join(_toml_str(s) for s in first.extras) + "]",
             "", "[groups]"]  # fmt: skip
    lines += [f"{_toml_str(case.name + '.' + fmt)} = {_toml_str(case.group)}" for case in suite]
    atomic_write(folder / "suite.toml", "\n".join(lines) + "\n")
    return folder
