"""ReplayApp: the TTES stub (window or headless) with its soldiers driven by DIS instead of the keyboard.

Each translator slot is a stub slot. Every frame the replay (or any source of translations) advances by the
frame's ``dt``; new soldiers are added to the stub (kind = DI.fig + the rifle of the entity type, look = force
and camouflage), removed ones hidden (their slot waits for the entity to come back), and each live soldier is
placed at its dead-reckoned position on the terrain (local east-north-up frame about the origin; feet on the
ground by the stub's ray cast) with its heading. With a server link the translations also go to the server
(server index = base + slot, subscribed) and the joint updates that come back pose the soldiers; without one
the stub's offline poser shows each soldier's posture, weapon and gait (also for soldiers whose server update
table shares no joint with the stub's figure, such as the synthetic library's chain soldier).

Looks: friendly, opposing and neutral forces get different uniform colours; a camouflage paint scheme
(appearance bit 0) tints the uniform by the camouflage type (desert, winter, forest, other).
"""

from __future__ import annotations

import logging
import os
from typing import Protocol

import numpy as np

from client_stub.dis.drive import ProgressLine
from client_stub.dis.sink import ServerSink
from client_stub.dis.translator import DisTranslator, Translation
from client_stub.link.api import Link
from client_stub.link.client import LinkError
from client_stub.stub.app import DEFAULT_FIGURE, StubApp
from client_stub.stub.artic import bind_table
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
    """Where a ReplayApp's soldiers come from (a :class:`~client_stub.dis.replayer.Replayer`)."""

    translator: DisTranslator

    def advance(self, elapsed: float) -> Translation: ...


class ReplayApp(StubApp):
    """The stub fed by DIS (see the module docstring)."""

    def __init__(
        self,
        terrain: Terrain,
        source: TranslationSource,
        *,
        link: Link | None = None,
        artic_dir: str | os.PathLike[str] | None = None,
        progress: ProgressLine | None = None,
    ) -> None:
        super().__init__(terrain, artic_dir=artic_dir, capacity=16)
        self.source = source
        self.link = link
        self.sink = ServerSink(link, subscribe=True) if link is not None else None
        self.progress = progress
        self.elapsed = 0.0
        self.look = np.zeros(0, np.int64)
        self.translator = source.translator
        self.squad_view = False  # camera framing the whole squad (headless demos); keys hand it back
        self._cam: np.ndarray | None = None

    # -- keys: the DIS stream drives the soldiers; cameras and soldier selection still work -------
    def handle_key(self, key: str) -> str | None:
        if key in ("1", "2", "3", "4", "5", "6", "LEFT", "RIGHT", "UP", "DOWN", "a", "A"):
            return "replay: the DIS PDUs drive the soldiers (cameras: b c f v o u d i j, soldiers: n p)"
        if key.lower() in tuple("bcfvoudijwsqerg"):
            self.squad_view = False  # the user takes the camera
        return super().handle_key(key)

    def camera_pose(self) -> np.ndarray:
        """The squad view frames the live soldiers from above the south-west, following them smoothly (when
        they are spread wide, one force at a time: friendly and opposing in turn)."""
        s = self.soldiers
        live = np.flatnonzero(s.alive[: s.count])
        if not self.squad_view or not len(live):
            return super().camera_pose()
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
    def frame(self, dt: float) -> None:
        self.time += dt
        self.elapsed += dt
        tr = self.source.advance(self.elapsed)
        if self.sink is not None:
            try:
                self.sink.apply(tr)  # first: the stub binds new soldiers to the server soldiers made here
            except LinkError as exc:
                self._lose_server(exc)
        self._take(tr)
        self._place_soldiers(dt)
        if self.link is not None:
            self._apply_updates(self.link.swap())
        s = self.soldiers
        n = s.count
        slots = np.arange(n)
        for kind_id, k in enumerate(self.kinds):
            rows = slots[(self.slot_kind[:n] == kind_id) & s.alive[:n]]
            if not len(rows):
                continue
            k.crowd.set_entity(rows, s.entity_matrices(rows))
            off = rows if self.link is None else rows[self.server_of[rows] < 0]
            if len(off):
                k.poser.pose(
                    off, s.appearance[off], s.weapon[off], s.speed[off] * s.moving(off), s.distance[off], dt
                )
        if self.progress is not None:
            r = getattr(self.source, "replay_time", self.elapsed)
            self.progress.update(
                self.elapsed, float(r), self.translator.alive, int(getattr(self.source, "pdus", 0))
            )

    def _lose_server(self, exc: Exception) -> None:
        """The server went away: the replay goes on, posed by the stub."""
        log.warning("server connection lost: %s; the stub poses the soldiers from now on", exc)
        self.link = None
        self.sink = None
        self.server_of[:] = -1
        self.slot_of_server.clear()
        if getattr(self, "_slot_by_server", None) is not None:
            self._slot_by_server[:] = -1

    def _take(self, tr: Translation) -> None:
        """New soldiers into the stub, removed ones hidden."""
        s = self.soldiers
        for slot in tr.removed.tolist():
            if slot < s.count:
                s.alive[slot] = False
                kind = int(self.slot_kind[slot])
                if kind >= 0:
                    self.kinds[kind].crowd.active[slot] = False
        for row in tr.created:
            slot = int(row["slot"])
            while s.count <= slot:  # slots are handed out in order: normally exactly one add
                s.add((0.0, 0.0))
                s.alive[s.count - 1] = False
            self._grow()
            if len(self.look) < s.capacity:
                self.look = np.concatenate([self.look, np.zeros(s.capacity - len(self.look), np.int64)])
            s.alive[slot] = True
            s.force[slot] = Force.OPPOSING if int(row["force"]) == 2 else Force.FRIENDLY
            self.look[slot] = int(look_of(row["force"], row["paint"], row["camouflage"]))
            weapon = RIFLE_FIGURES[int(row["rifle"])]
            kind = self.kind(DEFAULT_FIGURE, weapon)
            self.slot_kind[slot] = -1  # force _set_kind to re-activate the crowd row
            self._set_kind(slot, kind)
            if self.link is not None and self.sink is not None and slot < self.sink.capacity:
                self._bind(slot, kind)

    def _bind(self, slot: int, kind: int) -> None:
        """The server soldier of ``slot`` (created by the sink): its wire table bound to our kind."""
        assert self.sink is not None and self.link is not None
        index = self.sink.base + slot
        weapon = self.sink.weapon_of.get(index, "")
        wire = next(
            (t for t in self.link.tables.values() if t.figure == self.sink.figure and t.weapon == weapon),
            None,
        )
        if wire is None:
            return
        k = self.kinds[kind]
        if wire.table_id not in k.bindings:
            k.bindings[wire.table_id] = bind_table(k.table, wire)
            if not len(k.bindings[wire.table_id].dof_dst):
                log.warning("update table %d shares no joint with %s: the stub poses these soldiers itself",
                            wire.table_id, k.figure)  # fmt: skip
        if not len(k.bindings[wire.table_id].dof_dst):
            return  # e.g. the synthetic library's chain soldier: the server still gets every request
        self._map_server(slot, index)

    def _map_server(self, slot: int, index: int) -> None:
        """Record slot <-> server index in the maps StubApp._apply_updates reads (a public StubApp method for
        this is asked of the stub's owner)."""
        self.server_of[slot] = index
        self.slot_of_server[index] = slot
        by_server = getattr(self, "_slot_by_server", None)
        if by_server is not None:
            if index >= len(by_server):
                grown = np.full(max(index + 1, 2 * len(by_server), 16), -1, np.int64)
                grown[: len(by_server)] = by_server
                self._slot_by_server = by_server = grown
            by_server[index] = slot

    def _place_soldiers(self, dt: float) -> None:
        """Dead-reckoned position and heading, posture and weapon, feet on the terrain."""
        s = self.soldiers
        tr = self.translator
        live = np.flatnonzero(s.alive[: s.count])
        live = live[tr.live[live]] if len(live) else live
        if not len(live):
            return
        now = getattr(self.source, "now", self.elapsed)
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
        z = self.terrain.height(pos[:, :2], s.position[live, 2] + RAY_START, default=np.nan)
        lost = np.isnan(z)
        if lost.any():
            z[lost] = self.terrain.height(pos[lost, :2], np.inf, default=0.0)
        s.position[live, 2] = z

    def draw(self) -> None:
        """Live soldiers only, grouped by kind and look."""
        r = self.renderer
        if r is None:
            return
        s = self.soldiers
        n = s.count
        slots = np.flatnonzero(s.alive[:n])
        look = self.look[slots] if len(self.look) >= n else np.zeros(len(slots), np.int64)
        for kind_id, k in enumerate(self.kinds):
            for lk in range(15):
                rows = slots[(self.slot_kind[slots] == kind_id) & (look == lk)]
                key = LOOK_BASE + lk
                if not len(rows) and (kind_id, key) not in r.soldiers:
                    continue
                meshes = r.soldier_meshes(kind_id, k.layout, key)
                meshes.update(k.crowd.world(rows) if len(rows) else np.zeros((0, k.layout.nnodes, 4, 4)))
        r.set_camera(self.camera_pose())

    def finish(self) -> None:
        """Remove every soldier from the server (the replay is over)."""
        reset = self.translator.reset()
        if self.sink is not None:
            try:
                self.sink.apply(reset)
            except LinkError as exc:
                self._lose_server(exc)
        self._take(reset)
