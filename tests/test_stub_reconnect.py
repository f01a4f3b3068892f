"""The stub survives its server (issue 17): a lost server shows within one frame (the soldiers go on, posed by
the stub), the stub reconnects with backoff (in stub time: frames drive it, no sleeps) and binds its soldiers
again, and gives up after ``give_up_after`` seconds (``ttes stub`` then exits 3)."""

from __future__ import annotations

import functools
from pathlib import Path

import trio
from test_stub_network import FakeServer, flat_terrain

from client_stub.stub.app import StubApp
from client_stub.stub.jack import JackProc
from client_stub.stub.live import LiveSoldiers
from client_stub.stub.simsoldier import Behaviour


async def _serving(
    server: FakeServer, port: int, task_status: trio.TaskStatus[tuple[int, trio.CancelScope]]
) -> None:
    with trio.CancelScope() as scope:
        async with trio.open_nursery() as n:
            listeners = await n.start(
                functools.partial(trio.serve_tcp, server.handle, port, host="127.0.0.1")
            )
            task_status.started((listeners[0].socket.getsockname()[1], scope))


def connector(port: int):  # type: ignore[no-untyped-def]
    def connect() -> JackProc:
        jack = JackProc()
        jack.initsocketconnection("127.0.0.1", port, 5.0)
        return jack

    return connect


async def stub_on(port: int, tmp_path: Path, give_up_after: float) -> tuple[StubApp, LiveSoldiers]:
    live = LiveSoldiers(reconnect=connector(port), give_up_after=give_up_after, ready_timeout=10.0)
    app = StubApp(flat_terrain(), live, artic_dir=tmp_path)
    app.add_soldier((0.0, 0.0), 0.0)
    app.add_soldier((5.0, 0.0), 0.0, speed=1.0, behaviour=Behaviour.SQUARE)
    app.add_soldier((-5.0, 0.0), 90.0)
    jack = await trio.to_thread.run_sync(connector(port))
    assert await trio.to_thread.run_sync(live.connect, app, jack, 10.0)
    return app, live


async def test_the_stub_shows_a_lost_server_and_binds_its_soldiers_again(
    nursery: trio.Nursery, tmp_path: Path
) -> None:
    first = FakeServer()
    port, scope = await nursery.start(_serving, first, 0)
    app, live = await stub_on(port, tmp_path, give_up_after=60.0)
    try:
        assert app.server_of[:3].tolist() == [0, 1, 2] and not app.server_lost
        jack = live.jack
        assert jack is not None
        scope.cancel()  # the server goes away
        with trio.fail_after(10):
            await trio.to_thread.run_sync(jack.closed.wait)
        await trio.to_thread.run_sync(app.frame, 0.1)  # the next frame shows it
        assert "server lost" in app.server_lost and app.server_lost_count == 1
        assert app.server_of[:3].tolist() == [-1, -1, -1]  # posed by the stub from now on
        for _ in range(3):  # nothing listens: the attempts fail, the stub goes on
            await trio.to_thread.run_sync(app.frame, 0.5)
        assert app.server_lost and not app.gave_up
        second = FakeServer()
        await nursery.start(_serving, second, port)
        for _ in range(40):
            await trio.to_thread.run_sync(app.frame, 0.5)
            if not app.server_lost:
                break
        assert not app.server_lost and app.server_of[:3].tolist() == [0, 1, 2]
        await trio.to_thread.run_sync(app.handle_key, "3")  # soldier 0 kneels: requests go to the new server
        await trio.to_thread.run_sync(app.frame, 0.1)
        with trio.fail_after(10):
            await second.got_requests.wait()
        assert second.subscribed == {0, 1, 2} and second.jcl == ['read_file("jack-ttes-soldier_low.jcl");']
    finally:
        await trio.to_thread.run_sync(app.close)


async def test_the_stub_gives_up_after_its_time(nursery: trio.Nursery, tmp_path: Path) -> None:
    server = FakeServer()
    port, scope = await nursery.start(_serving, server, 0)
    app, live = await stub_on(port, tmp_path, give_up_after=5.0)
    try:
        jack = live.jack
        assert jack is not None
        scope.cancel()
        with trio.fail_after(10):
            await trio.to_thread.run_sync(jack.closed.wait)
        for _ in range(14):
            await trio.to_thread.run_sync(app.frame, 0.5)
        assert app.gave_up and "gave up after" in app.gave_up
    finally:
        await trio.to_thread.run_sync(app.close)
