"""Issue 16, latency: a request is read and answered between the tick's phases, never behind the tick's work.

The tick samples, lets the readers in, then publishes; the writers encode one at a time with the readers let
in before each turn (``TtesServer.let_readers_in``). Under ``autojump_clock`` CPU time is free, so these
tests check the order of the steps, which is what sets the latency on a real machine: a request that
arrives while the tick samples is applied before the tick's publish and answered in a frame of its own
right after it; one that arrives while a client's batch is encoded is applied before the next encode starts.
And a client that floods requests neither stalls the tick nor delays another client's answer.
"""

from __future__ import annotations

import os

import numpy as np
import pytest
import trio
from test_app_walkthrough import STEP, port_of, vel, watching
from test_server_support import Client, running_server

from protocol.entity import Appearance as A
from protocol.entity import WeaponState as W
from protocol.entity import make_entity_requests
from protocol.events import EntityRequests, JointUpdates, Ready, Subscribe
from server import app
from server.session import Session

HZ = 30.0


def requests_applied(server) -> int:  # type: ignore[no-untyped-def]
    return int(server.world.manager.stats["requests"])


async def test_a_request_that_arrives_while_the_tick_samples_is_answered_right_after_its_publish(
    autojump_clock: trio.abc.Clock,
) -> None:
    """The request's bytes land in the socket while the tick samples (written from inside the sampling): the
    reader applies it before the tick publishes, and the client gets the tick's frame, then at once the
    answer, labelled with the next tick and already kneeling, before that next tick."""
    async with running_server(throttle=0.0) as server:
        c = await watching(server)
        await trio.sleep_until(server._t0 + 1.01)
        rest = c.pose(1, 0)[0].copy()
        kneel = c.conn.send(EntityRequests(make_entity_requests(0, A.KNEEL, W.DEPLOYED)))
        sample, publish = server.sample, server.publish
        seen: dict[str, float] = {}

        def sample_then_request(scheduled: float | None = None):  # type: ignore[no-untyped-def]
            update = sample(scheduled)
            if "tick" not in seen:
                seen["tick"], seen["applied"] = server.ticks, requests_applied(server)
                os.write(c.stream.socket.fileno(), kneel)  # arrives mid-tick
            return update

        def publish_after(update):  # type: ignore[no-untyped-def]
            if "published" not in seen and "tick" in seen:
                seen["published"] = requests_applied(server)
            publish(update)

        server.sample, server.publish = sample_then_request, publish_after
        ev = await c.expect(JointUpdates, lambda e: e.tick == seen["tick"] + 1)
        nxt = server.next_tick
        assert seen["published"] == seen["applied"] + 1  # applied between sampling and publishing
        assert server.now() < nxt and server.ticks == seen["tick"]  # the answer, before the next tick
        assert ev.indices.tolist() == [0] and np.abs(ev.dofs[0] - rest).max() > STEP  # already kneeling


async def test_a_request_that_arrives_while_one_client_is_encoded_is_applied_before_the_next_encode(
    autojump_clock: trio.abc.Clock,
) -> None:
    """Two watching clients; a third client's request lands while the first writer of a tick encodes. The
    readers are let in before the second writer's turn, so the request is applied (and answered) before
    that encode starts, not after every client's encode."""
    async with running_server(throttle=0.0) as server:
        a, b = await watching(server), await watching(server)
        c = await Client.open(port_of(server))
        await c.expect(Ready)
        await c.requests(index=[0, 1], velocity=vel(1.4, 0.0), heading=0.0)  # both walk: every tick sends
        await trio.sleep(1.0)
        kneel = c.conn.send(EntityRequests(make_entity_requests(2, A.KNEEL, W.DEPLOYED)))
        take = Session.take_output
        log: list[tuple[int, int]] = []  # (session, requests applied) at the start of each encode

        def take_output(session: Session, now: float | None = None, max_rows: int | None = None) -> bytes:
            log.append((session.id, requests_applied(server)))
            if len(log) == 1:
                os.write(c.stream.socket.fileno(), kneel)  # arrives while this client is encoded
            return take(session, now, max_rows)

        try:
            Session.take_output = take_output  # type: ignore[method-assign]
            with trio.move_on_after(1.5 / HZ):  # the next tick's writes
                while len(log) < 2:
                    await trio.sleep(0.001)
        finally:
            Session.take_output = take  # type: ignore[method-assign]
        assert len(log) >= 2 and log[1][0] != log[0][0]
        assert log[1][1] == log[0][1] + 1  # applied between the two encodes
        assert server.answers >= 1
        await a.drain(0.1)
        await b.drain(0.1)


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
            watcher.events.clear()
            ticks: list[int] = []
            with trio.move_on_after(2.0):
                while True:
                    ev = await watcher.next_event()
                    if isinstance(ev, JointUpdates) and 0 in ev.indices.tolist():
                        ticks.append(ev.tick)
            assert requests_applied(server) < 20_000  # still flooding: read at its request rate
            assert len(ticks) >= 2.0 * HZ - 1 and set(np.diff(ticks).tolist()) == {1}  # every tick
            await watcher.send(Subscribe((1,)))
            await watcher.drain(0.2)
            walking = watcher.pose(1, 1)[0].copy()
            nxt = server.next_tick
            await watcher.requests(index=1, appearance=A.KNEEL, weapon=W.DEPLOYED)
            ev = await watcher.expect(JointUpdates, lambda e: 1 in e.indices.tolist())
            assert server.now() < nxt  # answered before the next tick, in the middle of the flood
            k = ev.indices.tolist().index(1)
            assert np.abs(ev.dofs[k] - walking).max() > STEP
            await sent.wait()
            while requests_applied(server) < 20_000:
                await trio.sleep(0.1)


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
        publish = server.publish

        def publish_then_answer(update):  # type: ignore[no-untyped-def]
            publish(update)  # the writers are woken, not yet run: answer soldier 1 first
            server.world.manager.apply_requests(
                make_entity_requests(1, A.KNEEL, W.DEPLOYED), server.request_time()
            )
            server.answer_requests()
            server.publish = publish

        server.publish = publish_then_answer
        got: list[tuple[int, list[int]]] = []
        with trio.fail_after(1.0 / HZ):  # the next tick's write
            while len(got) < 2:
                ev = await c.next_event()
                if isinstance(ev, JointUpdates):
                    got.append((ev.tick, ev.indices.tolist()))
        assert server.answers == 1
        assert got == [(board.ticks, [0]), (board.ticks + 1, [1])]


async def test_a_large_batch_goes_out_in_turns_and_an_answer_is_written_between_them(
    autojump_clock: trio.abc.Clock, monkeypatch: pytest.MonkeyPatch
) -> None:
    """With 3 soldiers a turn, a watcher of 10 walking soldiers gets its tick in 4 turns, every soldier once
    and under the tick's number, even with its own throttle (the turns of one write are not held back). A
    second client watching the resting soldier asks it to kneel during the watcher's first turn: its answer
    is written before the watcher's second turn, not after the watcher's whole batch."""
    monkeypatch.setattr(app, "ENCODE_TURN_ROWS", 3)
    async with running_server(throttle=0.0) as server:
        w = await Client.open(port_of(server))
        await w.expect(Ready)
        await w.requests(index=list(range(9)), velocity=vel(1.4, 0.0), heading=0.0)  # 9 walk, 1 rests
        await w.send(Subscribe(tuple(range(10))))
        await w.jcl("set_ttes_soldier_throttle(0.1);")
        c = await Client.open(port_of(server), name="asker")
        await c.expect(Ready)
        await c.send(Subscribe((9,)))
        await w.drain(1.0)
        await c.drain(0.01)
        kneel = c.conn.send(EntityRequests(make_entity_requests(9, A.KNEEL, W.DEPLOYED)))
        take = Session.take_output
        turns: list[tuple[str, bool]] = []  # (client, more owed) of each write with updates

        def take_output(session: Session, now: float | None = None, max_rows: int | None = None) -> bytes:
            data = take(session, now, max_rows)
            if data and (turns or session.owed):  # from the watcher's first turn of a tick on
                turns.append((session.name, session.owed))
                if len(turns) == 1:
                    os.write(c.stream.socket.fileno(), kneel)  # arrives during the watcher's first turn
            return data

        monkeypatch.setattr(Session, "take_output", take_output)
        got: dict[int, list[int]] = {}
        with trio.move_on_after(0.35):
            while True:
                ev = await w.next_event()
                if isinstance(ev, JointUpdates):
                    got.setdefault(ev.tick, []).extend(ev.indices.tolist())
        full = [t for t, rows in got.items() if len(rows) >= 9]
        assert full and all(sorted(got[t])[:9] == list(range(9)) for t in full)  # each soldier once a tick
        assert all(len(set(rows)) == len(rows) for rows in got.values())
        assert np.diff(full).min() == 3  # its own throttle: every third tick, the turns of one write together
        assert turns[:3] == [("test", True), ("asker", False), ("test", True)]  # the answer between turns
