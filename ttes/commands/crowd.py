"""`ttes crowd`: render thousands of soldiers (moderngl, offscreen with --headless) and report frames/second.

The soldiers follow the realistic mix of `ttes loadtest`: posed from a Jack/TTES server's update stream
(--spawn-server, or --host/--port), or on the client alone (--offline, the default without a server). Three
levels of detail by distance: soldier.fig near, DI.fig in the middle, a 2-triangle silhouette impostor far
away. A free camera orbits the crowd, or stands where --camera puts it. `ttes crowd prepare` writes the near
level's geometry (client_stub/crowd/data/soldier.tips, spat from figures/soldier.fig).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from ttes.arguments import UsageError, count, host, output_file, port, positive, size
from ttes.link_options import add_link_options, link_credentials


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "crowd", help="render a crowd of soldiers (moderngl) and measure fps", description=__doc__
    )
    actions = p.add_subparsers(dest="crowd_command", metavar="ACTION")
    prep = actions.add_parser(
        "prepare",
        help="write the near level's TIPS geometry from figures/soldier.fig",
        description="Spit figures/soldier.fig to client_stub/crowd/data/soldier.tips (read by the renderer).",
    )
    prep.add_argument("--out", type=Path, help="output file (default client_stub/crowd/data/soldier.tips)")
    prep.add_argument("--check", action="store_true", help="exit 1 if the shipped file is not current")
    prep.set_defaults(crowd_func=_prepare)
    p.add_argument("--headless", action="store_true", help="render offscreen (EGL); the only mode so far")
    p.add_argument("--soldiers", type=count(1), default=1000)
    p.add_argument("--seconds", type=positive, default=10.0)
    p.add_argument(
        "--out",
        type=output_file(".png", ".mp4"),
        metavar="FILE.png|FILE.mp4",
        help="last frame (.png) or every frame (.mp4)",
    )
    p.add_argument("--size", type=size, default="1280x720", help="image size WIDTHxHEIGHT (default 1280x720)")
    where = p.add_mutually_exclusive_group()
    where.add_argument("--offline", action="store_true", help="pose on the client, no server (default)")
    where.add_argument("--spawn-server", action="store_true", help="run a `ttes server` child and use it")
    where.add_argument("--host", type=host, help="use the Jack/TTES server at this address")
    p.add_argument("--port", type=port, default=7000)
    p.add_argument(
        "--clients", type=count(1), default=2, help="connections sharing the soldiers (server mode)"
    )
    p.add_argument("--server-data", choices=("auto", "synthetic", "default"), default="auto")
    p.add_argument("--mix", choices=("realistic", "moving"), default="realistic")
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--spacing", type=float, default=3.0, help="metres between soldiers' home positions")
    p.add_argument("--near", type=float, default=10.0, help="soldier.fig closer than this many metres")
    p.add_argument("--mid", type=float, default=30.0, help="DI.fig closer than this, impostors beyond")
    p.add_argument(
        "--camera", metavar="X,Y,Z,HEADING,PITCH", help="a fixed free-camera pose (default: orbit the crowd)"
    )
    p.add_argument("--terrain", help="terrain mesh (default the village; 'none' for none)")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    add_link_options(p)
    p.set_defaults(func=run, crowd_func=None)


def run(args: argparse.Namespace) -> int:
    if args.crowd_func is not None:
        return int(args.crowd_func(args))
    from client_stub.crowd.app import NEAR_TIPS, CrowdConfig, run_crowd
    from ttes.output import print_json

    if not args.headless:
        print("ttes crowd: only --headless is implemented (no window)", file=sys.stderr)
        return 2
    if not NEAR_TIPS.is_file():
        write_near_tips(NEAR_TIPS)
    width, height = args.size
    pose = None
    if args.camera:
        try:
            pose = tuple(float(v) for v in args.camera.split(","))
        except ValueError:
            pose = ()
        if len(pose) != 5:
            print("ttes crowd: error: --camera wants X,Y,Z,HEADING,PITCH", file=sys.stderr)
            return 2
    server = bool(args.spawn_server or args.host)
    cfg = CrowdConfig(
        soldiers=args.soldiers,
        seconds=args.seconds,
        width=width,
        height=height,
        out=str(args.out) if args.out else None,
        source="server" if server else "offline",
        host=args.host or "127.0.0.1",
        port=args.port,
        spawn_server=args.spawn_server,
        server_data=args.server_data,
        clients=args.clients,
        mix=args.mix,
        seed=args.seed,
        spacing=args.spacing,
        near_m=args.near,
        mid_m=args.mid,
        camera="fixed" if pose else "orbit",
        camera_pose=pose,
        terrain=args.terrain,
        credentials=link_credentials(args),
    )
    try:
        cfg.check()
    except ValueError as exc:  # options that do not go together (--near beyond --mid)
        raise UsageError(str(exc)) from None
    try:
        stats = run_crowd(cfg)
    except RuntimeError as exc:
        print(f"ttes crowd: error: {exc}", file=sys.stderr)
        return 1
    stats.pop("_image", None)
    if args.json:
        print_json(stats)
        return 0
    drawn = stats["mean_drawn"]
    print(
        f"ttes crowd: {stats['soldiers']} soldiers, {stats['width']}x{stats['height']}, "
        f"{stats['frames']} frames in {stats['seconds']} s: {stats['fps']} fps "
        f"(frame p50 {stats['frame_ms_p50']} ms, "
        f"max {stats['frame_ms_max']} ms)\n"
        f"  drawn per frame: near {drawn['near']}, mid {drawn['mid']}, far {drawn['far']} "
        f"({stats['triangles_last_frame']} triangles in the last frame); source {stats['source']}"
        + (
            f", posing {stats['posing']}, {stats['soldier_updates_received']} soldier updates"
            if server
            else ""
        )
        + (f"\n  wrote {stats['out']}" if stats.get("out") else "")
    )
    return 0


def near_tips_text() -> str:
    """figures/soldier.fig spat as TIPS (the CLI may read Peabody files; the renderer may not)."""
    from peabody.tips import format_tips, load_for_spit
    from ttes.paths import FIGURES

    return format_tips(load_for_spit([FIGURES / "soldier.fig"]))


def write_near_tips(out: Path) -> None:
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(near_tips_text(), encoding="utf-8")


def _prepare(args: argparse.Namespace) -> int:
    from client_stub.crowd.app import NEAR_TIPS

    out = args.out or NEAR_TIPS
    text = near_tips_text()
    if args.check:
        current = out.is_file() and out.read_text(encoding="utf-8") == text
        print(f"{out}: {'current' if current else 'stale or missing'}")
        return 0 if current else 1
    write_near_tips(out)
    print(f"wrote {out} ({len(text)} bytes)")
    return 0
