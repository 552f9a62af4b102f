"""Test-suite files: round trips, suite.toml, and every DataError (API and CLI)."""

import subprocess
import sys

import numpy as np
import pytest

import reachconf as rc
from reachconf.io import TestCase, TestSuite, load_case, load_suite, save_suite

T = np.round(np.arange(0, 1.0 + 1e-9, 0.1), 10)


def make_case(name="c1", group="g"):
    U = np.column_stack([np.sin(T)])
    Y = np.column_stack([T, T**2])
    return TestCase(name, group, T, U, Y, ("u",), ("y1", "y2"), {"u_req": np.cos(T)})


def write(path, text):
    path.write_text(text)
    return path


def test_round_trip_csv_and_npz(tmp_path):
    suite = TestSuite([make_case("a", "lc"), make_case("b", "dlc")], name="s")
    for fmt in ("csv", "npz"):
        folder = save_suite(suite, tmp_path / fmt, fmt=fmt)
        back = load_suite(folder)
        assert [c.name for c in back] == ["a", "b"]
        assert list(back.groups()) == ["lc", "dlc"]
        for c0, c1 in zip(suite, back):
            assert c1.input_names == ("u",) and c1.output_names == ("y1", "y2")
            np.testing.assert_array_equal(c0.t, c1.t)
            np.testing.assert_array_equal(c0.U, c1.U)
            np.testing.assert_array_equal(c0.Y, c1.Y)
            np.testing.assert_array_equal(c0.extras["u_req"], c1.extras["u_req"])


def test_npz_case_with_a_signal_named_file(tmp_path):
    """np.savez takes its archive as ``file``: a signal of that name raised TypeError; it is saved and read back."""
    case = TestCase("c", "g", T, np.column_stack([np.sin(T)]), np.column_stack([T]), ("file",), ("y",))
    back = load_suite(save_suite(TestSuite([case]), tmp_path / "s", fmt="npz"))
    assert back[0].input_names == ("file",)
    np.testing.assert_array_equal(back[0].U[:, 0], np.sin(T))
    with np.load(tmp_path / "s" / "c.npz") as z:  # a plain numpy archive
        assert sorted(z.files) == ["file", "t", "y"]


def test_save_suite_into_a_folder_holding_another_suite(tmp_path):
    """Another suite's case files would silently join the saved suite when loaded: refused, or replaced on request."""
    folder = save_suite(TestSuite([make_case("a", "lc"), make_case("b", "lc"), make_case("c", "dlc")], name="old"),
                        tmp_path / "s")  # fmt: skip
    (folder / "notes.txt").write_text("kept")
    new = TestSuite([make_case("a", "sl"), make_case("d", "sl")], name="new")
    with pytest.raises(rc.DataError, match=r"b\.csv, c\.csv.*replace=True"):
        save_suite(new, folder)
    assert sorted(c.name for c in load_suite(folder)) == ["a", "b", "c"]  # nothing was written or deleted
    assert [c.group for c in load_suite(folder)] == ["lc", "lc", "dlc"]
    save_suite(new, folder, replace=True)
    back = load_suite(folder)
    assert [c.name for c in back] == ["a", "d"] and [c.group for c in back] == ["sl", "sl"]
    assert back.name == "new" and (folder / "notes.txt").read_text() == "kept"
    save_suite(new, folder)  # the same suite again: nothing stale, no error
    assert [c.name for c in load_suite(folder)] == ["a", "d"]


def test_save_suite_onto_a_file_is_a_data_error(tmp_path):
    """Audit: a file at the folder's path (or above it) gave pathlib's FileExistsError / NotADirectoryError."""
    suite = TestSuite([make_case("a", "lc")], name="s")
    (tmp_path / "afile.txt").write_text("x")
    with pytest.raises(rc.DataError, match="afile.txt: is a file, not a folder"):
        save_suite(suite, tmp_path / "afile.txt")
    with pytest.raises(rc.DataError, match="cannot create the suite folder"):
        save_suite(suite, tmp_path / "afile.txt" / "sub")
    assert (tmp_path / "afile.txt").read_text() == "x"


def test_suite_toml_groups_rename_units(tmp_path):
    write(tmp_path / "run1.csv", "time,steer,y1,y2\n0,10,0,0\n0.1,20,1,1\n0.2,30,2,4\n")
    write(tmp_path / "suite.toml", 'inputs = ["u"]\noutputs = ["y1", "y2"]\n[groups]\n"run1.csv" = "slalom"\n'
          '[rename]\ntime = "t"\nsteer = "u"\n[units]\nu = "deg"\n')  # fmt: skip
    suite = load_suite(tmp_path)
    case = suite[0]
    assert case.group == "slalom"
    np.testing.assert_allclose(case.U[:, 0], np.radians([10, 20, 30]))
    assert suite.select(group="slalom")[0].name == "run1"
    seg = case.segment(0.05, 0.2)
    assert seg.t.size == 2


def test_model_columns(tmp_path):
    m = rc.Model(name="m", states=("x",), inputs=("u",), dynamics=lambda s: [s.u - s.x])
    write(tmp_path / "a.csv", "t,u,x\n0,1,0\n1,1,0.5\n")
    suite = load_suite(tmp_path, model=m)
    assert suite[0].input_names == ("u",) and suite[0].output_names == ("x",)
    write(tmp_path / "a.csv", "t,u,x,extra\n0,1,0,3\n1,1,0.5,3\n")
    with pytest.raises(rc.DataError, match=r"a.csv.*unknown columns \['extra'\]"):
        load_suite(tmp_path, model=m)
    write(tmp_path / "a.csv", "t,u\n0,1\n1,1\n")
    with pytest.raises(rc.DataError, match=r"a.csv.*missing columns \['x'\]"):
        load_suite(tmp_path, model=m)


BAD = [
    ("t,y\n0,1\n1,nan\n", r"bad.csv: row 3, column 'y'.*NaN"),
    ("t,y\n0,1\n1,inf\n", r"bad.csv: row 3, column 'y'.*NaN/inf"),
    ("t,y\n0,1\n0,2\n", r"bad.csv: row 3, column 't'.*not strictly increasing"),
    ("t,y\n0,1\n", r"bad.csv.*at least 2 samples"),
    ("t,y\n0,1\n1,abc\n", r"bad.csv: row 3, column 'y': not a number: 'abc'"),
    ("t,y\n0,1\n1\n", r"bad.csv: row 3: 1 cells, the header has 2"),
    ("", r"bad.csv: file is empty"),
    ("y\n1\n2\n", r"bad.csv: missing column 't'"),
    ("t,y,y\n0,1,1\n1,2,2\n", r"bad.csv: row 1: duplicate columns"),
]


@pytest.mark.parametrize("text, message", BAD)
def test_bad_files_name_file_row_column(tmp_path, text, message):
    write(tmp_path / "good.csv", "t,y\n0,1\n1,2\n")
    write(tmp_path / "bad.csv", text)
    with pytest.raises(rc.DataError, match=message):
        load_suite(tmp_path)


def test_wrong_units_and_bad_toml(tmp_path):
    write(tmp_path / "a.csv", "t,y\n0,1\n1,2\n")
    write(tmp_path / "suite.toml", '[units]\ny = "furlong"\n')
    with pytest.raises(rc.DataError, match="unknown unit 'furlong'"):
        load_suite(tmp_path)
    write(tmp_path / "suite.toml", "[units\n")
    with pytest.raises(rc.DataError, match="invalid TOML"):
        load_suite(tmp_path)
    write(tmp_path / "suite.toml", 'colour = "red"\n')
    with pytest.raises(rc.DataError, match="unknown keys"):
        load_suite(tmp_path)
    write(tmp_path / "suite.toml", '[groups]\n"missing.csv" = "x"\n')
    with pytest.raises(rc.DataError, match="files that do not exist"):
        load_suite(tmp_path)


def test_empty_and_missing_folders(tmp_path):
    with pytest.raises(rc.DataError, match="does not exist"):
        load_suite(tmp_path / "nope")
    with pytest.raises(rc.DataError, match="no .csv or .npz"):
        load_suite(tmp_path)
    with pytest.raises(rc.DataError, match="unsupported file type"):
        load_case(write(tmp_path / "x.txt", "t\n"))


def test_testcase_validation():
    with pytest.raises(rc.DataError, match="U must have shape"):
        TestCase("c", "g", T, np.zeros((T.size, 2)), np.zeros((T.size, 1)), ("u",), ("y",))
    with pytest.raises(rc.DataError, match="duplicate signal names"):
        TestCase("c", "g", T, np.zeros((T.size, 1)), np.zeros((T.size, 1)), ("y",), ("y",))
    with pytest.raises(rc.DataError, match="empty"):
        TestSuite([])
    case = make_case()
    swapped = case.select(("u_req",), ("y1",))
    np.testing.assert_array_equal(swapped.U[:, 0], np.cos(T))
    assert "u" in swapped.extras


def test_cli_reports_bad_data_in_one_line(tmp_path):
    write(tmp_path / "suite" / "bad.csv" if (tmp_path / "suite").mkdir() is None else None, "t,X\n0,1\n0,2\n")
    write(tmp_path / "run.toml", 'model = "vanderpol"\nsuite = "suite"\n[sets]\nV = [[-0.1, 0.1], [-0.1, 0.1]]\n')
    proc = subprocess.run([sys.executable, "-m", "reachconf.cli", "conform", str(tmp_path / "run.toml")],
                          capture_output=True, text=True, timeout=120)  # fmt: skip
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("reachconf: error:") and "bad.csv" in lines[0]
    assert "Traceback" not in proc.stderr


def test_with_requests_replaces_inputs_by_mapped_requests():
    t = np.linspace(0, 1, 6)
    sig = {"a": np.sin(t), "d": np.cos(t), "a_req": 2 * np.sin(t), "d_req": np.cos(t) / 3, "ref": t, "y": t**2}
    case = TestCase.from_signals("c", t, sig, ("a", "d"), ("y",), group="g")
    req = case.with_requests({"d": (3.0, 0.5)})
    np.testing.assert_array_equal(req.signal("a"), sig["a_req"])
    np.testing.assert_allclose(req.signal("d"), 3.0 * sig["d_req"] + 0.5)
    assert set(req.extras) == {"ref"} and req.input_names == ("a", "d") and req.group == "g"
    only = case.with_requests(inputs=["a"])
    np.testing.assert_array_equal(only.signal("d"), sig["d"])
    assert "d_req" in only.extras
    with pytest.raises(rc.DataError, match="no request signals"):
        only.with_requests(inputs=["a"])
