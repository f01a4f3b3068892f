"""JackProc / JackSoldier against a small fake Jack/TTES server speaking the same sans-IO protocol."""

from __future__ import annotations

import contextlib
import functools
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pytest
import trimesh
import trio

from client_stub.link.buffer import UpdateBuffer
from client_stub.link.client import LinkError
from client_stub.link.spawn import free_port
from client_stub.stub.app import StubApp
from client_stub.stub.artic import articulation, update_table_for
from client_stub.stub.jack import JackProc
from client_stub.stub.live import LiveSoldiers
from client_stub.stub.simsoldier import Behaviour, Force
from client_stub.stub.terrain import terrain_from_mesh
from client_stub.stub.tips import load_tips
from protocol import coords
from protocol.connection import NEED_DATA, PAUSED, SERVER, Connection
from protocol.entity import Appearance
from protocol.events import (
    Accept,
    ConnectionClosed,
    CreateSoldier,
    EntityRequests,
    Goodbye,
    Hello,
    Jcl,
    JointUpdates,
    Ping,
    Pong,
    ProtocolError,
    Ready,
    SoldierCreated,
    Subscribe,
    UpdateTableMsg,
)
from protocol.update_table import UpdateTable

DATA = Path(__file__).resolve().parent.parent / "client_stub" / "data"
TABLE_ID = 4


def wire_table() -> UpdateTable:
    """The table a server sends for DI.fig + AK_47.fig (the server builds it the same way)."""
    di = articulation(load_tips(DATA / "DI.tips").figures[0])
    ak = articulation(load_tips(DATA / "AK_47.tips").figures[0])
    return update_table_for(di, ak, TABLE_ID)


@dataclass
class FakeServer:
    """Answers like the real server: ACCEPT, tables + READY after the start-up JCL, soldiers on request, and
    a joint update per entity-request batch whose values encode the request (so tests can trace them)."""

    table: UpdateTable = field(default_factory=wire_table)
    jcl: list[str] = field(default_factory=list)
    requests: list[np.ndarray] = field(default_factory=list)
    subscribed: set[int] = field(default_factory=set)
    pongs: list[int] = field(default_factory=list)
    goodbye: trio.Event = field(default_factory=trio.Event)
    got_requests: trio.Event = field(default_factory=trio.Event)
    next_index: int = 2
    tick: int = 0

    async def handle(self, stream: trio.SocketStream) -> None:
        conn = Connection(SERVER, max_soldiers=16)
        async with stream:
            while True:
                ev = conn.next_event()
                if ev is NEED_DATA:
                    conn.receive_data(await stream.receive_some(65536))
                    continue
                out = b""
                if ev is PAUSED or isinstance(ev, Hello):
                    out = conn.send(Accept("fake-jack", max_soldiers=16))
                    out += conn.send(Ping(77))
                elif isinstance(ev, Jcl):
                    self.jcl.append(ev.text)
                    out = conn.send(UpdateTableMsg(self.table)) + conn.send(
                        Ready(((0, TABLE_ID), (1, TABLE_ID)))
                    )
                elif isinstance(ev, CreateSoldier):
                    out = conn.send(SoldierCreated(ev.id, self.next_index, TABLE_ID))
                    self.next_index += 1
                elif isinstance(ev, Subscribe):
                    self.subscribed |= set(ev.indices)
                elif isinstance(ev, Pong):
                    self.pongs.append(ev.nonce)
                elif isinstance(ev, EntityRequests):
                    self.requests.append(ev.rows.copy())
                    out = conn.send(self.updates(ev.rows))
                    self.got_requests.set()
                elif isinstance(ev, Goodbye):
                    self.goodbye.set()
                    return
                elif isinstance(ev, ConnectionClosed | ProtocolError):
                    return
                if out:
                    await stream.send_all(out)

    def updates(self, rows: np.ndarray) -> JointUpdates:
        """Soldier i's left knee bends 0.1 rad per appearance value; his root stands 0.9 m up, yawed 30°."""
        idx = np.unique(rows["index"].astype(np.int64))
        last = {int(r["index"]): r for r in rows}
        n, d = len(idx), self.table.ndofs
        dofs = np.zeros((n, d))
        knee = next(i for i, e in enumerate(self.table.entries) if e.name == "left_knee")
        col = sum(e.ndofs for e in self.table.entries[:knee])
        dofs[:, col] = [0.1 * last[int(i)]["appearance"] for i in idx]
        positions = np.zeros((n, self.table.nfigures, 3))
        positions[:, 0] = [0.0, 0.0, 0.9]
        positions[:, 1] = [0.2, 0.4, 1.1]
        yaw = coords.matrix_to_quat(coords.heading_transform(30.0, np.zeros(3))[:3, :3])
        orientations = np.broadcast_to(yaw, (n, self.table.nfigures, 4)).copy()
        self.tick += 1
        return JointUpdates(TABLE_ID, idx, dofs, positions, orientations, self.tick)


def flat_terrain():
    return terrain_from_mesh(trimesh.creation.box(extents=(200, 200, 2)), {"office": [30.0, -20.0]})


async def _serve(nursery: trio.Nursery, server: FakeServer) -> int:
    listeners = await nursery.start(functools.partial(trio.serve_tcp, server.handle, 0, host="127.0.0.1"))
    return listeners[0].socket.getsockname()[1]


async def test_stub_runs_against_a_fake_server(nursery: trio.Nursery, tmp_path: Path) -> None:
    server = FakeServer()
    port = await _serve(nursery, server)
    live = LiveSoldiers()
    app = StubApp(flat_terrain(), live, artic_dir=tmp_path)
    app.add_soldier((0.0, 0.0), 0.0)
    app.add_soldier((5.0, 0.0), 0.0, speed=1.0, behaviour=Behaviour.SQUARE)
    app.add_soldier((-5.0, 0.0), 90.0, force=Force.OPPOSING)
    jack = JackProc()
    with trio.fail_after(20):
        await trio.to_thread.run_sync(jack.initsocketconnection, "127.0.0.1", port)
        assert jack.connected and jack.accept is not None and jack.accept.name == "fake-jack"
        assert await trio.to_thread.run_sync(live.connect, app, jack, 10.0)
    try:
        assert server.jcl == ['read_file("jack-ttes-soldier_low.jcl");']
        assert jack.jackready and jack.ready_soldiers == {0: TABLE_ID, 1: TABLE_ID}
        # slots 0 and 1 took the soldiers the start-up script made, slot 2 was created
        assert app.server_of[:3].tolist() == [0, 1, 2]
        assert set(jack.table) == {0, 1, 2}
        kind = app.kinds[app.slot_kind[0]]
        assert (kind.figure, kind.weapon) == ("DI.fig", "AK_47.fig") and kind.bindings[TABLE_ID].agrees
        assert (app.artic_dir / "DI+AK_47.artic").is_file()

        graph = kind.layout.figures[0]
        knee = graph.dof_slices["left_knee"].start
        step = kind.table.entries[graph.joint_names.index("left_knee")].dofs[0].step
        with trio.fail_after(20):
            await trio.to_thread.run_sync(app.handle_key, "3")  # soldier 0 kneels
            await trio.to_thread.run_sync(app.frame, 0.1)
            await server.got_requests.wait()
            # the answer may already have been taken by that frame's swap, or arrive later
            while abs(kind.crowd.dofs[0, knee] - 0.3) > step:
                await trio.to_thread.run_sync(jack.wait_updates, 1.0)
                await trio.to_thread.run_sync(app.frame, 0.1)
        assert server.subscribed == {0, 1, 2}  # sent before the requests, so handled before them
        rows = server.requests[0]
        assert sorted(rows["index"].tolist()) == [0, 1, 2]  # server indices
        first = {int(r["index"]): r for r in rows}
        assert first[0]["appearance"] == Appearance.KNEEL
        np.testing.assert_allclose(first[2]["position"], [-5.0, 0.0, 1.0], atol=1e-6)  # feet on the box top
        # the joint update reached slot 0's scene graph: knee DOF and figure placements
        assert abs(kind.crowd.dofs[0, knee] - 0.3) <= step
        assert abs(kind.crowd.dofs[1, knee] - 0.2) <= step
        np.testing.assert_allclose(kind.crowd.placements[0, 0, :3, 3], [0.0, 0.0, 0.9], atol=1e-3)
        np.testing.assert_allclose(kind.crowd.placements[0, 1, :3, 3], [0.2, 0.4, 1.1], atol=1e-3)
        r = kind.crowd.placements[0, 0, :3, :3]
        a = math.radians(30)
        np.testing.assert_allclose(r @ [0.0, 1.0, 0.0], [math.sin(a), math.cos(a), 0], atol=1e-3)
        world = kind.crowd.world(np.array([0]))
        assert np.isclose(world[0, 0, 2, 3], 1.0)  # entity on the ground (box top at z = 1)
        # JackSoldier.request: Figure 10's per-soldier call
        server.got_requests = trio.Event()
        await trio.to_thread.run_sync(
            jack.table[1].request, Appearance.PRONE, 1, (0.0, 0.5, 0.0), 0.0, (1.0, 2.0, 0.0)
        )
        with trio.fail_after(10):
            await server.got_requests.wait()
        assert server.requests[-1]["appearance"].tolist() == [Appearance.PRONE]
        assert server.pongs == [77]
    finally:
        await trio.to_thread.run_sync(app.close)
    with trio.fail_after(10):
        await server.goodbye.wait()
    assert jack.closed.is_set()


async def test_connecting_to_nothing_fails_cleanly() -> None:
    jack = JackProc()
    port = free_port()
    with pytest.raises(LinkError, match="cannot connect"):
        await trio.to_thread.run_sync(jack.initsocketconnection, "127.0.0.1", port, 5.0)
    assert jack.closed.is_set() and not jack.connected
    with pytest.raises(LinkError):
        await trio.to_thread.run_sync(jack.send, Ping(1))


async def test_a_server_speaking_garbage_is_a_protocol_error(nursery: trio.Nursery) -> None:
    async def garbage(stream: trio.SocketStream) -> None:
        async with stream:
            await stream.receive_some(1024)
            await stream.send_all(b"\x00\x00\x00\x05\x99junk")
            with contextlib.suppress(trio.BrokenResourceError):
                await stream.receive_some(1024)

    listeners = await nursery.start(functools.partial(trio.serve_tcp, garbage, 0, host="127.0.0.1"))
    port = listeners[0].socket.getsockname()[1]
    jack = JackProc()
    with pytest.raises(LinkError, match="protocol error 3"):
        await trio.to_thread.run_sync(jack.initsocketconnection, "127.0.0.1", port, 10.0)
    assert isinstance(jack.errors[0], ProtocolError)


def test_update_buffer_is_a_double_buffer() -> None:
    table = wire_table()
    buf = UpdateBuffer(table)
    g = table.nfigures

    def ev(indices: list[int], value: float) -> JointUpdates:
        n = len(indices)
        dofs = np.full((n, table.ndofs), value)
        return JointUpdates(
            TABLE_ID, np.array(indices), dofs, np.zeros((n, g, 3)), np.tile([1.0, 0, 0, 0], (n, g, 1))
        )

    buf.write(ev([1, 3], 0.5))
    buf.write(ev([3], 0.7))  # the newest pose of a soldier wins
    front = buf.flip()
    assert front is not None and front.indices.tolist() == [1, 3] and front.dofs[1, 0] == 0.7
    assert buf.flip() is None  # taken: nothing fresh in the other buffer yet
    buf.write(ev([2], 0.1))  # the reader writes the back buffer
    buf.write(ev([40], 0.9))  # growth keeps the back buffer's flags
    back = buf.flip()
    assert back is not None and back.indices.tolist() == [2, 40] and back.dofs[1, 0] == 0.9
    assert buf.flip() is None and buf.flip() is None
