"""The listening socket of one simulator connection, and the error when its port is taken.

Standard library only, on purpose: the pool binds this socket and launches the simulator before
the gRPC server's modules (numpy, protobuf, the codec) are imported, so the simulator boots while
they load; the HTTP/2 transport then serves on the socket (docs/performance.md, "Start-up and
exit").
"""
from __future__ import annotations

import socket

from trainer.errors import PortInUseError


def listen(bind: str, port: int) -> socket.socket:
    """A non-blocking socket listening on ``bind:port`` (an IPv6 address has a colon); OSError if
    it cannot bind. A simulator that connects before anyone accepts waits in the backlog."""
    family = socket.AF_INET6 if ":" in bind else socket.AF_INET
    listener = socket.socket(family, socket.SOCK_STREAM)
    try:
        listener.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)  # TIME_WAIT only
        listener.bind((bind, port))
        listener.listen(8)
    except OSError:
        listener.close()
        raise
    listener.setblocking(False)
    return listener


def port_in_use_error(bind: str, port: int, editor: bool, simulator: str = "") -> PortInUseError:
    """The one message for a taken port; ``simulator`` names the simulator that would have used
    it (empty for none), ``editor``: the Unity Editor connects (no --env), which always uses its
    fixed port, so the advice differs."""
    if editor:
        return PortInUseError(
            f"Port {port} on {bind} is already in use; the Unity Editor always connects "
            f"to port {port}, so --base-port cannot help. Stop the process holding it (often "
            f"another training run waiting for the Editor; `ss -ltnp 'sport = :{port}'` or "
            f"`lsof -i :{port}` names it), or train a built player with --env and --base-port."
        )
    named = f" ({simulator})" if simulator else ""
    return PortInUseError(
        f"Port {port} on {bind} is already in use{named}, maybe by another "
        "training run or a simulator that did not exit. Stop it, or pick other ports with "
        "--base-port."
    )
