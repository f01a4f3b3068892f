"""Issue 21: a front-end hears the blocks of soldier indices its clients watch, not every shard's whole tick.

Each front-end received and decoded every shard's batch whole (114 MB/s each at 48,000 soldiers on the
16-core machine) to merge the few rows its clients watch. A shard now publishes a batch per block of
indices on the block's topic, and a front-end subscribes to the blocks its clients watch (and, each tick,
to every shard's pulse): here blocks of 16, the client's soldiers 10..39 in blocks 0, 1 and 2. A front-end
whose clients watch every block that holds a soldier hears the whole shard instead (one batch a shard a
tick), and a shard publishes only the streams some front-end hears."""

from __future__ import annotations

import contextlib
from collections.abc import AsyncIterator

import trio
from test_fabric_inprocess import Bus, MemoryFabric, cluster, crowd, moving
from test_server_support import Client, make_server

from protocol.events import CreateSoldier, JointUpdates, Ready, SoldierCreated, Subscribe, Unsubscribe
from server.app import TtesServer
from server.fabric import WHOLE
from server.fabric.nodes import FrontNode, Sharding, ShardNode

BLOCK = 16
MADE = 30  # 10..39 (the start-up script's are 0..9)
WATCHED = (10, 11, 12, 13, 14, 15)  # block 0, both shards' soldiers
LATE = 20  # block 1: an observer watches it a while, then it stops unheard, then one watches it again


async def _learned(node: FrontNode) -> None:
    """Until the shards answered its books (till then it hears all their blocks: their soldiers)."""
    with trio.fail_after(30):  # a deadline, not a timing
        while node._asked:
            await trio.sleep(0.1)


async def test_a_front_end_hears_only_the_blocks_its_clients_watch(autojump_clock: trio.abc.Clock) -> None:
    async with cluster(block=BLOCK) as (front, node, shards, _):
        c = await crowd(front, MADE, WATCHED)
        await _learned(node)
        await moving(c, 10, 3)
        assert set(node._subs) == {(0, 0), (1, 0)}
        before = node.rows_decoded.copy()
        # updates of both shards' soldiers reach the client, each soldier's in order
        ticks: dict[int, list[int]] = {i: [] for i in WATCHED}
        with trio.fail_after(30):
            while min(len(t) for t in ticks.values()) < 10:
                ju = await c.expect(JointUpdates)
                for i in set(ju.indices.tolist()) & set(WATCHED):
                    ticks[i].append(ju.tick)
        assert all(t == sorted(t) for t in ticks.values())
        grew = node.rows_decoded - before
        assert grew[0] >= 10 * len(WATCHED) and grew[1:].sum() == 0  # never a row of blocks 1 and 2

        obs = await Client.open(front.addresses[0][1], "obs", role="observer")
        await obs.expect(Ready)
        await obs.send(Subscribe((LATE,)))  # its block is heard from now on (a key asked for)
        await moving(obs, LATE, 3)
        assert set(node._subs) == {(0, 0), (1, 0), (0, 1), (1, 1)} and node.rows_decoded[1] > before[1]
        await obs.send(Unsubscribe((LATE,)))  # no client watches block 1 again: heard no more
        with trio.fail_after(30):
            while set(node._subs) != {(0, 0), (1, 0)}:
                await moving(c, 10, 1)
        await obs.aclose()

        await c.requests(index=[LATE], velocity=(0.0, 0.0, 0.0))  # it stops, unheard
        await trio.sleep(5.0)
        obs = await Client.open(front.addresses[0][1], "obs", role="observer")
        await obs.expect(Ready)
        board, shard = front.board_ref.board, shards[LATE % 2].board_ref.board
        assert board is not None and shard is not None
        held = node.watching  # as if a batch of block 1 in flight when it was dropped was merged after it:
        held.held[LATE], held.codes[LATE] = True, shard.codes[LATE] + 1  # held, and stale now
        await obs.send(Subscribe((LATE,)))  # heard again: what was held of block 1 is stale, a key comes
        known = False
        with trio.move_on_after(1.0):  # while the key comes: never the pose it had when last heard
            while True:
                if board.valid[LATE]:
                    assert (board.codes[LATE] == shard.codes[LATE]).all()
                    known = True
                await trio.sleep(0.001)
        assert known
        with trio.fail_after(30):
            while LATE not in (await obs.expect(JointUpdates)).indices.tolist():
                pass
        again = 0
        with trio.move_on_after(2.0):  # it stands: that was its one update (not a stale pose, then this)
            while True:
                again += LATE in (await obs.expect(JointUpdates)).indices.tolist()
        assert again == 0
        await obs.aclose()
        await c.aclose()


def _node(shard: TtesServer) -> ShardNode:
    node = getattr(shard.on_publish, "__self__", None)
    assert isinstance(node, ShardNode)
    return node


def _sent(shards: list[TtesServer]) -> list[dict[int, int]]:
    """Each shard's batches so far, per stream (WHOLE or a block), and its ticks (under -1)."""
    return [{**_node(s).block_seq, -1: _node(s).seq} for s in shards]


async def test_a_front_end_that_hears_every_block_hears_one_batch_a_shard_a_tick(
    autojump_clock: trio.abc.Clock,
) -> None:
    """One front-end whose client watches all its soldiers (blocks 0, 1 and 2): it hears each shard's
    whole stream, one batch a tick (no block batch goes: nobody hears a block alone); when the client
    watches block 0 alone again, it hears that block and the shards stop the whole stream."""
    async with cluster(block=BLOCK) as (front, node, shards, _):
        c = await crowd(front, MADE, tuple(range(10 + MADE)))
        await _learned(node)
        await moving(c, 39, 3)
        assert set(node._subs) == {(0, WHOLE), (1, WHOLE)}
        before = _sent(shards)
        await moving(c, 39, 10)
        for b, a in zip(before, _sent(shards), strict=True):
            assert a[WHOLE] - b[WHOLE] == a[-1] - b[-1] > 0  # one whole batch a tick
            assert all(a[k] == b[k] for k in a if k not in (WHOLE, -1))  # no block batch
        await c.send(Unsubscribe(tuple(range(16, 10 + MADE))))
        with trio.fail_after(30):
            while set(node._subs) != {(0, 0), (1, 0)}:
                await moving(c, 10, 1)
        await moving(c, 10, 3)
        before = _sent(shards)
        await moving(c, 10, 10)
        for shard, b, a in zip(shards, before, _sent(shards), strict=True):
            assert a[WHOLE] == b[WHOLE] and a[0] - b[0] == a[-1] - b[-1]  # block 0's batches alone
            assert _node(shard).heard == {0}
        await c.aclose()


@contextlib.asynccontextmanager
async def two_fronts() -> AsyncIterator[tuple[list[TtesServer], list[FrontNode], list[TtesServer]]]:
    """Front-ends 0/2 and 1/2 (index shares of whole blocks of 16) and two shards on one in-memory bus."""
    bus, token = Bus(), trio.lowlevel.current_trio_token()
    fronts, nodes, shards = [], [], []
    async with trio.open_nursery() as nursery:
        for k in range(2):
            front = make_server()
            front.start_world()  # its start-up soldiers before the share applies, as `ttes front`
            nodes.append(FrontNode(front, MemoryFabric(bus), 2, front=Sharding(k, 2), block=BLOCK))
            await nursery.start(front.serve)
            nodes[-1].start(token)
            fronts.append(front)
        for k in range(2):
            shard = make_server()
            shard.codes_only()
            node = ShardNode(shard, MemoryFabric(bus), Sharding(k, 2), block=BLOCK)
            await nursery.start(shard.serve)
            node.keep_own()
            node.start(token)
            shards.append(shard)
        yield fronts, nodes, shards
        for s in (*fronts, *shards):
            s.shutdown()


async def _walkers(front: TtesServer, count: int, watched: tuple[int, ...]) -> tuple[Client, list[int]]:
    c = await Client.open(front.addresses[0][1], "ig", client_id=f"c{front.addresses[0][1]}")
    await c.expect(Ready)
    for rid in range(count):
        await c.send(CreateSoldier(rid + 1, "DI.fig", "AK_47.fig", None))
    made = sorted([(await c.expect(SoldierCreated)).index for _ in range(count)])
    await c.send(Subscribe(watched))
    await c.requests(index=made, velocity=(0.0, 1.4, 0.0))
    return c, made


async def test_two_front_ends_each_watching_a_block_hear_only_their_blocks(
    autojump_clock: trio.abc.Clock,
) -> None:
    """Front-end 0's client walks soldiers in blocks 0 and 2 (its share) and watches block 0's; front-end
    1's walks block 1's and watches them. Each hears its block of both shards and decodes no other row;
    the shards publish blocks 0 and 1 (not 2, which nobody watches, nor the whole shard)."""
    async with two_fronts() as (fronts, nodes, shards):
        for n in nodes:
            await _learned(n)
        c0, made0 = await _walkers(fronts[0], 14, tuple(range(10, 16)))
        c1, made1 = await _walkers(fronts[1], 16, tuple(range(16, 32)))
        assert made0 == [*range(10, 16), *range(32, 40)] and made1 == list(range(16, 32)), (made0, made1)
        await moving(c0, 10, 3)
        await moving(c1, 16, 3)
        assert set(nodes[0]._subs) == {(0, 0), (1, 0)} and set(nodes[1]._subs) == {(0, 1), (1, 1)}
        decoded = [n.rows_decoded.copy() for n in nodes]
        before = _sent(shards)
        await moving(c0, 10, 10)
        await moving(c1, 16, 10)
        grew = [n.rows_decoded - d for n, d in zip(nodes, decoded, strict=True)]
        assert grew[0][0] > 0 and grew[0][1:].sum() == 0
        assert grew[1][1] > 0 and grew[1][0] == grew[1][2:].sum() == 0
        for shard, b, a in zip(shards, before, _sent(shards), strict=True):
            assert _node(shard).heard == {0, 1}
            assert a[0] > b[0] and a[1] > b[1] and a.get(2) == b.get(2) and a.get(WHOLE) == b.get(WHOLE)
        await c0.aclose()
        await c1.aclose()
