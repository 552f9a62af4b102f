"""Dask scheduler addresses checked before any work (form, scheme, port, and a TCP probe)."""

from __future__ import annotations

from reachconf.errors import OptionsError

__all__ = ["check_scheduler", "DASK_SCHEMES"]

#: address schemes of a Dask scheduler
DASK_SCHEMES = ("tcp", "tls", "inproc", "ucx", "ws", "wss")


def check_scheduler(scheduler, timeout: float = 5.0, probe: bool = True):
    """Check a Dask scheduler address before any work: its form, and (``probe``) that something listens there.

    Parameters
    ----------
    scheduler : str or dask.distributed.Client or None
        ``"tcp://host:port"`` (or another scheme of :data:`DASK_SCHEMES`).
    timeout : float
        Seconds to wait for the TCP connection of the probe.
    probe : bool
        Open (and close) a TCP connection to ``host:port`` (tcp, tls, ws, wss).

    Raises
    ------
    OptionsError
        Naming the address and what happened: malformed, unknown scheme, no
        port, host not found, connection refused, no answer within ``timeout``.
    """
    import socket
    from urllib.parse import urlsplit

    if scheduler is None or not isinstance(scheduler, str):
        if scheduler is not None and type(scheduler).__name__ != "Client":
            raise OptionsError(f"scheduler must be an address 'tcp://host:port' or a dask Client, got {scheduler!r}")
        return scheduler
    where = f"scheduler {scheduler!r}"
    if "://" not in scheduler:
        raise OptionsError(f"{where}: expected an address like 'tcp://host:8786'")
    parts = urlsplit(scheduler)
    if parts.scheme not in DASK_SCHEMES:
        raise OptionsError(f"{where}: unknown scheme {parts.scheme!r}; use one of {', '.join(DASK_SCHEMES)}")
    if parts.scheme in ("inproc", "ucx"):
        return scheduler
    try:
        host, port = parts.hostname, parts.port
    except ValueError as exc:  # port out of range or not a number
        raise OptionsError(f"{where}: bad port ({exc})") from None
    if not host or port is None:
        raise OptionsError(f"{where}: expected host and port, like 'tcp://host:8786'")
    if probe:
        try:
            socket.create_connection((host, port), timeout=timeout).close()
        except socket.gaierror as exc:
            raise OptionsError(f"{where}: host {host!r} not found ({exc.strerror or exc})") from None
        except (TimeoutError, socket.timeout):
            raise OptionsError(f"{where}: no answer from {host}:{port} within {timeout:g} s "
                               "(is the scheduler running, and is the address right?)") from None  # fmt: skip
        except OSError as exc:
            raise OptionsError(f"{where}: cannot connect to {host}:{port}: {exc.strerror or exc} "
                               "(is a Dask scheduler running there?)") from None  # fmt: skip
    return scheduler
