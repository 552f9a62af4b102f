"""The run's one pool: job order, early exit, Ctrl-C, lost local workers, bad arguments, unguarded scripts."""

import os
import signal
import subprocess
import sys
import textwrap

import pytest

from reachconf.errors import OptionsError
from reachconf.runner import Interrupted, Pool, WorkersLost, run_cases
from reachconf.runner.local import MAX_RESTARTS

CALLS = []


def square(x):
    return x * x


def record(job):
    CALLS.append(job)
    return job >= 0


def interrupt_at(job):
    if job == 2:
        raise KeyboardInterrupt
    return job


def crash_once(job):
    """Kill this worker process the first time job 3 runs (the marker file says it happened)."""
    value, marker = job
    if value == 3:
        try:
            fd = os.open(marker, os.O_CREAT | os.O_EXCL | os.O_WRONLY)
        except FileExistsError:
            pass
        else:
            os.close(fd)
            os.kill(os.getpid(), signal.SIGKILL)
    return value * value


def crash_always(job):
    if job == 1:
        os.kill(os.getpid(), signal.SIGKILL)
    return job


def test_results_in_job_order_serial_and_processes():
    jobs = list(range(-4, 9))
    serial = Pool().map(square, jobs, progress=False)
    with Pool(workers=2) as pool:
        assert pool.kind == "processes" and pool.size == 2
        assert pool.map(square, jobs, progress=False) == serial
        assert pool.map(square, [5], progress=False) == [25]  # the same workers, a second map
    assert serial == [x * x for x in jobs]
    assert run_cases(square, jobs, workers=2, progress=False) == serial


def test_first_failures_stops_at_the_first_failing_batch():
    CALLS.clear()
    pool = Pool()
    assert pool.first_failures(record, [0, 1, -1, 2, -2], batch=1) == [(2, False)]
    assert CALLS == [0, 1, -1]  # nothing after the first failure
    CALLS.clear()
    assert pool.first_failures(record, [0, 1, -1, 2, -2], batch=2) == [(2, False)]
    assert CALLS == [0, 1, -1, 2]  # the whole batch that failed
    assert pool.first_failures(record, [0, 1, 2]) == []


def test_ctrl_c_keeps_the_finished_results():
    with pytest.raises(Interrupted) as info:
        Pool().map(interrupt_at, [0, 1, 2, 3], progress=False)
    assert info.value.partial == [0, 1, None, None]
    assert isinstance(info.value, KeyboardInterrupt)


def test_lost_local_worker_is_reported_and_its_jobs_run_again(tmp_path, capsys):
    marker = str(tmp_path / "killed")
    jobs = [(v, marker) for v in range(8)]
    with Pool(workers=2) as pool:
        values = pool.map(crash_once, jobs, progress=False)
        assert values == [v * v for v in range(8)]
        assert pool.map(square, [2, 3], progress=False) == [4, 9]  # the restarted pool keeps working
    assert os.path.exists(marker)
    err = capsys.readouterr().err
    # (the forkserver cannot always read a killed process's status under load: then "255: unknown, or killed")
    assert "reachconf: warning: lost local worker process" in err and ("SIGKILL" in err or "or killed" in err)
    assert len(pool.log) == 1 and "restart 1 of at most" in pool.log[0]


def test_a_job_that_always_kills_its_worker_gives_up():
    with Pool(workers=2) as pool, pytest.raises(WorkersLost, match="died") as info:
        pool.map(crash_always, [0, 1, 2, 3], progress=False)
    assert len(info.value.partial) == 4
    assert len(pool.log) == MAX_RESTARTS


@pytest.mark.parametrize("kwargs, match", [({"workers": 0}, "workers"), ({"workers": 2.0}, "workers"),
                                           ({"workers": True}, "workers"),
                                           ({"workers": 2, "scheduler": "tcp://127.0.0.1:8786"}, "not both"),
                                           ({"worker_timeout": 0}, "worker_timeout"),
                                           ({"worker_timeout": "60"}, "worker_timeout")])  # fmt: skip
def test_bad_pool_arguments(kwargs, match):
    with pytest.raises(OptionsError, match=match):
        Pool(**kwargs)


def test_bad_worker_timeout_variable(monkeypatch):
    monkeypatch.setenv("REACHCONF_WORKER_TIMEOUT", "soon")
    with pytest.raises(OptionsError, match="REACHCONF_WORKER_TIMEOUT"):
        Pool()
    monkeypatch.setenv("REACHCONF_WORKER_TIMEOUT", "7.5")
    assert Pool().worker_timeout == 7.5


def test_a_script_without_main_guard_can_use_workers(tmp_path):
    """The README's quickstart style: workers= in a script with no ``if __name__ == "__main__":``."""
    script = tmp_path / "quick.py"
    script.write_text(textwrap.dedent("""
        from reachconf.runner import run_cases
        print("result", run_cases(abs, [-1, -2, -3], workers=2, progress=False))
    """))
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(p for p in sys.path if p))
    out = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=300, env=env)
    assert out.returncode == 0, out.stderr
    assert out.stdout.count("result [1, 2, 3]") == 1  # the workers did not run the script


def test_progress_bars_only_on_a_terminal_by_default(monkeypatch):
    """Bars are for a person watching: not in a log file (every \\r frame ended up there), unless asked for."""
    import io
    import sys

    from reachconf.runner.pool import progress_bar, progress_shown

    monkeypatch.setattr(sys, "stderr", io.StringIO())  # not a terminal
    monkeypatch.delenv("REACHCONF_PROGRESS", raising=False)
    assert not progress_shown() and progress_bar(10, "x").disable
    monkeypatch.setenv("REACHCONF_PROGRESS", "1")
    assert progress_shown() and not progress_bar(10, "x").disable
    assert progress_bar(1, "x").disable  # a single job: no bar
    monkeypatch.setenv("REACHCONF_PROGRESS", "0")
    assert not progress_shown() and not progress_bar(10, "x", progress=True).disable
