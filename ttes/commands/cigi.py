"""`ttes cigi`: the host side of CIGI 3.3: a scene of soldiers sent to a CIGI image generator over UDP.

Creates --soldiers soldiers on the server (a grid 3 m apart, postures taking turns: stand, kneel, prone),
subscribes to them and, --fps times a second, sends the IG at --ig HOST:PORT one message per frame (more when
a frame is bigger than --max-datagram): IG Control, then per soldier Entity Control (geodetic about --origin,
yaw = heading, the entity type of his figure), an Articulated Part Control for the figure root (part 0) and
Short Articulated Part Controls for the joint DOFs (parts 1..). The part IDs, joint by joint, and the entity
types are written to --map (JSON) for the IG integrator. docs/CIGI.md has the packets' layouts.
The IG's Start of Frame datagrams are received on --listen HOST:PORT (default 127.0.0.1:8005; "off": none)
and counted, with the newest IG frame number and the last host frame number the IG read (the host still runs
free at --fps; a datagram that is not a Start of Frame is counted as malformed).

Exit status: 0 done (--frames sent, --seconds passed or Ctrl-C), 1 no server, the part map cannot be
written or --listen cannot be bound, 2 bad arguments.
"""

from __future__ import annotations

import argparse
import json
import socket
import sys
from pathlib import Path

from ttes.arguments import count, host, host_port, listen_host_port, port, positive
from ttes.link_options import add_link_options, link_credentials, link_error

DEFAULT_IG = "127.0.0.1:8004"
DEFAULT_LISTEN = "127.0.0.1:8005"


def listen_address(text: str) -> tuple[str, int] | None:
    """``HOST:PORT`` to receive the IG's Start of Frame on, or ``off``."""
    return None if text.strip().lower() == "off" else listen_host_port(text)


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "cigi",
        help="send soldiers to a CIGI 3.3 image generator (UDP)",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--ig", type=host_port, default=host_port(DEFAULT_IG), metavar="HOST:PORT",
                   help=f"the image generator's CIGI address (default {DEFAULT_IG})")  # fmt: skip
    p.add_argument("--listen", type=listen_address, default=listen_address(DEFAULT_LISTEN),
                   metavar="HOST:PORT|off",
                   help=f"receive the IG's Start of Frame (default {DEFAULT_LISTEN}; off: none)")  # fmt: skip
    p.add_argument("--host", type=host, help="Jack/TTES server host (default 127.0.0.1)")
    p.add_argument("--port", type=port, default=7000, help="server port (default 7000)")
    p.add_argument("--with-server", action="store_true", help="run a private server in this process")
    p.add_argument("--data-dir", help="private server: its data directory")
    p.add_argument("--synthetic-server", action="store_true", help="private server: synthetic motion library")
    p.add_argument("--soldiers", type=count(1, 4096), default=10, help="soldiers in the scene (default 10)")
    p.add_argument("--fps", type=positive, default=30.0, help="frames per second (default 30)")
    p.add_argument("--frames", type=count(1), help="stop after this many frames (default: until Ctrl-C)")
    p.add_argument("--seconds", type=positive, help="stop after this many seconds")
    p.add_argument("--origin", metavar="LAT,LON,H", help="geodetic origin of the scene (default 0,0,0)")
    p.add_argument("--max-datagram", type=count(120, 65507), default=1472, metavar="BYTES",
                   help="largest UDP payload (default 1472: one Ethernet frame)")  # fmt: skip
    p.add_argument("--map", type=Path, default=Path("cigi-parts.json"), metavar="FILE",
                   help="the part-ID map for the IG integrator (default cigi-parts.json)")  # fmt: skip
    p.add_argument("--json", action="store_true", help="the summary as JSON")
    add_link_options(p)
    p.set_defaults(func=run)


def _address(addr: tuple) -> str:
    return f"{addr[0]}:{addr[1]}"


def run(args: argparse.Namespace) -> int:
    from protocol.dis import LocalFrame
    from ttes.commands.replay import parse_origin

    try:
        origin = parse_origin(args.origin) or LocalFrame(0.0, 0.0, 0.0)
    except ValueError as exc:
        print(f"ttes cigi: {exc}", file=sys.stderr)
        return 2
    if args.with_server and args.host:
        print("ttes cigi: --with-server or --host, not both", file=sys.stderr)
        return 2
    summary = _serve(args, origin)
    if summary is None:
        return 1
    if args.json:
        from ttes.output import print_json

        print_json({"event": "summary", **summary})
    else:
        print(
            f"cigi summary: {summary['frames']} frames, {summary['soldiers_sent']} soldiers, "
            f"{summary['datagrams']} datagrams, {summary['bytes']} bytes to {summary['ig']}; part map "
            f"{summary['map']}"
        )
        print(_sof_line(summary))
    return 0


def _sof_line(summary: dict) -> str:
    if summary["listen"] is None:
        return "cigi IG: not listening (--listen off)"
    return (
        f"cigi IG: {summary['sof_received']} Start of Frame on {summary['listen']} "
        f"({summary['sof_malformed']} malformed), IG frame {summary['ig_frame']}, "
        f"last host frame {summary['ig_last_host_frame']}"
    )


def _bind_listener(address: tuple[str, int]) -> socket.socket:
    """The UDP socket the IG's Start of Frame arrives on; OSError when the address cannot be bound."""
    sock = socket.socket(socket.AF_INET6 if ":" in address[0] else socket.AF_INET, socket.SOCK_DGRAM)
    try:
        sock.bind(address)
    except OSError:
        sock.close()
        raise
    return sock


def _serve(args: argparse.Namespace, origin: object) -> dict | None:
    import contextlib

    import trio

    from client_stub.cigi import listen
    from client_stub.cigi.host import CigiHost, HostConfig
    from client_stub.link.client import Client, LinkError
    from protocol import cigi_scene
    from ttes.commands.replay import private_server, stop_on_signal

    async def main() -> dict | None:
        async with contextlib.AsyncExitStack() as stack:
            host_, port_ = args.host or "127.0.0.1", args.port
            if args.with_server:
                server = await stack.enter_async_context(
                    private_server(Path(args.data_dir) if args.data_dir else None, args.synthetic_server)
                )
                host_, port_ = server.addresses[0]
            nursery = await stack.enter_async_context(trio.open_nursery())
            link = link_credentials(args).apply(Client("ttes-cigi"))
            await link.open(nursery, host_, port_)
            udp = stack.enter_context(socket.socket(socket.AF_INET6 if ":" in args.ig[0] else socket.AF_INET,
                                                    socket.SOCK_DGRAM))  # fmt: skip
            cfg = HostConfig(args.soldiers, args.fps, origin, args.max_datagram)  # type: ignore[arg-type]
            cigi_host = CigiHost(link, cfg, lambda msg: udp.sendto(msg, args.ig))
            counter, ear = listen.SofCounter(), None
            if args.listen is not None:
                try:
                    ear = trio.socket.from_stdlib_socket(stack.enter_context(_bind_listener(args.listen)))
                except OSError as exc:
                    print(f"ttes cigi: cannot listen on {_address(args.listen)}: {exc.strerror or exc}",
                          file=sys.stderr)  # fmt: skip
                    await link.aclose()
                    return None
            await cigi_host.populate()
            try:
                args.map.write_text(json.dumps(cigi_scene.part_map(link.tables), indent=1) + "\n")
            except OSError as exc:
                print(f"ttes cigi: cannot write {args.map}: {exc.strerror or exc}", file=sys.stderr)
                await link.aclose()
                return None
            with trio.CancelScope() as scope:
                if args.seconds is not None:
                    scope.deadline = trio.current_time() + args.seconds
                async with trio.open_nursery() as inner:
                    inner.start_soon(stop_on_signal, inner.cancel_scope)
                    if ear is not None:
                        inner.start_soon(listen.receive, ear, counter)
                    await cigi_host.run(args.frames)
                    inner.cancel_scope.cancel()
            for i in cigi_host.table_of:
                link.remove(i)
            await link.aclose()
            listening = None if ear is None else _address(ear.getsockname())
            return {**cigi_host.stats, "ig": _address(args.ig), "map": str(args.map), "listen": listening,
                    **counter.stats()}  # fmt: skip

    try:
        return trio.run(main)
    except (LinkError, BaseExceptionGroup) as exc:
        if (failure := link_error(exc)) is None:
            raise
        print(f"ttes cigi: {failure}", file=sys.stderr)
        return None
