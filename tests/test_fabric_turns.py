"""Issue 21: work comes in bounded turns, so a request is not kept waiting behind a burst — a shard answers
what arrived together at once (not one answer per operation), and a front-end's reader leaves the loop to
the others between turns of a client's creation burst. In one process on trio's autojump clock."""

from __future__ import annotations

import os

import numpy as np
import pytest
import trio
from test_fabric_inprocess import RUN, WALK, Bus, MemoryFabric, cluster, live, walker
from test_server_support import Client, make_server

from protocol.entity import make_entity_requests
from protocol.events import CreateSoldier, EntityRequests, Ready, SoldierCreated, Subscribe
from server import app
from server.fabric import poses_topic, requests_topic
from server.fabric import requests as req
from server.fabric.batch import PULSE, Batch, decode_batch, encode_batch
from server.fabric.nodes import Sharding, ShardNode
from server.session import Session


async def test_a_shard_answers_the_requests_that_arrived_together_in_one_batch(
    autojump_clock: trio.abc.Clock,
) -> None:
    bus = Bus()
    batches = []
    bus.topics[poses_topic(0, 0)].append(lambda data: batches.append(decode_batch(data)))  # block 0
    shard = make_server()
    node = ShardNode(shard, MemoryFabric(bus), Sharding(0, 1))
    async with trio.open_nursery() as nursery:
        await nursery.start(shard.serve)
        await trio.sleep(0.2)
        ops = req.decode(
            req.pack([req.requests(make_entity_requests(index=[i], velocity=WALK)) for i in (1, 2, 3)])
        )
        answers, sent = shard.answers, len(batches)
        node.backlog.put(ops)
        assert node.take_turn() == 1  # the three messages' rows, taken as one batch
        m = shard.world.manager
        assert m is not None and all(m.soldier_info(i)["speed"] > 1.0 for i in (1, 2, 3))
        assert shard.answers == answers + 1  # one answer for the three (it was one each)
        (answer,) = batches[sent:]
        assert not answer.key and {1, 2, 3} <= set(answer.indices.tolist())
        shard.shutdown()


async def test_a_shards_turn_ends_when_its_cpu_is_spent(
    autojump_clock: trio.abc.Clock, monkeypatch: pytest.MonkeyPatch
) -> None:
    """At least one operation a turn; the rest wait for the next (after the tick, if it is due)."""
    monkeypatch.setattr("server.fabric.nodes.TURN_S", 0.0)
    shard = make_server()
    node = ShardNode(shard, MemoryFabric(Bus()), Sharding(0, 1))
    async with trio.open_nursery() as nursery:
        await nursery.start(shard.serve)
        await trio.sleep(0.2)
        node.backlog.put(
            req.decode(req.pack([req.create(20 + k, "DI.fig", "AK_47.fig", None) for k in range(3)]))
        )
        assert node.take_turn() == 1 and len(node.backlog) == 2
        assert 20 in live(shard) and 21 not in live(shard)
        shard.shutdown()


async def test_a_creation_burst_leaves_the_other_clients_requests_in_between(
    autojump_clock: trio.abc.Clock, monkeypatch: pytest.MonkeyPatch
) -> None:
    """One client creates a crowd in one write; another's request, sent just after, is taken between the
    burst's turns, not after all of it (it waited for up to ``control_queue`` creations, 256: 12-14 ms of
    CPU on this machine; now a turn is ``READ_TURN_S``, here one event per turn)."""
    monkeypatch.setattr(app, "READ_TURN_S", 0.0)
    burst = 200
    async with cluster() as (front, node, shards, _):
        seen: list[int] = []  # the front-end's soldiers when each request was relayed
        relay = node.requests
        monkeypatch.setattr(node, "requests", lambda rows: (seen.append(len(live(front))), relay(rows)))
        a = await Client.open(front.addresses[0][1], "crowd", client_id="alpha")
        b = await Client.open(front.addresses[0][1], "ig", client_id="beta")
        await a.expect(Ready)
        await b.expect(Ready)
        await a.send_raw(
            b"".join(a.conn.send(CreateSoldier(k + 1, "DI.fig", "AK_47.fig")) for k in range(burst))
        )
        await b.requests(index=[0], velocity=RUN)
        with trio.fail_after(30):
            for _ in range(burst):
                await a.expect(SoldierCreated)
        assert len(seen) == 1 and seen[0] < 10 + burst  # taken while the burst was being created
        with trio.fail_after(30):
            while sum(len(live(s)) for s in shards) < 10 + burst:
                await trio.sleep(0.1)
        await a.aclose()
        await b.aclose()


async def test_a_front_end_wakes_only_the_writers_of_clients_subscribed_to_what_changed(
    autojump_clock: trio.abc.Clock,
) -> None:
    """A shard's answer for one soldier wakes the writer of the client that watches it, not the others
    (whose writers would encode nothing, and could run first)."""
    async with cluster() as (front, _, _, _):
        a = await walker(front, 11)  # subscribed to 0..11
        b = await Client.open(front.addresses[0][1], "other", client_id="beta")
        await b.expect(Ready)
        await b.send(CreateSoldier(1, "DI.fig", "AK_47.fig", 13))
        await b.expect(SoldierCreated)
        await b.send(Subscribe((13,)))
        await trio.sleep(0.5)
        board = front.board_ref.board
        assert board is not None
        by_name = {s.name: s for s in front.sessions.values()}
        for rows, woken in (([11], {"ig"}), ([13], {"other"}), ([11, 13], {"ig", "other"})):
            for s in by_name.values():
                s.wake = trio.Event()
            front._published(board, len(rows), np.asarray(rows))
            assert {n for n, s in by_name.items() if s.wake.is_set()} == woken
        await a.aclose()
        await b.aclose()


@pytest.mark.parametrize("turns", [True, False])
async def test_a_request_that_arrives_during_one_clients_encode_is_relayed_before_the_next_ones(
    autojump_clock: trio.abc.Clock, monkeypatch: pytest.MonkeyPatch, turns: bool
) -> None:
    """A shard's batch wakes two clients' writers; a third client's request that arrives while the first
    encodes goes to its shard before the second encode (it waited for both: ~3.5 ms each at 20,000, as
    it still does with ``TTES_FRONT_TURNS=0``, the bench's A/B switch)."""
    monkeypatch.setattr(app, "FRONT_TURNS", turns)
    async with cluster() as (front, node, _, _):
        a = await walker(front, 11)  # subscribed to 0..11; 11 walks (shard 1)
        b = await Client.open(front.addresses[0][1], "other", client_id="beta")
        c = await Client.open(front.addresses[0][1], "asker", client_id="gamma")
        for client, index in ((b, 13), (c, 15)):
            await client.expect(Ready)
            await client.send(CreateSoldier(1, "DI.fig", "AK_47.fig", index))
            await client.expect(SoldierCreated)
        await b.send(Subscribe((13,)))
        await b.requests(index=[13], velocity=WALK)  # 11 and 13 in each of shard 1's batches: both woken
        await trio.sleep(0.5)
        order: list[str] = []
        request = c.conn.send(EntityRequests(make_entity_requests(index=[15], velocity=RUN)))
        relay, take_output = node.requests, Session.take_output

        def relayed(rows: np.ndarray) -> None:
            order.append("relay")
            relay(rows)

        def encoding(self: Session, now: float | None = None) -> bytes:
            data = take_output(self, now)
            if self.name in ("ig", "other") and data and len(order) < 3:
                if not order:  # the first encode of the pair: c's request arrives meanwhile
                    os.write(c.stream.socket.fileno(), request)  # in the kernel's buffer at once
                order.append("encode")
            return data

        monkeypatch.setattr(node, "requests", relayed)
        monkeypatch.setattr(Session, "take_output", encoding)
        with trio.fail_after(5):
            while len(order) < 3:
                await trio.sleep(0.01)
        assert order == (["encode", "relay", "encode"] if turns else ["encode", "encode", "relay"])
        for client in (a, b, c):
            await client.aclose()


async def test_a_request_that_arrives_while_a_shard_ticks_is_sampled_by_that_tick_and_sent_first(
    autojump_clock: trio.abc.Clock, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A shard's tick lets its requests in between advancing the soldiers and sampling them (its loop is
    not deaf for the whole sampling): a request that arrives meanwhile is sampled by that tick, not answered
    after it, and its soldier's codes go first, in a batch of their own, before the tick's batch of every
    soldier (issue 21: they waited for the tick's quantising and batch, and the front-end merged them with
    the tick, so their client waited for the whole tick's encode); the tick's batch does not send them
    again."""
    bus = Bus()
    sent_out: list[Batch] = []  # the block's batches and the tick pulses, in the order sent
    for topic in (poses_topic(0, 0), poses_topic(0)):
        bus.topics[topic].append(lambda data: sent_out.append(decode_batch(data)))
    shard = make_server()
    node = ShardNode(shard, MemoryFabric(bus), Sharding(0, 1))
    m = shard.world.manager
    assert m is not None
    arm: list[int] = []
    advance = m._advance

    def advance_then_arrive(idx: np.ndarray) -> None:  # a request reaches the fabric while the tick samples
        advance(idx)
        if arm and m.ticks > arm[0]:  # the tick's advance
            arm.clear()
            for put in bus.topics[requests_topic(0)]:
                put(req.pack([req.requests(make_entity_requests(index=[1], velocity=RUN))]))

    monkeypatch.setattr(m, "_advance", advance_then_arrive)
    async with trio.open_nursery() as nursery:
        await nursery.start(shard.serve)
        node.start(trio.lowlevel.current_trio_token())
        for put in bus.topics[requests_topic(0)]:  # 2 walks: every tick's batch carries it
            put(req.pack([req.requests(make_entity_requests(index=[2], velocity=WALK))]))
        await trio.sleep(0.2)
        answers, sent = shard.answers, len(sent_out)
        arm.append(m.ticks)
        while arm:
            await trio.sleep(0.001)
        await trio.sleep(0.3 / shard.config.tick_hz)  # the tick's end (and an answer after it)
        assert not arm and m.soldier_info(1)["speed"] > 3.0
        first, *rest = sent_out[sent:]
        assert first.block == 0 and first.indices.tolist() == [1] and not first.key  # its own batch, first
        pulse = next(b for b in rest if b.block == PULSE)  # the tick's end
        assert pulse.tick == first.tick  # first of that tick
        (tick,) = rest[: rest.index(pulse)]  # then the tick's batch, without it
        assert 2 in tick.indices.tolist() and (tick.key or 1 not in tick.indices.tolist())
        assert shard.answers == answers and not m.table.requested[1]  # and no answer after the tick
        shard.shutdown()


@pytest.mark.parametrize("first", [True, False])
async def test_a_front_end_merges_an_answer_before_the_tick_that_came_with_it(
    autojump_clock: trio.abc.Clock, monkeypatch: pytest.MonkeyPatch, first: bool
) -> None:
    """A shard's answer and another shard's tick arrive together (the front-end's loop was busy): the answer
    is merged and its client's writer encodes it before the tick's batch is merged (issue 21: that client
    waited for the encode of the tick's rows, its own and the other clients'); then the tick follows, and
    that client's rows of it are not held back by the throttle as a second write of the tick. With
    ``answers_first`` off (``TTES_ANSWERS_FIRST=0``, the bench's A/B), both in one publish, as before."""
    async with cluster() as (front, node, _, _):
        front.answers_first = first
        a = await Client.open(front.addresses[0][1], "ticked", client_id="alpha")
        b = await Client.open(front.addresses[0][1], "answered", client_id="beta")
        for client, indices in ((a, (10,)), (b, (12, 13))):  # 10 and 12 on shard 0, 13 on shard 1
            await client.expect(Ready)
            for index in indices:
                await client.send(CreateSoldier(1, "DI.fig", "AK_47.fig", index))
                await client.expect(SoldierCreated)
            await client.send(Subscribe(indices))
        await trio.sleep(0.5)
        board = front.board_ref.board
        assert board is not None

        def batch(k: int, indices: list[int], answer: bool) -> bytes:  # the soldiers' codes, changed
            stream = next(s for s in node._subs if s[0] == k)
            seq = node._block_seq.get(stream, -1) + 1
            rows = np.asarray(indices)
            codes = board.codes[rows].astype(np.uint16) ^ 1
            tables = board.table_of[rows]
            return encode_batch(
                Batch(k, 2, seq, board.tick, 0.0, rows, tables, codes, False, stream[1], (), answer)
            )

        writes: list[tuple[str, bool, bool]] = []  # (client, wrote, whether the tick was merged by then)
        version = board.version[10]
        take_output = Session.take_output

        def encoding(self: Session, now: float | None = None) -> bytes:
            data = take_output(self, now)
            writes.append((self.name, bool(data), bool(board.version[10] != version)))
            return data

        monkeypatch.setattr(Session, "take_output", encoding)
        tick, answer = batch(0, [10, 12], False), batch(1, [13], True)
        with node._pending_lock:  # arrived while the loop was busy: the tick first
            node._pending = {0: [tick], 1: [answer]}
        front.publish_fed()
        with trio.fail_after(1):
            while board.version[10] == version or sum(w[0] == "answered" for w in writes) < (
                2 if first else 1
            ):
                await trio.sleep(0)
        answered = [(wrote, ticked) for name, wrote, ticked in writes if name == "answered"]
        if first:  # the answer alone, then the tick's row at once
            assert answered[:2] == [(True, False), (True, True)] and writes[0][0] == "answered"
        else:  # one write of both (either writer may go first)
            assert answered[0] == (True, True)
        for client in (a, b):
            await client.aclose()
