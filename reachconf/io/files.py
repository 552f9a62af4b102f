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

Every problem raises :class:`reachconf.DataError` naming the file, row and
column; a suite is either loaded completely or not at all.
"""

from __future__ import annotations

import csv
import math
import tomllib
from pathlib import Path

import numpy as np

from reachconf.errors import DataError
from reachconf.io.atomic import atomic_write
from reachconf.io.cases import TestCase, TestSuite, check_signals

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


def _read_toml(folder: Path) -> dict:
    path = folder / "suite.toml"
    if not path.exists():
        return {}
    try:
        with open(path, "rb") as fh:
            cfg = tomllib.load(fh)
    except tomllib.TOMLDecodeError as exc:
        raise DataError(f"{path}: invalid TOML: {exc}") from None
    known = {"name", "inputs", "outputs", "extras", "groups", "rename", "units", "description"}
    unknown = set(cfg) - known
    if unknown:
        raise DataError(f"{path}: unknown keys {sorted(unknown)}; allowed: {sorted(known)}")
    for key in ("groups", "rename", "units"):
        if key in cfg and not isinstance(cfg[key], dict):
            raise DataError(f"{path}: [{key}] must be a table")
    for key in ("inputs", "outputs", "extras"):
        if key in cfg and not (isinstance(cfg[key], list) and all(isinstance(s, str) for s in cfg[key])):
            raise DataError(f"{path}: {key} must be a list of column names")
    return cfg


def _read_csv_columns(path: Path) -> dict:
    try:
        with open(path, newline="", encoding="utf-8") as fh:
            rows = list(csv.reader(fh))
    except UnicodeDecodeError as exc:
        raise DataError(f"{path}: not a text CSV file ({exc.reason})") from None
    rows = [r for r in rows if r and not (len(r) == 1 and not r[0].strip())]
    if not rows:
        raise DataError(f"{path}: file is empty")
    header = [h.strip() for h in rows[0]]
    if any(not h for h in header):
        raise DataError(f"{path}: row 1: empty column name in the header")
    dup = {h for h in header if header.count(h) > 1}
    if dup:
        raise DataError(f"{path}: row 1: duplicate columns {sorted(dup)}")
    data = np.empty((len(rows) - 1, len(header)))
    for r, row in enumerate(rows[1:], start=2):
        if len(row) != len(header):
            raise DataError(f"{path}: row {r}: {len(row)} cells, the header has {len(header)}")
        for c, cell in enumerate(row):
            try:
                data[r - 2, c] = float(cell)
            except ValueError:
                raise DataError(f"{path}: row {r}, column {header[c]!r}: not a number: {cell!r}") from None
    return {h: data[:, i] for i, h in enumerate(header)}


def _read_npz_columns(path: Path) -> dict:
    try:
        with np.load(path, allow_pickle=False) as z:
            cols = {k: np.asarray(z[k], dtype=float) for k in z.files}
    except (OSError, ValueError) as exc:
        raise DataError(f"{path}: cannot read npz: {exc}") from None
    if not cols:
        raise DataError(f"{path}: file is empty")
    for k, v in cols.items():
        if v.ndim != 1:
            raise DataError(f"{path}: array {k!r} must be 1-D, got shape {v.shape}")
    sizes = {v.size for v in cols.values()}
    if len(sizes) > 1:
        raise DataError(f"{path}: arrays have different lengths {sorted(sizes)}")
    return cols


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
    path = Path(path)
    if not path.is_file():
        raise DataError(f"{path}: no such file")
    suffix = path.suffix.lower()
    if suffix == ".csv":
        cols = _read_csv_columns(path)
    elif suffix == ".npz":
        cols = _read_npz_columns(path)
    else:
        raise DataError(f"{path}: unsupported file type {suffix!r} (use .csv or .npz)")
    rename = dict(rename or {})
    cols = {rename.get(k, k): v for k, v in cols.items()}
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
    t, U, Y = check_signals(where, cols["t"], U, Y, inputs, outputs, first_row=2 if suffix == ".csv" else 1)
    for k in extras:
        bad = ~np.isfinite(cols[k])
        if bad.any():
            raise DataError(f"{path}: row {int(np.argmax(bad)) + 2}, column {k!r}: NaN/inf not allowed")
    return TestCase(path.stem, group, t, U, Y, tuple(inputs), tuple(outputs), {k: cols[k] for k in extras})


def load_suite(path, model=None) -> TestSuite:
    """Load every ``.csv``/``.npz`` file of a folder as a :class:`TestSuite` (see module docstring).

    Raises :class:`reachconf.DataError` on the first bad file, naming it; nothing is half-loaded.
    """
    folder = Path(path)
    if not folder.is_dir():
        raise DataError(f"{folder}: test suite folder does not exist")
    cfg = _read_toml(folder)
    files = sorted(p for p in folder.iterdir() if p.suffix.lower() in (".csv", ".npz") and not p.name.startswith("."))
    if not files:
        raise DataError(f"{folder}: no .csv or .npz test case files")
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


def save_case(case: TestCase, path) -> Path:
    """Write one case as ``.csv`` or ``.npz`` (by the suffix of ``path``), atomically."""
    path = Path(path)
    if path.suffix.lower() == ".npz":
        import io as _io

        buf = _io.BytesIO()
        np.savez(buf, **{"t": case.t, **case.signals})
        atomic_write(path, buf.getvalue())
    else:
        atomic_write(path, _case_csv(case))
    return path


def _toml_str(s: str) -> str:
    return '"' + s.replace("\\", "\\\\").replace('"', '\\"') + '"'


def save_suite(suite: TestSuite, path, fmt: str = "csv") -> Path:
    """Write a suite as a folder of ``.csv`` (or ``.npz``) files plus ``suite.toml``."""
    if fmt not in ("csv", "npz"):
        raise DataError(f"fmt must be 'csv' or 'npz', got {fmt!r}")
    folder = Path(path)
    folder.mkdir(parents=True, exist_ok=True)
    first = suite[0]
    for case in suite:
        if case.input_names != first.input_names or case.output_names != first.output_names:
            raise DataError(f"suite {suite.name!r}: case {case.name!r} has other signals than {first.name!r}")
        save_case(case, folder / f"{case.name}.{fmt}")
    lines = [f"name = {_toml_str(suite.name)}",
             "inputs = [" + ", ".join(_toml_str(s) for s in first.input_names) + "]",
             "outputs = [" + ", ".join(_toml_str(s) for s in first.output_names) + "]",
             "extras = [" + ", ".join(_toml_str(s) for s in first.extras) + "]",
             "", "[groups]"]  # fmt: skip
    lines += [f"{_toml_str(case.name + '.' + fmt)} = {_toml_str(case.group)}" for case in suite]
    atomic_write(folder / "suite.toml", "\n".join(lines) + "\n")
    return folder
