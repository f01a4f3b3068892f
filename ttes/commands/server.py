"""`ttes server`: run the Jack/TTES animation server (seed 002, sections 3.6-3.7) until SIGINT/SIGTERM.

Runs the start-up script (`jack-ttes-soldier_low.jcl` in the data dir) and prints a line containing `ready`
and the bound address once it accepts connections. Binds 127.0.0.1 unless told otherwise.

Role tokens (observer_token, controller_token, operator_token in the --config file) may come from the
environment instead: TTES_OBSERVER_TOKEN, TTES_CONTROLLER_TOKEN, TTES_OPERATOR_TOKEN win over the file.
Without any token the server listens on loopback only. Tokens are never logged or printed.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

from server.fabric import BLOCK, DDS_DOMAIN_MAX, FabricConfig
from ttes.arguments import UsageError, count, host, listen_port, non_negative, positive

if TYPE_CHECKING:
    from server.app import TtesServer
    from server.fabric.nodes import Sharding


def register(sub: argparse._SubParsersAction) -> None:
    p = add_server_parser(sub, "server", "run the Jack/TTES animation server", __doc__ or "")
    p.add_argument(
        "--shard",
        metavar="K/N",
        help="animate only soldiers whose index is K modulo N and publish them on the fabric (ttes front "
        "serves the clients; needs the [fabric] extra)",
    )
    add_fabric_options(p)


def add_fabric_options(p: argparse.ArgumentParser) -> None:
    """The publish/subscribe fabric between shards and front-ends (docs/SCALING.md)."""
    p.add_argument(
        "--fabric", choices=("zenoh", "dds"), default="zenoh", help="fabric engine (default zenoh)"
    )
    p.add_argument("--fabric-listen", metavar="HOST:PORT", default="", help="fabric endpoint to listen on")
    p.add_argument(
        "--fabric-connect",
        metavar="HOST:PORT",
        action="append",
        default=[],
        help="fabric endpoint to connect to (repeatable; a shard connects to its front-ends)",
    )
    p.add_argument(
        "--fabric-block",
        metavar="N",
        type=count(1, 65536),
        default=BLOCK,
        help="soldier indices per pose topic: a front-end hears the blocks its clients watch, or each "
        f"shard whole when they watch every block (default {BLOCK}; shards and front-ends must agree)",
    )
    p.add_argument(
        "--fabric-domain",
        metavar="ID",
        type=count(0, DDS_DOMAIN_MAX),
        help="Cyclone DDS domain id (default 0): clusters on one network in different domains never "
        "hear each other; --fabric dds only",
    )


def add_server_parser(
    sub: argparse._SubParsersAction, name: str, help_text: str, description: str
) -> argparse.ArgumentParser:
    """The parser of ``ttes server`` and of ``ttes front`` (a front-end takes the same settings)."""
    from server.config import limits_help

    p = sub.add_parser(
        name,
        help=help_text,
        description=description,
        epilog="limits (config file keys; docs/PROTOCOL.md section 15 says what a peer may cost):\n"
        + limits_help(),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument(
        "--host", type=host, help="address to bind (default 127.0.0.1; 0.0.0.0 inside a container)"
    )
    p.add_argument("--port", type=listen_port, help="TCP port (default 7000; 0 = any free port)")
    p.add_argument(
        "--ws-port",
        type=listen_port,
        help="also serve the protocol over WebSocket on this port (browsers: ttes web; 0 = any free port)",
    )
    p.add_argument(
        "--data-dir", help="folder with the start-up script, figures/, channelsets/, posture_graphs/"
    )
    p.add_argument(
        "--cache-dir",
        help="channelset .npz caches (default $TTES_CACHE_DIR or ~/.cache/jack-ttes; never the data dir)",
    )
    p.add_argument("--config", metavar="FILE.toml", help="settings file (flags override it)")
    p.add_argument("--tick-hz", type=positive, help="simulation ticks per second (default 30)")
    p.add_argument(
        "--startup-script", help='JCL run at start-up (default jack-ttes-soldier_low.jcl; "" = none)'
    )
    p.add_argument(
        "--throttle", type=non_negative, help="seconds between two updates of one soldier (overrides JCL)"
    )
    p.add_argument("--json-logs", action="store_true", default=None, help="log one JSON object per line")
    p.add_argument(
        "--synthetic",
        action="store_true",
        help="serve a generated synthetic motion library (from a temporary data dir) instead of --data-dir",
    )
    p.add_argument("--json", action="store_true", help="print the ready line as JSON")
    p.set_defaults(func=run)
    return p


def run(args: argparse.Namespace) -> int:
    import logging
    import os
    import tempfile

    import trio

    from protocol import fused
    from server.app import TtesServer, check_exposure, run_server
    from server.config import ConfigError, ServerConfig, load_config, with_env_tokens
    from server.logging import configure
    from server.motion import blend_loop
    from ttes.output import print_json

    cfg = load_config(args.config) if args.config else ServerConfig()  # a bad file: exit 1, naming it
    try:  # a flag's value the settings refuse: a usage error
        cfg = with_env_tokens(cfg, os.environ).with_overrides(
            host=args.host,
            port=args.port,
            ws_port=args.ws_port,
            data_dir=args.data_dir,
            cache_dir=args.cache_dir,
            tick_hz=args.tick_hz,
            startup_script=args.startup_script,
            throttle=args.throttle,
            json_logs=args.json_logs,
        )
    except ConfigError as exc:
        raise UsageError(str(exc)) from None
    plan = _fabric_plan(args)
    tmp = None
    if args.synthetic:
        from server.startup import write_synthetic_data_dir

        tmp = tempfile.TemporaryDirectory(prefix="ttes-synthetic-")
        synth = write_synthetic_data_dir(tmp.name)
        cfg = cfg.with_overrides(data_dir=synth.path, startup_script=synth.startup_script)
    configure(json_logs=cfg.json_logs, level=logging.DEBUG if args.verbose > 1 else logging.INFO)
    try:
        try:
            check_exposure(cfg)  # no tokens: loopback only (--host beyond it without tokens: a usage error)
        except ConfigError as exc:
            raise UsageError(str(exc)) from None
        server = TtesServer(cfg)
        server.bind()  # a port in use fails here, at once and naming host:port, before the data loads
        server.freeze_gc = True  # the loaded library out of the GC's full collections (server.gc_freeze)
        fused.warm()  # the compiled encode (the fast extra) before the first client, not at its first update
        blend_loop.warm()  # and the sampling's blend, before the first tick
        server.start_world()  # a bad script or data dir fails here, before accepting
        start_fabric, close_fabric = _fabric_node(server, plan, args.fabric_block)

        def listening(s: TtesServer) -> None:
            start_fabric()
            host, port = s.addresses[0]
            m = s.world.manager
            soldiers = m.count if m is not None else 0
            if args.json:
                print_json(
                    {
                        "event": "ready" if s.world.ready else "listening",
                        "host": host,
                        "port": port,
                        "addresses": [f"{h}:{p}" for h, p in s.addresses],
                        "websocket": [f"{h}:{p}" for h, p in s.ws_addresses],
                        "soldiers": soldiers,
                    }
                )
            else:
                state = "ready" if s.world.ready else "listening (not ready: waiting for a client's JCL)"
                ws = "".join(f", WebSocket ws://{h}:{p}/" for h, p in s.ws_addresses[:1])
                print(f"ttes server: {state} on {host}:{port}{ws} ({soldiers} soldiers)", flush=True)
            sys.stdout.flush()

        try:
            trio.run(lambda: run_server(server, on_listening=listening))
        except BaseExceptionGroup as group:  # errors inside trio's nurseries arrive grouped
            leaf = _first_leaf(group)
            if isinstance(leaf, OSError | ValueError):
                raise leaf from None
            raise
        finally:
            close_fabric()  # its threads would keep the process alive
        return 0
    finally:
        if tmp is not None:
            tmp.cleanup()


@dataclass(frozen=True)
class _FabricPlan:
    """What ``--shard``/``ttes front`` asked for, checked before the data loads (a usage error at once)."""

    sharding: Sharding | None  # this shard (None: a front-end)
    front: Sharding  # which front-end of how many
    shards: int
    config: FabricConfig


def _fabric_plan(args: argparse.Namespace) -> _FabricPlan | None:
    """The node this process joins the fabric as, or None (a plain server); a bad value: UsageError."""
    shard, shards = getattr(args, "shard", None), getattr(args, "shards", None)
    if shard is None and shards is None:
        return None
    from server.fabric.batch import MAX_FRONTS
    from server.fabric.nodes import Sharding

    try:
        sharding = Sharding.parse(shard) if shard is not None else None
        front = Sharding.parse(getattr(args, "front", None) or "0/1")
        if front.n > MAX_FRONTS:
            raise ValueError(
                f"--front {args.front}: at most {MAX_FRONTS} front-ends (a batch's fence count is a byte)"
            )
    except ValueError as exc:
        raise UsageError(str(exc)) from None
    domain = getattr(args, "fabric_domain", None)
    if domain is not None and args.fabric != "dds":
        raise UsageError(
            f"--fabric-domain {domain}: a DDS domain, and --fabric is {args.fabric} "
            "(Zenoh's nodes meet at their --fabric-listen/--fabric-connect endpoints)"
        )
    config = FabricConfig(args.fabric, args.fabric_listen, tuple(args.fabric_connect), domain or 0)
    return _FabricPlan(sharding, front, int(shards or 1), config)


def _fabric_node(
    server: TtesServer, plan: _FabricPlan | None, block: int
) -> tuple[Callable[[], None], Callable[[], None]]:
    """Join the fabric as a shard (``--shard``) or a front-end (``ttes front``); returns what starts taking
    messages (call it on the trio loop once serving) and what leaves the fabric (no-ops: a plain server)."""
    if plan is None:
        return (lambda: None), (lambda: None)
    import trio

    from server.fabric import open_fabric
    from server.fabric.nodes import FrontNode, ShardNode

    fabric = open_fabric(plan.config)
    if plan.sharding is not None:
        server.codes_only()  # its batches carry codes: the board's float poses would be written for nothing
        node = ShardNode(server, fabric, plan.sharding, block=block)
        node.keep_own()
        return (lambda: node.start(trio.lowlevel.current_trio_token())), fabric.close
    node_f = FrontNode(server, fabric, plan.shards, front=plan.front, block=block)
    return (lambda: node_f.start(trio.lowlevel.current_trio_token())), fabric.close


def _first_leaf(exc: BaseException) -> BaseException:
    while isinstance(exc, BaseExceptionGroup) and exc.exceptions:
        exc = exc.exceptions[0]
    return exc
