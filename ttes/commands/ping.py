"""`ttes ping`: connect to a Jack/TTES server, shake hands and ping it; exit 0 if it answers.

Used by the Docker healthcheck. Connects as an observer, so it never changes the server's state; a server
with role tokens wants one (--token or $TTES_TOKEN: the observer's or a higher role's).
"""

from __future__ import annotations

import argparse
import sys
import time
from typing import TYPE_CHECKING

from ttes.arguments import host, port, positive
from ttes.link_options import add_link_options, link_credentials

if TYPE_CHECKING:
    from client_stub.link.auth import Credentials


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("ping", help="check that a Jack/TTES server answers", description=__doc__)
    p.add_argument("--host", type=host, default="127.0.0.1", help="server address (default 127.0.0.1)")
    p.add_argument("--port", type=port, default=7000, help="server port (default 7000)")
    p.add_argument(
        "--timeout", type=positive, default=3.0, help="seconds to wait for each answer (default 3)"
    )
    p.add_argument("--json", action="store_true", help="machine-readable output")
    add_link_options(p)
    p.set_defaults(func=run)


class PingFailed(Exception):
    pass


def ping(
    host: str, port: int, timeout: float = 3.0, credentials: Credentials | None = None
) -> dict[str, object]:
    """Handshake + PING over the client link; the server's ACCEPT fields and the round-trip time. PingFailed
    on any problem."""
    import trio

    from client_stub.link.client import Client, LinkError

    async def main() -> dict[str, object]:
        t0 = time.perf_counter()
        client = Client("ttes-ping", "observer", buffer_updates=False)
        if credentials is not None:
            credentials.apply(client)
        failed, answered, rtt = None, False, 0.0
        async with trio.open_nursery() as nursery:
            try:
                await client.open(nursery, host, port, soldierprefix=None, wait_ready=False, timeout=timeout)
            except LinkError as exc:
                failed = str(exc)
            else:
                t1 = time.perf_counter()
                answered = await client.roundtrip(timeout)
                rtt = time.perf_counter() - t1
                await client.aclose("ping done")
        if failed is not None:
            raise PingFailed(failed)
        accept = client.accept
        if not answered or accept is None:
            raise PingFailed(client.failure or f"no PONG within {timeout:g} s")
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

    return trio.run(main)


def run(args: argparse.Namespace) -> int:
    from ttes.output import print_json

    try:
        info = ping(args.host, args.port, args.timeout, link_credentials(args))
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
