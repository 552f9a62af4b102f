"""Output paths of a run: checked before the work, locked against other runs, partial results kept apart.

* :func:`check_output_folder` / :func:`check_output_file` create what is
  missing and probe that a file can be written there, so that a bad
  ``--out``/``--json`` fails in the first second, naming the user's path —
  not after the computation, not naming a temporary file.
* :class:`OutputLock` holds an exclusive lock (``flock``; released by the
  operating system if the process dies) on an output folder
  (``<folder>/.reachconf.lock``) or file (``.<name>.lock`` next to it):
  a second run into the same ``--out`` or ``--json`` fails at once with
  :class:`~reachconf.errors.OutputError` naming the run that holds it, so two
  runs never mix their files.
* :class:`RunOutputs` bundles both for one command; partial results (Ctrl-C)
  go to a *new* file (``<json stem>.partial.json`` or
  ``<folder>/<command>.partial.json``, numbered if that exists), never over
  an earlier complete result.
"""

from __future__ import annotations

import os
import socket
import sys
import tempfile
import time
from pathlib import Path

from reachconf.errors import OutputError
from reachconf.io.atomic import atomic_write, make_folder, os_reason, write_new
from reachconf.io.jsonfile import json_text

try:  # POSIX
    import fcntl
except ImportError:  # pragma: no cover - Windows: exclusive creation of the lock file instead
    fcntl = None

__all__ = ["check_output_folder", "check_output_file", "check_not_input", "OutputLock", "RunOutputs", "LOCK_NAME"]

#: name of the lock file in a locked output folder
LOCK_NAME = ".reachconf.lock"


def _probe(folder: Path, user_path: Path, option: str):
    """Create and remove a file in ``folder``; OutputError naming ``user_path`` if that fails."""
    try:
        fd, tmp = tempfile.mkstemp(prefix=".reachconf-probe.", dir=folder)
    except OSError as exc:
        raise OutputError(f"{user_path}: {option}: cannot write into {folder}: {os_reason(exc)}") from None
    os.close(fd)
    os.unlink(tmp)


def check_output_folder(path, option: str = "--out") -> Path:
    """Make sure ``path`` is (or can become) a writable folder; create it.

    Raises
    ------
    OutputError
        ``path`` is a file, a parent is a file, or the folder is not writable
        (the message names ``path`` and ``option``).
    """
    if not str(path):
        raise OutputError(f"{option}: the folder name is empty")
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise OutputError(f"{path}: {option} must be a folder, but it is a file")
    _probe(make_folder(path, path, option), path, option)
    return path


def check_output_file(path, option: str = "--json") -> Path:
    """Make sure a file can be written at ``path`` (its folder is created); it may exist (it is replaced).

    Raises
    ------
    OutputError
        ``path`` is a folder, its parent is a file, or the folder is not writable.
    """
    text = os.fspath(path)
    if not text:
        raise OutputError(f"{option}: the file name is empty")
    if text.endswith(("/", os.sep)):
        raise OutputError(f"{text}: {option} must be a file name, but it ends with {text[-1]!r} (a folder)")
    path = Path(path)
    if path.is_dir():
        raise OutputError(f"{path}: {option} must be a file name, but it is a folder")
    _probe(make_folder(path.parent, path, option), path, option)
    return path


def check_not_input(path, option: str, files=(), folders=()) -> None:
    """An output must not overwrite what the run reads: raise if ``path`` is one of ``files`` or lies in one of ``folders``.

    ``files``: the run file (and other input files); ``folders``: the test-suite folders (a result written
    there would replace a case file or ``suite.toml``, or be read back as a case by the next run).

    Raises
    ------
    OutputError
        Naming ``path``, ``option`` and the input it would overwrite.
    """
    target = Path(path).resolve()
    for f in files:
        if Path(f).resolve() == target:
            raise OutputError(f"{path}: {option} is the run's input {f}; choose another {option}")
    for d in folders:
        d = Path(d).resolve()
        if target == d or d in target.parents:
            raise OutputError(f"{path}: {option} lies in the test-suite folder {d}, which the run reads; "
                              f"choose another {option}")  # fmt: skip


def _describe_run() -> str:
    args = " ".join(Path(sys.argv[0]).name if i == 0 else a for i, a in enumerate(sys.argv)) if sys.argv else ""
    stamp = time.strftime("%Y-%m-%d %H:%M:%S")
    return f"pid {os.getpid()} on {socket.gethostname()}, started {stamp}: {args}"[:500]


class OutputLock:
    """Exclusive lock of an output folder or file for the duration of one run.

    Use as a context manager, or :meth:`acquire` / :meth:`release`.  The
    lock file holds the process id, host, start time and command of the run
    holding it, which the error message of a second run quotes.

    Parameters
    ----------
    target : path-like
        The folder or file the run writes.
    option : str
        The command-line option that named it (for messages).
    """

    def __init__(self, target, option: str = "--out"):
        self.target = Path(target)
        self.option = option
        if self.target.is_dir():
            self.path = self.target / LOCK_NAME
        else:
            self.path = self.target.with_name(f".{self.target.name}.lock")
        self._fd = None

    def _busy(self, holder: str):
        kind = "folder" if self.target.is_dir() else "file"
        return OutputError(f"{self.target}: another reachconf run is writing this {kind} ({holder or 'unknown run'});"
                           f" wait for it to finish or choose another {self.option}")  # fmt: skip

    def acquire(self) -> "OutputLock":
        """Take the lock or raise :class:`OutputError` naming the run that holds it."""
        info = _describe_run().encode("utf-8", "replace")
        if fcntl is None:  # pragma: no cover - Windows
            try:
                fd = os.open(self.path, os.O_CREAT | os.O_EXCL | os.O_RDWR, 0o666)
            except FileExistsError:
                raise self._busy(f"lock file {self.path}; delete it if no run is active") from None
            os.write(fd, info)
            self._fd = fd
            return self
        for _ in range(100):
            try:
                fd = os.open(self.path, os.O_CREAT | os.O_RDWR, 0o666)
            except OSError as exc:
                raise OutputError(f"{self.target}: {self.option}: cannot create the lock file {self.path.name}: "
                                  f"{os_reason(exc)}") from None  # fmt: skip
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except OSError:
                holder = os.read(fd, 1000).decode("utf-8", "replace").strip()
                os.close(fd)
                raise self._busy(holder) from None
            try:  # the file may have been removed by the run that released it just now: lock the current one
                same = os.stat(self.path).st_ino == os.fstat(fd).st_ino
            except FileNotFoundError:
                same = False
            if not same:
                os.close(fd)
                continue
            os.ftruncate(fd, 0)
            os.write(fd, info)
            self._fd = fd
            return self
        raise OutputError(f"{self.target}: {self.option}: could not take the lock {self.path}")  # pragma: no cover

    def release(self):
        """Remove the lock file and release the lock (idempotent)."""
        if self._fd is None:
            return
        try:
            os.unlink(self.path)  # while still holding it: a run waiting on the old file sees it is gone
        except OSError:
            pass
        os.close(self._fd)
        self._fd = None

    def __enter__(self):
        return self.acquire()

    def __exit__(self, *exc):
        self.release()
        return False


class RunOutputs:
    """The output folder and JSON file of one command, checked and locked before the work starts.

    Use as a context manager around the whole run (checks and locks on
    entry, releases on exit), or :meth:`open` / :meth:`close`.

    Parameters
    ----------
    command : str
        Name of the command (names the partial-results file in the folder).
    folder : path-like, optional
        ``--out``: created, probed and locked.
    json : path-like, optional
        ``--json``: its folder created and probed, the file locked.
    """

    def __init__(self, command: str, folder=None, json=None):
        self.command = command
        if folder is not None and not os.fspath(folder):  # Path("") is the current folder
            raise OutputError("--out: the folder name is empty")
        self.folder = None if folder is None else Path(folder)
        self._json_text = None if json is None else os.fspath(json)  # a trailing "/" (a folder) is lost in Path
        self.json = None if json is None else Path(json)
        self._locks = []

    def open(self) -> "RunOutputs":
        """Check and lock every output path (OutputError on the first problem; nothing stays locked then)."""
        try:
            if self.folder is not None:
                check_output_folder(self.folder, "--out")
                self._locks.append(OutputLock(self.folder, "--out").acquire())
            if self.json is not None:
                check_output_file(self._json_text, "--json")
                self._locks.append(OutputLock(self.json, "--json").acquire())
        except BaseException:
            self.close()
            raise
        return self

    def close(self):
        """Release the locks."""
        while self._locks:
            self._locks.pop().release()

    def __enter__(self):
        return self.open()

    def __exit__(self, *exc):
        self.close()
        return False

    def write_json(self, path, obj) -> Path:
        """Strict JSON of ``obj`` (no NaN/Infinity) to ``path``, atomically."""
        return atomic_write(path, json_text(obj))

    def in_folder(self, name: str) -> Path | None:
        """``folder / name``, or None without a folder."""
        return None if self.folder is None else self.folder / name

    def partial_target(self) -> Path | None:
        """Where partial results go: next to ``--json`` or into the folder; None if neither was given."""
        if self.json is not None:
            return self.json.with_name(f"{self.json.stem}.partial.json")
        if self.folder is not None:
            return self.folder / f"{self.command}.partial.json"
        return None

    def save_partial(self, obj) -> Path | None:
        """Write partial results to a new file (never over an earlier one); returns its path or None."""
        target = self.partial_target()
        if target is None:
            return None
        return write_new(target, json_text(obj))
