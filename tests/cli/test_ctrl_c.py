"""Ctrl-C on a real ``reachconf`` process (issue 19, Why 7): no traceback, earlier results kept, partial saved."""

import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from reachconf.demo import demo_run_file

pytestmark = pytest.mark.skipif(not Path("/proc/self/maps").exists() or os.name != "posix",
                                reason="needs POSIX signals and /proc")  # fmt: skip


def start(*args):
    env = dict(os.environ, PYTHONUNBUFFERED="1", REACHCONF_PROGRESS="0")
    return subprocess.Popen([sys.executable, "-m", "reachconf.cli", *map(str, args)], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, env=env)  # fmt: skip


def wait_until_loaded(proc, library, timeout=60):
    """Wait until the process has mapped a shared library whose path contains ``library``."""
    maps = Path(f"/proc/{proc.pid}/maps")
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline and proc.poll() is None:
        try:
            if library in maps.read_text():
                return
        except OSError:
            pass
        time.sleep(0.005)
    pytest.fail(f"the process did not load {library} in {timeout} s (exit status {proc.poll()})")


@pytest.fixture()
def run_file(tmp_path):
    shutil.copytree(demo_run_file().parent, tmp_path / "demo")
    return tmp_path / "demo" / "run.toml"


def test_ctrl_c_while_importing_gives_no_traceback(run_file, tmp_path):
    """Pressed in the first fraction of a second (numpy is being imported), it gave a KeyboardInterrupt traceback."""
    proc = start("conform", run_file, "--json", tmp_path / "c.json")
    wait_until_loaded(proc, "numpy")
    proc.send_signal(signal.SIGINT)
    out, err = proc.communicate(timeout=120)
    assert proc.returncode == 130, err
    assert "Traceback" not in err and err.strip().splitlines()[-1].startswith("reachconf: interrupted"), err
    assert not (tmp_path / "c.json").exists()


def test_ctrl_c_during_the_work_keeps_the_earlier_result_and_saves_the_finished_cases(run_file, tmp_path):
    earlier = tmp_path / "c.json"
    earlier.write_text('{"an earlier": "complete result"}')
    proc = start("conform", run_file, "--kind", "trace", "--json", earlier)
    first = proc.stdout.readline()  # the first case is done
    assert first.startswith("lane_change_01: trace: "), first + proc.stderr.read()
    proc.send_signal(signal.SIGINT)
    out, err = proc.communicate(timeout=120)
    if proc.returncode == 0:
        pytest.skip("the run finished before the signal arrived")
    assert proc.returncode == 130, err
    assert "Traceback" not in err, err
    partial = tmp_path / "c.partial.json"
    assert err.strip().splitlines()[-1] == f"reachconf: interrupted; partial results in {partial}"
    assert earlier.read_text() == '{"an earlier": "complete result"}'
    saved = json.loads(partial.read_text())
    assert saved["interrupted"] is True and "lane_change_01" in saved["partial"]
    assert saved["partial"]["lane_change_01"]["trace"]["verdict"] in ("conformant", "not_conformant", "undecided")


def test_ctrl_c_inside_code_that_swallows_exceptions_is_delivered_again(monkeypatch):
    """CI saw Ctrl-C land in importlib's weakref callback while numpy was imported: Python printed "Exception
    ignored", the KeyboardInterrupt was lost and the run finished with status 0."""
    from types import SimpleNamespace

    from reachconf import cli

    sent = []
    monkeypatch.setattr(cli.os, "kill", lambda pid, sig: sent.append((pid, sig)))
    callback = SimpleNamespace(f_code=SimpleNamespace(co_name="cb", co_filename="<frozen importlib._bootstrap>"))
    assert cli._on_ctrl_c(signal.SIGINT, callback) is None  # not raised where it would be ignored ...
    assert sent == [(os.getpid(), signal.SIGINT)] and cli._on_ctrl_c.pressed  # ... but sent again
    finalizer = SimpleNamespace(f_code=SimpleNamespace(co_name="__del__", co_filename="x.py"))
    assert cli._on_ctrl_c(signal.SIGINT, finalizer) is None and len(sent) == 2
    with pytest.raises(KeyboardInterrupt):  # anywhere else: raised at once
        cli._on_ctrl_c(signal.SIGINT, sys._getframe())
    assert len(sent) == 2
