"""Issue 21: a front-end hears the blocks of soldier indices its clients watch, not every shard's whole tick.

Each front-end received and decoded every shard's batch whole (114 MB/s each at 48,000 soldiers on the
16-core machine) to merge the few rows its clients watch. A shard now publishes a batch per block of
indices on the block's topic, and a front-end subscribes to the blocks its clients watch (and, each tick,
to every shard's pulse): here blocks of 16, the client's soldiers 10..39 in blocks 0, 1 and 2."""

from __future__ import annotations

import trio
from test_fabric_inprocess import cluster, crowd, moving
from test_server_support import Client

from protocol.events import JointUpdates, Ready, Subscribe, Unsubscribe
from server.fabric.nodes import FrontNode

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
