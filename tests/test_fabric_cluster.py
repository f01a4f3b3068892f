"""Issue 21: two shards and a front-end as real processes on 127.0.0.1 over the Zenoh fabric, one client.

The client speaks to the front-end exactly as to a single server. Soldier ``i`` lives in shard ``i % 2``:
a created soldier must appear in its own shard alone (each shard's own READY lists its soldiers), the
requests of a soldier must reach its shard (it walks: its pose keeps changing), and the updates of both
shards' soldiers must reach the one client, in tick order.
"""

from __future__ import annotations

import contextlib
from collections import Counter
from collections.abc import Iterator

import pytest
import trio
from test_server_support import Client, synthetic_dir

from client_stub.link.spawn import ServerProcess, free_port
from protocol.events import CreateSoldier, JointUpdates, Ready, SoldierCreated, SoldierRemoved, Subscribe
from server.fabric import engine_flags

pytest.importorskip("zenoh")

WALK = (0.0, 1.4, 0.0)


@contextlib.contextmanager
def cluster(shards: int = 2, fabric: str = "zenoh") -> Iterator[list[ServerProcess]]:
    """A front-end, then ``shards`` shards connected to its fabric endpoint; stopped on exit."""
    d = synthetic_dir()
    data = ["--data-dir", str(d.path), "--startup-script", d.startup_script, *engine_flags(fabric)]
    endpoint = f"127.0.0.1:{free_port()}"
    procs = [ServerProcess([*data, "--shards", str(shards), "--fabric-listen", endpoint], command="front")]
    try:
        procs += [
            ServerProcess([*data, "--shard", f"{k}/{shards}", "--fabric-connect", endpoint])
            for k in range(shards)
        ]
        for p in procs:
            p.wait_ready()
        yield procs
    finally:
        for p in procs:
            p.stop()


async def _soldiers_of(port: int) -> list[int]:
    """The soldiers a server's own READY lists (an observer sees every soldier)."""
    c = await Client.open(port, "check", role="observer")
    ready = await c.expect(Ready)
    await c.aclose()
    return sorted(i for i, _ in ready.soldiers)


@pytest.mark.parametrize("fabric", ["zenoh", "dds"])
async def test_requests_reach_their_shard_and_both_shards_reach_one_client(fabric: str) -> None:
    """On both engines (each tells a shard which of its pose topics a front-end hears)."""
    if fabric == "dds":
        pytest.importorskip("cyclonedds")
    with cluster(fabric=fabric) as (front, *shards):
        c = await Client.open(front.port, "ig", client_id="alpha")
        ready = await c.expect(Ready)
        assert sorted(i for i, _ in ready.soldiers) == list(range(10))  # the start-up script's, as one server
        created = []
        for rid in (1, 2):
            await c.send(CreateSoldier(rid, "DI.fig", "AK_47.fig", None))
            created.append((await c.expect(SoldierCreated, lambda e, rid=rid: e.id == rid)).index)
        assert created == [10, 11]
        await c.send(Subscribe(tuple(range(12))))
        await c.requests(index=created, velocity=WALK)
        updates: Counter[int] = Counter()
        ticks = []
        with trio.fail_after(60):  # a deadline, not a timing: the walkers' poses keep changing
            while min(updates[10], updates[11]) < 10 or not {0, 1} <= set(updates):
                ju = await c.expect(JointUpdates)
                ticks.append(ju.tick)
                updates.update(ju.indices.tolist())
        assert ticks == sorted(ticks)
        for k, shard in enumerate(shards):  # each soldier lives in its own shard alone
            assert await _soldiers_of(shard.port) == [i for i in range(12) if i % 2 == k]
        await c.aclose()


async def test_a_killed_shards_soldiers_go_on_in_the_survivor() -> None:
    """Failover: shard 1 is killed; within its silence limit the front-end hands its soldiers (the
    start-up script's odd ones and a walker created by the client) to shard 0 with their last requests.
    The client sees no soldier removed and the walker moving again."""
    with cluster() as (front, *shards):
        c = await Client.open(front.port, "ig", client_id="alpha")
        await c.expect(Ready)
        await c.send(CreateSoldier(1, "DI.fig", "AK_47.fig", 11))
        assert (await c.expect(SoldierCreated)).index == 11
        await c.send(Subscribe(tuple(range(12))))
        await c.requests(index=[11], velocity=WALK)
        await _updates_of(c, 11, 5)
        shards[1].proc.kill()
        shards[1].proc.wait()
        with trio.fail_after(60):
            while await _soldiers_of(shards[0].port) != [*range(10), 11]:  # the survivor animates all
                await trio.sleep(0.2)
        await _updates_of(c, 11, 10)  # walking on: its last request went with it
        assert not [e for e in c.events if isinstance(e, SoldierRemoved)]
        await c.aclose()


async def _updates_of(c: Client, index: int, count: int) -> None:
    seen = 0
    with trio.fail_after(60):
        while seen < count:
            ju = await c.expect(JointUpdates)
            seen += int(index in ju.indices)
