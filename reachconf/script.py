"""Run an example's ``main()`` as the command line runs a command: Ctrl-C ends it with one line and status 130.

Ctrl-C inside compiled code (numba, a solver) surfaces as a ``SystemError`` or a library error that carries the
``KeyboardInterrupt`` only as its context; a pool of workers raises
:class:`~reachconf.runner.Interrupted`.  Each is an interruption, not an internal error (status 1) or a user
error (status 2).  What the example had written stays as it was: its files are written atomically.
"""

from __future__ import annotations

import signal
import sys
import threading

__all__ = ["run_script", "caused_by_ctrl_c"]

#: the exit status of an interrupted run (128 + SIGINT), as :mod:`reachconf.cli`
EXIT_INTERRUPTED = 130


def caused_by_ctrl_c(exc: BaseException) -> bool:
    """Did Ctrl-C cause ``exc`` (it, or an exception in its chain of causes and contexts)?"""
    seen = set()
    while exc is not None and id(exc) not in seen:
        if isinstance(exc, KeyboardInterrupt):
            return True
        seen.add(id(exc))
        exc = exc.__cause__ or exc.__context__
    return False


def run_script(main, name: str, argv=None) -> int:
    """``main(argv)``'s exit status; 130 with ``"<name>: interrupted"`` on stderr when Ctrl-C stopped it."""
    pressed = []

    def on_ctrl_c(signum, frame):  # any error after this counts as the interruption
        pressed.append(True)
        raise KeyboardInterrupt

    main_thread = threading.current_thread() is threading.main_thread()
    previous = signal.signal(signal.SIGINT, on_ctrl_c) if main_thread else None
    try:
        return main(argv) if argv is not None else main()
    except BaseException as exc:
        if isinstance(exc, SystemExit):
            raise
        if pressed or caused_by_ctrl_c(exc):
            done = f" ({exc})" if "jobs finished" in str(exc) else ""
            print(f"{name}: interrupted{done}; files written before stay complete, none is half-written",
                  file=sys.stderr)  # fmt: skip
            return EXIT_INTERRUPTED
        raise
    finally:
        if previous is not None:
            signal.signal(signal.SIGINT, previous)
