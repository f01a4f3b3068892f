"""`ttes stub`: the TTES stub image generator (seed 002, 3.5 and 4): a village, soldiers, keys, Jack.

With a display it opens a window (press ? for the keys); with --headless it renders offscreen (EGL) to a
video or a PNG, touring every posture and locomotion mode. Soldiers are posed by a Jack/TTES server
(--host/--port, or --spawn-server to start `ttes server` on a free loopback port), or offline without one.
`ttes stub make-terrain` regenerates the village mesh. `ttes stub --scenario FILE --record OUT.mp4` records
one soldier doing what a scenario file says (client_stub/stub/scenario.py), posed by an in-process server,
one frame per server tick, with a contact sheet beside it.

A lost server shows at the next frame (window caption, console; the stub poses the soldiers meanwhile); the
stub reconnects with backoff (0.5..8 s) and binds its soldiers again. Exit status: 0 done; 1 no terrain or no
server at the start; 2 bad arguments or no display; 3 the server was lost and not back (given up after
--give-up-after, or still lost at the end of a headless run).
"""

from __future__ import annotations

import argparse
import contextlib
import functools
import os
import sys
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from client_stub.link.auth import Credentials
    from client_stub.stub.jack import JackProc

from ttes.arguments import (
    HEADLESS_NEEDS_OUT,
    VIDEO_SUFFIXES,
    UsageError,
    host,
    non_negative,
    number,
    output_file,
    port,
    positive,
    size,
    video_or_png,
)
from ttes.link_options import add_link_options, link_credentials


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("stub", help="the TTES stub image generator (pyrender)", description=__doc__)
    p.add_argument(
        "--headless", action="store_true", help="render offscreen (EGL) instead of opening a window"
    )
    p.add_argument("--seconds", type=positive, default=40.0, help="headless: length of the run (default 40)")
    p.add_argument(
        "--out",
        type=video_or_png,
        help=f"--headless (needed): the video ({', '.join(VIDEO_SUFFIXES)}) or a .png of the last frame",
    )
    p.add_argument("--fps", type=number(1, 120), default=15.0, help="frames per second (default 15)")
    p.add_argument("--size", type=size, default="640x480", help="image size WxH (default 640x480)")
    p.add_argument(
        "--renderer",
        choices=("gl", "pyrender"),
        default="gl",
        help="headless: moderngl (gl, default: fast) or pyrender (the window's renderer, multisampled)",
    )
    p.add_argument("--host", type=host, help="Jack/TTES server host")
    p.add_argument("--port", type=port, default=7000, help="server port (default 7000)")
    p.add_argument("--spawn-server", action="store_true", help="start `ttes server` on a free loopback port")
    p.add_argument(
        "--server-data-dir",
        type=Path,
        help="--spawn-server: the server's data dir (default: the repository's if it has the start-up "
        "script, else a stand-in: synthetic motions on the shipped figures)",
    )
    p.add_argument("--terrain", type=Path, help="terrain mesh (OBJ, glTF, PLY); default: the village")
    p.add_argument(
        "--terrain-up", choices=("y", "z"), help="the terrain file's up axis (default: y for glTF)"
    )
    p.add_argument("--artic-dir", type=Path, help="where the TIPS loader writes the .artic files")
    p.add_argument("--no-tour", action="store_true", help="headless: no scripted key presses")
    p.add_argument(
        "--ready-timeout", type=positive, default=30.0, help="seconds to wait for the server's READY"
    )
    p.add_argument(
        "--give-up-after",
        type=non_negative,
        default=120.0,
        metavar="S",
        help="seconds of reconnecting to a lost server before the stub gives up and exits 3 (default 120)",
    )
    p.add_argument("--json", action="store_true", help="machine-readable summary")
    add_link_options(p)
    p.add_argument("--scenario", type=Path, help="a scenario file of timed requests for one soldier")
    p.add_argument(
        "--record",
        type=output_file(*VIDEO_SUFFIXES),
        help="--scenario: the video (.mp4/.gif), one frame per server tick",
    )
    p.add_argument(
        "--sheet", type=output_file(".png"), help="--scenario: contact sheet PNG (default: beside the video)"
    )
    p.add_argument(
        "--tick-hz", type=number(1, 240), default=30.0, help="--scenario: the server's tick rate (30)"
    )
    actions = p.add_subparsers(dest="stub_command", metavar="ACTION")
    terrain = actions.add_parser(
        "make-terrain",
        help="regenerate the village mesh (client_stub/data/village.glb)",
        description="Write the generated village (glTF binary) and its landmarks (.json beside it).",
    )
    terrain.add_argument(
        "--out", dest="terrain_out", type=Path, help="output .glb (default: the shipped one)"
    )
    terrain.add_argument("--json", dest="terrain_json", action="store_true", help="machine-readable output")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    if args.stub_command == "make-terrain":
        return _make_terrain(args)
    if args.scenario or args.record:
        return _record_scenario(args)
    from ttes.output import na, print_json

    width, height = args.size
    if args.headless:
        if args.out is None:
            raise UsageError(HEADLESS_NEEDS_OUT)
        os.environ.setdefault("PYOPENGL_PLATFORM", "egl")
    elif not (
        os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY") or sys.platform in ("darwin", "win32")
    ):
        print("ttes stub: no display; use --headless", file=sys.stderr)
        return 2
    from client_stub.link.client import LinkError
    from client_stub.link.spawn import spawn_server
    from client_stub.stub.app import StubApp
    from client_stub.stub.live import LiveSoldiers, populate_demo
    from client_stub.stub.terrain import DEFAULT_TERRAIN, TerrainError, load_terrain
    from ttes.progress import ProgressBar

    try:
        terrain = load_terrain(args.terrain or DEFAULT_TERRAIN, args.terrain_up)
    except TerrainError as exc:
        print(f"ttes stub: {exc}", file=sys.stderr)
        return 1
    live = LiveSoldiers()
    app = StubApp(terrain, live, artic_dir=args.artic_dir)
    populate_demo(app)
    server = None
    stack = contextlib.ExitStack()
    try:
        if args.spawn_server or args.host:
            host, port = args.host or "127.0.0.1", args.port
            try:
                if args.spawn_server:
                    data_dir = args.server_data_dir or _server_data_dir(stack)
                    with ProgressBar("ttes server: loading its library") as loading:
                        server = spawn_server(
                            ["--data-dir", str(data_dir)], data="default", waiting=loading.waited
                        )
                    host, port = server.host, server.port
                jack = _connect(host, port, link_credentials(args))
            except LinkError as exc:
                print(f"ttes stub: {exc}", file=sys.stderr)
                return 1
            live.reconnect = functools.partial(_connect, host, port, link_credentials(args))
            live.give_up_after, live.ready_timeout = args.give_up_after, args.ready_timeout
            if not live.connect(app, jack, args.ready_timeout):
                print(
                    f"ttes stub: server not ready ({jack.failure or 'timeout'}); posing offline",
                    file=sys.stderr,
                )
        from client_stub.stub.gl_render import offscreen_renderer
        from client_stub.stub.render import StubRenderer

        app.renderer = (
            offscreen_renderer(width, height, args.renderer)
            if args.headless
            else StubRenderer(width, height, offscreen=False)
        )
        app.renderer.set_terrain(terrain.meshes)
        if not args.headless:
            from client_stub.stub.viewer import run_viewer

            run_viewer(app, width, height, args.fps)
            return 3 if app.gave_up else 0
        from client_stub.stub.headless import run_headless
        with ProgressBar("ttes stub") as bar:
            summary = run_headless(app, args.seconds, args.out, fps=args.fps, realtime=app.link is not None,
                                   tour=not args.no_tour, progress=bar)  # fmt: skip
        app.renderer.close()
    finally:
        app.close()
        if server is not None:
            code = server.stop()
            server.close()
            print(f"ttes server stopped (exit {code})", file=sys.stderr)
        stack.close()
    if args.json:
        print_json(summary)
    else:
        print(
            f"wrote {summary['out']}: {summary['frames']} frames, {summary['soldiers']} soldiers, "
            f"render {na(summary['render_fps'])} fps, server {'yes' if summary['server'] else 'no'}"
        )
    if app.gave_up or app.server_lost:
        print(f"ttes stub: {app.gave_up or app.server_lost}", file=sys.stderr)
        return 3
    return 0


def _record_scenario(args: argparse.Namespace) -> int:
    if not (args.scenario and args.record):
        raise UsageError("--scenario and --record go together")
    os.environ.setdefault("PYOPENGL_PLATFORM", "egl")
    from client_stub.stub.scenario import ScenarioError, load_scenario
    from client_stub.stub.terrain import DEFAULT_TERRAIN, TerrainError, load_terrain
    from ttes.output import print_json
    from ttes.scenario_record import Recording, record

    try:
        scenario = load_scenario(args.scenario)
        terrain = load_terrain(args.terrain or DEFAULT_TERRAIN, args.terrain_up)
    except (OSError, ScenarioError, TerrainError) as exc:
        print(f"ttes stub: {args.scenario}: {exc}", file=sys.stderr)
        return 1
    sheet = args.sheet or args.record.with_name(args.record.stem + "_sheet.png")
    rec = Recording(scenario, terrain, args.record, sheet, args.size, args.tick_hz,
                    args.server_data_dir, args.artic_dir)  # fmt: skip
    summary = record(rec)
    if args.json:
        print_json(summary)
    else:
        print(
            f"wrote {summary['out']} ({summary['frames']} frames at {summary['hz']:g} Hz), {summary['sheet']}"
        )
    return 0


def _connect(host: str, port: int, credentials: Credentials) -> JackProc:
    """A connected Jack link, with the command's token and TLS (LinkError when nothing answers)."""
    from client_stub.stub.jack import JackProc

    jack = JackProc()
    credentials.apply(jack.client)
    jack.initsocketconnection(host, port)
    return jack


def _make_terrain(args: argparse.Namespace) -> int:
    from client_stub.stub.terrain_gen import DEFAULT_OUT, write_village
    from ttes.output import print_json

    summary = write_village(args.terrain_out or DEFAULT_OUT)
    if args.terrain_json:
        print_json(summary)
    else:
        print(
            f"wrote {summary['file']}: {summary['bytes']} bytes, {summary['triangles']} triangles, "
            f"{summary['buildings']} buildings"
        )
    return 0


STARTUP_SCRIPT = "jack-ttes-soldier_low.jcl"


def _server_data_dir(stack: contextlib.ExitStack) -> Path:
    """The shipped data dir (the checkout's, or an install's copy) when the start-up script is on its search
    path (it lives in posture_graphs/), else a temporary stand-in."""
    import tempfile

    import ttes.paths
    from server.data_root import SEARCH_SUBDIRS

    if any((ttes.paths.ROOT / sub / STARTUP_SCRIPT).is_file() for sub in ("", *SEARCH_SUBDIRS)):
        return ttes.paths.ROOT
    tmp = Path(stack.enter_context(tempfile.TemporaryDirectory(prefix="ttes-stub-server-")))
    return stand_in_data_dir(tmp)


def stand_in_data_dir(directory: Path, soldiers: int = 10) -> Path:
    """A server data dir with the shipped figures (DI.fig, AK_47.fig, M16.fig) and the synthetic motion
    library of ``server.soldier.synthetic`` recorded on them, plus the seed's start-up files: until authored
    channelsets ship, this lets the stub and a real server agree on the figure (same joints, same table)."""
    import shutil

    import ttes.paths
    from peabody.loader import read_figure
    from server.soldier.synthetic import write_synthetic_library

    figures = directory / "figures"
    figures.mkdir(parents=True, exist_ok=True)
    for name in ("DI.fig", "AK_47.fig", "AK_47.pss", "M16.fig", "M16.pss"):
        shutil.copy(ttes.paths.FIGURES / name, figures / name)
    shutil.copytree(ttes.paths.FIGURES / "DI", figures / "DI", dirs_exist_ok=True)
    figs = [read_figure(figures / "DI.fig"), read_figure(figures / "AK_47.fig")]
    write_synthetic_library(directory / "posture_graphs", figs)
    env = "".join(
        f'figure Di2_{i} {{ file = "DI.fig"; }}\nfigure AK_47_{i} {{ file = "AK_47.fig"; }}\n'
        for i in range(soldiers)
    )
    (directory / "jack-ttes-soldier_low.env").write_text(env, encoding="utf-8")
    script = ['read_file("jack-ttes-soldier_low.env");']
    script += [f'create_soldier_state("s{i}","Di2_{i}","AK_47_{i}");' for i in range(soldiers)]
    script += [
        'set_channelset_parameters("no");',
        "set_ttes_soldier_throttle(0.04);",
        "start_ttes_socket_simulation();",
    ]
    (directory / STARTUP_SCRIPT).write_text("\n".join(script) + "\n", encoding="utf-8")
    return directory
