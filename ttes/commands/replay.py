"""`ttes replay`: replay a DIS logfile (pcap, pcapng, .dislog or raw PDUs) through Jack/TTES into the stub.

One soldier per lifeform entity: created on first sight, removed after the DIS timeout (12 s), when the
entity is deactivated or by a Remove Entity PDU, dead-reckoned between PDUs with its own algorithm, placed on
the stub's terrain in a local frame about --origin (default: the first entity). Appearance, velocity and
heading become entity requests for the server; Fire PDUs make a standing-still shooter fire for a moment.
Paced by the capture's receipt times, scaled by --speed (0 = as fast as possible); a silence longer than
--max-gap (5 s) replays as --max-gap seconds. --exercise N keeps exercise N's PDUs only.

With a display it opens the stub window (cameras and soldier selection on the keys; ? lists them);
--headless --out demo.mp4 renders a video; --no-stub only drives the server. The server: --host/--port for a
running one; by default a private one (its own process for the window; in this process for --no-stub, and for
--headless under a virtual clock, so the video is exact however slowly it renders). --offline: no server, the
stub poses the soldiers itself. The stub's terrain point (0, 0) is the local frame's origin.

A replay survives a server restart (window, --headless with --host, --no-stub): it goes on, the stub poses
the soldiers meanwhile (the window says "server lost"), the server is reconnected with backoff (0.5..8 s) and
the live soldiers are created again and posed by it (sink_relinked in the summary). Exit status: 0 replayed,
1 no server (at the start, or lost for longer than --give-up-after), a file that is not DIS, or nothing to
replay; 2 bad arguments (--start past the log's end included) or no display.
"""

from __future__ import annotations

import argparse
import contextlib
import functools
import math
import os
import sys
from collections.abc import AsyncIterator
from pathlib import Path
from typing import Any

from ttes.arguments import (
    HEADLESS_NEEDS_OUT,
    VIDEO_SUFFIXES,
    UsageError,
    host,
    non_negative,
    number,
    port,
    positive,
    size,
    video_or_png,
)
from ttes.commands.dis import exercise_id, not_dis
from ttes.link_options import add_link_options, link_credentials, link_error

DEFAULT_MAX_GAP = 5.0  # s: longer silences of a log replay as this long
_HELD = (  # what a log without soldiers holds instead: counter, words
    ("records", "records"),
    ("pdus", "DIS PDUs"),
    ("non_lifeforms", "non-lifeform entity states"),
    ("other_pdus", "PDUs of other types"),
    ("other_exercise", "PDUs of other exercises"),
    ("other_port", "UDP datagrams to other ports"),
    ("unsupported_version", "PDUs of unsupported versions"),
)


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "replay",
        help="replay a DIS logfile through Jack/TTES into the stub",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("logfile", type=Path, help="pcap, pcapng, .dislog or raw DIS PDUs")
    p.add_argument("--speed", type=_speed, default=1.0, help="replay speed factor (default 1; 0 = unlimited)")
    p.add_argument(
        "--loop", action="store_true", help="start again at the end (soldiers are removed and re-made)"
    )
    p.add_argument(
        "--start",
        type=float,
        default=0.0,
        metavar="T",
        help="begin T seconds into the log (silences included; at most the log's length)",
    )
    p.add_argument(
        "--max-gap",
        type=_max_gap,
        default=DEFAULT_MAX_GAP,
        metavar="S",
        help=f"replay a silence of the log longer than S seconds as S seconds (default "
        f"{DEFAULT_MAX_GAP:g}; 0: as recorded)",
    )
    p.add_argument(
        "--exercise",
        type=exercise_id,
        metavar="N",
        help="only the PDUs of DIS exercise N (1..255; default: every exercise)",
    )
    p.add_argument("--entities", metavar="FILTER",
                   help="keep only these, comma-separated: SITE:APP:ENTITY (numbers or *), force=N, "
                        "friendly, opposing, neutral, marking=TEXT or marking=PREFIX*")  # fmt: skip
    p.add_argument("--origin", metavar="LAT,LON,H", help="local frame origin (default: the first entity)")
    p.add_argument("--timeout", type=float, default=12.0, help="seconds without a PDU before a soldier goes")
    p.add_argument("--format", choices=("auto", "pcap", "pcapng", "dislog", "raw"), default="auto")
    p.add_argument("--dis-port", type=port, default=3000, help="UDP port of DIS in captures (default 3000)")
    p.add_argument("--any-port", action="store_true", help="read DIS on every UDP port of a capture")
    p.add_argument(
        "--headless", action="store_true", help="render offscreen (EGL) to --out instead of a window"
    )
    p.add_argument(
        "--out",
        type=video_or_png,
        help=f"--headless (needed): the video ({', '.join(VIDEO_SUFFIXES)}) or a .png of the last frame",
    )
    p.add_argument("--seconds", type=positive, help="headless: video length (default: the log, at --speed)")
    p.add_argument("--fps", type=number(1, 120), default=15.0, help="frames per second (default 15)")
    p.add_argument("--size", type=size, default="640x480", help="image size WxH (default 640x480)")
    p.add_argument(
        "--camera",
        choices=("action", "squad", "birds-eye", "soldier", "overhead"),
        default="action",
        help="start camera (default: ACTION CAM on a soldier and those near him, turning from force to force "
        "every 10 s; squad: the whole squad; keys take over)",
    )
    p.add_argument("--no-stub", action="store_true", help="no image generator: only drive the server")
    p.add_argument("--host", type=host, help="Jack/TTES server host (default: a private server)")
    p.add_argument("--port", type=port, default=7000, help="server port with --host (default 7000)")
    p.add_argument("--offline", action="store_true", help="no server: the stub poses the soldiers itself")
    p.add_argument(
        "--data-dir", type=Path, help="private server: its data directory (default: the project's)"
    )
    p.add_argument("--synthetic-server", action="store_true",
                   help="private server: serve the generated synthetic motion library")  # fmt: skip
    p.add_argument("--terrain", type=Path, help="terrain mesh (default: the village)")
    p.add_argument("--json", action="store_true", help="machine-readable summary on stdout")
    add_link_options(p)
    p.add_argument(
        "--give-up-after",
        type=non_negative,
        default=120.0,
        metavar="S",
        help="a lost server is reconnected (backoff 0.5..8 s; the soldiers are created again) "
        "for this long before the replay exits 1 (default 120; 0: exit at once)",
    )
    p.set_defaults(func=run)


def _max_gap(text: str) -> float | None:
    """``--max-gap S``: seconds (> 0), or 0 / ``off`` to keep the log's silences (None)."""
    if text.lower() in ("0", "off", "none"):
        return None
    try:
        v = float(text)
    except ValueError:
        v = math.nan
    if not (math.isfinite(v) and v > 0):
        raise argparse.ArgumentTypeError(
            f"--max-gap must be seconds > 0 (0: keep the silences), not {text!r}"
        )
    return v


def _speed(text: str) -> float:
    if text.lower() in ("0", "inf", "max", "unlimited"):
        return math.inf
    v = float(text)
    if not (math.isfinite(v) and v > 0):
        raise argparse.ArgumentTypeError("speed must be > 0 (or 0 for unlimited)")
    return v


def parse_origin(text: str | None) -> Any:
    """``LAT,LON,H`` -> LocalFrame (ValueError with the reason)."""
    if not text:
        return None
    from protocol.dis import LocalFrame

    try:
        lat, lon, h = (float(v) for v in text.split(","))
    except ValueError:
        raise ValueError(f"--origin must be LAT,LON,H in degrees and metres, not {text!r}") from None
    if not (-90 <= lat <= 90 and -180 <= lon <= 360 and math.isfinite(h)):
        raise ValueError(f"--origin {text!r} out of range")
    return LocalFrame(lat, lon, h)


@contextlib.asynccontextmanager
async def private_server(
    data_dir: Path | None, synthetic: bool, quiet: bool = True, websocket: bool = False
) -> AsyncIterator[Any]:
    """A Jack/TTES server in this trio run on a free loopback port (and a WebSocket one with ``websocket``:
    ``ttes web``). The project's data dir first; without a motion library there (or with ``synthetic``) the
    generated synthetic one."""
    import logging
    import tempfile

    import trio

    from server.app import TtesServer
    from server.config import ServerConfig
    from server.jcl import JclError
    from server.logging import configure
    from server.startup import write_synthetic_data_dir

    configure(level=logging.WARNING if quiet else logging.INFO)
    with tempfile.TemporaryDirectory(prefix="ttes-replay-") as tmp:
        server = None
        if not synthetic:
            ws_port = 0 if websocket else None
            cfg = ServerConfig(port=0, ws_port=ws_port).with_overrides(data_dir=data_dir)
            server = TtesServer(cfg)
            try:
                server.start_world()
            except (JclError, OSError, ValueError) as exc:
                print(f"ttes: private server: {exc}; using the synthetic motion library", file=sys.stderr)
                server = None
        if server is None:
            synth = write_synthetic_data_dir(tmp)
            server = TtesServer(
                ServerConfig(
                    port=0,
                    ws_port=0 if websocket else None,
                    data_dir=synth.path,
                    startup_script=synth.startup_script,
                )
            )
            server.start_world()
        async with trio.open_nursery() as nursery:
            await nursery.start(server.serve)
            try:
                yield server
            finally:
                server.shutdown()


def run(args: argparse.Namespace) -> int:
    loaded = _load(args)
    if isinstance(loaded, int):
        return loaded
    replayer, size = loaded
    if args.no_stub:
        summary = _run_server_only(args, replayer)
    elif args.headless:
        if args.loop and args.seconds is None:
            raise UsageError("--loop --headless needs --seconds")
        if args.out is None:
            raise UsageError(HEADLESS_NEEDS_OUT)
        os.environ.setdefault("PYOPENGL_PLATFORM", "egl")
        summary = _run_headless(args, replayer, size)
    else:
        if not (
            os.environ.get("DISPLAY")
            or os.environ.get("WAYLAND_DISPLAY")
            or sys.platform in ("darwin", "win32")
        ):
            print("ttes replay: no display; use --headless --out FILE.mp4 (or --no-stub)", file=sys.stderr)
            return 2
        summary = _run_window(args, replayer, size)
    if summary is None:
        return 1
    if args.json:
        from ttes.output import print_json

        print_json(summary)
    else:
        extra = f", wrote {summary['out']} ({summary['frames']} frames)" if "out" in summary else ""
        skipped = summary.get("silence_skipped_s", 0)
        cut = f" ({skipped:.1f} s of silence skipped, --max-gap {args.max_gap:g} s)" if skipped else ""
        print(f"replayed {summary['replay_time']:.1f} s{cut}: {summary['created']} soldiers, "
              f"{summary['pdus']} PDUs, {summary['requests']} requests{extra}")  # fmt: skip
    return 0


def _log_length(replayer: Any) -> float | None:
    """The replay time the status lines count to: the log's length (None when looping)."""
    return None if replayer.loop else replayer.cursor.duration


def _load(args: argparse.Namespace) -> tuple[Any, tuple[int, int]] | int:
    """The checked arguments and the log, as a Replayer (and the image size); else the exit status: 2 for
    bad arguments (--start past the log's end included), 1 for a file that cannot be read, is not DIS or holds
    no soldier."""
    from client_stub.dis import EntityFilter, FilterError, LogCursor, Replayer
    from protocol.dis import DisError, read_log

    try:
        entity_filter = EntityFilter.parse(args.entities) if args.entities else None
        origin = parse_origin(args.origin)
        if not (math.isfinite(args.start) and args.start >= 0):
            raise ValueError("--start must be >= 0 seconds")
        if not (math.isfinite(args.timeout) and args.timeout > 0):
            raise ValueError("--timeout must be > 0 seconds")
        if args.offline and args.no_stub:
            raise ValueError("--offline --no-stub would do nothing")
    except (FilterError, ValueError) as exc:
        print(f"ttes replay: {exc}", file=sys.stderr)
        return 2
    try:  # a log that cannot be read is a runtime error (1), not a usage error
        log = read_log(args.logfile, fmt=args.format, port=None if args.any_port else args.dis_port,
                       exercise=args.exercise)  # fmt: skip
    except (DisError, OSError) as exc:
        print(f"ttes replay: {exc}", file=sys.stderr)
        return 1
    if not_dis("replay", args.logfile, log):
        return 1
    if not len(log.batch):
        print(f"ttes replay: {args.logfile}: {nothing_to_replay(log)}", file=sys.stderr)
        return 1
    if args.start > log.duration:
        print(f"ttes replay: --start {args.start:g} is past the end of {args.logfile} "
              f"({log.duration:.1f} s long)", file=sys.stderr)  # fmt: skip
        return 2
    cursor = LogCursor(log, entity_filter, max_gap=args.max_gap)
    replayer = Replayer(cursor, speed=args.speed, loop=args.loop, start=args.start, origin=origin,
                        timeout=args.timeout)  # fmt: skip
    return replayer, args.size


def nothing_to_replay(log: Any) -> str:
    """Why a DIS log gives no soldiers, in words (what it holds instead, and the option that may help)."""
    c = log.counters
    held = [f"{what}: {c.get(k, 0)}" for k, what in _HELD if c.get(k, 0) or k in ("records", "pdus")]
    hint = ""
    if c.get("other_port"):
        hint = "; DIS on another port? try --dis-port P or --any-port"
    elif c.get("other_exercise"):
        hint = f"; exercises in the log: {', '.join(map(str, sorted(log.exercises)))}"
    return f"no lifeform Entity State PDUs to replay ({', '.join(held)}){hint}"


async def stop_on_signal(scope: Any) -> None:
    """Cancel ``scope`` on SIGINT / SIGTERM (so the caller can still take its soldiers off the server)."""
    import signal

    import trio

    with trio.open_signal_receiver(signal.SIGINT, signal.SIGTERM) as signals:
        async for _ in signals:
            scope.cancel()
            return


# -- server only ---------------------------------------------------------------------------------
def _run_server_only(args: argparse.Namespace, replayer: Any) -> dict | None:
    import trio

    from client_stub.dis.drive import ProgressLine, replay_to_server
    from client_stub.dis.reconnect import connector, keep_linked_or_stop
    from client_stub.dis.sink import ServerSink
    from client_stub.link.client import Client, LinkError

    async def main() -> dict:
        async with contextlib.AsyncExitStack() as stack:
            host, port = args.host, args.port
            if host is None:
                server = await stack.enter_async_context(private_server(args.data_dir, args.synthetic_server))
                host, port = server.addresses[0]
            async with trio.open_nursery() as nursery:
                connect = connector(nursery, host, port, credentials=link_credentials(args))
                sink = ServerSink(await connect())
                progress = ProgressLine(out=None if args.json else sys.stderr, total=_log_length(replayer))
                failures: list[str] = []

                async def drain() -> None:
                    if not sink.lost:
                        await sink.link.drain()  # type: ignore[attr-defined]

                async with trio.open_nursery() as inner:  # Ctrl-C ends the replay, not the clean-up
                    inner.start_soon(stop_on_signal, inner.cancel_scope)
                    inner.start_soon(
                        keep_linked_or_stop, sink, connect, inner.cancel_scope, failures, args.give_up_after
                    )
                    await replay_to_server(replayer, sink, progress=progress, drain=drain, finish=False)
                    inner.cancel_scope.cancel()
                sink.apply(replayer.finish())  # the soldiers leave the server
                summary = {**replayer.status(), **{f"sink_{k}": v for k, v in sink.stats.items()}}
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
        print(f"ttes replay: {failure}", file=sys.stderr)
        return None


# -- headless video ------------------------------------------------------------------------------
def _run_headless(args: argparse.Namespace, replayer: Any, size: tuple[int, int]) -> dict | None:
    import time

    import trio
    import trio.testing

    from client_stub.link.client import LinkError

    seconds = args.seconds
    if seconds is None:
        seconds = (
            (replayer.cursor.t_end - replayer.t_begin) / replayer.speed + 1.0
            if not replayer.unlimited
            else 1.0
        )
    fps = args.fps
    if not (math.isfinite(fps) and 1 <= fps <= 120 and 0 < seconds <= 24 * 3600):
        print("ttes replay: --fps must be 1..120 and --seconds positive", file=sys.stderr)
        return None
    realtime = args.host is not None  # a server we do not own runs on the wall clock

    async def main() -> dict:
        async with contextlib.AsyncExitStack() as stack:
            connect = None
            if not args.offline:
                from client_stub.dis.reconnect import connector

                host, port = args.host, args.port
                if host is None:
                    server = await stack.enter_async_context(
                        private_server(args.data_dir, args.synthetic_server)
                    )
                    host, port = server.addresses[0]
                nursery = await stack.enter_async_context(trio.open_nursery())
                connect = connector(nursery, host, port, "ttes-replay", credentials=link_credentials(args))
            app = _make_app(args, replayer, await connect() if connect is not None else None)
            failures: list[str] = []
            try:
                summary = await _render_linked(app, connect, failures, seconds, fps, size, args)
            finally:
                app.source.finish(app)  # the soldiers leave the server
                if app.source.sink is not None:
                    await app.source.sink.link.aclose()
            if failures:
                raise LinkError(failures[0])
            if app.source.sink is not None:
                summary["server_errors"] = len(app.source.sink.link.errors)
            return summary

    t = time.perf_counter()
    try:
        if realtime:
            summary = trio.run(main)
        else:
            summary = trio.run(main, clock=trio.testing.MockClock(autojump_threshold=0))
    except (LinkError, BaseExceptionGroup) as exc:
        if (failure := link_error(exc)) is None:
            raise
        print(f"ttes replay: {failure}", file=sys.stderr)
        return None
    summary["wall_s"] = round(time.perf_counter() - t, 2)
    return summary


async def _render_linked(
    app: Any,
    connect: Any,
    failures: list[str],
    seconds: float,
    fps: float,
    size: tuple[int, int],
    args: argparse.Namespace,
) -> dict:
    """:func:`_render`, with the sink kept linked (a restarted server gets the soldiers again); a server lost
    for longer than --give-up-after ends the video early with the reason in ``failures``."""
    import trio

    from client_stub.dis.reconnect import keep_linked_or_stop

    sink = app.source.sink
    summary: dict = {}
    async with trio.open_nursery() as inner:
        if sink is not None:
            inner.start_soon(
                keep_linked_or_stop, sink, connect, inner.cancel_scope, failures, args.give_up_after
            )
        summary = await _render(app, seconds, fps, size, args)
        inner.cancel_scope.cancel()
    return summary


def _make_app(args: argparse.Namespace, replayer: Any, link: Any, reconnect: Any = None) -> Any:
    from client_stub.dis.drive import ProgressLine
    from client_stub.dis.soldiers import DisSoldiers, replay_app
    from client_stub.link.retry import RetrySchedule
    from client_stub.stub.camera import View
    from client_stub.stub.terrain import DEFAULT_TERRAIN, load_terrain

    terrain = load_terrain(args.terrain or DEFAULT_TERRAIN)
    app = replay_app(
        terrain,
        replayer,
        link=link,
        progress=ProgressLine(out=None if args.json else sys.stderr, total=_log_length(replayer)),
        reconnect=reconnect,
        retry=RetrySchedule(give_up_after=args.give_up_after),
    )
    camera = getattr(args, "camera", "action")
    assert isinstance(app.source, DisSoldiers)
    app.source.squad_view = camera == "squad"
    if camera == "action":
        app.camera.action_view()
        app.camera.action_tour = True
    elif camera == "overhead":
        app.camera.overhead()
    elif camera != "squad":
        app.camera.view = View.BIRDS_EYE if camera == "birds-eye" else View.SOLDIER_CAM
    return app


async def _render(
    app: Any, seconds: float, fps: float, size: tuple[int, int], args: argparse.Namespace
) -> dict:
    import imageio.v2 as imageio
    import numpy as np
    import trio

    from client_stub.stub.gl_render import offscreen_renderer

    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    app.renderer = offscreen_renderer(*size)
    app.renderer.set_terrain(app.terrain.meshes)
    video = out.suffix.lower() in (".mp4", ".mov", ".mkv", ".avi", ".gif")
    writer = None
    if video:
        kw: dict[str, Any] = {"fps": fps}
        if out.suffix.lower() != ".gif":
            kw.update(codec="libx264", quality=7, macro_block_size=8, pixelformat="yuv420p")
        writer = imageio.get_writer(out, **kw)
    nframes = max(round(seconds * fps), 1)
    dt = 1.0 / fps
    t0 = trio.current_time()
    frame = None
    try:
        for i in range(nframes):
            await trio.sleep_until(t0 + i * dt)
            app.frame(dt if i else 0.0)
            app.draw()
            frame = app.renderer.render()
            if writer is not None:
                writer.append_data(frame)
    finally:
        if writer is not None:
            writer.close()
        app.renderer.close()
    if not video and frame is not None:
        imageio.imwrite(out, frame)
    dis = app.source
    if dis.progress is not None:
        dis.progress.update(dis.elapsed, dis.replay.replay_time, dis.translator.alive, dis.replay.pdus, True)
    return {
        **dis.replay.status(),
        **({f"sink_{k}": v for k, v in dis.sink.stats.items()} if dis.sink is not None else {}),
        "out": str(out),
        "frames": nframes,
        "fps": fps,
        "server": app.link is not None,
        "last_frame_mean": None if frame is None else float(np.asarray(frame).mean()),
    }


# -- the window ----------------------------------------------------------------------------------
def _run_window(args: argparse.Namespace, replayer: Any, size: tuple[int, int]) -> dict | None:
    from client_stub.link.client import LinkError
    from client_stub.link.spawn import spawn_server
    from client_stub.stub.render import StubRenderer
    from client_stub.stub.viewer import run_viewer
    from ttes.progress import ProgressBar

    server = app = None
    try:
        link = reconnect = None
        if not args.offline:
            host, port = args.host, args.port
            try:
                if host is None:
                    extra = ["--data-dir", str(args.data_dir)] if args.data_dir else []
                    data = "synthetic" if args.synthetic_server else "auto"
                    with ProgressBar("ttes server: loading its library") as loading:
                        server = spawn_server(extra, data=data, waiting=loading.waited)
                    host, port = server.host, server.port
                link = _ready_jack(host, port, args)
            except LinkError as exc:
                print(f"ttes replay: {exc}", file=sys.stderr)
                return None
            if args.give_up_after > 0:
                reconnect = functools.partial(_ready_jack, host, port, args, client_id=link.client.client_id)
        app = _make_app(args, replayer, link, reconnect)
        app.renderer = StubRenderer(*size, offscreen=False)
        app.renderer.set_terrain(app.terrain.meshes)
        run_viewer(app, *size, args.fps)
        app.source.finish(app)
        if app.gave_up:
            print(f"ttes replay: {app.gave_up}", file=sys.stderr)
            return None
        summary = {**replayer.status()}
        if app.source.sink is not None:
            summary.update({f"sink_{k}": v for k, v in app.source.sink.stats.items()})
        return summary
    finally:
        if app is not None and app.source.sink is not None:
            app.source.sink.link.quit()  # the link in use (a reconnect's); the first one's too
        if link is not None:
            link.quit()
        if server is not None:
            server.close()


def _ready_jack(host: str, port: int, args: argparse.Namespace, client_id: str = "") -> Any:
    """A threaded link to ``host:port`` that has run the start-up JCL and seen READY (LinkError if not);
    ``client_id``: the first link's, so a server that kept our soldiers hands them back."""
    from client_stub.link.client import LinkError
    from client_stub.stub.jack import JackProc

    jack = JackProc("ttes-replay")
    link_credentials(args).apply(jack.client)
    if client_id:
        jack.client.client_id = client_id
    jack.initsocketconnection(host, port)
    jack.start()
    if not jack.wait_ready(30.0):
        why = jack.failure or "server not ready"
        jack.quit()
        raise LinkError(why)
    return jack
