"""Clients that survive (issue 17): the DIS sink places soldiers in any free server index, keeps within the
server's per-client cap (the excess dropped with a counter), and re-creates its soldiers on a new link after a
server restart (reconnect with backoff). In-process servers under trio's autojump clock."""

from __future__ import annotations

from collections.abc import Awaitable, Callable
from pathlib import Path

import numpy as np
import pytest
import trio
from test_replay_support import exercise_pcap
from test_server_support import make_server, running_server

from client_stub.dis.drive import ProgressLine, replay_to_server
from client_stub.dis.gateway import DisGateway, GatewayConfig
from client_stub.dis.reconnect import GaveUp, keep_linked, keep_linked_or_stop
from client_stub.dis.reconnect import connector as reconnect_connector
from client_stub.dis.replayer import Replayer
from client_stub.dis.sink import MAX_SOLDIERS_PER_CLIENT, ServerSink
from client_stub.dis.translator import SOLDIER_DTYPE, Translation
from client_stub.link.client import Client, LinkError
from protocol.dis.synth import synthesize
from protocol.entity import ENTITY_REQUEST_DTYPE, Appearance
from protocol.update_table import UpdateTable
from server.app import TtesServer


async def until(condition: Callable[[], bool], timeout: float = 20.0) -> None:
    """Wait (trio time) until ``condition`` holds: the server runs JCL in a worker thread, during which the
    autojump clock moves on, so a fixed sleep says nothing."""
    with trio.fail_after(timeout):
        while not condition():
            await trio.sleep(0.05)


def test_soldiers_the_server_kept_for_us_are_taken_back_not_created() -> None:
    link = FakeLink({0: 0})
    sink = ServerSink(link, subscribe=True)  # type: ignore[arg-type]
    sink.apply(born(range(3)))
    assert link.created == [1, 2, 3]
    link.fail = True
    sink.apply(Translation(removed=np.array([2])))
    same = FakeLink({0: 0, 1: 0, 2: 0, 3: 0})  # the same server, our soldiers still there (client id)
    sink.rebind(same)  # type: ignore[arg-type]
    assert same.created == [] and sorted(same.subscribed) == [1, 2] and sink.stats["reclaimed"] == 2
    assert sink.server_index(np.array([0, 1])).tolist() == [1, 2]  # the slots keep their indices
    assert same.rows[0]["index"].tolist() == [1, 2]


async def serving(nursery: trio.Nursery, port: int = 0) -> TtesServer:
    """A server (the synthetic library) started in ``nursery``; ``port`` 0: any free one."""
    server = make_server(report_interval=1000.0, port=port)
    await nursery.start(server.serve)
    return server


def connector(nursery: trio.Nursery, port: int, timeout: float) -> Callable[[], Awaitable[Client]]:
    return reconnect_connector(nursery, "127.0.0.1", port, "ttes-gateway", timeout)


class FakeLink:
    """Records what the sink sends; ``fail`` makes every send raise LinkError (a lost server)."""

    def __init__(self, ready: dict[int, int], max_soldiers: int = 16384) -> None:
        self.ready_soldiers = ready
        self.max_soldiers = max_soldiers
        self.tables: dict[int, UpdateTable] = {}
        self.created: list[int] = []
        self.removed: list[int] = []
        self.rows: list[np.ndarray] = []
        self.subscribed: list[int] = []
        self.fail = False

    def _check(self) -> None:
        if self.fail:
            raise LinkError("connection lost")

    def create(self, index: int | None, figure: str, weapon: str) -> int:
        self._check()
        assert index is not None
        self.created.append(index)
        return len(self.created)

    def remove(self, index: int) -> None:
        self._check()
        self.removed.append(index)

    def subscribe(self, indices: list[int] | np.ndarray) -> None:
        self._check()
        self.subscribed += [int(i) for i in indices]

    def send_requests(self, rows: np.ndarray) -> None:
        self._check()
        self.rows.append(rows.copy())

    def react(self, indices: list[int] | np.ndarray, kind: object) -> None:
        self._check()

    def swap(self) -> list:
        return []


def born(slots: list[int] | range) -> Translation:
    created = np.zeros(len(slots), SOLDIER_DTYPE)
    created["slot"] = list(slots)
    rows = np.zeros(len(slots), ENTITY_REQUEST_DTYPE)
    rows["index"] = list(slots)
    rows["appearance"] = Appearance.KNEEL
    return Translation(created=created, requests=rows)


def test_one_soldier_at_the_last_index_does_not_stop_the_sink() -> None:
    link = FakeLink({16383: 0})
    sink = ServerSink(link)  # type: ignore[arg-type]
    sink.apply(born(range(3)))
    assert link.created == [0, 1, 2]
    assert link.rows[0]["index"].tolist() == [0, 1, 2]
    holes = FakeLink({0: 0, 2: 0, 5: 0}, max_soldiers=8)
    sink = ServerSink(holes)  # type: ignore[arg-type]
    sink.apply(born(range(6)))
    assert holes.created == [1, 3, 4, 6, 7] and sink.stats["dropped"] == 1
    assert sink.server_index(np.array([0, 4])).tolist() == [1, 7]


def test_a_burst_beyond_the_per_client_cap_is_dropped_with_a_counter() -> None:
    link = FakeLink({i: 0 for i in range(10)})
    sink = ServerSink(link)  # type: ignore[arg-type]
    sink.apply(born(range(5000)))
    assert len(link.created) == MAX_SOLDIERS_PER_CLIENT
    assert sink.stats["dropped"] == 5000 - MAX_SOLDIERS_PER_CLIENT
    assert len(link.rows[0]) == MAX_SOLDIERS_PER_CLIENT


def test_a_lost_link_is_remembered_and_a_new_one_gets_the_soldiers_again() -> None:
    link = FakeLink({0: 0})
    sink = ServerSink(link, subscribe=True)  # type: ignore[arg-type]
    sink.apply(born(range(3)))
    link.fail = True
    gone = Translation(removed=np.array([1]))
    stand = np.zeros(1, ENTITY_REQUEST_DTYPE)
    stand["index"], stand["appearance"] = 2, Appearance.PRONE
    sink.apply(gone)
    sink.apply(Translation(requests=stand))  # never raises: the sink keeps the state for the next link
    assert sink.lost and sink.stats["while_lost"] == 2
    fresh = FakeLink({0: 0, 7: 0})  # the restarted server made one more start-up soldier
    sink.rebind(fresh)  # type: ignore[arg-type]
    assert not sink.lost and sink.stats["relinked"] == 1 and sink.stats["reclaimed"] == 0
    assert fresh.created == [1, 3] and sorted(fresh.subscribed) == [1, 3]  # the slots keep their indices
    (rows,) = fresh.rows
    assert rows["index"].tolist() == [1, 3]
    assert rows["appearance"].tolist() == [Appearance.KNEEL, Appearance.PRONE]


async def test_the_sink_relinks_after_a_server_restart(autojump_clock: trio.abc.Clock) -> None:
    async with trio.open_nursery() as nursery:
        first = await serving(nursery)
        port = first.addresses[0][1]
        connect = connector(nursery, port, 2.0)
        link = await connect()
        sink = ServerSink(link)
        sink.apply(born(range(3)))
        await until(lambda: first.world.manager is not None and first.world.manager.count == 13)
        linker = await nursery.start(keep_linked, sink, connect, (0.5, 1.0, 2.0), 30.0)
        first.shutdown()
        await first.stopped.wait()
        await trio.sleep(3.0)  # the server is away for a while: the sink keeps its soldiers' state
        sink.apply(Translation(removed=np.array([0])))
        assert sink.lost
        second = await serving(nursery, port)
        await until(lambda: not sink.lost)
        await until(lambda: second.world.manager is not None and second.world.manager.count == 12)
        m = second.world.manager  # 10 start-up soldiers + the two still alive
        assert m is not None
        assert m.soldier_info(sink.server_index(np.array([1]))[0])["goal"].startswith("KNEEL")
        assert sink.stats["relinked"] == 1
        linker.cancel()
        second.shutdown()


async def test_keep_linked_gives_up_after_its_time(autojump_clock: trio.abc.Clock) -> None:
    async with trio.open_nursery() as nursery:
        server = await serving(nursery)
        connect = connector(nursery, server.addresses[0][1], 1.0)
        sink = ServerSink(await connect())
        server.shutdown()
        await server.stopped.wait()
        with pytest.raises(GaveUp, match="gave up after"):
            await keep_linked(sink, connect, (0.5, 1.0), 5.0)


async def test_the_gateway_survives_a_burst_of_5000_new_entities(autojump_clock: trio.abc.Clock) -> None:
    burst = [p.payload for p in synthesize(soldiers=5000, seconds=0.1, seed=1).packets]
    async with running_server(report_interval=1000.0) as server, trio.open_nursery() as nursery:
        link = Client("ttes-gateway")
        await link.open(nursery, "127.0.0.1", server.addresses[0][1])
        sink = ServerSink(link)
        gateway = DisGateway(GatewayConfig(port=0))
        sink.apply(gateway.handle(burst, trio.current_time()))
        m = server.world.manager
        assert m is not None
        await until(lambda: m.count == 10 + MAX_SOLDIERS_PER_CLIENT)
        assert gateway.translator.alive == 5000 and sink.stats["dropped"] == 5000 - MAX_SOLDIERS_PER_CLIENT
        assert not link.closed and not link.errors and server.clients_dropped == 0
        assert await link.roundtrip(timeout=5.0)
        sink.apply(gateway.stop())  # the gateway's soldiers leave the server
        await until(lambda: m.count == 10)
        await link.aclose()
        nursery.cancel_scope.cancel()


async def test_a_replay_goes_on_through_a_server_restart(
    autojump_clock: trio.abc.Clock, tmp_path: Path
) -> None:
    _, log = exercise_pcap(tmp_path)
    async with trio.open_nursery() as nursery:
        first = await serving(nursery)
        port = first.addresses[0][1]
        connect = connector(nursery, port, 2.0)
        sink = ServerSink(await connect())
        failures: list[str] = []
        servers = [first]

        async def restart() -> None:
            await trio.sleep(10.0)
            first.shutdown()
            await first.stopped.wait()
            await trio.sleep(4.0)
            servers.append(await serving(nursery, port))

        async with trio.open_nursery() as inner:
            inner.start_soon(keep_linked_or_stop, sink, connect, inner.cancel_scope, failures, 30.0)
            inner.start_soon(restart)
            status = await replay_to_server(
                Replayer(log), sink, progress=ProgressLine(out=None), finish=False
            )
            m = servers[-1].world.manager
            assert len(servers) == 2 and m is not None
            assert m.count == 10 + status["alive"] and status["alive"] == 4  # the second server has them all
            inner.cancel_scope.cancel()
        assert not failures and sink.stats["relinked"] == 1 and sink.stats["while_lost"] > 0
        servers[-1].shutdown()


async def test_a_reconnect_to_the_same_server_takes_the_soldiers_back(autojump_clock: trio.abc.Clock) -> None:
    async with trio.open_nursery() as nursery:
        server = await serving(nursery)
        connect = connector(nursery, server.addresses[0][1], 2.0)
        link = await connect()
        sink = ServerSink(link)
        sink.apply(born(range(3)))
        m = server.world.manager
        assert m is not None
        await until(lambda: m.count == 13)
        linker = await nursery.start(keep_linked, sink, connect, (0.5, 1.0), 30.0)
        await link.aclose("network blip")  # within the owner's grace period: the server keeps the soldiers
        await until(lambda: sink.stats["relinked"] == 1 and not sink.lost)
        new = sink.link
        assert isinstance(new, Client) and new is not link and new.client_id == link.client_id
        assert await new.roundtrip(5.0)
        assert sink.stats["reclaimed"] == 3 and m.count == 13 and not new.errors
        linker.cancel()
        server.shutdown()


async def test_every_reconnected_link_carries_the_commands_token(monkeypatch: pytest.MonkeyPatch) -> None:
    """A gateway with --token must send it again on each reconnection (the first link's id kept too)."""
    from client_stub.link.auth import Credentials

    opened: list[tuple[str, str]] = []

    async def fake_open(self: Client, nursery: trio.Nursery, host: str, port: int, **_: float) -> None:
        opened.append((self.token, self.client_id))

    monkeypatch.setattr(Client, "open", fake_open)
    async with trio.open_nursery() as nursery:
        connect = reconnect_connector(nursery, "127.0.0.1", 1, credentials=Credentials(token="s3cret-token"))
        await connect()
        await connect()
    assert [t for t, _ in opened] == ["s3cret-token", "s3cret-token"]
    assert opened[0][1] == opened[1][1]
