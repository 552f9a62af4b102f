"""Fuzzed test-suite files through the loaders (issue 19): CSV, NPZ, suite.toml.

Property: a file either loads — and then holds exactly the numbers written —
or raises :class:`reachconf.DataError` whose message names the file; never
another exception type and never a warning.  The CSV test compares with an
independent oracle of what is valid (plain decimal numbers, a header of
unique names with ``t``, finite values, strictly increasing time).
"""

import contextlib
import io
import math
import os
import re
import tempfile
import warnings
from pathlib import Path

import numpy as np
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

from conftest import toml_text
from reachconf.errors import DataError
from reachconf.io import load_case, load_suite

#: examples per fuzz test; REACHCONF_FUZZ_EXAMPLES=5000 for a long run
FUZZ = settings(max_examples=int(os.environ.get("REACHCONF_FUZZ_EXAMPLES", 120)), deadline=None, suppress_health_check=[HealthCheck.too_slow])

def load_or_error(load, path):
    """``(result, None)``, or ``(None, error)`` for a DataError naming ``path``; anything else (another
    exception type, a warning such as numpy's ComplexWarning) fails the test."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        try:
            return load(path), None
        except DataError as exc:
            assert str(path) in str(exc)
            return None, exc


# ---------------------------------------------------------------- CSV

_DECIMAL = re.compile(r"[+-]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?|[+-]?(nan|inf|infinity)", re.IGNORECASE | re.ASCII)


def oracle_number(cell: str):
    """The value a strict reader must give ``cell``, or None if it is not a plain decimal number."""
    s = cell.strip()
    return float(s) if _DECIMAL.fullmatch(s) else None


numbers = st.one_of(
    st.floats(allow_nan=False, allow_infinity=False, width=64).map(repr),
    st.integers(-(10**6), 10**6).map(str),
    st.floats(-1e6, 1e6).map(lambda x: f"{x:.3e}"),
)
odd_cells = st.sampled_from(["1_0", "", " ", "nan", "inf", "-Infinity", "1e", "0x1", "١٢", "１", "1.2.3", "True",
                             "1 0", " 7 ", "+.5", "5.", "\u00a03", "-", "1e400"])  # fmt: skip
cell_text = st.text(alphabet="0123456789.eE+-_ naif\u0661\u00a0", max_size=6)
cells = st.one_of(numbers, numbers, numbers, odd_cells, cell_text)
names = st.sampled_from(["t", "t", "y", "u", "z", "", " y", "é"])


@st.composite
def csv_files(draw):
    """A valid file (unique names with ``t``, numbers, increasing time), then 0-3 random faults."""
    header = ["t"] + draw(st.lists(st.sampled_from(["y", "u", "z"]), max_size=3, unique=True))
    header = draw(st.permutations(header))
    n_rows = draw(st.integers(2, 6))
    times = np.cumsum(draw(st.lists(st.sampled_from([0.1, 0.25, 1.0, 3.0]), min_size=n_rows, max_size=n_rows)))
    rows = [[repr(float(t)) if h == "t" else draw(numbers) for h in header] for t in times]
    for _ in range(draw(st.sampled_from([0, 0, 0, 1, 1, 2, 3]))):
        if not rows:
            break
        fault = draw(st.sampled_from(["cell", "cell", "cell", "name", "width", "time", "rows"]))
        r = draw(st.integers(0, len(rows) - 1))
        if fault == "cell" and rows[r]:
            rows[r][draw(st.integers(0, len(rows[r]) - 1))] = draw(st.one_of(odd_cells, cell_text))
        elif fault == "name":
            header[draw(st.integers(0, len(header) - 1))] = draw(names)
        elif fault == "width":
            rows[r] = rows[r][:-1] if draw(st.booleans()) else rows[r] + [draw(numbers)]
        elif fault == "time" and "t" in header and header.index("t") < len(rows[r]):
            i = header.index("t")  # (row 0 may have lost its time cell to an earlier "width" fault)
            rows[r][i] = draw(st.sampled_from(["0", "-1"] + ([rows[0][i]] if i < len(rows[0]) else [])))
        elif fault == "rows":
            rows = rows[: draw(st.integers(0, 1))]
    blank = draw(st.lists(st.integers(0, len(rows) + 1), max_size=3))
    return header, rows, blank, draw(st.booleans()), draw(st.sampled_from(["\n", "\r\n"]))


def expected_columns(header, rows):
    """Oracle: the columns a strict reader returns, or None if it must reject the file."""
    names_ = [h.strip() for h in header]
    rows = [r for r in rows if r and not (len(r) == 1 and not r[0].strip())]  # a blank line, skipped
    if not rows or any(not h for h in names_) or len(set(names_)) != len(names_) or "t" not in names_:
        return None
    values = []
    for row in rows:
        if len(row) != len(header):
            return None
        vals = [oracle_number(c) for c in row]
        if any(v is None or not math.isfinite(v) for v in vals):
            return None
        values.append(vals)
    cols = {h: np.array([v[i] for v in values]) for i, h in enumerate(names_)}
    if cols["t"].size < 2 or np.any(np.diff(cols["t"]) <= 0):
        return None
    return cols


@FUZZ
@given(csv_files())
def test_fuzzed_csv_loads_exactly_or_raises_a_data_error_naming_the_file(spec):
    header, rows, blank, bom, newline = spec
    lines = [",".join(header)] + [",".join(r) for r in rows]
    for b in sorted(blank, reverse=True):
        lines.insert(min(b + 1, len(lines)), "")
    text = ("\ufeff" if bom else "") + newline.join(lines) + newline
    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / "case.csv"
        path.write_bytes(text.encode("utf-8"))
        expected = expected_columns(header, rows)
        case, error = load_or_error(load_case, path)
        if error is not None:
            assert expected is None, f"rejected a valid file: {error}"
            event("rejected")
            return
        event("loaded")
        assert expected is not None, f"accepted an invalid file:\n{text}"
        np.testing.assert_array_equal(case.t, expected["t"])
        for name in case.output_names:
            np.testing.assert_array_equal(case.signal(name), expected[name])


@FUZZ
@given(st.binary(max_size=300), st.sampled_from(["case.csv", "case.npz"]))
def test_arbitrary_bytes_raise_a_data_error_naming_the_file(data, name):
    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / name
        path.write_bytes(data)
        load_or_error(load_case, path)


# ---------------------------------------------------------------- NPZ

dtypes = st.sampled_from(["float64", "float32", "int64", "int8", "uint16", "complex128", "bool", "U3", "S2"])


@st.composite
def npz_files(draw):
    """A valid file (1-D real arrays of one length, increasing ``t``), then 0-2 faults of content or bytes."""
    n = draw(st.integers(2, 5))
    arrays = {"t": np.cumsum(draw(st.lists(st.sampled_from([0.1, 0.5, 2.0]), min_size=n, max_size=n)))}
    for name in draw(st.lists(st.sampled_from(["y", "u"]), max_size=2, unique=True)):
        arrays[name] = np.array(draw(st.lists(st.floats(-1e9, 1e9), min_size=n, max_size=n)))
        arrays[name] = arrays[name].astype(draw(st.sampled_from(["float64", "float64", "float32", "int64", "int8"])))
    for _ in range(draw(st.sampled_from([0, 0, 1, 2]))):
        if not arrays:
            break
        name = draw(st.sampled_from(sorted(arrays)))
        fault = draw(st.sampled_from(["dtype", "shape", "length", "nan", "drop"]))
        with warnings.catch_warnings(), contextlib.suppress(ValueError, TypeError):  # a fault that cannot be made
            warnings.simplefilter("ignore")
            if fault == "dtype":
                arrays[name] = arrays[name].astype(draw(dtypes))
            elif fault == "shape":
                arrays[name] = arrays[name].reshape(-1, 1)
            elif fault == "length":
                arrays[name] = arrays[name][:-1]
            elif fault == "nan":
                arrays[name] = np.where(np.arange(arrays[name].size) == 0, np.nan, arrays[name])
            else:
                del arrays[name]
    buf = io.BytesIO()
    np.savez(buf, **arrays)
    data = buf.getvalue()
    mutation = draw(st.sampled_from(["none", "none", "none", "truncate", "flip", "junk"]))
    if mutation == "truncate":
        data = data[: draw(st.integers(0, len(data) - 1))]
    elif mutation == "flip":
        i = draw(st.integers(0, len(data) - 1))
        data = data[:i] + bytes([data[i] ^ draw(st.integers(1, 255))]) + data[i + 1 :]
    elif mutation == "junk":
        data = draw(st.binary(min_size=1, max_size=20)) + data
    return arrays, mutation, data


@FUZZ
@given(npz_files())
def test_fuzzed_npz_loads_exactly_or_raises_a_data_error_naming_the_file(spec):
    arrays, mutation, data = spec
    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / "case.npz"
        path.write_bytes(data)
        case, error = load_or_error(load_case, path)  # no ComplexWarning: complex data is an error
        if error is not None:
            event("npz rejected " + mutation)
            return
        event("npz loaded " + mutation)
        if mutation == "none":  # a flipped byte may hit a time stamp or a zip field that is not checked
            assert all(a.dtype.kind in "iuf" and a.ndim == 1 for a in arrays.values()), arrays
            np.testing.assert_array_equal(case.t, arrays["t"].astype(float))
            for name in case.output_names:
                np.testing.assert_array_equal(case.signal(name), arrays[name].astype(float))


# ---------------------------------------------------------------- suite.toml


scalars = st.one_of(st.text(max_size=8), st.integers(-5, 5), st.floats(allow_nan=True), st.booleans())
values = st.recursive(scalars, lambda inner: st.one_of(st.lists(inner, max_size=3),
                                                       st.dictionaries(st.sampled_from(["a.csv", "a", "t", "y", "u",
                                                                                        "x"]), inner, max_size=3)),
                      max_leaves=6)  # fmt: skip
column_lists = st.lists(st.sampled_from(["t", "y", "u", "v", "y2"]), max_size=3)
cols = st.sampled_from(["t", "y", "u", "y2", "v"])
right_types = {
    "name": st.text(max_size=8),
    "description": st.text(max_size=8),
    "inputs": st.lists(cols, max_size=2),
    "outputs": st.lists(cols, max_size=2),
    "extras": st.lists(cols, max_size=2),
    "groups": st.dictionaries(st.sampled_from(["a.csv", "a", "b.csv"]), st.text(max_size=4), max_size=2),
    "rename": st.dictionaries(cols, cols, max_size=2),
    "units": st.dictionaries(cols, st.sampled_from(["deg", "km/h", "rad", "furlong", " G "]), max_size=2),
}


@st.composite
def suite_docs(draw):
    """Keys of suite.toml with values of the right type, then 0-2 of them given any value or an unknown key."""
    doc = {k: draw(right_types[k]) for k in draw(st.lists(st.sampled_from(sorted(right_types)), max_size=4))}
    for _ in range(draw(st.sampled_from([0, 0, 1, 2]))):
        doc[draw(st.sampled_from([*right_types, "colour"]))] = draw(values)
    return doc


@FUZZ
@given(suite_docs())
def test_fuzzed_suite_toml_loads_or_raises_a_data_error_naming_the_folder(doc):
    with tempfile.TemporaryDirectory() as d:
        folder = Path(d)
        (folder / "a.csv").write_text("t,y,u,y2\n0,1,2,3\n0.5,1.5,2.5,3.5\n1,2,3,4\n")
        (folder / "suite.toml").write_text(toml_text(doc), encoding="utf-8")
        suite, error = load_or_error(load_suite, folder)
        if error is not None:
            event("toml rejected")
            return
        event("toml loaded")
        case = suite[0]
        assert case.t.size == 3 and np.all(np.isfinite(case.Y))
        assert isinstance(suite.name, str) and isinstance(case.group, str)


def test_npz_whose_central_directory_names_an_unsupported_zip_version_is_a_data_error(tmp_path):
    """Found by the fuzz test above (a flipped byte): zipfile raises NotImplementedError("zip file version 10.9")
    while opening such an archive; it must be a DataError naming the file."""
    path = tmp_path / "case.npz"
    np.savez(path, t=np.array([0.1, 0.2, 0.3]), y=np.zeros(3))
    raw = bytearray(path.read_bytes())
    cd = raw.rfind(b"PK\x01\x02")  # a central directory entry: signature, version made by (2), version needed (2)
    raw[cd + 6 : cd + 8] = (109).to_bytes(2, "little")  # "version needed to extract" 10.9
    path.write_bytes(bytes(raw))
    case, error = load_or_error(load_case, path)
    assert case is None and "not a readable .npz file" in str(error)


def test_npz_member_flagged_encrypted_is_a_data_error(tmp_path):
    """Found by the fuzzer (27 Nov): a flipped 'encrypted' flag bit made zipfile raise RuntimeError past the reader."""
    from reachconf.io.readers import read_npz_columns

    path = tmp_path / "case.npz"
    np.savez(path, t=np.arange(4.0), y=np.zeros(4))
    data = bytearray(path.read_bytes())
    for sig, offset in ((b"PK\x03\x04", 6), (b"PK\x01\x02", 8)):  # general-purpose flags of local and central headers
        at = data.find(sig)
        while at >= 0:
            data[at + offset] |= 1
            at = data.find(sig, at + 4)
    path.write_bytes(bytes(data))
    try:
        read_npz_columns(path)
    except DataError as exc:
        assert "case.npz: array 't' cannot be read" in str(exc), exc
    else:
        raise AssertionError("an encrypted member was read")
