"""Issue 16, latency: a request that lands while the writers encode a tick is written ahead of its rest.

After a tick's publish every writer encodes the tick for its client, one after the other (a few ms each with
thousands of soldiers). A request that landed meanwhile was answered as the next tick's update and went out
behind the whole encode of its client's tick (and of those before it). Now the soldiers it answers are
sampled at once and published as more of that tick (``TtesServer._answer_in_tick``); a writer that still owes
the tick writes them first, on their own (``Session.take_answers``), then the rest. Under ``autojump_clock``
CPU time is free: these tests check the order of the writes and what each frame carries, which set the
latency on a real machine.
"""

from __future__ import annotations

import os

import numpy as np
import trio
from test_app_walkthrough import STEP, port_of, vel, watching
from test_server_support import Client, frames_until, running_server

from protocol.entity import Appearance as A
from protocol.entity import WeaponState as W
from protocol.entity import make_entity_requests
from protocol.events import EntityRequests, Ready, Subscribe

HZ = 30.0


async def test_a_request_landing_during_another_clients_encode_is_written_before_its_own_tick(
    autojump_clock: trio.abc.Clock,
) -> None:
    """Two clients watch walking soldier 1; client ``b`` also watches soldier 0, at rest. A kneel for soldier
    0 lands in ``b``'s socket while ``a``'s writer encodes the tick. ``b`` gets soldier 0 kneeling under the
    tick's number in a frame of its own, then the tick's soldier 1 (was: soldier 1 at the tick, then
    soldier 0 as the next tick's, after ``b``'s whole encode). At the default throttle soldier 1 still gets
    every tick."""
    async with running_server(throttle=0.04) as server:
        b = await watching(server)
        await b.requests(index=1, velocity=vel(1.4, 0.0), heading=0.0)
        await b.send(Subscribe((1,)))
        a = await Client.open(port_of(server), name="a")
        await a.expect(Ready)
        await a.send(Subscribe((1,)))
        await trio.sleep_until(server._t0 + 1.51)
        rest = b.pose(1, 0)[0].copy()
        session_a = next(s for s in server.sessions.values() if s.name == "a")
        session_b = next(s for s in server.sessions.values() if s is not session_a)
        take = session_a.take_output
        kneel = b.conn.send(EntityRequests(make_entity_requests(0, A.KNEEL, W.DEPLOYED)))
        landed: list[int] = []  # the tick whose encodes it landed in

        def taking(now: float | None = None) -> bytes:
            if not landed and session_b.ticked:  # b's writer still owes the tick: a's encodes it first
                landed.append(server.board_ref.board.ticks)
                os.write(b.stream.socket.fileno(), kneel)  # lands while a's writer encodes the tick
            return take(now)

        b.events.clear()
        await b.drain(1.5 / HZ)
        answers = server.answers
        session_a.take_output = taking  # type: ignore[method-assign]
        # until soldier 1's frame two ticks after the landing (a's writer encodes first within a few ticks)
        frames = await frames_until(
            b, lambda fs: bool(landed) and any(t >= landed[0] + 2 and 1 in i for t, i, _ in fs)
        )
        tick = landed[0]
        frames = [f for f in frames if f[0] >= tick]
        assert [(t, i) for t, i, _ in frames[:2]] == [(tick, [0]), (tick, [1])]
        assert [t for t, i, _ in frames if 1 in i][:3] == [tick, tick + 1, tick + 2]  # every tick
        assert np.abs(frames[0][2].dofs[0] - rest).max() > STEP  # it shows the kneel already
        assert server.answers == answers  # not an answer as the next tick's


async def test_a_walk_off_a_rest_landing_during_the_encodes_moves_the_joints_in_its_first_frame(
    autojump_clock: trio.abc.Clock,
) -> None:
    """One client watches soldiers 0 (at rest) and 1 (walking); a walk for soldier 0 lands right after the
    tick's publish, before the writer encodes: the writer lets the reader in, which answers it as more of
    the tick, and writes it first; its joints already move (the walk start skips its still first frame)."""
    async with running_server(throttle=0.0) as server:
        c = await watching(server)
        await c.requests(index=1, velocity=vel(1.4, 0.0), heading=0.0)
        await c.send(Subscribe((1,)))
        await trio.sleep_until(server._t0 + 1.51)
        rest = c.pose(1, 0)[0].copy()
        board = server.board_ref.board
        publish = server.publish_tick
        walk = c.conn.send(EntityRequests(make_entity_requests(0, A.UPRIGHT, W.DEPLOYED, vel(1.4, 0.0), 0.0)))

        def publishing(update, again: bool = False) -> None:  # type: ignore[no-untyped-def]
            publish(update, again)
            os.write(c.stream.socket.fileno(), walk)  # lands after the publish, before the encodes
            server.publish_tick = publish  # type: ignore[method-assign]

        c.events.clear()
        await c.drain(1.5 / HZ)
        answers, before = server.answers, board.ticks
        server.publish_tick = publishing  # type: ignore[method-assign]
        tick = before + 1
        frames = await frames_until(c, lambda fs: any(t > tick for t, _, _ in fs))  # the next tick's frame
        frames = [f for f in frames if f[0] == tick]
        assert [(t, i) for t, i, _ in frames] == [(tick, [0]), (tick, [1])]
        assert np.abs(frames[0][2].dofs[0] - rest).max() > STEP
        assert server.answers == answers
