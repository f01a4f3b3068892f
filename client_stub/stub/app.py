"""The stub application: soldiers, their scene graphs, the server connection and the frame loop.

One :class:`StubApp` ties the pieces of ``ttes stub`` together, window or not:

* kinds of soldier (figure + weapon), each loaded from TIPS files (``LoadTIPSFile``), with its articulation
  file written and read back to build the update table (section 3.7), its :class:`EntityLayout` and
  :class:`Crowd` (the per-soldier scene graphs) and an offline poser;
* the :class:`SimSoldiers` (slots 0, 1, 2 ...) and the keyboard controller;
* optionally a :class:`JackProc`: each slot is bound to a server soldier (those the start-up JCL created,
  then CREATE_SOLDIER), the slot's changed requests go out once a frame as one batch, and the joint updates
  that arrived are copied into the crowds through each wire table's binding. Slots without a server soldier
  are posed offline.

:meth:`StubApp.frame` advances everything by ``dt``; :meth:`StubApp.draw` updates the renderer.
"""

from __future__ import annotations

import logging
import os
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from client_stub.link.client import LinkError, UpdateBatch
from client_stub.stub.artic import (
    TableBinding,
    articulation,
    bind_table,
    read_artic,
    update_table_for,
    write_artic,
)
from client_stub.stub.camera import CameraState, camera_pose
from client_stub.stub.jack import JackProc
from client_stub.stub.keys import StubController
from client_stub.stub.offline import OfflinePoser
from client_stub.stub.scene_graph import Crowd, EntityLayout, FigureGraph
from client_stub.stub.simsoldier import Behaviour, Force, SimSoldiers
from client_stub.stub.terrain import Terrain
from client_stub.stub.tips import TipsFigure, load_tips
from protocol import coords
from protocol.entity import Appearance, WeaponState
from protocol.update_table import UpdateTable

log = logging.getLogger("ttes.stub")
DATA = Path(__file__).resolve().parent.parent / "data"
DEFAULT_FIGURE = "DI.fig"
WEAPONS = {Force.FRIENDLY: "M16.fig", Force.OPPOSING: "AK_47.fig"}


@dataclass
class Kind:
    """Everything shared by the soldiers of one figure + weapon."""

    figure: str
    weapon: str
    layout: EntityLayout
    crowd: Crowd
    poser: OfflinePoser
    table: UpdateTable  # ours, from the articulation file
    bindings: dict[int, TableBinding] = field(default_factory=dict)  # wire table id -> binding


class StubApp:
    """The stub's state and per-frame work (see the module docstring)."""

    def __init__(
        self,
        terrain: Terrain,
        *,
        data_dir: str | os.PathLike[str] = DATA,
        artic_dir: str | os.PathLike[str] | None = None,
        capacity: int = 16,
        max_soldiers: int = 64,
    ) -> None:
        self.terrain = terrain
        self.data_dir = Path(data_dir)
        self.artic_dir = Path(artic_dir) if artic_dir else Path(tempfile.gettempdir()) / "ttes-stub"
        self.soldiers = SimSoldiers(terrain, capacity)
        self.camera = CameraState()
        self.controller = StubController(self.soldiers, self.camera, max_soldiers=max_soldiers)
        self.kinds: list[Kind] = []
        self._kind_of_files: dict[tuple[str, str], int] = {}
        self._tips: dict[str, TipsFigure] = {}
        self.slot_kind = np.full(capacity, -1, np.int64)
        self.server_of = np.full(capacity, -1, np.int64)  # slot -> server soldier index
        self.slot_of_server: dict[int, int] = {}
        self._slot_by_server = np.full(0, -1, np.int64)  # the same map as an array, for whole batches
        self.jack: JackProc | None = None
        self.renderer = None
        self.time = 0.0

    # -- kinds -----------------------------------------------------------------------------------------------

    def _tips_figure(self, filename: str) -> TipsFigure:
        stem = Path(filename).stem
        if stem not in self._tips:
            tips = load_tips(self.data_dir / f"{stem}.tips")
            if not tips.figures:
                raise ValueError(f"{stem}.tips holds no figure")
            self._tips[stem] = tips.figures[0]
        return self._tips[stem]

    def kind(self, figure: str, weapon: str) -> int:
        """The kind of soldier made of these figure files (loaded on first use)."""
        key = (figure, weapon)
        if key in self._kind_of_files:
            return self._kind_of_files[key]
        tips = [self._tips_figure(figure)] + ([self._tips_figure(weapon)] if weapon else [])
        artic = [articulation(t) for t in tips]
        self.artic_dir.mkdir(parents=True, exist_ok=True)
        path = self.artic_dir / f"{Path(figure).stem}{'+' + Path(weapon).stem if weapon else ''}.artic"
        write_artic(artic, path)
        artic = read_artic(path)  # the update table is built from the file, as in 1994
        table = update_table_for(artic[0], artic[1] if len(artic) > 1 else None)
        layout = EntityLayout([FigureGraph(t) for t in tips])
        crowd = Crowd(layout, max(self.soldiers.capacity, 1))
        kind = Kind(figure, weapon, layout, crowd, OfflinePoser(crowd), table)
        self.kinds.append(kind)
        self._kind_of_files[key] = len(self.kinds) - 1
        return len(self.kinds) - 1

    def _grow(self) -> None:
        cap = self.soldiers.capacity
        if len(self.slot_kind) < cap:
            extra = cap - len(self.slot_kind)
            self.slot_kind = np.concatenate([self.slot_kind, np.full(extra, -1, np.int64)])
            self.server_of = np.concatenate([self.server_of, np.full(extra, -1, np.int64)])
        for k in self.kinds:
            k.crowd.grow(cap)

    def _set_kind(self, slot: int, kind: int) -> None:
        old = int(self.slot_kind[slot])
        if old == kind:
            return
        if old >= 0:
            self.kinds[old].crowd.active[slot] = False
        self.slot_kind[slot] = kind
        self.kinds[kind].crowd.grow(self.soldiers.capacity)
        self.kinds[kind].crowd.active[slot] = True

    # -- soldiers --------------------------------------------------------------------------------------------

    def add_soldier(self, xy: np.ndarray | tuple[float, float], heading: float = 0.0, **kw: object) -> int:
        """A SimSoldier (keywords of :meth:`SimSoldiers.add`), its kind by force, its server soldier."""
        slot = self.soldiers.add(xy, heading, **kw)  # type: ignore[arg-type]
        self._place(slot)
        return slot

    def _place(self, slot: int) -> None:
        self._grow()
        force = Force(int(self.soldiers.force[slot]))
        weapon = WEAPONS[force]
        self._set_kind(slot, self.kind(DEFAULT_FIGURE, weapon))
        if self.jack is not None and self.jack.jackready:
            self._bind_server(slot, weapon)

    def handle_key(self, key: str) -> str | None:
        before = self.soldiers.count
        message = self.controller.handle(key)
        for slot in range(before, self.soldiers.count):  # key 'a' added soldiers
            self._place(slot)
        return message

    # -- the server ------------------------------------------------------------------------------------------

    def connect(
        self, jack: JackProc, ready_timeout: float = 30.0, soldierprefix: str = "soldier_low"
    ) -> bool:
        """Start Jack (the start-up JCL), wait for READY, bind every slot to a server soldier, subscribe."""
        self.jack = jack
        jack.start(soldierprefix)
        if not jack.wait_ready(ready_timeout):
            log.warning(
                "server not ready after %.0f s: soldiers stay offline (%s)", ready_timeout, jack.failure
            )
            return False
        for slot in range(self.soldiers.count):
            self._bind_server(slot, WEAPONS[Force(int(self.soldiers.force[slot]))])
        return True

    def _bind_server(self, slot: int, weapon: str) -> None:
        """Give ``slot`` a server soldier: a free one from READY, else CREATE_SOLDIER."""
        jack = self.jack
        if jack is None or self.server_of[slot] >= 0:
            return
        free = sorted(set(jack.ready_soldiers) - set(self.slot_of_server))
        try:
            if free:
                index = free[0]
                js = jack.soldier(index, jack.ready_soldiers[index])
            else:
                try:
                    js = jack.new_soldier(DEFAULT_FIGURE, weapon, timeout=5.0)
                except LinkError:
                    js = jack.new_soldier(DEFAULT_FIGURE, "AK_47.fig", timeout=5.0)
        except LinkError as exc:
            log.warning("soldier %d stays offline: %s", slot, exc)
            return
        wire = jack.tables.get(js.updatetable)
        if wire is None:
            log.warning("soldier %d: update table %d unknown; offline", slot, js.updatetable)
            return
        kind = self.kind(wire.figure, wire.weapon)
        k = self.kinds[kind]
        if wire.table_id not in k.bindings:
            binding = bind_table(k.table, wire)
            if not binding.agrees:
                log.warning("update table %d differs from ours (missing %s)", wire.table_id, binding.missing)
            k.bindings[wire.table_id] = binding
        self._set_kind(slot, kind)
        self.server_of[slot] = js.soldiernum
        self.slot_of_server[js.soldiernum] = slot
        if js.soldiernum >= len(self._slot_by_server):
            grown = np.full(max(js.soldiernum + 1, 2 * len(self._slot_by_server), 16), -1, np.int64)
            grown[: len(self._slot_by_server)] = self._slot_by_server
            self._slot_by_server = grown
        self._slot_by_server[js.soldiernum] = slot
        self.soldiers.dirty[slot] = True
        jack.subscribe([js.soldiernum])

    def _apply_updates(self, batches: list[UpdateBatch]) -> None:
        for batch in batches:
            idx = np.asarray(batch.indices, np.int64)
            known = idx < len(self._slot_by_server)
            slots = np.full(len(idx), -1, np.int64)
            slots[known] = self._slot_by_server[idx[known]]
            ok = slots >= 0
            if not ok.any():
                continue
            slots, dofs = slots[ok], batch.dofs[ok]
            pos, quat = batch.positions[ok], batch.orientations[ok]
            for kind_id in np.unique(self.slot_kind[slots]):
                k = self.kinds[int(kind_id)]
                binding = k.bindings.get(batch.table)
                if binding is None:
                    continue
                sel = self.slot_kind[slots] == kind_id
                rows = slots[sel]
                q = k.crowd.dofs[rows].copy()
                q[:, binding.dof_dst] = dofs[sel][:, binding.dof_src]
                k.crowd.set_dofs(rows, q)
                place = k.crowd.placements[rows].copy()
                for f, src in enumerate(binding.figure_src):
                    if src >= 0:
                        place[:, f] = coords.pose7_to_transform(pos[sel][:, src], quat[sel][:, src])
                k.crowd.set_placements(rows, place)

    # -- per frame -------------------------------------------------------------------------------------------

    def frame(self, dt: float) -> None:
        """Advance the soldiers, talk to the server, update every soldier's scene graph."""
        self.time += dt
        s = self.soldiers
        s.step(dt)
        self._grow()
        n = s.count
        slots = np.arange(n)
        requests = s.requests()
        jack = self.jack
        if jack is not None and jack.connected:
            on_server = self.server_of[requests["index"]] >= 0
            out = requests[on_server]
            out["index"] = self.server_of[out["index"]]
            try:
                jack.send_requests(out)
                self._apply_updates(jack.swap())
            except LinkError as exc:
                log.warning("server connection lost: %s; soldiers continue offline", exc)
                self.server_of[:] = -1
                self.slot_of_server.clear()
                self._slot_by_server[:] = -1
                self.jack = None
        for kind_id, k in enumerate(self.kinds):
            rows = slots[self.slot_kind[:n] == kind_id]
            if not len(rows):
                continue
            k.crowd.set_entity(rows, s.entity_matrices(rows))
            off = rows[self.server_of[rows] < 0]
            if len(off):
                k.poser.pose(
                    off, s.appearance[off], s.weapon[off], s.speed[off] * s.moving(off), s.distance[off], dt
                )

    def draw(self) -> None:
        """Hand the soldiers' world matrices and the camera to the renderer."""
        r = self.renderer
        if r is None:
            return
        n = self.soldiers.count
        slots = np.arange(n)
        for kind_id, k in enumerate(self.kinds):
            for force in (Force.FRIENDLY, Force.OPPOSING):
                rows = slots[(self.slot_kind[:n] == kind_id) & (self.soldiers.force[:n] == force)]
                if not len(rows) and (kind_id, int(force)) not in r.soldiers:
                    continue
                meshes = r.soldier_meshes(kind_id, k.layout, force)
                meshes.update(k.crowd.world(rows) if len(rows) else np.zeros((0, k.layout.nnodes, 4, 4)))
        r.set_camera(self.camera_pose())

    def camera_pose(self) -> np.ndarray:
        s = self.soldiers
        cur = self.controller.current
        feet, heading = (s.position[cur], float(s.heading[cur])) if cur < s.count else (np.zeros(3), 0.0)
        return camera_pose(self.camera, feet, heading, self.terrain.bounds)

    def close(self) -> None:
        if self.jack is not None:
            self.jack.quit()
            self.jack = None


def populate_demo(app: StubApp) -> None:
    """The seed's start (4.1): soldier 0 standing in the middle of the village, soldier 1 walking a square,
    soldier 2 a circle; then friendly soldiers kneeling and prone, and an opposing group (Figure 8)."""
    t = app.terrain
    centre = t.landmark("centre")
    square = t.landmarks["square"]
    circle = t.landmarks["circle"]
    groups = t.landmarks["groups"]
    fr, op = np.asarray(groups["friendly"]), np.asarray(groups["opposing"])
    app.add_soldier(centre, 0.0)
    app.add_soldier(square["centre"], 0.0, speed=1.3, behaviour=Behaviour.SQUARE, size=square["side"])
    app.add_soldier(circle["centre"], 90.0, speed=1.2, behaviour=Behaviour.CIRCLE, size=circle["radius"])
    app.add_soldier(fr + np.array([-3.0, 0.0]), 20.0, appearance=Appearance.KNEEL, weapon=WeaponState.FIRING)
    app.add_soldier(fr + np.array([3.0, -2.0]), 10.0, appearance=Appearance.PRONE, weapon=WeaponState.FIRING)
    opposing = dict(force=Force.OPPOSING)
    app.add_soldier(op + np.array([-4.0, 0.0]), 200.0, weapon=WeaponState.FIRING, **opposing)
    app.add_soldier(op + np.array([0.0, 2.0]), 180.0, appearance=Appearance.KNEEL, **opposing)
    app.add_soldier(op + np.array([4.0, 0.0]), 170.0, appearance=Appearance.PRONE, **opposing)
    app.add_soldier(
        op + np.array([0.0, -8.0]), 180.0, speed=3.6, behaviour=Behaviour.SQUARE, size=12.0, **opposing
    )
    app.add_soldier(op + np.array([7.0, -3.0]), 0.0, appearance=Appearance.DEAD, **opposing)
