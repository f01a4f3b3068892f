"""Issue 21: two front-ends in front of the same two shards, as real processes on 127.0.0.1 (Zenoh, and
Cyclone DDS: there the second front-end once hung writing to ``ttes/fronts``, ``server.fabric.dds_node``).

Two clients create soldiers at once, each through its own front-end: every soldier gets an index of its
own (each front-end allots from its share, ``ttes front --front K/M``), lives in its own shard alone, and
both front-ends know every soldier (they tell each other on ``ttes/fronts``): an observer of either sees
them all, and the updates of a soldier created through the other front-end.
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator

import pytest
import test_fabric_inprocess as inprocess
import trio
from test_fabric_cluster import WALK, _soldiers_of
from test_server_support import Client, synthetic_dir

from client_stub.link.spawn import ServerProcess, free_port
from protocol.events import CreateSoldier, JointUpdates, Ready, SoldierCreated, Subscribe
from server.fabric import engine_flags
from server.fabric.fronts import IndexShare

pytest.importorskip("zenoh")

START = 10  # the synthetic start-up script's soldiers, at 0..9 in every process
EACH = 24  # soldiers each client creates


@contextlib.contextmanager
def two_fronts(
    fabric: str = "zenoh", front_args: tuple[str, ...] = ()
) -> Iterator[tuple[list[ServerProcess], list[ServerProcess]]]:
    """Front-ends 0/2 and 1/2 (the second connects to the first; ``front_args`` for both), then 2 shards
    connected to both."""
    d = synthetic_dir()
    data = ["--data-dir", str(d.path), "--startup-script", d.startup_script, *engine_flags(fabric)]
    ends = [f"127.0.0.1:{free_port()}" for _ in range(2)]
    procs: list[ServerProcess] = []
    try:
        for k, end in enumerate(ends):
            joins = [a for e in ends[:k] for a in ("--fabric-connect", e)]
            args = [*data, "--shards", "2", "--front", f"{k}/2", "--fabric-listen", end, *joins, *front_args]
            procs.append(ServerProcess(args, command="front"))
        for k in range(2):
            joins = [a for e in ends for a in ("--fabric-connect", e)]
            procs.append(ServerProcess([*data, "--shard", f"{k}/2", *joins]))
        for p in procs:
            p.wait_ready()
        yield procs[:2], procs[2:]
    finally:
        for p in procs:
            p.stop()


async def _create(port: int, client_id: str, out: dict[str, list[int]]) -> None:
    c = await Client.open(port, "ig", client_id=client_id)
    await c.expect(Ready)
    for rid in range(1, EACH + 1):  # all at once: the front-end takes them in one read
        await c.send(CreateSoldier(rid, "DI.fig", "AK_47.fig", None))
    made = [await c.expect(SoldierCreated) for _ in range(EACH)]
    out[client_id] = [e.index for e in sorted(made, key=lambda e: e.id)]
    await c.requests(index=out[client_id], velocity=WALK)
    await c.aclose()


@pytest.mark.parametrize("fabric", ["zenoh", "dds"])
async def test_two_front_ends_create_at_once_without_collision_and_both_see_all(fabric: str) -> None:
    if fabric == "dds":
        pytest.importorskip("cyclonedds")
    with two_fronts(fabric) as (fronts, shards):
        made: dict[str, list[int]] = {}
        async with trio.open_nursery() as nursery:
            for front, cid in zip(fronts, ("alpha", "beta"), strict=True):
                nursery.start_soon(_create, front.port, cid, made)
        alpha, beta = made["alpha"], made["beta"]
        assert len(set(alpha)) == len(set(beta)) == EACH and not set(alpha) & set(beta)
        every = sorted([*range(START), *alpha, *beta])
        # the other front-end's books, and each soldier in its own shard alone: no creation collided
        want = [every, every, *([i for i in every if i % 2 == k] for k in range(2))]
        have: list[list[int]] = []
        with contextlib.suppress(trio.TooSlowError), trio.fail_after(60):  # a deadline, not a timing
            while (have := [await _soldiers_of(p.port) for p in (*fronts, *shards)]) != want:
                await trio.sleep(0.1)
        assert have == want
        for front, theirs in ((fronts[0], beta), (fronts[1], alpha)):  # the other's walkers move here
            obs = await Client.open(front.port, "obs", role="observer")
            await obs.expect(Ready)
            await obs.send(Subscribe(tuple(theirs)))
            seen: set[int] = set()
            with trio.fail_after(60):
                while seen != set(theirs):
                    seen |= set((await obs.expect(JointUpdates)).indices.tolist()) & set(theirs)
            await obs.aclose()


async def _created_while_deaf(c: inprocess.Fronts, deaf_s: float) -> None:
    """Three soldiers created through each front-end, the fabric heard again ``deaf_s`` later: every
    front-end and shard has them all (a deadline, not a timing; the clients stay: no orphan goes)."""
    made: list[int] = []
    clients: list[Client] = []
    for front, cid in zip(c.servers, ("alpha", "beta"), strict=True):
        client = await Client.open(front.addresses[0][1], "ig", client_id=cid)
        await client.expect(Ready)
        for rid in range(1, 4):
            await client.send(CreateSoldier(rid, "DI.fig", "AK_47.fig", None))
        made += [(await client.expect(SoldierCreated)).index for _ in range(3)]
        clients.append(client)
    await trio.sleep(deaf_s)
    for fabric in (*c.fabrics, *c.shard_fabrics):
        fabric.deaf = ()
    every = sorted([*range(START), *made])
    want = [every, every, *([i for i in every if i % 2 == k] for k in range(2))]
    with contextlib.suppress(trio.TooSlowError), trio.fail_after(30):
        while [inprocess.live(s) for s in (*c.servers, *c.shards)] != want:
            await trio.sleep(0.1)
    assert [inprocess.live(s) for s in (*c.servers, *c.shards)] == want
    for client in clients:
        await client.aclose()


async def test_soldiers_created_before_a_shards_subscription_is_known_reach_it_and_every_front_end(
    autojump_clock: trio.abc.Clock,
) -> None:
    """Zenoh drops what a node publishes before it knows of a subscriber: a shard's first pulses reached
    the front-ends before its subscription to its requests did (CI, under load), and they sent it their
    sync and their ``books`` into the void. Here every node is deaf to the requests and ``ttes/fronts``
    for 3 s while two clients create soldiers. On main each front-end asked each shard once and waited for
    the answer for ever: the shards never had the soldiers, and 12 s after their clients left every
    front-end held the 10 start-up soldiers alone (the CI failure of the test above). A front-end asks
    again, its sync first, until the shard answers."""
    async with inprocess.fronts(deaf=("ttes/requests", "ttes/fronts")) as c:
        await _created_while_deaf(c, 3)


async def test_a_front_end_that_missed_the_others_creations_learns_them_from_the_shards(
    autojump_clock: trio.abc.Clock,
) -> None:
    """Each front-end misses the other's first messages on ``ttes/fronts``: a shard's key pulse that names
    soldiers its books lack (twice) makes it ask for the shard's books. On main front-end 0 never did: it
    compared only the indices below its table's length, and front-end 1's share (4096 on) is beyond."""
    async with inprocess.fronts(deaf=("ttes/fronts",)) as c:
        await _created_while_deaf(c, 3)


def test_each_front_end_allots_its_own_share_spread_over_the_shards() -> None:
    shares = [IndexShare(k, 2, 3, 24) for k in range(2)]  # blocks of 3 indices
    live: set[int] = {0, 1}  # the start-up script's
    got: list[list[int]] = [[], []]
    for _ in range(5):
        for k, share in enumerate(shares):
            i = share.allot(None, live.__contains__)
            share.taken(i)
            live.add(i)
            got[k].append(i)
    assert got == [[2, 6, 7, 8, 12], [3, 4, 5, 9, 10]]  # blocks of 3 (one soldier per shard), alternating
    assert sorted(i % 3 for i in got[0][1:4]) == [0, 1, 2]
    live.discard(4)  # removed
    shares[1].freed(4)
    assert shares[1].allot(None, live.__contains__) == 4
    shares[0].freed(4)  # not its own: never allotted there
    assert shares[0].allot(None, live.__contains__) == 13
    with pytest.raises(ValueError, match="another front-end"):
        shares[0].allot(3, live.__contains__)
