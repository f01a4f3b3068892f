"""The stub application: kinds of soldier, their scene graphs, the frame loop; a source moves the soldiers.

One :class:`StubApp` ties the pieces of an image generator together, window or not:

* kinds of soldier (figure + weapon), each loaded from TIPS files (``LoadTIPSFile``), with its articulation
  file written and read back to build the update table (section 3.7), its :class:`EntityLayout` and
  :class:`Crowd` (the per-soldier scene graphs) and an offline poser;
* the soldier slots (:class:`SimSoldiers`), their kind and look, and the keyboard controller;
* a :class:`SoldierSource` that moves the soldiers each frame and talks to the server about them: the
  stub's own soldiers (:class:`client_stub.stub.live.LiveSoldiers`: behaviours, keys, a ``JackProc``) or a
  DIS replay (:class:`client_stub.dis.soldiers.DisSoldiers`). Through the source's link the joint updates
  that arrived are copied into the crowds by each wire table's binding; slots without a server soldier are
  posed offline.

:meth:`StubApp.frame` advances everything by ``dt``; :meth:`StubApp.draw` updates the renderer.
"""

from __future__ import annotations

import logging
import os
import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Protocol

import numpy as np

from client_stub.data_paths import STUB_DATA
from client_stub.link.buffer import UpdateBatch
from client_stub.link.client import LinkError
from client_stub.stub.action import action_points, follow_action, soldier_labels
from client_stub.stub.artic import (
    TableBinding,
    articulation,
    bind_table,
    read_artic,
    update_table_for,
    write_artic,
)
from client_stub.stub.camera import CameraState, View, action_pose, camera_pose
from client_stub.stub.grounding import body_figure, ground_figures
from client_stub.stub.keys import KEY_HELP, StubController
from client_stub.stub.offline import OfflinePoser
from client_stub.stub.overlay import Label, Overlay
from client_stub.stub.scene_graph import Crowd, EntityLayout, FigureGraph
from client_stub.stub.simsoldier import Force, SimSoldiers
from client_stub.stub.terrain import Terrain
from client_stub.stub.tips import TipsFigure, load_tips
from protocol import coords
from protocol.update_table import UpdateTable

if TYPE_CHECKING:
    from client_stub.link.api import Link
    from client_stub.renderer import StubBackend

log = logging.getLogger("ttes.stub")
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


class SoldierSource(Protocol):
    """Where a :class:`StubApp`'s soldiers come from, frame by frame."""

    @property
    def link(self) -> Link | None:
        """The server link whose joint updates pose the soldiers bound to server soldiers (None: offline)."""
        ...

    def step(self, app: StubApp, dt: float) -> None:
        """Move ``app.soldiers`` by ``dt``, add or hide soldiers, tell the server (LinkError: link lost)."""
        ...

    def added(self, app: StubApp, slot: int) -> None:
        """A soldier the keys added in ``slot``."""
        ...

    def refuse_key(self, key: str) -> str | None:
        """A message when this source does not let ``key`` through to the keyboard controller."""
        ...

    def camera_pose(self, app: StubApp) -> np.ndarray | None:
        """The camera this source wants (None: the keyboard's camera)."""
        ...

    def lose_server(self) -> None:
        """The link is gone: go on without it."""
        ...

    def close(self) -> None: ...


class StubApp:
    """The stub's state and per-frame work (see the module docstring); ``source`` defaults to the stub's own
    soldiers without a server."""

    def __init__(
        self,
        terrain: Terrain,
        source: SoldierSource | None = None,
        *,
        data_dir: str | os.PathLike[str] = STUB_DATA,
        artic_dir: str | os.PathLike[str] | None = None,
        capacity: int = 16,
        max_soldiers: int = 64,
    ) -> None:
        if source is None:
            from client_stub.stub.live import LiveSoldiers

            source = LiveSoldiers()
        self.terrain = terrain
        self.source = source
        self.data_dir = Path(data_dir)
        self.artic_dir = Path(artic_dir) if artic_dir else Path(tempfile.gettempdir()) / "ttes-stub"
        self.soldiers = SimSoldiers(terrain, capacity)
        self.camera = CameraState()
        self.controller = StubController(self.soldiers, self.camera, max_soldiers=max_soldiers)
        self.kinds: list[Kind] = []
        self._kind_of_files: dict[tuple[str, str], int] = {}
        self._tips: dict[str, TipsFigure] = {}
        self.slot_kind = np.full(capacity, -1, np.int64)
        self.look = np.zeros(capacity, np.int64)  # slot -> the renderer's colour key (a force, or a DIS look)
        self.server_of = np.full(capacity, -1, np.int64)  # slot -> server soldier index
        self.slot_of_server: dict[int, int] = {}
        self._slot_by_server = np.full(0, -1, np.int64)  # the same map as an array, for whole batches
        self.renderer: StubBackend | None = None
        self.show_help = False  # the keys over the picture (``?`` toggles)
        self.figure_box = np.full((0, 2, 3), np.nan)  # slot -> lowest and highest joint as last drawn
        self._turned = 0.0  # when a touring ACTION CAM last turned to another soldier
        self.source_camera = False  # the source chose the last camera pose (the replay's squad view)
        self.labels = True  # name and posture above each soldier
        self.time = 0.0
        self.server_lost = ""  # "server lost: why" while the source has no server (after having one)
        self.server_lost_count = 0
        self.gave_up = ""  # the source stopped reconnecting (``ttes stub`` exits 3)

    @property
    def link(self) -> Link | None:
        return self.source.link

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

    def binding(self, kind: int, wire: UpdateTable) -> TableBinding:
        """The binding of a server update table to our kind's table (by entry name; made on first use)."""
        k = self.kinds[kind]
        if wire.table_id not in k.bindings:
            binding = bind_table(k.table, wire)
            if not len(binding.dof_dst):
                log.warning("update table %d shares no joint with %s: the stub poses these soldiers itself",
                            wire.table_id, k.figure)  # fmt: skip
            elif not binding.agrees:
                log.warning("update table %d differs from ours (missing %s)", wire.table_id, binding.missing)
            k.bindings[wire.table_id] = binding
        return k.bindings[wire.table_id]

    def grow(self) -> None:
        """Per-slot arrays as long as the soldiers' capacity."""
        cap = self.soldiers.capacity
        if len(self.slot_kind) < cap:
            extra = cap - len(self.slot_kind)
            self.slot_kind = np.concatenate([self.slot_kind, np.full(extra, -1, np.int64)])
            self.look = np.concatenate([self.look, np.zeros(extra, np.int64)])
            self.server_of = np.concatenate([self.server_of, np.full(extra, -1, np.int64)])
        for k in self.kinds:
            k.crowd.grow(cap)

    def set_kind(self, slot: int, kind: int, *, reactivate: bool = False) -> None:
        """``slot`` shows a soldier of ``kind`` (``reactivate``: also when it already was, but hidden)."""
        old = int(self.slot_kind[slot])
        if old == kind and not reactivate:
            return
        if old >= 0:
            self.kinds[old].crowd.active[slot] = False
        self.slot_kind[slot] = kind
        self.kinds[kind].crowd.grow(self.soldiers.capacity)
        self.kinds[kind].crowd.active[slot] = True

    def hide(self, slot: int) -> None:
        """The soldier of ``slot`` is gone (its slot may come back)."""
        self.soldiers.alive[slot] = False
        kind = int(self.slot_kind[slot])
        if kind >= 0:
            self.kinds[kind].crowd.active[slot] = False

    # -- soldiers --------------------------------------------------------------------------------------------

    def add_soldier(self, xy: np.ndarray | tuple[float, float], heading: float = 0.0, **kw: object) -> int:
        """A SimSoldier (keywords of :meth:`SimSoldiers.add`), its kind by force; the source hears of it."""
        slot = self.soldiers.add(xy, heading, **kw)  # type: ignore[arg-type]
        self._place(slot)
        return slot

    def _place(self, slot: int) -> None:
        self.grow()
        force = Force(int(self.soldiers.force[slot]))
        self.look[slot] = int(force)
        self.set_kind(slot, self.kind(DEFAULT_FIGURE, WEAPONS[force]))
        self.source.added(self, slot)

    def handle_key(self, key: str) -> str | None:
        refused = self.source.refuse_key(key)
        if refused is not None:
            return refused
        before = self.soldiers.count
        message = self.controller.handle(key)
        if key == "?":
            self.show_help = not self.show_help
        elif len(key) == 1 and key.lower() in "bcfvxoudijnp":
            self.camera.action_tour = False  # the user takes the camera (and the current soldier)
        for slot in range(before, self.soldiers.count):  # key 'a' added soldiers
            self._place(slot)
        return message

    # -- the server ------------------------------------------------------------------------------------------

    def map_server(self, slot: int, index: int) -> None:
        """Slot ``slot`` shows server soldier ``index``: its joint updates pose it from now on."""
        self.server_of[slot] = index
        self.slot_of_server[index] = slot
        if index >= len(self._slot_by_server):
            grown = np.full(max(index + 1, 2 * len(self._slot_by_server), 16), -1, np.int64)
            grown[: len(self._slot_by_server)] = self._slot_by_server
            self._slot_by_server = grown
        self._slot_by_server[index] = slot

    def lose_server(self, exc: Exception) -> None:
        """The server went away: the soldiers go on, posed by the stub (a source that can reconnects)."""
        log.warning("server lost: %s; the stub poses the soldiers from now on", exc)
        self.server_lost = f"server lost: {exc}"
        self.server_lost_count += 1
        self.source.lose_server()
        self.server_of[:] = -1
        self.slot_of_server.clear()
        self._slot_by_server[:] = -1

    def regain_server(self) -> None:
        """The source has a server again (its soldiers bound again)."""
        log.warning("server back after %s", self.server_lost.removeprefix("server lost: "))
        self.server_lost = ""

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
        """The source moves the soldiers and talks to the server; the server's poses and the offline poser's
        go into every live soldier's scene graph."""
        self.time += dt
        try:
            self.source.step(self, dt)
            self.grow()
            link = self.source.link
            if link is not None:
                if not getattr(link, "connected", True):  # the link's thread saw the server go
                    raise LinkError(getattr(link, "failure", None) or "connection closed")
                self._apply_updates(link.swap())
        except LinkError as exc:
            self.lose_server(exc)
        s = self.soldiers
        n = s.count
        slots = np.flatnonzero(s.alive[:n])
        for kind_id, k in enumerate(self.kinds):
            rows = slots[self.slot_kind[slots] == kind_id]
            if not len(rows):
                continue
            k.crowd.set_entity(rows, s.entity_matrices(rows))
            off = rows[self.server_of[rows] < 0]
            if len(off):
                k.poser.pose(
                    off, s.appearance[off], s.weapon[off], s.speed[off] * s.moving(off), s.distance[off], dt
                )
            if k.layout.figures:  # on the ground under the feet, not under the entity (slopes, root offsets)
                ground_figures(k.crowd, rows, body_figure(k.layout), self._ground)

    def draw(self) -> None:
        """Hand the live soldiers' world matrices (by kind and look), the camera and the overlay (labels,
        caption, keys) to the renderer."""
        r = self.renderer
        if r is None:
            return
        n = self.soldiers.count
        slots = np.flatnonzero(self.soldiers.alive[:n])
        labels: list[Label] = []
        self.figure_box = np.full((self.soldiers.capacity, 2, 3), np.nan)
        for kind_id, k in enumerate(self.kinds):
            mine = slots[self.slot_kind[slots] == kind_id]
            looks = set(self.look[mine].tolist()) | {key for kid, key in r.soldiers if kid == kind_id}
            for look in sorted(looks):
                rows = mine[self.look[mine] == look]
                world = k.crowd.world(rows) if len(rows) else np.zeros((0, k.layout.nnodes, 4, 4))
                r.soldier_meshes(kind_id, k.layout, look).update(world)
                joints = world[:, 1:, :3, 3]
                self.figure_box[rows] = np.stack([joints.min(axis=1), joints.max(axis=1)], axis=1)
                if self.labels:
                    labels += soldier_labels(self.soldiers, rows, world, self.controller.current)
        r.set_camera(self.camera_pose())
        r.overlay = Overlay(labels, self._caption(), KEY_HELP if self.show_help else ())

    def _caption(self) -> str:
        cur = self.controller.current
        who = f" · current soldier {cur}" if cur < self.soldiers.count else ""
        view = "the source's camera (squad view)" if self.source_camera else self.camera.view.value
        return f"{view}{who}"

    def camera_pose(self) -> np.ndarray:
        wanted = self.source.camera_pose(self)
        self.source_camera = wanted is not None
        if wanted is not None:
            return wanted
        s = self.soldiers
        cur = self.controller.current
        if self.camera.view is View.ACTION:
            return self._action_pose()
        feet, heading = (s.position[cur], float(s.heading[cur])) if cur < s.count else (np.zeros(3), 0.0)
        if cur < s.count and self.slot_kind[cur] >= 0:
            feet = self.figure_feet(cur, feet)
        return camera_pose(self.camera, feet, heading, self.terrain.bounds)

    def _action_pose(self) -> np.ndarray:
        if self.camera.action_tour:  # the replay's: a live soldier, the next force's every 10 s
            turned = follow_action(self.soldiers, self.controller.current, self.time, self._turned)
            if turned is not None:
                self.controller.current, self._turned = turned
        r = self.renderer
        yfov, aspect = (r.yfov_deg, r.width / r.height) if r is not None else (50.0, 4 / 3)
        points = action_points(self.soldiers, self.figure_box, self.controller.current)
        return action_pose(self.camera, points, yfov, aspect, self.terrain.height)

    def figure_feet(self, slot: int, feet: np.ndarray) -> np.ndarray:
        """Where the soldier's figure stands: the server sends a root offset (the figure trails or leads its
        entity through a step, issue 16), so the camera aims at the figure's root, not at the entity."""
        k = self.kinds[int(self.slot_kind[slot])]
        figs = k.layout.figures
        if not figs:
            return feet
        body = body_figure(k.layout)
        root = k.crowd.entity[slot] @ k.crowd.placements[slot, body]
        return np.array([root[0, 3], root[1, 3], k.crowd.entity[slot, 2, 3]])

    def _ground(self, xy: np.ndarray, top: np.ndarray) -> np.ndarray:
        return self.terrain.height(xy, top, default=0.0)

    def close(self) -> None:
        self.source.close()
