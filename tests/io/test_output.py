"""The one writer of output files (issue 19): unique temporary names, messages naming the user's path,
locks against a second run into the same output, partial results in new files, strict JSON."""

import json
import os
import tempfile
import threading

import numpy as np
import pytest

from reachconf.errors import OutputError
from reachconf.io import OutputLock, RunOutputs, atomic_write, json_text, write_new
from reachconf.io.output import LOCK_NAME, check_output_file, check_output_folder


def _deny_writes(monkeypatch):
    """What an unwritable folder does (the tests run as root, where chmod does not stop writes)."""
    def mkstemp(suffix=None, prefix=None, dir=None, text=False):
        name = os.path.join(dir or ".", f"{prefix or 'tmp'}b5jlj0z3")
        raise PermissionError(13, "Permission denied", name)

    monkeypatch.setattr(tempfile, "mkstemp", mkstemp)


def test_unwritable_folder_error_names_the_users_path(tmp_path, monkeypatch):
    """Why 1: the message named the temporary file ``.synthesis.json.b5jlj0z3``."""
    _deny_writes(monkeypatch)
    target = tmp_path / "out" / "synthesis.json"
    with pytest.raises(OutputError) as err:
        atomic_write(target, "{}")
    assert str(err.value).startswith(f"{target}: ") and "Permission denied" in str(err.value)
    assert "b5jlj0z3" not in str(err.value)
    for check in (lambda: check_output_folder(tmp_path / "o"), lambda: check_output_file(tmp_path / "r.json")):
        with pytest.raises(OutputError, match="Permission denied") as err:
            check()
        assert "b5jlj0z3" not in str(err.value)


def test_output_paths_of_the_wrong_kind(tmp_path):
    (tmp_path / "file").write_text("x")
    with pytest.raises(OutputError, match=r"file: --out must be a folder, but it is a file"):
        check_output_folder(tmp_path / "file")
    with pytest.raises(OutputError, match=r"file/sub: --out: cannot create the folder"):
        check_output_folder(tmp_path / "file" / "sub")
    with pytest.raises(OutputError, match=r"--json must be a file name, but it is a folder"):
        check_output_file(tmp_path)
    with pytest.raises(OutputError, match=r"r.json: --json: .*file is a file, not a folder"):
        check_output_file(tmp_path / "file" / "r.json")
    with pytest.raises(OutputError, match="is a folder"):
        atomic_write(tmp_path, "x")


def test_concurrent_writes_to_one_file_never_mix_or_fail(tmp_path):
    """Why 4: runs used one shared temporary name (``.synthesis.png.tmp.png``) and failed on each other."""
    target = tmp_path / "synthesis.png"
    payloads = [bytes([i]) * 200_000 for i in range(8)]
    errors = []

    def writer(data):
        try:
            for _ in range(5):
                atomic_write(target, data)
        except Exception as exc:  # noqa: BLE001 - any failure is the finding
            errors.append(exc)

    threads = [threading.Thread(target=writer, args=(p,)) for p in payloads]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert errors == []
    assert target.read_bytes() in payloads  # one writer's whole content
    assert [p.name for p in tmp_path.iterdir()] == ["synthesis.png"]  # no temporary file left


def test_a_second_run_into_a_locked_folder_fails_clearly(tmp_path):
    out = tmp_path / "out"
    with RunOutputs("synth", folder=out, json=tmp_path / "r.json"):
        assert (out / LOCK_NAME).exists()
        with pytest.raises(OutputError, match=r"out: another reachconf run is writing this folder \(pid \d+"):
            RunOutputs("synth", folder=out).open()
        with pytest.raises(OutputError, match=r"r.json: another reachconf run is writing this file"):
            RunOutputs("conform", json=tmp_path / "r.json").open()
        RunOutputs("conform", json=tmp_path / "other.json").open().close()  # another file is fine
    assert not (out / LOCK_NAME).exists() and not (tmp_path / ".r.json.lock").exists()
    with OutputLock(out):  # released: the next run gets it
        pass


def test_lock_taken_by_many_threads_at_once_is_held_by_one(tmp_path):
    holders, barrier = [], threading.Barrier(6)

    def take():
        barrier.wait()
        try:
            lock = OutputLock(tmp_path).acquire()
        except OutputError:
            return
        holders.append(lock)

    threads = [threading.Thread(target=take) for _ in range(6)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert len(holders) == 1
    holders[0].release()


def test_partial_results_never_replace_a_file(tmp_path):
    """Why 7: an earlier complete result was replaced by an empty partial one."""
    done = tmp_path / "r.json"
    done.write_text('{"complete": true}')
    outputs = RunOutputs("synth", json=done)
    first = outputs.save_partial({"partial": [1]})
    second = outputs.save_partial({"partial": [2]})
    assert first.name == "r.partial.json" and second.name == "r.partial-2.json"
    assert json.loads(done.read_text()) == {"complete": True}
    assert json.loads(first.read_text()) == {"partial": [1]}
    with pytest.raises(FileExistsError):
        atomic_write(first, "x", overwrite=False)
    assert write_new(tmp_path / "new.json", "1").name == "new.json"
    assert RunOutputs("synth", folder=tmp_path / "o").partial_target() == tmp_path / "o" / "synth.partial.json"
    assert RunOutputs("synth").save_partial({"x": 1}) is None


def test_json_has_no_non_finite_numbers():
    """Why 3: ``Infinity`` in the JSON, which strict parsers reject."""
    obj = {"a": float("inf"), "b": np.float64("nan"), "c": [np.inf, -np.inf, 1.5], "d": np.array([1.0, np.nan]),
           "e": np.int64(3), "f": np.bool_(True), 2.5: "key"}  # fmt: skip
    text = json_text(obj)
    back = json.loads(text, parse_constant=lambda c: pytest.fail(f"non-JSON constant {c}"))
    assert back == {"a": None, "b": None, "c": [None, None, 1.5], "d": [1.0, None], "e": 3, "f": True, "2.5": "key"}


def test_streams_are_written_not_replaced(tmp_path):
    link = tmp_path / "link.json"
    real = tmp_path / "real.json"
    real.write_text("old")
    link.symlink_to(real)
    atomic_write(link, "new")
    assert link.is_symlink() and real.read_text() == "new"
