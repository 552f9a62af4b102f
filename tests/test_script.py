"""Examples end on Ctrl-C with one line and status 130 (an outside review saw a numba SystemError and status 1 from
the wind turbine and the real car, and status 2, the user-error status, from the real car's pool)."""

import pytest

from reachconf.runner import Interrupted
from reachconf.script import EXIT_INTERRUPTED, run_script


def _raises(exc):
    def main():
        raise exc
    return main


def _from_compiled_code():
    try:
        raise KeyboardInterrupt
    except KeyboardInterrupt:
        raise SystemError("CPUDispatcher(<function perstep_fit>) returned a result with an exception set")


@pytest.mark.parametrize("main", [_raises(KeyboardInterrupt()), _from_compiled_code, _raises(Interrupted([1, None]))])
def test_an_interrupted_example_exits_130_with_one_line(main, capsys):
    assert run_script(main, "windturbine") == EXIT_INTERRUPTED
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("windturbine: interrupted")


def test_other_errors_and_statuses_pass_through():
    assert run_script(lambda: 2, "x") == 2
    with pytest.raises(SystemError):
        run_script(_raises(SystemError("a real bug")), "x")
