"""Issue 16, latency: requests are read and answered before the tick's work, and a flood holds nothing back.

The tick and the writers let the readers in first (``TtesServer.let_readers_in``), and a reader answers the
requests it handled at once (``TtesServer.answer_requests``). Under ``autojump_clock`` CPU time is free, so
these tests check the order of the steps, which sets the latency on a real machine. The server reads a client
at its request rate (``max_requests_per_s``: TCP backpressure, never a drop), so one client's flood cannot
hold the tick loop or another client's answer back.
"""

from __future__ import annotations

import os

import numpy as np
import pytest
import trio
from test_app_walkthrough import STEP, port_of, vel, watching
from test_server_support import Client, frames_until, running_server

from protocol.entity import Appearance as A
from protocol.entity import WeaponState as W
from protocol.entity import make_entity_requests
from protocol.events import EntityRequests, JointUpdates, Ready, Subscribe

HZ = 30.0


def requests_applied(server) -> int:  # type: ignore[no-untyped-def]
    return int(server.world.manager.stats["requests"])


async def test_a_flood_of_requests_stalls_neither_the_tick_nor_another_clients_answer(
    autojump_clock: trio.abc.Clock,
) -> None:
    """One client sends 20,000 request rows as fast as its socket takes them (the server reads it at its
    request rate, 4,000 rows/s: TCP backpressure for 5 s). Meanwhile another client's walking soldier gets
    an update every tick, and its kneel request is answered before the next tick."""
    async with running_server(throttle=0.0, max_requests_per_s=4000.0) as server:
        watcher = await watching(server)
        await watcher.requests(index=0, velocity=vel(1.4, 0.0), heading=0.0)
        flood = await Client.open(port_of(server), name="flood")
        await flood.expect(Ready)
        await trio.sleep(1.0)
        rows = make_entity_requests(
            np.arange(2, 10).repeat(125), A.UPRIGHT, W.DEPLOYED, vel(1.2, 90.0), 90.0
        )  # 1,000 rows: eight soldiers
        sent = trio.Event()

        async def flooding() -> None:
            for k in range(20):
                rows["velocity"][:, 1] = 0.1 * (k % 2)  # a real change every frame
                await flood.send(EntityRequests(rows))
            sent.set()

        async with trio.open_nursery() as nursery:
            nursery.start_soon(flooding)
            await trio.sleep(0.5)
            await watcher.caught_up(server)
            first = server.ticks
            frames = await frames_until(watcher, lambda fs: bool(fs) and fs[-1][0] >= first + 2 * HZ, 4.0)
            ticks = [t for t, indices, _ in frames if 0 in indices]
            assert requests_applied(server) < 20_000  # still flooding: read at its request rate
            assert ticks[0] <= first + 1 and set(np.diff(ticks).tolist()) == {1}  # every tick for 2 s
            await watcher.send(Subscribe((1,)))
            await watcher.drain(0.2)
            await watcher.caught_up(server)
            walking = watcher.pose(1, 1)[0].copy()
            nxt = server.next_tick
            written = watcher.writes(server)
            await watcher.requests(index=1, appearance=A.KNEEL, weapon=W.DEPLOYED)
            ev = await watcher.expect(JointUpdates, lambda e: 1 in e.indices.tolist())
            assert written[0][0] < nxt  # answered before the next tick, in the middle of the flood
            k = ev.indices.tolist().index(1)
            assert np.abs(ev.dofs[k] - walking).max() > STEP
            await sent.wait()
            while requests_applied(server) < 20_000:
                await trio.sleep(0.1)


async def test_a_request_that_arrives_at_the_tick_is_applied_before_the_tick_samples(
    autojump_clock: trio.abc.Clock,
) -> None:
    """Bytes that land in the socket at the tick's own instant are read, applied and answered before the tick
    samples (the tick lets the readers in first), so nothing waits behind the tick's work for them; the
    next tick then sends the kneeling soldier only if it moved on."""
    async with running_server(throttle=0.0) as server:
        c = await watching(server)
        await trio.sleep_until(server._t0 + 1.01)
        rest = c.pose(1, 0)[0].copy()
        tick_at = server.next_tick
        kneel = c.conn.send(EntityRequests(make_entity_requests(0, A.KNEEL, W.DEPLOYED)))
        tick = server.run_tick
        seen: list[int] = []

        async def recording_tick(scheduled: float | None = None) -> None:
            seen.append(requests_applied(server))
            await tick(scheduled)

        server.run_tick = recording_tick  # type: ignore[method-assign]
        before = requests_applied(server)
        await trio.sleep_until(server._t0 + tick_at)  # wakes with the tick loop
        os.write(c.stream.socket.fileno(), kneel)
        ev = await c.expect(JointUpdates)
        while not seen:  # the answer may be written before the tick even samples (TtesServer._tick_loop)
            await trio.sleep(0.001)
        assert seen[0] == before + 1  # applied before the tick sampled
        assert ev.indices.tolist() == [0] and np.abs(ev.dofs[0] - rest).max() > STEP  # already kneeling


@pytest.mark.parametrize("walk", [False, True])
async def test_a_request_that_lands_while_the_tick_samples_goes_out_with_that_tick(
    autojump_clock: trio.abc.Clock, walk: bool
) -> None:
    """Bytes that land while the tick samples are read before it publishes (``TtesServer.run_tick``). A kneel
    or a walk off a rest (each begins at its first moving frame: the walk start's first frame is still) is
    sampled again into that tick and goes out in its frames under its number, not in an answer after them
    (a walk waited for the tick's quantise and encodes, then went out as the next tick's). The joints show
    it, not only the root offset. At the default throttle (the tick's due rule holds)."""
    async with running_server(throttle=0.04) as server:
        c = await watching(server)
        await trio.sleep_until(server._t0 + 1.01)
        rest = c.pose(1, 0)[0].copy()
        m, board = server.world.manager, server.board_ref.board
        rows = (
            make_entity_requests(0, A.UPRIGHT, W.DEPLOYED, vel(1.4, 0.0), 0.0)
            if walk
            else make_entity_requests(0, A.KNEEL, W.DEPLOYED)
        )
        request = c.conn.send(EntityRequests(rows))
        sample = m.tick

        def sampling(now: float):  # type: ignore[no-untyped-def]
            update = sample(now)
            os.write(c.stream.socket.fileno(), request)  # lands while the tick samples
            m.tick = sample
            return update

        m.tick = sampling
        answers, before = server.answers, board.ticks
        with trio.fail_after(1.0 / HZ):  # the write of that tick
            ev = await c.expect(JointUpdates, lambda e: 0 in e.indices.tolist() and e.tick > before)
        assert ev.tick == before + 1 and server.answers == answers
        assert np.abs(ev.dofs[ev.indices.tolist().index(0)] - rest).max() > STEP  # it shows the request
        assert not m.table.requested[0]


async def test_tick_frames_keep_their_tick_when_an_answer_is_published_before_they_are_encoded(
    autojump_clock: trio.abc.Clock,
) -> None:
    """A writer that encodes after an answer was published sends the tick's rows under the tick's number and
    only the answered soldier under the next one (tick numbers never decrease within the write)."""
    async with running_server(throttle=0.0) as server:
        c = await watching(server)
        await c.requests(index=[0], velocity=vel(1.4, 0.0), heading=0.0)
        await c.send(Subscribe((1,)))
        await c.drain(1.0)
        board = server.board_ref.board
        server.answers = 0
        tick = server.run_tick

        async def tick_then_answer(scheduled: float | None = None) -> None:
            await tick(scheduled)  # the writers are woken, not yet run: answer soldier 1 first
            server.next_tick = (scheduled or 0.0) + 1.0 / HZ
            rows = make_entity_requests(1, A.KNEEL, W.DEPLOYED)
            server.world.manager.apply_requests(rows, server.request_time())
            server.answer_requests()
            server.run_tick = tick  # type: ignore[method-assign]

        server.run_tick = tick_then_answer  # type: ignore[method-assign]
        got: list[tuple[int, list[int]]] = []
        with trio.fail_after(1.0 / HZ):  # the next tick's write
            while len(got) < 2:
                ev = await c.next_event()
                if isinstance(ev, JointUpdates):
                    got.append((ev.tick, ev.indices.tolist()))
        assert server.answers == 1
        assert got == [(board.ticks, [0]), (board.ticks + 1, [1])]
