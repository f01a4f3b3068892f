"""`ttes web`: the browser image generator: serves the page (three.js) that draws a server's soldiers.

Open the printed URL in a browser. The page connects to the Jack/TTES server's WebSocket port (`ttes server
--ws-port N`, docs/PROTOCOL.md section 2.1), takes --soldiers soldiers (the start-up script's first, then
CREATE_SOLDIER), draws the village and every soldier from the server's FIGURE message, and answers the stub's
keys (1-4 posture, 5-6 weapon, arrows, n/p, a, u/d/i/j/o camera, b/c/f/v/x views, w/s/q/e/r/g fly; ? lists
them). URL parameters override the defaults: ?soldiers=100&version=1&motion=walk&role=observer&view=action&
ws=ws://host:port/.

--replay LOGFILE (a pcap/pcapng/.dislog of DIS, as `ttes replay` reads) replays it into the private server
while the page watches as an observer: every replayed soldier where the log puts him, posed by the server.

Exit status: 0 stopped (Ctrl-C, or --seconds passed), 1 the page cannot be served (port in use, three.js not
vendored) or the private server cannot start, 2 bad arguments.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from ttes.arguments import UsageError, count, host, host_port, listen_port, positive

DEFAULT_SERVER = "127.0.0.1:7001"


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "web",
        help="serve the browser image generator (three.js over the server's WebSocket port)",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument(
        "--host", type=host, default="127.0.0.1", help="address to serve the page on (default 127.0.0.1)"
    )
    p.add_argument(
        "--port", type=listen_port, default=8080, help="HTTP port (default 8080; 0 = any free port)"
    )
    p.add_argument("--server", type=host_port, metavar="HOST:PORT",
                   help=f"the Jack/TTES server's WebSocket address (default {DEFAULT_SERVER})")  # fmt: skip
    p.add_argument(
        "--with-server", action="store_true", help="run a private server (with a WebSocket port) here"
    )
    p.add_argument("--data-dir", help="private server: its data directory")
    p.add_argument("--synthetic-server", action="store_true", help="private server: synthetic motion library")
    p.add_argument("--soldiers", type=count(1, 4096), default=4, help="soldiers the page takes (default 4)")
    p.add_argument("--version-wire", type=count(1, 2), default=2, dest="wire_version",
                   help="protocol version the page asks for (default 2)")  # fmt: skip
    p.add_argument(
        "--replay", metavar="LOGFILE", help="replay a DIS log into the private server; the page follows"
    )
    p.add_argument("--speed", type=positive, default=1.0, help="--replay: speed (default 1)")
    p.add_argument("--loop", action="store_true", help="--replay: start again at the end")
    p.add_argument("--seconds", type=positive, help="stop after this many seconds (default: until Ctrl-C)")
    p.add_argument("--json", action="store_true", help="print the ready line (URLs) as JSON")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from client_stub.web.vendor import VENDOR, vendored

    if args.with_server and args.server:
        raise UsageError("--with-server or --server, not both")
    if args.replay and args.server:
        raise UsageError("--replay runs its own server: not with --server")
    if not vendored():
        print(
            f"ttes web: three.js is not vendored in {VENDOR}: run `make vendor` (needs npm)", file=sys.stderr
        )
        return 1
    replayer = None
    if args.replay:
        replayer = _replayer(args)
        if replayer is None:
            return 1
    from server.listen import bind_tcp

    try:
        sockets = bind_tcp(args.host, args.port)  # a taken port fails now, naming it, before the data loads
        return _serve(args, replayer, sockets)
    except OSError as exc:
        print(f"ttes web: {exc.strerror or exc}", file=sys.stderr)
        return 1


def _replayer(args: argparse.Namespace) -> Any:
    """The DIS log as a Replayer (None, said why, when it cannot be read or holds no soldier)."""
    from client_stub.dis import LogCursor, Replayer
    from protocol.dis import DisError, read_log
    from ttes.commands.replay import not_dis, nothing_to_replay

    try:
        log = read_log(args.replay)
    except (DisError, OSError) as exc:
        print(f"ttes web: {exc}", file=sys.stderr)
        return None
    if not_dis("web", args.replay, log):
        return None
    if not len(log.batch):
        print(f"ttes web: {args.replay}: {nothing_to_replay(log)}", file=sys.stderr)
        return None
    return Replayer(LogCursor(log), speed=args.speed, loop=args.loop)


async def _replay(nursery: Any, server: Any, replayer: Any, site: Any) -> None:
    """Drive the private server with the replay (as ``ttes replay --no-stub``); the site tells the page where
    the soldiers are, and their DIS force (the page colours them by it)."""
    from client_stub.dis.drive import replay_to_server
    from client_stub.dis.sink import ServerSink
    from client_stub.link.client import Client

    link = Client("ttes-web-replay")
    host, port = server.addresses[0]
    await link.open(nursery, host, port)
    sink = ServerSink(link)
    site.entities = lambda: (sink.live_requests(), replayer.translator.force[sink.live_slots()])
    await replay_to_server(replayer, sink, finish=False)


def _serve(args: argparse.Namespace, replayer: Any, sockets: list[Any]) -> int:
    import contextlib

    import trio

    from client_stub.web.site import Site, serve_site
    from ttes.commands.replay import private_server, stop_on_signal
    from ttes.output import print_json

    async def main() -> int:
        async with contextlib.AsyncExitStack() as stack:
            ws_host, ws_port = args.server or (
                DEFAULT_SERVER.split(":")[0],
                int(DEFAULT_SERVER.split(":")[1]),
            )
            if args.with_server or replayer is not None:
                data_dir = Path(args.data_dir) if args.data_dir else None
                server = await stack.enter_async_context(
                    private_server(data_dir, args.synthetic_server, websocket=True)
                )
                ws_host, ws_port = server.ws_addresses[0]
            ws_url = f"ws://{_url_host(ws_host)}:{ws_port}/"
            site = Site({"ws": ws_url, "soldiers": args.soldiers, "version": args.wire_version})
            nursery = await stack.enter_async_context(trio.open_nursery())
            if replayer is not None:
                site.config.update(role="observer", entities="entities.json")
                nursery.start_soon(_replay, nursery, server, replayer, site)
            where = await nursery.start(serve_site, site, sockets)
            url = f"http://{_url_host(where[0])}:{where[1]}/"
            if args.json:
                print_json({"event": "ready", "url": url, "server": ws_url})
            else:
                print(f"ttes web: open {url} (the page connects to {ws_url})", flush=True)
            sys.stdout.flush()
            with trio.move_on_after(args.seconds if args.seconds is not None else float("inf")):
                await stop_on_signal(nursery.cancel_scope)
            nursery.cancel_scope.cancel()
        return 0

    return trio.run(main)


def _url_host(h: str) -> str:
    return f"[{h}]" if ":" in h else h
