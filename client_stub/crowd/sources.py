"""Where the crowd's poses come from: the server's update stream, or an offline stand-in.

Both keep a :class:`CrowdState` (struct of arrays, one row per soldier): feet position and compass heading
(owned by the client, dead-reckoned by the :class:`~client_stub.loadtest.mix.MixDriver`, feet put on the
terrain), DI.fig joint angles and the figure placements of the soldier root and the rifle in the soldier's
frame (from the wire: docs/PROTOCOL.md 8.3), and a ``dirty`` flag per soldier whose pose changed.

:class:`NetworkSource` is ``ttes loadtest``'s session in decode mode, run by trio in a thread: it creates
the soldiers and drives them with the realistic mix (the same requests as the load test); its link clients
keep the decoded poses in their double buffers, which :meth:`NetworkSource.update` swaps into the state
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
from client_stub.link.auth import Credentials
from client_stub.link.buffer import UpdateBatch
from client_stub.loadtest.client import LoadError
from client_stub.loadtest.mix import APPEARANCE, SPEED, WEAPON, MixDriver
from client_stub.loadtest.session import LoadSession, LoadTestConfig, first_leaf
from client_stub.stub.artic import TableBinding, articulation, bind_table, update_table_for
from client_stub.stub.ground import GroundQuery
from client_stub.stub.offline import OfflinePoser
from client_stub.stub.scene_graph import Crowd, EntityLayout, FigureGraph
from client_stub.stub.terrain import Terrain
from client_stub.stub.tips import TipsFigure
from protocol import coords
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


class WireBinding:
    """Fresh wire poses into the state: wire tables are bound to ours by entry name; a table that names too
    few of DI.fig's DOFs marks its soldiers for offline posing instead."""

    def __init__(self, ours: UpdateTable) -> None:
        self.ours = ours
        self.bindings: dict[int, TableBinding] = {}
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

    def apply(
        self, state: CrowdState, wire: UpdateTable, batch: UpdateBatch, slots: np.ndarray
    ) -> np.ndarray:
        """One swapped batch (its rows are the soldiers ``slots``) into ``state``, marked dirty; returns the
        slots that need offline posing instead."""
        b, bound = self.binding(wire)
        if not bound:
            return slots
        body = b.dof_dst < state.dofs.shape[1]
        q = np.asarray(batch.dofs, np.float32)
        state.dofs[np.ix_(slots, b.dof_dst[body])] = q[:, b.dof_src[body]]
        for f, src in enumerate(b.figure_src[:2].tolist()):
            if src >= 0:
                place = coords.pose7_to_transform(batch.positions[:, src], batch.orientations[:, src])
                state.placement[slots, f] = to34(place)
        state.rifle_from_palm[slots] = not (len(b.figure_src) > 1 and b.figure_src[1] >= 0)
        state.dirty[slots] = True
        return slots[:0]


class NetworkSource:
    """Soldiers on a Jack/TTES server, driven by the realistic mix, posed from the decoded update stream."""

    def __init__(
        self, n: int, body: FigureGraph, rifle: FigureGraph | None, body_tips: TipsFigure,
        rifle_tips: TipsFigure | None, *, host: str, port: int, clients: int, terrain: Terrain | None,
        centre: tuple[float, float], spacing: float, mix: str = "realistic", seed: int = 1,
        timeout_s: float = 120.0, credentials: Credentials | None = None,
    ) -> None:  # fmt: skip
        self.n = n
        self.heights = ground_heights(terrain)
        self.state = CrowdState.empty(n, body, rifle)
        ours = update_table_for(articulation(body_tips), articulation(rifle_tips) if rifle_tips else None)
        self.wire = WireBinding(ours)
        self.poser = _Poser(body, n)
        cfg = LoadTestConfig(
            soldiers=n, clients=clients, decode=True, mix=mix, seed=seed, timeout_s=timeout_s,
            credentials=credentials or Credentials(),
        )  # fmt: skip
        self.session = LoadSession(cfg, buffer_updates=True)
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
            leaf = first_leaf(exc)  # trio groups what a nursery's body raised
            why = str(leaf) if isinstance(leaf, LoadError) else f"network: {leaf!r}"  # a refusal: as it is
            self.failure = self.failure or why
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

    # -- the render thread ----------------------------------------------------------------------------------
    def update(self, t: float) -> None:
        if self.failure:
            raise RuntimeError(self.failure)
        dt = max(0.0, t - self.time)
        self.time = t
        st = self.state
        offline = self._take_updates()
        d = self.session.driver
        position, heading = d.position[: self.n].copy(), d.heading[: self.n].copy()  # racy but harmless
        if len(offline):
            self.poser.pose(st, d, offline, max(dt, 1e-3))
        moved = np.flatnonzero(np.any(position[:, :2] != st.position[:, :2], axis=1))
        st.position[moved] = position[moved]
        st.heading[:] = heading
        if self.heights is not None and len(moved):
            st.position[moved, 2] = self.heights(position[moved, :2])

    def _take_updates(self) -> np.ndarray:
        """Swap every link's double buffers into the state; returns the soldiers to pose offline."""
        offline = []
        slot_of = self.session.slot_of
        for c in self.session.clients:
            for batch in c.link.swap():
                slots = slot_of[batch.indices]
                keep = slots >= 0
                if keep.all():
                    part = batch
                else:
                    part = UpdateBatch(batch.table, batch.indices[keep], batch.dofs[keep],
                                       batch.positions[keep], batch.orientations[keep])  # fmt: skip
                offline.append(self.wire.apply(self.state, c.tables[batch.table], part, slots[keep]))
        return np.concatenate(offline) if offline else np.zeros(0, np.int64)

    def stats(self) -> dict:
        received = sum(c.link.soldier_updates for c in self.session.clients)
        return {"source": "server", "posing": self.wire.posing, "soldier_updates_received": received}

    def close(self) -> None:
        self.stop.set()
        self._thread.join(15.0)
        if self._thread.is_alive():
            log.warning("network thread did not stop")
