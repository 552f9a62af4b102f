"""Atomic file writes: the one writer every result, cache file and picture goes through.

A reader never sees a half-written file: the data goes to a temporary file
with a unique name (``.<name>.<random>``) in the target folder, which then
replaces the target in one ``os.replace`` (or, with ``overwrite=False``, is
linked to it only if the target does not exist yet).  An interrupted write
(Ctrl-C, a full disk) leaves the old file, if any, in place and no temporary
file behind.  Errors are :class:`~reachconf.errors.OutputError` naming the
target, never the temporary file.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

from reachconf.errors import OutputError

__all__ = ["atomic_write", "atomic_write_text", "write_new", "make_folder", "os_reason"]


def os_reason(exc: OSError) -> str:
    """The operating system's reason in an OSError (``"Permission denied"``), for messages."""
    return exc.strerror or str(exc) or type(exc).__name__


def make_folder(folder, user_path, what: str = "cannot write") -> Path:
    """Create ``folder`` (and its parents); :class:`OutputError` naming ``user_path`` if that fails.

    Parameters
    ----------
    folder : path-like
        The folder to create (it may exist).
    user_path : path-like
        The path the user gave (the folder itself or a file in it): messages name it.
    what : str
        Start of the message after the path (e.g. ``"--out"``).
    """
    folder = Path(folder)
    if folder.exists() and not folder.is_dir():
        raise OutputError(f"{user_path}: {what}: {folder} is a file, not a folder")
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise OutputError(f"{user_path}: {what}: cannot create the folder {folder}: {os_reason(exc)}") from None
    return folder


def atomic_write(path, data: bytes | str, overwrite: bool = True) -> Path:
    """Write ``data`` to ``path`` atomically; create the parent folders.

    Parameters
    ----------
    path : path-like
        The file to (re)place.
    data : bytes or str
        The whole content; a ``str`` is written as UTF-8.  Arrays and figures
        are written by serialising them to bytes first (``np.savez`` or
        ``fig.savefig`` into an ``io.BytesIO``).
    overwrite : bool, default True
        If False, the file is created only if ``path`` does not exist (an
        atomic link; :class:`FileExistsError` otherwise, nothing written).

    Returns
    -------
    Path
        ``path``.

    Raises
    ------
    OutputError
        The folder is not writable, ``path`` is a folder, its parent is a
        file, ...: the message names ``path``.
    FileExistsError
        ``overwrite=False`` and ``path`` exists.
    """
    path = given = Path(path)
    if isinstance(data, str):
        data = data.encode("utf-8")
    try:
        is_dir, is_link = path.is_dir(), path.is_symlink()
    except OSError as exc:  # e.g. a name longer than the file system allows
        raise OutputError(f"{str(path)[:300]}: cannot write: {os_reason(exc)}") from None
    if is_dir:
        raise OutputError(f"{path}: is a folder, expected a file name")
    if is_link:  # write the file it points to (the link stays)
        path = Path(os.path.realpath(path))
    if path.exists() and not path.is_file():  # a device or pipe (/dev/stdout): stream into it, never replace it
        try:
            with open(path, "wb") as fh:
                fh.write(data)
        except OSError as exc:
            raise OutputError(f"{path}: cannot write: {os_reason(exc)}") from None
        return given
    make_folder(path.parent, path)
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", dir=path.parent)
    except OSError as exc:
        raise OutputError(f"{path}: cannot write into {path.parent}: {os_reason(exc)}") from None
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)  # mkstemp creates 0600; give the usual permissions
        if overwrite:
            os.replace(tmp, path)
        else:
            _link_new(tmp, path)
    except FileExistsError:
        os.unlink(tmp)
        raise
    except OSError as exc:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise OutputError(f"{path}: cannot write: {os_reason(exc)}") from None
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise
    return given


def _link_new(tmp, path):
    """Move ``tmp`` to ``path`` only if ``path`` does not exist (FileExistsError otherwise)."""
    try:
        os.link(tmp, path)  # atomic, and fails if path exists: never replaces an earlier file
    except FileExistsError:
        raise
    except OSError:  # no hard links here (FAT, some network file systems): reserve the name, then replace
        os.close(os.open(path, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o666))
        os.replace(tmp, path)
        return
    os.unlink(tmp)


def atomic_write_text(path, text: str) -> Path:
    """Write ``text`` (UTF-8) to ``path`` atomically: :func:`atomic_write` for text."""
    return atomic_write(path, text)


def write_new(path, data: bytes | str) -> Path:
    """Write ``data`` to a file that does not exist yet: ``path``, else ``stem-2.suffix``, ``stem-3.suffix``, ...

    Used for partial results (Ctrl-C), which must never replace an earlier
    file.  Returns the path written.
    """
    path = Path(path)
    for k in range(1, 10_000):
        target = path if k == 1 else path.with_name(f"{path.stem}-{k}{path.suffix}")
        try:
            return atomic_write(target, data, overwrite=False)
        except FileExistsError:
            continue
    raise OutputError(f"{path}: 10,000 files of this name exist already")
