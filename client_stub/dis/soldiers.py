"""DisSoldiers: the TTES stub's soldiers driven by DIS (a replay, or any source of translations).

A :class:`~client_stub.stub.app.SoldierSource` for :class:`~client_stub.stub.app.StubApp`. Each translator
slot is a stub slot. Every frame the replay advances by the frame's ``dt``; new soldiers are added to the stub
(kind = DI.fig + the rifle of the entity type, look = force and camouflage), removed ones hidden (their slot
waits for the entity to come back), and each live soldier is placed at its dead-reckoned position on the
terrain (local east-north-up frame about the origin; feet on the ground by the stub's ray cast) with its
heading. With a server link the translations also go to the server (server index = base + slot,
subscribed) and the joint updates that come back pose the soldiers; without one the stub's offline poser
shows each soldier's posture, weapon and gait (also for soldiers whose server update table shares no joint
with the stub's figure, such as the synthetic library's chain soldier).

A lost server shows within a frame (the stub poses the soldiers meanwhile; the sink keeps what they are). A
new link comes either from ``reconnect`` (the window's threaded link: tried on the frames, on a
:class:`~client_stub.link.retry.RetrySchedule` in stub time) or from whoever relinks the sink (the headless
replay runs :func:`client_stub.dis.reconnect.keep_linked`); either way the next frame binds every live
soldier to its server soldier again. Out of time: ``app.gave_up`` says so (the replay exits 1).

Looks: friendly, opposing and neutral forces get different uniform colours; a camouflage paint scheme
(appearance bit 0) tints the uniform by the camouflage type (desert, winter, forest, other).
"""

from __future__ import annotations

import contextlib
import logging
import os
from collections.abc import Callable
from typing import Protocol

import numpy as np

from client_stub.dis.drive import ProgressLine
from client_stub.dis.sink import ServerSink
from client_stub.dis.translator import DisTranslator, Translation
from client_stub.link.api import Link
from client_stub.link.client import LinkError
from client_stub.link.retry import RetrySchedule
from client_stub.stub.app import DEFAULT_FIGURE, StubApp
from client_stub.stub.camera import look_at
from client_stub.stub.render import FORCE_UNIFORMS
from client_stub.stub.simsoldier import RAY_START, Force
from client_stub.stub.terrain import Terrain
from protocol import coords
from protocol.dis import RIFLE_FIGURES

log = logging.getLogger("ttes.replay.stub")
SQUAD_FOCUS_SECONDS = 10.0  # the squad view turns to the other force this often
SQUAD_CAMERA_EASE = 0.12  # per frame: how fast the squad view follows the soldiers
SQUAD_ALL_SPAN = 45.0  # m: soldiers spread wider than this are framed one force at a time
LOOK_BASE = 100  # render colour keys of the looks (the renderer's own keys are the forces 0, 1)
_FORCE_COLOURS = {
    0: (0.30, 0.36, 0.20),  # friendly: olive drab
    1: (0.62, 0.16, 0.10),  # opposing: brick red (stands out on sand and grass)
    2: (0.33, 0.38, 0.52),  # neutral / other: slate blue
}
_CAMO_TINTS = (
    (0.76, 0.66, 0.45),
    (0.88, 0.90, 0.92),
    (0.16, 0.26, 0.12),
    (0.45, 0.45, 0.42),
)  # desert..other


def look_of(force: np.ndarray, paint: np.ndarray, camouflage: np.ndarray) -> np.ndarray:
    """Look index per soldier: 5 per force class (uniform, then the four camouflage types)."""
    fc = np.where(force == 1, 0, np.where(force == 2, 1, 2))
    return fc * 5 + np.where(paint == 1, 1 + (camouflage & 3), 0)


def look_colour(look: int) -> tuple[float, float, float]:
    base = np.array(_FORCE_COLOURS[look // 5])
    k = look % 5
    rgb = base if k == 0 else 0.7 * base + 0.3 * np.array(_CAMO_TINTS[k - 1])  # the force's hue stays
    return (float(rgb[0]), float(rgb[1]), float(rgb[2]))


for _look in range(15):  # register the looks with the renderer's colour table
    FORCE_UNIFORMS.setdefault(LOOK_BASE + _look, look_colour(_look))


class TranslationSource(Protocol):
    """Where DisSoldiers come from (a :class:`~client_stub.dis.replayer.Replayer`)."""

    translator: DisTranslator

    def advance(self, elapsed: float) -> Translation: ...


def replay_app(
    terrain: Terrain,
    replay: TranslationSource,
    *,
    link: Link | None = None,
    artic_dir: str | os.PathLike[str] | None = None,
    progress: ProgressLine | None = None,
    reconnect: Callable[[], Link] | None = None,
    retry: RetrySchedule | None = None,
) -> StubApp:
    """The stub fed by DIS: a :class:`StubApp` given :class:`DisSoldiers`."""
    source = DisSoldiers(replay, link=link, progress=progress, reconnect=reconnect, retry=retry)
    return StubApp(terrain, source, artic_dir=artic_dir)


class DisSoldiers:
    """The stub's soldiers from DIS translations (see the module docstring)."""

    def __init__(
        self,
        replay: TranslationSource,
        *,
        link: Link | None = None,
        progress: ProgressLine | None = None,
        reconnect: Callable[[], Link] | None = None,
        retry: RetrySchedule | None = None,
    ) -> None:
        self.replay = replay
        self.translator = replay.translator
        self.sink = ServerSink(link, subscribe=True) if link is not None else None
        self.reconnect = reconnect  # a new READY link (LinkError when none answers); None: others relink
        self.retry = retry or RetrySchedule()  # in stub time
        self._relinked = 0  # the sink's relink count when the slots were last bound
        self.progress = progress
        self.elapsed = 0.0
        self.squad_view = False  # camera framing the whole squad (headless demos); keys hand it back
        self._cam: np.ndarray | None = None

    @property
    def link(self) -> Link | None:
        """The sink's link while it works (None: no server, or lost)."""
        sink = self.sink
        return None if sink is None or sink.lost else sink.link

    # -- keys: the DIS stream drives the soldiers; cameras and soldier selection still work -------
    def refuse_key(self, key: str) -> str | None:
        if key in ("1", "2", "3", "4", "5", "6", "LEFT", "RIGHT", "UP", "DOWN", "a", "A"):
            return "replay: the DIS PDUs drive the soldiers (cameras: b c f v o u d i j, soldiers: n p)"
        if key.lower() in tuple("bcfvoudijwsqerg"):
            self.squad_view = False  # the user takes the camera
        return None

    def added(self, app: StubApp, slot: int) -> None:
        return  # the keys that add soldiers are refused

    def camera_pose(self, app: StubApp) -> np.ndarray | None:
        """The squad view frames the live soldiers from above the south-west, following them smoothly (when
        they are spread wide, one force at a time: friendly and opposing in turn)."""
        s = app.soldiers
        live = np.flatnonzero(s.alive[: s.count])
        if not self.squad_view or not len(live):
            return None
        p = s.position[live]
        lo, hi = p.min(axis=0), p.max(axis=0)
        if float(np.max(hi[:2] - lo[:2])) > SQUAD_ALL_SPAN:  # too far apart for one view: one force at a time
            forces = np.unique(s.force[live])
            focus = forces[int(self.elapsed // SQUAD_FOCUS_SECONDS) % len(forces)]
            p = s.position[live[s.force[live] == focus]]
            lo, hi = p.min(axis=0), p.max(axis=0)
        centre = (lo + hi) / 2
        span = float(np.max(hi[:2] - lo[:2]))
        if self._cam is None:
            self._cam = np.array([*centre, span])
        else:
            self._cam += SQUAD_CAMERA_EASE * (np.array([*centre, span]) - self._cam)
        c, span = self._cam[:3], float(self._cam[3])
        dist = max(14.0, 0.7 * span + 6.0)
        eye = c + dist * np.array([-0.25, -0.45, 0.86])  # steep enough to see over the houses
        return look_at(eye, c + np.array([0.0, 0.0, 1.0]))

    # -- per frame --------------------------------------------------------------------------------
    def step(self, app: StubApp, dt: float) -> None:
        self.elapsed += dt
        tr = self.replay.advance(self.elapsed)
        if self.sink is not None:  # first: the stub binds new soldiers to the server soldiers made here
            self.sink.apply(tr)  # never raises: a lost link keeps the state for the next one
        self._take(app, tr)
        self._place_soldiers(app, dt)
        if self.progress is not None:
            r = getattr(self.replay, "replay_time", self.elapsed)
            self.progress.update(
                self.elapsed, float(r), self.translator.alive, int(getattr(self.replay, "pdus", 0))
            )
        self._keep_linked(app)

    def _keep_linked(self, app: StubApp) -> None:
        """A lost link shows (LinkError: the app poses the soldiers); a new one binds every live soldier."""
        sink = self.sink
        if sink is None:
            return
        if sink.lost and not app.server_lost:
            raise LinkError(sink.lost)
        if sink.lost and self.reconnect is not None and not app.gave_up:
            self._try_again(app, sink)
        if not sink.lost and sink.stats["relinked"] != self._relinked:
            self._relinked = sink.stats["relinked"]
            for slot in sorted(sink.rifle_of):
                if slot < app.soldiers.count and app.slot_kind[slot] >= 0:
                    self._bind(app, slot, int(app.slot_kind[slot]))
            self.retry.reset()
            if app.server_lost:
                app.regain_server()

    def _try_again(self, app: StubApp, sink: ServerSink) -> None:
        """One reconnection attempt when the schedule says so; out of time: ``app.gave_up``."""
        assert self.reconnect is not None
        link = self.retry.attempt(app.time, self.reconnect, sink.lost)
        app.gave_up = self.retry.gave_up
        if link is None:
            return
        sink.rebind(link)
        log.warning("server back: %d soldiers bound again", len(sink.rifle_of))

    def lose_server(self) -> None:
        """The app saw the link go: the sink keeps its soldiers for the next link; a threaded link stops."""
        sink = self.sink
        if sink is None:
            return
        sink.lost = sink.lost or "connection lost"
        quit_link = getattr(sink.link, "quit", None)
        if self.reconnect is not None and quit_link is not None:
            with contextlib.suppress(LinkError):
                quit_link()

    def _take(self, app: StubApp, tr: Translation) -> None:
        """New soldiers into the stub, removed ones hidden."""
        s = app.soldiers
        for slot in tr.removed.tolist():
            if slot < s.count:
                app.hide(slot)
        for row in tr.created:
            slot = int(row["slot"])
            while s.count <= slot:  # slots are handed out in order: normally exactly one add
                s.add((0.0, 0.0))
                s.alive[s.count - 1] = False
            app.grow()
            s.alive[slot] = True
            s.force[slot] = Force.OPPOSING if int(row["force"]) == 2 else Force.FRIENDLY
            app.look[slot] = LOOK_BASE + int(look_of(row["force"], row["paint"], row["camouflage"]))
            kind = app.kind(DEFAULT_FIGURE, RIFLE_FIGURES[int(row["rifle"])])
            app.set_kind(slot, kind, reactivate=True)
            if self.sink is not None and not self.sink.lost and slot < self.sink.capacity:
                self._bind(app, slot, kind)  # while lost: bound when the next link comes

    def _bind(self, app: StubApp, slot: int, kind: int) -> None:
        """The server soldier of ``slot`` (created by the sink): its wire table bound to our kind."""
        sink = self.sink
        assert sink is not None
        index = int(sink.server_index(np.array([slot]))[0])
        weapon = sink.weapon_of.get(index, "")
        wire = next(
            (t for t in sink.link.tables.values() if t.figure == sink.figure and t.weapon == weapon),
            None,
        )
        if wire is None:
            return
        if not len(app.binding(kind, wire).dof_dst):
            return  # e.g. the synthetic library's chain soldier: the server still gets every request
        app.map_server(slot, index)

    def _place_soldiers(self, app: StubApp, dt: float) -> None:
        """Dead-reckoned position and heading, posture and weapon, feet on the terrain."""
        s = app.soldiers
        tr = self.translator
        live = np.flatnonzero(s.alive[: s.count])
        live = live[tr.live[live]] if len(live) else live
        if not len(live):
            return
        now = getattr(self.replay, "now", self.elapsed)
        pos, heading = tr.dead_reckoned(float(now), live)
        vel = tr.local_velocity[live]
        ahead = coords.compass_to_direction(heading)[:, :2]
        s.speed[live] = np.einsum("ij,ij->i", vel[:, :2], ahead)  # signed: backwards is negative
        s.distance[live] += np.abs(s.speed[live]) * dt
        s.heading[live] = heading
        s.appearance[live] = tr.posture[live]
        s.weapon[live] = tr.effective_weapon(live, float(now))
        s.position[live, :2] = pos[:, :2]
        # feet on the ground: a ray from just above the last height (walks under roofs, up slopes); nothing
        # there (a new or jumping soldier, a steep hill): from high above; off the terrain: 0
        terrain = app.terrain
        z = terrain.height(pos[:, :2], s.position[live, 2] + RAY_START, default=np.nan)
        lost = np.isnan(z)
        if lost.any():
            z[lost] = terrain.height(pos[lost, :2], np.inf, default=0.0)
        s.position[live, 2] = z

    def finish(self, app: StubApp) -> None:
        """Remove every soldier from the server (the replay is over)."""
        reset = self.translator.reset()
        if self.sink is not None:
            self.sink.apply(reset)
        self._take(app, reset)

    def close(self) -> None:
        return
