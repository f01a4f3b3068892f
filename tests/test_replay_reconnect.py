"""`ttes replay` with its stub survives a server restart (issue 17): a lost server shows within a frame (the
stub poses the soldiers meanwhile), the window's threaded link is tried again on a backoff schedule in stub
time, the headless replay's sink is relinked by ``keep_linked``, and either way every live soldier is created
again and posed by the new server. Out of time, the replay says it gave up (the command exits 1)."""

from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import trio
from test_dis_survive import connector
from test_replay_stub import FakeLink, village
from test_replay_support import exercise_pcap
from test_replay_translator import FRAME, make_log, pdu
from test_server_support import make_server

from client_stub.dis import Replayer
from client_stub.dis.soldiers import replay_app
from client_stub.link.buffer import UpdateBatch
from client_stub.link.client import LinkError
from client_stub.link.retry import RetrySchedule
from client_stub.stub.app import StubApp
from protocol.dis.appearance import LifeformState
from protocol.entity import Appearance
from server.app import TtesServer
from server.config import DEFAULT_DATA_DIR
from ttes.commands import replay as replay_command


class LosableLink(FakeLink):
    """A FakeLink whose server can go away (``connected`` False: what the threaded link's thread sees)."""

    def __init__(self, *args: Any) -> None:
        super().__init__(*args)
        self.connected = True
        self.quit_called = False

    def quit(self) -> None:
        self.quit_called = True


class Reconnector:
    """What the window passes as ``reconnect``: fails while ``up`` is False, else a new link."""

    def __init__(self, wire: Any) -> None:
        self.wire = wire
        self.up = False
        self.attempts = 0
        self.links: list[LosableLink] = []

    def __call__(self) -> LosableLink:
        self.attempts += 1
        if not self.up:
            raise LinkError("connection refused")
        self.links.append(LosableLink(self.wire))
        return self.links[-1]


def two_pdus() -> Replayer:
    prone = LifeformState.PRONE
    entries = [(0.0, pdu(1, (5.0, 5.0), force=2)), (2.0, pdu(1, (5.0, 5.0), force=2, state=prone))]
    return Replayer(make_log(entries), origin=FRAME, timeout=60.0)


def window_app(tmp_path: Path, give_up_after: float = 30.0) -> tuple[StubApp, LosableLink, Reconnector]:
    probe = replay_app(village(), two_pdus(), artic_dir=tmp_path)
    wire = dataclasses.replace(probe.kinds[probe.kind("DI.fig", "AK_47.fig")].table, table_id=7)
    first, reconnect = LosableLink(wire), Reconnector(wire)
    app = replay_app(village(), two_pdus(), link=first, artic_dir=tmp_path, reconnect=reconnect,
                     retry=RetrySchedule((0.5, 1.0), give_up_after))  # fmt: skip
    return app, first, reconnect


def test_the_window_replay_shows_a_lost_server_and_binds_its_soldiers_again(tmp_path: Path) -> None:
    app, first, reconnect = window_app(tmp_path)
    app.frame(0.0)
    assert app.server_of[0] == 2 and not app.server_lost  # bound to the soldier the sink made
    first.connected = False  # the server goes away
    app.frame(0.1)
    assert "server lost" in app.server_lost and app.server_of[0] == -1  # the stub poses him now
    assert first.quit_called and app.soldiers.alive[0]
    for _ in range(25):  # 2.5 s: nothing answers; the replay goes on (the entity goes prone at 2 s)
        app.frame(0.1)
    assert reconnect.attempts >= 2 and app.server_lost and not app.gave_up
    assert app.soldiers.appearance[0] == Appearance.PRONE
    reconnect.up = True
    for _ in range(20):
        app.frame(0.1)
        if not app.server_lost:
            break
    (second,) = reconnect.links
    assert not app.server_lost and app.server_of[0] == 2 and app.slot_of_server[2] == 0
    assert second.sent[:3] == [("create", 2, "DI.fig", "AK_47.fig"), ("subscribe", 2),
                               ("requests", [2], [Appearance.PRONE])]  # fmt: skip
    assert app.source.sink is not None and app.source.sink.stats["relinked"] == 1
    # the new server's joint updates pose him
    wire = second.tables[7]
    k = app.kinds[int(app.slot_kind[0])]
    second.pending = [UpdateBatch(7, np.array([2]), np.full((1, wire.ndofs), 0.25),
                                  np.zeros((1, wire.nfigures, 3)),
                                  np.tile([1.0, 0.0, 0.0, 0.0], (1, wire.nfigures, 1)))]  # fmt: skip
    app.frame(0.1)
    assert k.crowd.dofs[0] == pytest.approx(np.full(k.crowd.dofs.shape[1], 0.25))


def test_the_window_replay_gives_up_after_its_time(tmp_path: Path) -> None:
    app, first, reconnect = window_app(tmp_path, give_up_after=3.0)
    app.frame(0.0)
    first.connected = False
    for _ in range(50):
        app.frame(0.1)
    assert app.gave_up.startswith("gave up after") and "server lost" not in app.gave_up.split("(")[0]
    tried = reconnect.attempts
    for _ in range(20):
        app.frame(0.5)
    assert reconnect.attempts == tried  # no more attempts once it gave up
    assert app.soldiers.alive[0]  # the replay itself went on


async def serving(nursery: trio.Nursery, port: int = 0) -> TtesServer:
    """A server with the project's motion library (its DI.fig tables are the stub's: the server poses)."""
    server = make_server(
        report_interval=1000.0, port=port, share_library=False, data_dir=str(DEFAULT_DATA_DIR)
    )
    await nursery.start(server.serve)
    return server


def headless_args(**kw: Any) -> argparse.Namespace:
    base = dict(give_up_after=30.0, camera="squad", json=True, terrain=None)
    return argparse.Namespace(**{**base, **kw})


async def test_the_headless_replay_goes_on_through_a_server_restart(
    autojump_clock: trio.abc.Clock, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    _, log = exercise_pcap(tmp_path)
    seen: dict[str, Any] = {"lost": 0, "bound_after": None}

    async def frames(app: StubApp, seconds: float, fps: float, size: Any, args: Any) -> dict:
        """_render without the GL: the frames at the video's times."""
        t0 = trio.current_time()
        for i in range(round(seconds * fps)):
            await trio.sleep_until(t0 + i / fps)
            app.frame(1 / fps if i else 0.0)
            seen["lost"] += bool(app.server_lost)
            if i == 70:  # 7 s: before the restart
                seen["bound_before"] = app.server_of[: app.soldiers.count].copy()
        seen["bound_after"] = app.server_of[: app.soldiers.count].copy()
        return {"frames": round(seconds * fps)}

    monkeypatch.setattr(replay_command, "_render", frames)
    async with trio.open_nursery() as nursery:
        first = await serving(nursery)
        port = first.addresses[0][1]
        connect = connector(nursery, port, 2.0)
        servers = [first]
        app = replay_command._make_app(headless_args(), Replayer(log), await connect())

        async def restart() -> None:
            await trio.sleep(8.0)
            first.shutdown()
            await first.stopped.wait()
            await trio.sleep(4.0)
            servers.append(await serving(nursery, port))

        nursery.start_soon(restart)
        failures: list[str] = []
        await replay_command._render_linked(app, connect, failures, 30.0, 10.0, (64, 48), headless_args())
        second = servers[-1]
        m = second.world.manager
        assert len(servers) == 2 and m is not None and not failures
        sink = app.source.sink
        assert sink is not None and sink.stats["relinked"] == 1
        assert seen["lost"] >= 10  # the frames showed the loss (4 s away, 10 frames a second)
        alive = np.flatnonzero(app.soldiers.alive[: app.soldiers.count])
        assert len(alive) == 4 and m.count == 10 + 4  # the new server animates every live soldier
        assert (seen["bound_before"][alive] >= 0).all()  # the server posed them before the restart
        assert (seen["bound_after"][alive] >= 0).all() and not app.server_lost  # and after
        second.shutdown()
        nursery.cancel_scope.cancel()
