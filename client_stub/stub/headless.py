"""Headless runs: render the stub offscreen (EGL) to a video or a PNG, driven by a scripted tour.

The tour replays the seed's walkthrough (4.3) with keys on soldier 0 while soldiers 1 and 2 walk their
square and circle and the others hold their postures, so a short video shows every posture (standing,
kneeling, prone, dead; deployed and firing) and every locomotion mode (walk, run, walk backwards, crawl).
Its times are scaled to the length of the run. Without a server the simulation clock is exact (``dt`` =
1/fps); with one, frames follow the wall clock so the server's real-time motion and the stub's dead
reckoning agree.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from client_stub.stub.app import StubApp

# (seconds into a 40 s tour, keys pressed then)
TOUR: tuple[tuple[float, tuple[str, ...]], ...] = (
    (0.0, ("x", "?")),
    (2.0, ("?", "c")),
    (3.5, ("6",)),
    (5.0, ("i", "i", "i")),
    (6.0, ("3",)),
    (8.0, ("5",)),
    (9.0, ("4",)),
    (11.0, ("6",)),
    (12.5, ("5", "UP")),
    (13.0, ("i", "i", "i")),
    (16.0, ("DOWN", "2")),
    (17.5, ("UP", "UP", "UP", "LEFT")),
    (20.0, ("UP", "UP", "UP", "UP", "j", "j", "j")),
    (23.0, ("DOWN", "DOWN", "DOWN", "DOWN", "DOWN", "DOWN", "DOWN", "DOWN", "DOWN")),
    (26.0, ("UP", "UP", "o")),
    (28.0, ("i", "i", "i", "i", "i", "i", "i")),
    (30.0, ("1",)),
    (33.0, ("2", "n")),
    (35.0, ("n", "u")),
    (37.5, ("x",)),
)
TOUR_SECONDS = 40.0


@dataclass
class Tour:
    """Timed key presses, scaled to ``seconds``; :meth:`due` returns the keys whose time has come."""

    seconds: float
    _next: int = 0

    def due(self, t: float) -> list[str]:
        scale = min(1.0, self.seconds / TOUR_SECONDS)
        keys: list[str] = []
        while self._next < len(TOUR) and TOUR[self._next][0] * scale <= t + 1e-9:
            keys.extend(TOUR[self._next][1])
            self._next += 1
        return keys


def _frame(app: StubApp, step: float, t: float, script: Tour | None, quiet: bool) -> bool:
    """The tour's keys due at ``t`` and one frame of the app; False when it gave up on its server."""
    if script is not None:
        for key in script.due(t):
            message = app.handle_key(key)
            if message and not quiet:
                print(f"[{t:5.1f} s] {key}: {message}")
    lost = app.server_lost
    app.frame(step)
    if app.server_lost != lost and not quiet:
        print(f"[{t:5.1f} s] {app.server_lost or 'server back'}")
    return not app.gave_up


def run_headless(
    app: StubApp,
    seconds: float,
    out: str | Path,
    *,
    fps: float = 15.0,
    realtime: bool = False,
    tour: bool = True,
    quiet: bool = True,
    progress: Callable[[float, float], None] | None = None,
) -> dict:
    """Render ``seconds`` of the stub to ``out`` (``.mp4``/``.gif`` video, or ``.png``: the last frame);
    ``progress(t, seconds)`` after each frame (a progress bar)."""
    import imageio.v2 as imageio

    renderer = app.renderer
    if renderer is None:
        raise RuntimeError("StubApp has no renderer")
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    video = out.suffix.lower() in (".mp4", ".mov", ".mkv", ".avi", ".gif")
    nframes = max(round(seconds * fps), 1)
    script = Tour(seconds) if tour else None
    t = 0.0
    dt = 1.0 / fps
    frame = None
    frames: list[np.ndarray] = []
    rendered = 0
    render_time = 0.0
    start = time.perf_counter()
    last = start
    while True:
        if realtime:
            # the server runs on the wall clock: the run lasts `seconds` of it, however fast we render
            now = time.perf_counter()
            target = start + rendered * dt
            if now < target:
                time.sleep(target - now)
                now = target
            step, last = now - last, now
            if rendered and now - start >= seconds:
                break
        else:
            if rendered >= nframes:
                break
            step = dt if rendered else 0.0
        t += step
        if not _frame(app, step, t, script, quiet):
            break
        app.draw()
        r0 = time.perf_counter()
        frame = renderer.render()
        render_time += time.perf_counter() - r0
        rendered += 1
        if video:
            frames.append(frame)
        if progress is not None:
            progress(t, seconds)
    wall = time.perf_counter() - start
    if progress is not None and not app.gave_up:
        progress(seconds, seconds)  # done (the last frame shows t = seconds - 1/fps)
    if video and frames:
        # a real-time run plays back at the rate it achieved, so the video's time is the scene's time
        rate = fps if not realtime else max(1.0, min(fps, rendered / max(wall, 1e-6)))
        kwargs: dict = {"fps": rate}
        if out.suffix.lower() != ".gif":
            kwargs.update(codec="libx264", quality=7, macro_block_size=8, pixelformat="yuv420p")
        with imageio.get_writer(out, **kwargs) as writer:
            for f in frames:
                writer.append_data(f)  # type: ignore[attr-defined]  # (imageio's stubs lack the v2 writer)
    if not video and frame is not None:
        imageio.imwrite(out, frame)
    return {
        "out": str(out),
        "frames": rendered,
        "seconds": seconds,
        "fps": fps,
        "wall_s": round(wall, 3),
        "render_fps": round(rendered / render_time, 2) if render_time > 0 else None,
        "soldiers": int(app.soldiers.count),
        "server": app.link is not None,
        "server_lost": app.server_lost_count,
        "gave_up": app.gave_up,
        "last_frame_mean": None if frame is None else float(np.asarray(frame).mean()),
    }
