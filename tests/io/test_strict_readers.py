"""Strict readers (issue 19): what a test-suite file may hold, and the DataError for everything else.

Each test names the item of issue 19's "Why" list it covers; each failed
(misread the file, or raised another exception type) before the fix.
"""

import io
import pickle
import warnings
import zipfile

import numpy as np
import pytest

import reachconf as rc
from reachconf.io import TestCase, load_case, load_suite


def write(path, text, encoding="utf-8"):
    path.write_text(text, encoding=encoding)
    return path


# ---------------------------------------------------------------- Why 2: a rename onto an existing column


def test_rename_onto_an_existing_column_is_an_error(tmp_path):
    write(tmp_path / "a.csv", "t,X_gps,X\n0,1,10\n1,2,20\n")
    write(tmp_path / "suite.toml", '[rename]\nX_gps = "X"\n')
    with pytest.raises(rc.DataError, match=r"a.csv: rename 'X_gps' -> 'X' collides with the column 'X'"):
        load_suite(tmp_path)


def test_renames_of_two_columns_onto_one_name_are_an_error(tmp_path):
    write(tmp_path / "a.csv", "t,a,b\n0,1,10\n1,2,20\n")
    write(tmp_path / "suite.toml", '[rename]\na = "y"\nb = "y"\n')
    with pytest.raises(rc.DataError, match=r"suite.toml: \[rename\] renames several columns to \['y'\]"):
        load_suite(tmp_path)
    with pytest.raises(rc.DataError, match=r"a.csv: rename .* collides"):
        load_case(tmp_path / "a.csv", rename={"a": "y", "b": "y"})


def test_a_rename_that_swaps_names_is_fine(tmp_path):
    write(tmp_path / "a.csv", "t,a,b\n0,1,10\n1,2,20\n")
    case = load_case(tmp_path / "a.csv", rename={"a": "b", "b": "a"}, outputs=["a", "b"])
    np.testing.assert_array_equal(case.Y, [[10, 1], [20, 2]])


# ---------------------------------------------------------------- Why 5: truncated / foreign NPZ


def _npz_bytes(**arrays):
    buf = io.BytesIO()
    np.savez(buf, **arrays)
    return buf.getvalue()


@pytest.mark.parametrize("cut", [10, 100, -30, -5])
def test_truncated_npz_is_a_data_error(tmp_path, cut):
    data = _npz_bytes(t=np.arange(50.0), y=np.ones(50))
    (tmp_path / "a.npz").write_bytes(data[:cut])
    with pytest.raises(rc.DataError, match=r"a.npz: "):
        load_suite(tmp_path)


def test_foreign_npz_files_are_data_errors(tmp_path):
    cases = {
        "text.npz": b"t,y\n0,1\n1,2\n",
        "pickle.npz": pickle.dumps({"t": [0, 1]}),
        "npy.npz": _npy(np.arange(3.0)),
    }
    zipped = io.BytesIO()
    with zipfile.ZipFile(zipped, "w") as zf:
        zf.writestr("readme.txt", "hello")
    cases["zip.npz"] = zipped.getvalue()
    for name, data in cases.items():
        (tmp_path / name).write_bytes(data)
        with pytest.raises(rc.DataError, match=name):
            load_case(tmp_path / name)


def _npy(arr):
    buf = io.BytesIO()
    np.save(buf, arr)
    return buf.getvalue()


# ---------------------------------------------------------------- Why 6: silent misreads


@pytest.mark.parametrize("cell", ["1_0", "١٢", "１", "0x10", "1,0"])
def test_only_plain_decimal_numbers(tmp_path, cell):
    write(tmp_path / "a.csv", f't,y\n0,1\n1,"{cell}"\n')
    with pytest.raises(rc.DataError, match=r"a.csv: row 3, column 'y': not a number"):
        load_case(tmp_path / "a.csv")


def test_decimal_forms_that_are_numbers(tmp_path):
    write(tmp_path / "a.csv", "t,y\n0, 1.5 \n1,-2e-3\n2,+.5\n3,7.\n")
    np.testing.assert_array_equal(load_case(tmp_path / "a.csv").Y[:, 0], [1.5, -2e-3, 0.5, 7.0])


@pytest.mark.parametrize("dtype", [complex, object, bool, "U3"])
def test_npz_with_non_real_data_is_an_error(tmp_path, dtype):
    y = np.array([1, 2, 3]).astype(dtype) if dtype is not object else np.array([1.0, "a", None], dtype=object)
    buf = io.BytesIO()
    np.savez(buf, t=np.arange(3.0), y=y, allow_pickle=dtype is object)
    (tmp_path / "a.npz").write_bytes(buf.getvalue())
    with warnings.catch_warnings():  # complex values used to lose their imaginary part with only a warning
        warnings.simplefilter("error")
        with pytest.raises(rc.DataError, match=r"a.npz: array 'y' .*(dtype|cannot be read)"):
            load_case(tmp_path / "a.npz")


def test_complex_arrays_through_the_api_are_an_error():
    t = np.arange(3.0)
    with pytest.raises(rc.DataError, match=r"test case 'c': Y must hold real numbers, got complex"):
        TestCase("c", "g", t, np.zeros((3, 0)), (t + 1j)[:, None], (), ("y",))


def test_row_numbers_count_blank_lines(tmp_path):
    write(tmp_path / "a.csv", "t,y\n0,1\n\n\n1,2\n\n2,oops\n")
    with pytest.raises(rc.DataError, match=r"a.csv: row 7, column 'y': not a number: 'oops'"):
        load_case(tmp_path / "a.csv")
    write(tmp_path / "a.csv", "t,y\n0,1\n\n1,nan\n")
    with pytest.raises(rc.DataError, match=r"a.csv: row 4, column 'y'.*NaN"):
        load_case(tmp_path / "a.csv")
    write(tmp_path / "a.csv", "t,y\n0,1\n\n0,2\n")
    with pytest.raises(rc.DataError, match=r"a.csv: row 4, column 't'.*not strictly increasing"):
        load_case(tmp_path / "a.csv")


def test_utf8_byte_order_mark_is_accepted(tmp_path):
    write(tmp_path / "a.csv", "\ufefft,y\n0,1\n1,2\n")
    case = load_case(tmp_path / "a.csv")
    assert case.output_names == ("y",)
    np.testing.assert_array_equal(case.t, [0, 1])
    write(tmp_path / "suite.toml", '\ufeffoutputs = ["y"]\n')
    assert load_suite(tmp_path)[0].output_names == ("y",)


# ---------------------------------------------------------------- Why 5: API arguments


@pytest.mark.parametrize("bad", [None, 5, ""])
def test_load_suite_needs_a_path(bad):
    with pytest.raises(rc.DataError, match=r"load_suite: path must be a path"):
        load_suite(bad)
    with pytest.raises(rc.DataError, match=r"load_case: path must be a path"):
        load_case(bad)


def test_suite_toml_value_types(tmp_path):
    write(tmp_path / "a.csv", "t,y\n0,1\n1,2\n")
    for text, message in [
        ('name = 5\n', r"name must be a string"),
        ('[groups]\n"a.csv" = 3\n', r"\[groups\] a.csv must be a string"),
        ('[units]\ny = ["deg"]\n', r"\[units\] y must be a string"),
        ('outputs = ["y", "y"]\n', r"listed twice"),
        ("rename = 3\n", r"\[rename\] must be a table"),
    ]:
        write(tmp_path / "suite.toml", text)
        with pytest.raises(rc.DataError, match=message):
            load_suite(tmp_path)
    (tmp_path / "suite.toml").write_bytes(b'name = "\xff\xfe"\n')
    with pytest.raises(rc.DataError, match=r"suite.toml: not UTF-8"):
        load_suite(tmp_path)
