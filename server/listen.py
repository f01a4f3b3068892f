"""The server's listening sockets, bound before anything loads: a taken port fails at once, naming host:port.

``ttes server`` binds first and then runs the start-up script (seconds of loading), so "address already in
use" comes before the wait and says which address; ``TtesServer.serve`` wraps the bound sockets for trio.
The options follow ``trio.open_tcp_listeners``: every address the host resolves to, SO_REUSEADDR, IPv6 only
on IPv6 sockets.
"""

from __future__ import annotations

import socket


class ListenError(OSError):
    """The server cannot listen on ``host:port``; ``errno`` is the socket's, the message names the address."""

    def __str__(self) -> str:
        return str(self.strerror) if self.strerror else super().__str__()


def _where(host: str | None, port: int) -> str:
    shown = host if host is not None else "*"
    return f"[{shown}]:{port}" if ":" in shown else f"{shown}:{port}"


def bind_tcp(host: str | None, port: int, backlog: int = socket.SOMAXCONN) -> list[socket.socket]:
    """Listening TCP sockets on every address of ``host`` (None: all interfaces); ListenError otherwise."""
    where = _where(host, port)
    try:
        infos = socket.getaddrinfo(host, port, type=socket.SOCK_STREAM, flags=socket.AI_PASSIVE)
    except (socket.gaierror, UnicodeError) as exc:
        raise ListenError(f"cannot listen on {where}: {getattr(exc, 'strerror', None) or exc}") from None
    sockets: list[socket.socket] = []
    try:
        for family, kind, proto, _, address in infos:
            s = socket.socket(family, kind, proto)
            sockets.append(s)
            s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            if family == socket.AF_INET6:
                s.setsockopt(socket.IPPROTO_IPV6, socket.IPV6_V6ONLY, 1)
            s.bind(address)
            s.listen(backlog)
    except OSError as exc:
        for s in sockets:
            s.close()
        raise ListenError(exc.errno, f"cannot listen on {where}: {exc.strerror or exc}") from None
    return sockets
