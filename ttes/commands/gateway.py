"""`ttes gateway`: live DIS from UDP into the Jack/TTES server (one soldier per lifeform entity).

Listens for DIS on UDP (broadcast or multicast) bound to one interface, LOOPBACK BY DEFAULT: only senders on
this machine are heard. To hear an exercise on the LAN: --listen 0.0.0.0 (broadcast DIS, every interface; the
host's firewall must let UDP --dis-port in), or --dis-group ADDR --listen LOCAL_ADDR (multicast DIS). In a
container, broadcast DIS needs host networking. --exercise N keeps only exercise N's PDUs. Each lifeform
entity becomes a server soldier (created on first sight, removed after --timeout seconds of silence, when
deactivated or by a Remove Entity PDU; Entity State Update PDUs move him too); appearance, velocity and
heading become entity requests; Fire PDUs make a standing-still shooter fire for a moment. Malformed
datagrams, unknown PDU types and bursts are counted in the status line, never fatal. Stop with Ctrl-C: the
gateway's soldiers are removed from the server.

At most 4096 soldiers (the server's default cap per client): entities beyond it are counted (sink_dropped in
the status lines and the summary), not sent. A lost server is reconnected with backoff and the live soldiers
are created again (sink_relinked). Exit status: 0 stopped (Ctrl-C or --seconds), 1 no server (at the start, or
lost for longer than --give-up-after), or the DIS port cannot be bound; 2 bad arguments.
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path
from typing import TYPE_CHECKING

from ttes.arguments import host, listen_port, non_negative, port
from ttes.commands.dis import exercise_id
from ttes.link_options import add_link_options, link_credentials, link_error

LOOPBACK = "127.0.0.1"

if TYPE_CHECKING:
    from client_stub.dis.gateway import DisGateway
    from client_stub.dis.sink import ServerSink


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "gateway",
        help="live DIS (UDP) into the Jack/TTES server",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--dis-port", type=listen_port, default=3000, help="UDP port to listen on (default 3000)")
    p.add_argument("--dis-group", type=host, metavar="ADDR", help="multicast group to join (default: none)")
    p.add_argument("--listen", "--interface", dest="interface", type=host, default=LOOPBACK, metavar="ADDR",
                   help=f"local address to bind / join on (default {LOOPBACK}: this machine only; "
                        "0.0.0.0: every interface, to hear a LAN exercise's broadcasts)")  # fmt: skip
    p.add_argument(
        "--exercise",
        type=exercise_id,
        metavar="N",
        help="only the PDUs of DIS exercise N (1..255; default: every exercise)",
    )
    p.add_argument("--host", type=host, help="Jack/TTES server host (default 127.0.0.1)")
    p.add_argument("--port", type=port, default=7000, help="server port (default 7000)")
    p.add_argument("--with-server", action="store_true", help="run a private server in this process")
    p.add_argument("--data-dir", help="private server: its data directory")
    p.add_argument("--synthetic-server", action="store_true", help="private server: synthetic motion library")
    p.add_argument("--timeout", type=float, default=12.0, help="seconds without a PDU before a soldier goes")
    p.add_argument("--entities", metavar="FILTER", help="keep only these entities (as in `ttes replay`)")
    p.add_argument("--origin", metavar="LAT,LON,H", help="local frame origin (default: the first entity)")
    p.add_argument(
        "--status-every", type=non_negative, default=5.0, help="seconds between status lines (0: none)"
    )
    p.add_argument("--seconds", type=float, help="stop after this many seconds (default: run until Ctrl-C)")
    p.add_argument("--json", action="store_true", help="status lines and the final summary as JSON")
    add_link_options(p)
    p.add_argument("--give-up-after", type=non_negative, default=120.0, metavar="S",
                   help="a lost server is reconnected (backoff 0.5..8 s; the soldiers are created again) for "
                        "this long before the gateway exits 1 (default 120; 0: exit at once)")  # fmt: skip
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from client_stub.dis import EntityFilter, FilterError
    from client_stub.dis.gateway import DisGateway, GatewayConfig
    from ttes.commands.replay import parse_origin

    try:
        cfg = GatewayConfig(
            port=args.dis_port,
            interface=args.interface,
            group=args.dis_group,
            timeout=args.timeout,
            origin=parse_origin(args.origin),
            entity_filter=EntityFilter.parse(args.entities) if args.entities else None,
            exercise=args.exercise,
        )
        if not (0 <= args.dis_port <= 65535 and math.isfinite(args.timeout) and args.timeout > 0):
            raise ValueError("--dis-port must be 0..65535 and --timeout > 0")
        if args.seconds is not None and not (math.isfinite(args.seconds) and args.seconds > 0):
            raise ValueError("--seconds must be > 0")
    except (FilterError, ValueError) as exc:
        print(f"ttes gateway: {exc}", file=sys.stderr)
        return 2
    if args.with_server and args.host:
        print("ttes gateway: --with-server or --host, not both", file=sys.stderr)
        return 2
    gateway = DisGateway(cfg)
    data_dir = Path(args.data_dir) if args.data_dir else None
    try:
        summary = _serve(args, gateway, data_dir)
    except OSError as exc:
        print(f"ttes gateway: cannot listen on {args.interface}:{args.dis_port}: {exc.strerror or exc}",
              file=sys.stderr)  # fmt: skip
        return 1
    if summary is None:
        return 1
    _print(summary, args.json, final=True)
    return 0


def _serve(args: argparse.Namespace, gateway: DisGateway, data_dir: Path | None) -> dict | None:
    import contextlib

    import trio

    from client_stub.dis.reconnect import connector, keep_linked_or_stop
    from client_stub.dis.sink import ServerSink
    from client_stub.link.client import Client, LinkError
    from ttes.commands.replay import private_server, stop_on_signal

    async def main() -> dict:
        async with contextlib.AsyncExitStack() as stack:
            host, port = args.host or "127.0.0.1", args.port
            if args.with_server:
                server = await stack.enter_async_context(private_server(data_dir, args.synthetic_server))
                host, port = server.addresses[0]
            nursery = await stack.enter_async_context(trio.open_nursery())
            connect = connector(nursery, host, port, "ttes-gateway", credentials=link_credentials(args))
            sink = ServerSink(await connect())
            failures: list[str] = []
            with trio.CancelScope() as scope:
                if args.seconds is not None:
                    scope.deadline = trio.current_time() + args.seconds
                async with trio.open_nursery() as inner:
                    inner.start_soon(stop_on_signal, inner.cancel_scope)
                    inner.start_soon(
                        keep_linked_or_stop, sink, connect, inner.cancel_scope, failures, args.give_up_after
                    )
                    await inner.start(gateway.serve, sink)
                    assert gateway.address is not None
                    host_, port_ = gateway.address
                    if not args.json:
                        line = listening_line(args, host_, port_, f"{host}:{port}")
                        print(line, file=sys.stderr, flush=True)
                    if args.status_every > 0:
                        inner.start_soon(_status_loop, gateway, sink, args.status_every, args.json)
            sink.apply(gateway.stop())
            summary = _snapshot(gateway, sink)
            link = sink.link
            assert isinstance(link, Client)
            summary["server_errors"] = len(link.errors)
            await link.aclose()
            if failures:
                raise LinkError(failures[0])
            return summary

    try:
        return trio.run(main)
    except (LinkError, BaseExceptionGroup) as exc:
        if (failure := link_error(exc)) is None:
            raise
        print(f"ttes gateway: {failure}", file=sys.stderr)
        return None


def listening_line(args: argparse.Namespace, host: str, port: int, server: str) -> str:
    """The start-up line; on loopback it says how to hear a LAN exercise (else nothing would be heard)."""
    group = f" group {args.dis_group}" if args.dis_group else ""
    exercise = f", exercise {args.exercise}" if args.exercise else ""
    line = f"ttes gateway: listening for DIS on {host}:{port}{group}{exercise}, server {server}"
    if host.startswith("127.") and not args.dis_group:
        line += (
            "\nttes gateway: loopback only: senders on this machine are heard, a LAN exercise is not; to "
            f"hear one, --listen 0.0.0.0 (broadcast DIS on UDP {port}) or --dis-group ADDR (multicast)"
        )
    return line


def _snapshot(gateway: DisGateway, sink: ServerSink) -> dict:
    return {**gateway.snapshot(), **{f"sink_{k}": v for k, v in sink.stats.items()}, "server_lost": sink.lost}


async def _status_loop(gateway: DisGateway, sink: ServerSink, every: float, as_json: bool) -> None:
    import trio

    while True:
        await trio.sleep(every)
        _print(_snapshot(gateway, sink), as_json)


def _print(status: dict, as_json: bool, final: bool = False) -> None:
    if as_json:
        from ttes.output import print_json

        print_json({"event": "summary" if final else "status", **status})
        sys.stdout.flush()
        return
    bad = status["corrupt"] + status["non_dis"] + status["unsupported_version"]
    parts = [
        f"{status['alive']} soldiers alive ({status['translator_created']} created)",
        f"{status['datagrams']} datagrams",
        f"{status['pdus']} PDUs",
        f"{status['lifeforms']} lifeform states",
        f"{status['fire']} fire",
        f"{status['detonation']} detonation",
        f"{status['other_pdus']} other PDUs",
        f"{bad} malformed/foreign",
        f"largest burst {status['max_burst']}",
        f"{status['sink_dropped']} over the server's cap",
    ]
    if status["server_lost"]:
        parts.append(f"SERVER LOST ({status['server_lost']}): reconnecting")
    out = sys.stdout if final else sys.stderr
    print(f"{'gateway summary' if final else 'gateway'}: " + ", ".join(parts), file=out, flush=True)
