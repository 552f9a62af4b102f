"""Atomic file writes: the one writer every result, cache file and picture goes through.

A reader never sees a half-written file: the data goes to a temporary file in
the target folder, which then replaces the target in one ``os.replace``.  An
interrupted write (Ctrl-C, a full disk) leaves the old file, if any, in place.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

__all__ = ["atomic_write", "atomic_write_text"]


def atomic_write(path, data: bytes | str) -> Path:
    """Write ``data`` to ``path`` atomically; create the parent folders.

    Parameters
    ----------
    path : path-like
        The file to (re)place.
    data : bytes or str
        The whole content; a ``str`` is written as UTF-8.  Arrays and figures
        are written by serialising them to bytes first (``np.savez`` or
        ``fig.savefig`` into an ``io.BytesIO``).

    Returns
    -------
    Path
        ``path``.
    """
    path = Path(path)
    if isinstance(data, str):
        data = data.encode("utf-8")
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)  # mkstemp creates 0600; give the usual permissions
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise
    return path


def atomic_write_text(path, text: str) -> Path:
    """Write ``text`` (UTF-8) to ``path`` atomically: :func:`atomic_write` for text."""
    return atomic_write(path, text)
