"""`ttes ping`: connect to a Jack/TTES server, shake hands and ping it; exit 0 if it answers.

Used by the Docker healthcheck. Connects as an observer, so it never changes the server's state.
"""

from __future__ import annotations

import argparse
import socket
import sys
import time


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("ping", help="check that a Jack/TTES server answers", description=__doc__)
    p.add_argument("--host", default="127.0.0.1", help="server address (default 127.0.0.1)")
    p.add_argument("--port", type=int, default=7000, help="server port (default 7000)")
    p.add_argument("--timeout", type=float, default=3.0, help="seconds to wait for each answer (default 3)")
    p.add_argument("--json", action="store_true", help="machine-readable output")
    p.set_defaults(func=run)


class PingFailed(Exception):
    pass


def ping(host: str, port: int, timeout: float = 3.0) -> dict[str, object]:
    """Handshake + PING; the server's ACCEPT fields and the round-trip time. PingFailed on any problem."""
    from protocol.connection import CLIENT, NEED_DATA, Connection
    from protocol.events import Accept, ConnectionClosed, Error, Goodbye, Hello, Ping, Pong, ProtocolError

    conn = Connection(CLIENT)
    t0 = time.perf_counter()
    try:
        sock = socket.create_connection((host, port), timeout=timeout)
    except OSError as exc:
        raise PingFailed(f"cannot connect to {host}:{port}: {exc.strerror or exc}") from None
    with sock:
        sock.settimeout(timeout)

        def wait_for(kind: type) -> object:
            while True:
                ev = conn.next_event()
                if ev is NEED_DATA:
                    try:
                        conn.receive_data(sock.recv(65536))
                    except TimeoutError:
                        raise PingFailed(f"no {kind.__name__} within {timeout:g} s") from None
                    except OSError as exc:
                        raise PingFailed(f"connection failed: {exc.strerror or exc}") from None
                    continue
                if isinstance(ev, kind):
                    return ev
                if (isinstance(ev, Error) and ev.code < 100) or isinstance(ev, Goodbye):
                    raise PingFailed(f"server refused: {ev}")
                if isinstance(ev, ProtocolError | ConnectionClosed):
                    raise PingFailed(f"connection ended: {ev}")

        try:
            sock.sendall(conn.send(Hello("ttes-ping", "observer")))
            accept = wait_for(Accept)
            nonce = int(time.time_ns() & 0xFFFFFFFF)
            t1 = time.perf_counter()
            sock.sendall(conn.send(Ping(nonce)))
            while True:
                pong = wait_for(Pong)
                if pong.nonce == nonce:  # type: ignore[attr-defined]
                    break
            rtt = time.perf_counter() - t1
            sock.sendall(conn.send(Goodbye("ping done")))
        except OSError as exc:
            raise PingFailed(f"connection failed: {exc.strerror or exc}") from None
    assert isinstance(accept, Accept)
    return {
        "host": host,
        "port": port,
        "server": accept.name,
        "version": accept.version,
        "max_soldiers": accept.max_soldiers,
        "max_frame": accept.max_frame,
        "rtt_ms": round(rtt * 1000, 3),
        "total_ms": round((time.perf_counter() - t0) * 1000, 3),
    }


def run(args: argparse.Namespace) -> int:
    from ttes.output import print_json

    try:
        info = ping(args.host, args.port, args.timeout)
    except PingFailed as exc:
        if args.json:
            print_json({"ok": False, "host": args.host, "port": args.port, "error": str(exc)})
        else:
            print(f"ttes ping: {exc}", file=sys.stderr)
        return 1
    if args.json:
        print_json({"ok": True, **info})
    else:
        print(
            f"pong from {info['server']} at {args.host}:{args.port} in {info['rtt_ms']} ms "
            f"(protocol {info['version']}, max_soldiers {info['max_soldiers']})"
        )
    return 0
