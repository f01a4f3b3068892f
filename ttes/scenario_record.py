"""``ttes stub --scenario FILE --record OUT``: a real Jack/TTES server in-process, one stub frame per tick.

The server (``server.app.TtesServer`` on the shipped data, over loopback TCP) and the stub's trio-native
link run in one trio run on a ``MockClock`` that only moves when the recorder says so
(:class:`ServerClock`): the server ticks at its own rate in its own time while pyrender takes as long as it
needs per frame, so the video shows every tick the server sent, at the server's rate. This lives in ``ttes``
because it is the one place that may put a server and a client together (docs/ARCHITECTURE.md).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from pathlib import Path

import trio
import trio.testing

from client_stub.link.client import Client
from client_stub.stub.app import StubApp
from client_stub.stub.recording import ScenarioSoldier, record_scenario
from client_stub.stub.scenario import Scenario
from client_stub.stub.terrain import Terrain
from server.app import TtesServer
from server.config import ServerConfig

CLOCK_SLACK_S = 1e-6  # the tick loop sums its period: tick k may fall a rounding error after k / hz


@dataclass
class ServerClock:
    """The recorder's :class:`~client_stub.stub.recording.TickClock` over a server on a ``MockClock``."""

    clock: trio.testing.MockClock
    server: TtesServer

    async def to(self, t: float) -> None:
        await trio.testing.wait_all_tasks_blocked()  # what was sent before has been taken in
        ahead = t + CLOCK_SLACK_S - self.server.now()
        if ahead > 0:
            self.clock.jump(ahead)
        await trio.testing.wait_all_tasks_blocked()  # the ticks due by t ran and their bytes arrived


@dataclass(frozen=True)
class Recording:
    scenario: Scenario
    terrain: Terrain
    out: Path
    sheet: Path | None = None
    size: tuple[int, int] = (640, 480)
    tick_hz: float = 30.0
    data_dir: Path | None = None
    artic_dir: Path | None = None


def record(rec: Recording) -> dict:
    """Run ``rec`` (see the module docstring) and return the recorder's summary."""
    clock = trio.testing.MockClock(rate=0.0)
    return trio.run(functools.partial(_record, rec, clock), clock=clock)


async def _record(rec: Recording, clock: trio.testing.MockClock) -> dict:
    from client_stub.stub.render import StubRenderer

    config = ServerConfig(host="127.0.0.1", port=0, tick_hz=rec.tick_hz)
    if rec.data_dir is not None:
        config = config.with_overrides(data_dir=rec.data_dir)
    server = TtesServer(config)
    async with trio.open_nursery() as nursery:
        host, port = (await nursery.start(server.serve))[0]
        client = Client("ttes-stub-record")
        await client.open(nursery, host, port)
        start = rec.scenario.start
        made = await client.create_soldier(start.figure, start.weapon)
        soldier = ScenarioSoldier(rec.scenario, client, made.index, made.table)
        app = StubApp(rec.terrain, soldier, artic_dir=rec.artic_dir)
        soldier.bind(app)
        app.renderer = StubRenderer(*rec.size)
        ticks = ServerClock(clock, server)
        origin = (math.floor(server.now() * rec.tick_hz) + 1) / rec.tick_hz  # the soldier's first tick
        await ticks.to(origin)
        try:
            app.renderer.set_terrain(rec.terrain.meshes)
            summary = await record_scenario(app, soldier, ticks, rec.out, hz=rec.tick_hz, sheet=rec.sheet,
                                            origin=origin)  # fmt: skip
            summary["soldier_updates"] = client.soldier_updates
            summary["last_tick"] = client.last_tick
            summary["entity_moved_m"] = round(float(math.hypot(*soldier.xy)), 4)
        finally:
            app.renderer.close()
            clock.autojump_threshold = 0.0  # the shutdown's grace periods pass in no time
            await client.aclose()
            server.shutdown()
    summary["figure"], summary["weapon"] = start.figure, start.weapon
    return summary
