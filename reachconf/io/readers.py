"""Strict readers of test-case files: CSV and NPZ columns, ``suite.toml``.

What they accept, and nothing else (every other input is a
:class:`~reachconf.errors.DataError` naming the file, and the row and column
where there is one):

* CSV: UTF-8 (a byte-order mark, as Excel's "CSV UTF-8" writes, is
  accepted), a header row of unique non-empty names, then one row per sample
  of plain decimal numbers (``-1.5``, ``2e-3``; ``nan``/``inf`` are read and
  rejected later with their row).  Python's digit separators (``1_0``) and
  non-ASCII digits are not numbers.  Blank lines are skipped; row numbers in
  messages are the file's line numbers, blank lines included.
* NPZ: a zip of ``.npy`` arrays, each 1-D with an integer or real dtype
  (complex, boolean, string and object arrays are errors, not warnings), no
  pickles; a truncated or foreign file (not a zip, a zip of other files) is a
  DataError, and no array is allocated beyond the size the file holds.
* ``suite.toml``: UTF-8 TOML with the documented keys and value types.
"""

from __future__ import annotations

import csv
import tomllib
import zipfile
import zlib
from pathlib import Path

import numpy as np

from reachconf.errors import DataError

__all__ = ["read_csv_columns", "read_npz_columns", "read_suite_toml", "parse_decimal", "SUITE_KEYS"]

#: keys of ``suite.toml``
SUITE_KEYS = ("name", "description", "inputs", "outputs", "extras", "groups", "rename", "units")


def parse_decimal(cell: str) -> float:
    """A CSV cell as a float: plain ASCII decimal notation only (``ValueError`` otherwise).

    ``float()`` alone also takes ``"1_0"`` (10) and digits of other scripts;
    those are errors here.  ``nan``/``inf`` are returned (the caller rejects
    them with their row and column).
    """
    s = cell.strip()
    if not s.isascii() or "_" in s:
        raise ValueError(cell)
    return float(s)


def _cannot_read(path, exc) -> DataError:
    return DataError(f"{path}: cannot read the file: {exc.strerror or exc}")


def read_csv_columns(path: Path):
    """``(columns, rows)``: column name -> float array, and the file's line number of each sample."""
    records = []
    try:
        with open(path, newline="", encoding="utf-8-sig") as fh:
            reader = csv.reader(fh)
            try:
                for row in reader:
                    if row and not (len(row) == 1 and not row[0].strip()):
                        records.append((reader.line_num, row))
            except csv.Error as exc:
                raise DataError(f"{path}: row {reader.line_num}: not a CSV row ({exc})") from None
    except UnicodeDecodeError as exc:
        raise DataError(f"{path}: not a UTF-8 text CSV file ({exc.reason} at byte {exc.start})") from None
    except OSError as exc:
        raise _cannot_read(path, exc) from None
    if not records:
        raise DataError(f"{path}: file is empty")
    head_line, head = records[0]
    header = [h.strip() for h in head]
    if any(not h for h in header):
        raise DataError(f"{path}: row {head_line}: empty column name in the header")
    dup = {h for h in header if header.count(h) > 1}
    if dup:
        raise DataError(f"{path}: row {head_line}: duplicate columns {sorted(dup)}")
    data = np.empty((len(records) - 1, len(header)))
    rows = np.empty(len(records) - 1, dtype=np.int64)
    for i, (line, row) in enumerate(records[1:]):
        if len(row) != len(header):
            raise DataError(f"{path}: row {line}: {len(row)} cells, the header has {len(header)}")
        rows[i] = line
        for c, cell in enumerate(row):
            try:
                data[i, c] = parse_decimal(cell)
            except ValueError:
                raise DataError(f"{path}: row {line}, column {header[c]!r}: not a number: {cell!r}") from None
    return {h: data[:, i] for i, h in enumerate(header)}, rows


def _npy_header(fh):
    version = np.lib.format.read_magic(fh)
    if version == (1, 0):
        return np.lib.format.read_array_header_1_0(fh)
    if version == (2, 0):
        return np.lib.format.read_array_header_2_0(fh)
    raise ValueError(f"unsupported .npy format version {version}")


def read_npz_columns(path: Path) -> dict:
    """Column name -> float array of an ``.npz`` file (see the module docstring for what is accepted)."""
    try:
        zf = zipfile.ZipFile(path)
    except (zipfile.BadZipFile, EOFError, ValueError, NotImplementedError) as exc:  # (a corrupt version field)
        raise DataError(f"{path}: not a readable .npz file (truncated or not a zip archive: {exc})") from None
    except OSError as exc:
        raise _cannot_read(path, exc) from None
    cols = {}
    with zf:
        for info in zf.infolist():
            name = info.filename
            if info.is_dir():
                continue
            if not name.endswith(".npy"):
                raise DataError(f"{path}: member {name!r} is not a .npy array: not a test-case .npz file")
            key = name[:-4]
            if key in cols:
                raise DataError(f"{path}: array {key!r} appears twice")
            try:
                with zf.open(info) as fh:
                    shape, _, dtype = _npy_header(fh)
                if dtype.hasobject or dtype.kind not in "iuf":
                    kind = "complex" if dtype.kind == "c" else str(dtype)
                    raise DataError(f"{path}: array {key!r} has dtype {kind}; test-case arrays hold real numbers only")
                if len(shape) != 1:
                    raise DataError(f"{path}: array {key!r} must be 1-D, got shape {shape}")
                if shape[0] * dtype.itemsize > info.file_size:
                    raise DataError(f"{path}: array {key!r} is truncated ({shape[0]} values declared, "
                                    f"{info.file_size} bytes stored)")  # fmt: skip
                with zf.open(info) as fh:
                    arr = np.lib.format.read_array(fh, allow_pickle=False)
            except DataError:
                raise
            except (ValueError, OSError, EOFError, zipfile.BadZipFile, zlib.error, NotImplementedError,
                    RuntimeError) as exc:  # RuntimeError: zipfile's "encrypted, password required" (a flipped flag bit)
                raise DataError(f"{path}: array {key!r} cannot be read (truncated or corrupt: {exc})") from None
            cols[key] = np.asarray(arr, dtype=float)
    if not cols:
        raise DataError(f"{path}: file is empty (no arrays)")
    sizes = {v.size for v in cols.values()}
    if len(sizes) > 1:
        raise DataError(f"{path}: arrays have different lengths {sorted(sizes)}")
    return cols


def _string_table(cfg, key, path):
    table = cfg.get(key, {})
    if not isinstance(table, dict):
        raise DataError(f"{path}: [{key}] must be a table")
    for k, v in table.items():
        if not isinstance(v, str):
            raise DataError(f"{path}: [{key}] {k} must be a string, got {v!r}")
    return table


def read_suite_toml(folder: Path) -> dict:
    """The checked ``suite.toml`` of ``folder`` ({} if there is none)."""
    path = folder / "suite.toml"
    if not path.exists():
        return {}
    try:
        cfg = tomllib.loads(path.read_text(encoding="utf-8-sig"))
    except tomllib.TOMLDecodeError as exc:
        raise DataError(f"{path}: invalid TOML: {exc}") from None
    except UnicodeDecodeError as exc:
        raise DataError(f"{path}: not UTF-8 text ({exc.reason} at byte {exc.start})") from None
    except OSError as exc:
        raise _cannot_read(path, exc) from None
    unknown = set(cfg) - set(SUITE_KEYS)
    if unknown:
        raise DataError(f"{path}: unknown keys {sorted(unknown)}; allowed: {sorted(SUITE_KEYS)}")
    for key in ("name", "description"):
        if key in cfg and not isinstance(cfg[key], str):
            raise DataError(f"{path}: {key} must be a string, got {cfg[key]!r}")
    for key in ("groups", "rename", "units"):
        _string_table(cfg, key, path)
    listed = []
    for key in ("inputs", "outputs", "extras"):
        if key in cfg and not (isinstance(cfg[key], list) and all(isinstance(s, str) for s in cfg[key])):
            raise DataError(f"{path}: {key} must be a list of column names")
        listed += cfg.get(key, [])
    dup = sorted({s for s in listed if listed.count(s) > 1})
    if dup:
        raise DataError(f"{path}: columns {dup} are listed twice in inputs/outputs/extras")
    targets = list(cfg.get("rename", {}).values())
    dup = sorted({s for s in targets if targets.count(s) > 1})
    if dup:
        raise DataError(f"{path}: [rename] renames several columns to {dup}")
    return cfg

