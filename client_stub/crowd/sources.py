"""Where the crowd's poses come from: the server's update stream, or an offline stand-in.

Both keep a :class:`CrowdState` (struct of arrays, one row per soldier): feet position and compass heading
(owned by the client, dead-reckoned by the :class:`~client_stub.loadtest.mix.MixDriver`, feet put on the
terrain), DI.fig joint angles and the figure placements of the soldier root and the rifle in the soldier's
frame (from the wire: docs/PROTOCOL.md 8.3), and a ``dirty`` flag per soldier whose pose changed.

:class:`NetworkSource` is ``ttes loadtest``'s session in decode mode, run by trio in a thread: it creates
the soldiers, drives them with the realistic mix (the same requests as the load test) and writes each
decoded JOINT_UPDATES into a back buffer; :meth:`NetworkSource.update` swaps it into the state under a lock
(the render thread never waits for the network). The wire table is bound to DI.fig's by entry name
(:func:`~client_stub.stub.artic.bind_table`); when it names too few of DI.fig's joints (the synthetic test
server's chain figure) the soldiers whose updates arrived are posed by
:class:`~client_stub.stub.offline.OfflinePoser` instead, and ``posing`` says so.

:class:`OfflineSource` needs no server: the same mix, posed by the OfflinePoser (for render benchmarks).
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import trio

from client_stub.crowd.fk import to34
from client_stub.loadtest.mix import APPEARANCE, SPEED, WEAPON, MixDriver
from client_stub.loadtest.session import LoadSession, LoadTestConfig
from client_stub.stub.artic import TableBinding, articulation, bind_table, update_table_for
from client_stub.stub.ground import GroundQuery
from client_stub.stub.offline import OfflinePoser
from client_stub.stub.scene_graph import Crowd, EntityLayout, FigureGraph
from client_stub.stub.terrain import Terrain
from client_stub.stub.tips import TipsFigure
from protocol import coords
from protocol.events import JointUpdates
from protocol.update_table import UpdateTable

log = logging.getLogger("ttes.crowd")
EASE_S = 1.5  # a resting soldier is re-posed offline this long after its activity changed
MIN_BOUND_FRACTION = 0.5  # of DI.fig's DOFs the wire table must carry to pose from the wire


@dataclass
class CrowdState:
    position: np.ndarray  # (n, 3) feet, world metres
    heading: np.ndarray  # (n,) compass degrees
    dofs: np.ndarray  # (n, ndof) float32, DI.fig pose order
    placement: np.ndarray  # (n, 2, 3, 4) float32: soldier root, rifle (soldier frame)
    rifle_from_palm: np.ndarray  # (n,) bool: put the rifle in the right palm (no rifle placement known)
    dirty: np.ndarray  # (n,) bool: joints or placements changed since the renderer last took them

    @classmethod
    def empty(cls, n: int, body: FigureGraph, rifle: FigureGraph | None) -> CrowdState:
        place = np.zeros((n, 2, 3, 4), np.float32)
        place[:, 0] = to34(body.location)
        place[:, 1] = to34(rifle.location) if rifle is not None else to34(np.eye(4))
        return cls(
            np.zeros((n, 3)), np.zeros(n), np.zeros((n, body.ndof), np.float32), place,
            np.ones(n, bool), np.ones(n, bool),
        )  # fmt: skip


class _Poser:
    """The OfflinePoser over a DI-only crowd (its own rifle step would run the slow reference FK)."""

    def __init__(self, body: FigureGraph, n: int) -> None:
        self.crowd = Crowd(EntityLayout([body]), n)
        self.poser = OfflinePoser(self.crowd)
        self.odometer = np.zeros(n)

    def pose(self, state: CrowdState, driver: MixDriver, rows: np.ndarray, dt: float) -> None:
        if not len(rows):
            return
        act = driver.activity[rows]
        speed = SPEED[act]
        self.odometer[rows] += speed * dt
        self.poser.pose(rows, APPEARANCE[act], WEAPON[act], speed, self.odometer[rows], dt)
        state.dofs[rows] = self.crowd.dofs[rows]
        state.placement[rows, 0] = to34(self.crowd.placements[rows, 0])
        state.rifle_from_palm[rows] = True
        state.dirty[rows] = True


Heights = Callable[[np.ndarray], np.ndarray]


def ground_heights(terrain: Terrain | None) -> Heights | None:
    """Feet heights on the terrain's ``ground`` layer when it has one (the crowd walks through houses
    rather than on their roofs), else on the whole terrain; 0 off the terrain."""
    if terrain is None:
        return None
    ground = terrain.meshes.get("ground")
    if ground is None:
        return lambda xy: terrain.height(xy)
    query = GroundQuery(ground.vertices, ground.faces)
    return lambda xy: np.nan_to_num(query.heights(xy), nan=0.0)


def _ground(state: CrowdState, driver: MixDriver, heights: Heights | None, rows: np.ndarray) -> None:
    state.position[rows] = driver.position[rows]
    state.heading[rows] = driver.heading[rows]
    if heights is not None and len(rows):
        state.position[rows, 2] = heights(driver.position[rows, :2])


class OfflineSource:
    """The realistic mix posed on the client: no server, no network."""

    posing = "offline"

    def __init__(
        self, n: int, body: FigureGraph, rifle: FigureGraph | None, *, terrain: Terrain | None,
        centre: tuple[float, float], spacing: float, mix: str = "realistic", seed: int = 1,
    ) -> None:  # fmt: skip
        self.n = n
        self.driver = MixDriver(n, mix=mix, seed=seed, centre=centre, spacing=spacing)
        self.state = CrowdState.empty(n, body, rifle)
        self.poser = _Poser(body, n)
        self.heights = ground_heights(terrain)
        self.time = 0.0
        self._first = True

    def update(self, t: float) -> None:
        d = self.driver
        dt = max(0.0, t - self.time)
        self.time = t
        d.step(t)
        moving = d.moving
        busy = moving | (t - d.since < EASE_S) | self._first
        rows = np.flatnonzero(busy)
        self.poser.pose(self.state, d, rows, dt if not self._first else 1.0)
        _ground(self.state, d, self.heights, np.arange(self.n) if self._first else np.flatnonzero(moving))
        self.state.heading[:] = d.heading
        self._first = False

    def stats(self) -> dict:
        return {"source": "offline"}

    def close(self) -> None:
        return


class _CrowdSession(LoadSession):
    """The load-test session, keeping every decoded pose (latest wins) for the renderer."""

    def __init__(self, cfg: LoadTestConfig, sink: NetworkSource) -> None:
        super().__init__(cfg)
        self.sink = sink

    def _on_updates(self, conn: int, t: float, tick: int, idx: np.ndarray, nbytes: int, ev: object) -> None:
        super()._on_updates(conn, t, tick, idx, nbytes, ev)
        if isinstance(ev, JointUpdates):
            slots = self.slot_of[idx]
            keep = slots >= 0
            self.sink.receive(self.clients[conn].tables[ev.table], ev, slots[keep], keep)


class WireBuffer:
    """The back buffer of decoded poses: the network thread writes (:meth:`receive`), the render thread
    takes what is fresh (:meth:`take`), under one lock. Wire tables are bound to ours by entry name; a table
    that names too few of DI.fig's DOFs marks its soldiers for offline posing instead."""

    def __init__(self, n: int, ours: UpdateTable, state: CrowdState) -> None:
        self.ours = ours
        self.lock = threading.Lock()
        self.bindings: dict[int, TableBinding] = {}
        self.dofs = np.zeros_like(state.dofs)
        self.place = state.placement.copy()
        self.has_rifle = np.zeros(n, bool)
        self.fresh = np.zeros(n, bool)
        self.offline = np.zeros(n, bool)
        self.updates = 0
        self.posing = "server"

    def binding(self, wire: UpdateTable) -> tuple[TableBinding, bool]:
        b = self.bindings.get(wire.table_id)
        if b is None:
            b = self.bindings[wire.table_id] = bind_table(self.ours, wire)
            if len(b.dof_dst) < MIN_BOUND_FRACTION * self.ours.ndofs:
                self.posing = "offline (wire table does not name DI.fig's joints)"
                log.warning("update table %d binds %d of our %d DOFs: posing offline", wire.table_id,
                            len(b.dof_dst), self.ours.ndofs)  # fmt: skip
        return b, len(b.dof_dst) >= MIN_BOUND_FRACTION * self.ours.ndofs

    def receive(self, wire: UpdateTable, ev: JointUpdates, slots: np.ndarray, keep: np.ndarray) -> None:
        """One decoded batch (``keep`` selects the rows of ``ev`` whose soldiers are ``slots``)."""
        b, bound = self.binding(wire)
        with self.lock:
            self.updates += len(slots)
            self.fresh[slots] = True
            if not bound:
                self.offline[slots] = True
                return
            body = b.dof_dst < self.dofs.shape[1]
            q = np.asarray(ev.dofs, np.float32)[keep]
            self.dofs[np.ix_(slots, b.dof_dst[body])] = q[:, b.dof_src[body]]
            pos = np.asarray(ev.positions)[keep]
            quat = np.asarray(ev.orientations)[keep]
            for f, src in enumerate(b.figure_src[:2].tolist()):
                if src >= 0:
                    self.place[slots, f] = to34(coords.pose7_to_transform(pos[:, src], quat[:, src]))
            self.has_rifle[slots] = len(b.figure_src) > 1 and b.figure_src[1] >= 0

    def take(self, state: CrowdState) -> np.ndarray:
        """Copy the fresh wire poses into ``state`` (marking them dirty); returns the fresh soldiers that
        need offline posing."""
        with self.lock:
            rows = np.flatnonzero(self.fresh)
            self.fresh[rows] = False
            offline = rows[self.offline[rows]]
            wire = rows[~self.offline[rows]]
            state.dofs[wire] = self.dofs[wire]
            state.placement[wire] = self.place[wire]
            state.rifle_from_palm[wire] = ~self.has_rifle[wire]
        state.dirty[wire] = True
        return offline


class NetworkSource:
    """Soldiers on a Jack/TTES server, driven by the realistic mix, posed from the decoded update stream."""

    def __init__(
        self, n: int, body: FigureGraph, rifle: FigureGraph | None, body_tips: TipsFigure,
        rifle_tips: TipsFigure | None, *, host: str, port: int, clients: int, terrain: Terrain | None,
        centre: tuple[float, float], spacing: float, mix: str = "realistic", seed: int = 1,
        timeout_s: float = 120.0,
    ) -> None:  # fmt: skip
        self.n = n
        self.heights = ground_heights(terrain)
        self.state = CrowdState.empty(n, body, rifle)
        ours = update_table_for(articulation(body_tips), articulation(rifle_tips) if rifle_tips else None)
        self.wire = WireBuffer(n, ours, self.state)
        self.poser = _Poser(body, n)
        cfg = LoadTestConfig(
            soldiers=n, clients=clients, decode=True, mix=mix, seed=seed, timeout_s=timeout_s
        )
        self.session = _CrowdSession(cfg, self)
        self.session.driver = MixDriver(0, mix=mix, seed=seed, centre=centre, spacing=spacing)
        self.ready = threading.Event()
        self.stop = threading.Event()
        self.failure: str | None = None
        self.time = 0.0
        self._thread = threading.Thread(
            target=self._run, args=(host, port), name="crowd-network", daemon=True
        )
        self._thread.start()
        if not self.ready.wait(timeout_s) or self.failure:
            self.close()
            raise RuntimeError(self.failure or f"soldiers not ready within {timeout_s} s")

    # -- the network thread ---------------------------------------------------------------------------------
    def _run(self, host: str, port: int) -> None:
        try:
            trio.run(self._main, host, port)
        except BaseException as exc:  # the thread must end and say why
            self.failure = self.failure or f"network: {exc!r}"
        finally:
            self.ready.set()

    async def _main(self, host: str, port: int) -> None:
        s = self.session
        async with trio.open_nursery() as nursery:
            await s.connect(nursery, host, port)
            await s.grow(self.n)
            self.ready.set()
            while not self.stop.is_set():
                await s.drive(s.now() + 0.25)
            with trio.CancelScope(shield=True), trio.move_on_after(5.0):
                await s.close(remove=True)
            nursery.cancel_scope.cancel()

    def receive(self, wire: UpdateTable, ev: JointUpdates, slots: np.ndarray, keep: np.ndarray) -> None:
        self.wire.receive(wire, ev, slots, keep)

    # -- the render thread ----------------------------------------------------------------------------------
    def update(self, t: float) -> None:
        if self.failure:
            raise RuntimeError(self.failure)
        dt = max(0.0, t - self.time)
        self.time = t
        st = self.state
        offline = self.wire.take(st)
        d = self.session.driver
        position, heading = d.position[: self.n].copy(), d.heading[: self.n].copy()  # racy but harmless
        if len(offline):
            self.poser.pose(st, d, offline, max(dt, 1e-3))
        moved = np.flatnonzero(np.any(position[:, :2] != st.position[:, :2], axis=1))
        st.position[moved] = position[moved]
        st.heading[:] = heading
        if self.heights is not None and len(moved):
            st.position[moved, 2] = self.heights(position[moved, :2])

    def stats(self) -> dict:
        return {"source": "server", "posing": self.wire.posing, "soldier_updates_received": self.wire.updates}

    def close(self) -> None:
        self.stop.set()
        self._thread.join(15.0)
        if self._thread.is_alive():
            log.warning("network thread did not stop")
