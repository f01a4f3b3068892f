"""Record a scenario: one soldier driven by a scenario file's timed requests, one frame per server tick.

:class:`ScenarioSoldier` is the :class:`~client_stub.stub.app.SoldierSource` of a recording: it sends the
scenario's requests on the link and dead-reckons the entity as an image generator would (position from the
velocity it sent), and its camera follows the figure's root from a fixed world direction.

:func:`record_scenario` renders exactly one frame per server tick, however slowly the renderer runs: it is
handed a :class:`TickClock` that moves the server's time to a given instant and returns once every byte the
server sent by then has arrived (``ttes stub --scenario`` runs an in-process server on a trio
``MockClock``). Per frame: the clock goes to just before tick *k*, the requests due at tick *k* go out (the
server takes them at tick *k*'s time), the clock goes to tick *k*, and the frame shows tick *k*'s pose on
the entity at tick *k*'s position, so nothing in the picture is an artefact of render speed.
A contact sheet (a grid of frames every ``sheet_every`` seconds, each labelled with its time) goes beside the
video so a person can look at the whole run in one image.
"""

from __future__ import annotations

import math
import time
from pathlib import Path
from typing import TYPE_CHECKING, Protocol

import numpy as np

from client_stub.stub.app import StubApp
from client_stub.stub.camera import LOOK_HEIGHT, look_at
from client_stub.stub.feet import heights_above, sole_points, touchdowns, worst_by_window
from client_stub.stub.grounding import RAY_START
from client_stub.stub.scenario import Event, Scenario, describe
from protocol import coords
from protocol.entity import Appearance, WeaponState, make_entity_requests

if TYPE_CHECKING:
    from client_stub.link.api import Link

BEFORE_TICK_S = 1e-4  # requests go out this long before the tick that shows them


class TickClock(Protocol):
    async def to(self, t: float) -> None:
        """Make the server's time ``t`` (s since start) and return once what it sent by then has arrived."""
        ...


class ScenarioSoldier:
    """The one soldier of a scenario, bound to server soldier ``index`` (see the module docstring)."""

    def __init__(self, scenario: Scenario, link: Link, index: int, table: int) -> None:
        self.scenario = scenario
        self._link = link
        self.index = index
        self.table = table
        self.slot = -1
        s = scenario.start
        self.origin = np.zeros(2)
        self.xy = np.zeros(2)  # metres from the origin, dead-reckoned
        self.heading = s.heading % 360.0
        self.speed = 0.0
        self.direction = 0.0
        self.posture = Appearance.UPRIGHT
        self.weapon = WeaponState.DEPLOYED
        self.time = 0.0
        self._next = 0
        self._sent = False

    @property
    def link(self) -> Link | None:
        return self._link

    def bind(self, app: StubApp) -> int:
        """Add the soldier to ``app``, posed by server soldier ``index`` (its update table must be known)."""
        s = self.scenario.start
        centre = app.terrain.landmarks.get("centre", (0.0, 0.0))
        self.origin = np.asarray(centre, np.float64)[:2] + np.array([s.x, s.y])
        self.slot = app.add_soldier(self.origin, self.heading)
        wire = self._link.tables[self.table]
        kind = app.kind(wire.figure, wire.weapon)
        app.binding(kind, wire)
        app.set_kind(self.slot, kind)
        app.map_server(self.slot, self.index)
        self._link.subscribe([self.index])
        return self.slot

    def velocity(self) -> np.ndarray:
        return coords.compass_to_direction(self.heading + self.direction) * self.speed

    def prepare(self, app: StubApp, t: float) -> None:
        """Move the entity to time ``t`` and send the requests of the events due by then."""
        self.xy = self.xy + self.velocity()[:2] * max(t - self.time, 0.0)
        self.time = t
        changed = not self._sent
        events = self.scenario.events
        while self._next < len(events) and events[self._next].time <= t + 1e-9:
            self._apply(events[self._next])
            self._next += 1
            changed = True
        s = app.soldiers
        s.position[self.slot, :2] = self.origin + self.xy
        s.position[self.slot, 2] = float(app.terrain.height(s.position[self.slot : self.slot + 1, :2])[0])
        s.heading[self.slot] = self.heading
        s.appearance[self.slot] = self.posture
        s.weapon[self.slot] = self.weapon
        if changed:
            row = make_entity_requests(
                self.index, self.posture, self.weapon, self.velocity(), self.heading, s.position[self.slot]
            )
            self._link.send_requests(row)
            self._sent = True

    def _apply(self, e: Event) -> None:
        if e.speed is not None:
            self.speed = e.speed
        if e.direction is not None:
            self.direction = e.direction
        if e.heading is not None:
            self.heading = e.heading % 360.0
        if e.turn is not None:
            self.heading = (self.heading + e.turn) % 360.0
        if e.posture is not None:
            self.posture = e.posture
        if e.weapon is not None:
            self.weapon = e.weapon

    # -- SoldierSource ---------------------------------------------------------------------------------------
    def step(self, app: StubApp, dt: float) -> None:
        """Nothing: :meth:`prepare` moved the entity before the server's tick (:func:`record_scenario`)."""

    def added(self, app: StubApp, slot: int) -> None:
        return None

    def refuse_key(self, key: str) -> str | None:
        return "a recorded scenario takes no keys"

    def camera_pose(self, app: StubApp) -> np.ndarray:
        """From the scenario's fixed world azimuth, aimed at the figure's root (the feet's height + 1 m)."""
        c = self.scenario.camera
        feet = app.figure_feet(self.slot, app.soldiers.position[self.slot])
        target = feet + np.array([0.0, 0.0, LOOK_HEIGHT])
        el = math.radians(c.elevation)
        toward = coords.compass_to_direction(c.azimuth)
        eye = target + c.distance * (math.cos(el) * toward + np.array([0.0, 0.0, math.sin(el)]))
        return look_at(eye, target)

    def lose_server(self) -> None:
        self._link = None  # type: ignore[assignment]

    def close(self) -> None:
        return None


async def record_scenario(
    app: StubApp,
    soldier: ScenarioSoldier,
    clock: TickClock,
    out: str | Path,
    *,
    hz: float,
    sheet: str | Path | None = None,
    sheet_every: float = 0.5,
    origin: float = 0.0,
) -> dict:
    """Render ``soldier.scenario`` at the server's rate ``hz`` into ``out`` (.mp4/.gif) and the contact
    sheet ``sheet`` (PNG, a frame every ``sheet_every`` s); scenario time 0 is server time ``origin`` (a tick
    by which the soldier has a pose: one created between ticks has none before the next). Returns a summary.
    """
    import imageio.v2 as imageio

    renderer = app.renderer
    if renderer is None:
        raise RuntimeError("StubApp has no renderer")
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    nframes = math.floor(soldier.scenario.seconds * hz + 1e-9) + 1
    every = max(round(sheet_every * hz), 1)
    kwargs: dict = {"fps": hz}
    if out.suffix.lower() != ".gif":
        kwargs.update(codec="libx264", quality=7, macro_block_size=8, pixelformat="yuv420p")
    thumbs: list[tuple[float, np.ndarray]] = []
    soles: list[np.ndarray] = []
    ground: list[np.ndarray] = []  # per frame the ground under each sole point
    start = time.perf_counter()
    with imageio.get_writer(out, **kwargs) as writer:
        for k in range(nframes):
            t = k / hz
            await clock.to(origin + t - BEFORE_TICK_S)
            soldier.prepare(app, t)
            await clock.to(origin + t)
            app.frame(1.0 / hz if k else 0.0)
            app.draw()
            frame = renderer.render()
            writer.append_data(frame)  # type: ignore[attr-defined]  # (imageio's stubs lack the v2 writer)
            if k % every == 0:
                thumbs.append((t, frame))
            pts = sole_points(app, soldier.slot)
            if pts is not None:
                soles.append(pts)
                top = app.soldiers.position[soldier.slot, 2] + RAY_START
                ground.append(app.terrain.height(pts[:, :2], np.full(len(pts), top)))
    if sheet is not None:
        write_sheet(thumbs, sheet)
    return {
        "feet": _feet(soldier.scenario, soles, ground, hz),
        "out": str(out),
        "sheet": None if sheet is None else str(sheet),
        "frames": nframes,
        "hz": hz,
        "seconds": soldier.scenario.seconds,
        "wall_s": round(time.perf_counter() - start, 2),
        "server_index": soldier.index,
    }


def _feet(scenario: Scenario, soles: list[np.ndarray], ground: list[np.ndarray], hz: float) -> list[dict]:
    """Per scenario event (and the start): the touchdowns that began before the next and their worst slide,
    and how high the lowest sole point got above the ground under it."""
    if not soles:
        return []
    events = scenario.events
    pts, under = np.array(soles), np.array(ground)
    lowest = heights_above(pts, under).min(axis=1)
    windows = worst_by_window(touchdowns(pts, under, hz), [0.0] + [e.time for e in events], lowest, hz)
    for w, label in zip(windows, ["start", *(describe(e) for e in events)], strict=True):
        w["event"] = label
    return windows


def write_sheet(
    thumbs: list[tuple[float, np.ndarray]], path: str | Path, columns: int = 8, width: int = 320
) -> None:
    """A grid of frames (each scaled to ``width`` pixels), labelled with its time in seconds (PIL)."""
    from PIL import Image, ImageDraw

    if not thumbs:
        return
    h0, w0 = thumbs[0][1].shape[:2]
    w, h = min(width, w0), max(round(h0 * min(width, w0) / w0), 1)
    rows = -(-len(thumbs) // columns)
    sheet = Image.new("RGB", (columns * w, rows * h), (255, 255, 255))
    draw = ImageDraw.Draw(sheet)
    for n, (t, frame) in enumerate(thumbs):
        x, y = (n % columns) * w, (n // columns) * h
        sheet.paste(Image.fromarray(np.asarray(frame)[..., :3]).resize((w, h)), (x, y))
        draw.rectangle((x, y, x + 46, y + 13), fill=(0, 0, 0))
        draw.text((x + 3, y + 1), f"{t:5.1f} s", fill=(255, 255, 0))
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    sheet.save(path)
