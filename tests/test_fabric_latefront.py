"""Issue 21: a front-end that starts (or restarts) after soldiers were created through the others learns
every one of them from the shards, as real processes on 127.0.0.1 (Zenoh).

Front-ends 0/2 and 1/2 before two shards; a client creates soldiers through each and removes one of the
start-up script's; front-end 1/2 dies and a new one starts on its endpoint. The new one asks each shard for
its soldiers (figure, weapon, owner, table): its observers see them all, the soldiers created through the
dead one obey their owner when it comes back through the new one, and the new one allots no index that
is live. And a front-end serves the browser's WebSocket transport (``--ws-port``) as a server does.
"""

from __future__ import annotations

import numpy as np
import pytest
import trio
from test_app_websocket import ws_client
from test_fabric_cluster import WALK, _soldiers_of
from test_fabric_fronts import START, two_fronts
from test_server_support import Client, synthetic_dir

from client_stub.link.spawn import ServerProcess, free_port
from protocol.events import CreateSoldier, JointUpdates, Ready, RemoveSoldier, SoldierCreated, Subscribe
from server.fabric.fronts import answer, answer_scope, decode_answer, reconcile

pytest.importorskip("zenoh")

EACH = 6
GONE = 3  # a start-up soldier removed before the new front-end starts (its own start-up script makes it)


async def _create(c: Client, n: int, *, walk: bool) -> list[int]:
    for rid in range(1, n + 1):
        await c.send(CreateSoldier(rid, "DI.fig", "AK_47.fig", None))
    made = sorted(e.index for e in [await c.expect(SoldierCreated) for _ in range(n)])
    if walk:
        await c.requests(index=made, velocity=WALK)
    return made


async def _moving(port: int, soldiers: list[int], frames: int = 3) -> None:
    """An observer sees each of ``soldiers`` change in ``frames`` updates (a still soldier is sent once)."""
    obs = await Client.open(port, "obs", role="observer")
    await obs.expect(Ready)
    await obs.send(Subscribe(tuple(soldiers)))
    seen = dict.fromkeys(soldiers, 0)
    with trio.fail_after(30):  # a deadline, not a timing
        while min(seen.values()) < frames:
            for i in (await obs.expect(JointUpdates)).indices.tolist():
                if i in seen:
                    seen[i] += 1
    await obs.aclose()


async def test_a_restarted_front_end_learns_every_soldier_from_the_shards() -> None:
    with two_fronts() as (fronts, shards):
        for front in fronts:  # both shards heard (a removal sent before a shard listens is lost)
            await _moving(front.port, list(range(2)), frames=1)
        alpha = await Client.open(fronts[0].port, "ig", client_id="alpha")
        await alpha.expect(Ready)
        walkers = await _create(alpha, EACH, walk=True)
        beta = await Client.open(fronts[1].port, "ig", client_id="beta")
        await beta.expect(Ready)
        still = await _create(beta, EACH, walk=False)  # through the front-end that dies
        op = await Client.open(fronts[0].port, "op", role="operator")
        await op.expect(Ready)
        await op.send(RemoveSoldier(GONE))
        await op.aclose()
        every = sorted({*range(START), *walkers, *still} - {GONE})
        with trio.fail_after(30):
            while await _soldiers_of(shards[0].port) + await _soldiers_of(shards[1].port) != [
                i for k in range(2) for i in every if i % 2 == k
            ]:
                await trio.sleep(0.1)
        await beta.aclose()
        fronts[1].proc.kill()
        fronts[1].stop()
        args = fronts[1].cmd[fronts[1].cmd.index("--json") + 1 :]  # the same front-end 1/2 again
        with ServerProcess(args, command="front") as late:
            late.wait_ready()
            have: list[int] = []
            with trio.move_on_after(20):  # a deadline, not a timing
                while (have := await _soldiers_of(late.port)) != every:
                    await trio.sleep(0.1)
            assert have == every
            beta = await Client.open(late.port, "ig", client_id="beta")
            await beta.expect(Ready)
            await beta.requests(index=still, velocity=WALK)  # its own soldiers obey it through the new one
            more = await _create(beta, 2, walk=True)
            assert not set(more) & set(every)  # no live index allotted again
            await _moving(late.port, [*walkers, *still, *more])
            await beta.aclose()
        await alpha.aclose()


async def test_a_front_end_serves_websocket_clients() -> None:
    d = synthetic_dir()
    data = ["--data-dir", str(d.path), "--startup-script", d.startup_script]
    end = f"127.0.0.1:{free_port()}"
    with (
        ServerProcess(
            [*data, "--shards", "1", "--ws-port", "0", "--fabric-listen", end], command="front"
        ) as f,
        ServerProcess([*data, "--shard", "0/1", "--fabric-connect", end]) as shard,
    ):
        f.wait_ready()
        shard.wait_ready()
        ws = await ws_client(int(f.ready["websocket"][0].rsplit(":", 1)[1]))
        await ws.expect(Ready)
        (made,) = await _create(ws, 1, walk=True)  # animated by the shard, seen through the WebSocket
        await ws.send(Subscribe((made,)))
        seen = 0
        with trio.fail_after(30):  # a deadline, not a timing
            while seen < 3:  # it walks: its pose changes frame after frame
                seen += made in (await ws.expect(JointUpdates)).indices.tolist()
        await ws.aclose()


def test_the_books_take_the_shards_soldiers_but_not_over_what_a_front_end_knows() -> None:
    a, b = ("DI.fig", "AK_47.fig"), ("M16.fig", "M16_rifle.fig")
    books_here = {0: (0, *a, None), 1: (1, *a, None), 4: (4, *a, "x"), 6: (6, *b, "y"), 7: (7, *a, None)}
    scope = {0, 4, 6, 7}  # what the answering shard animates of these (1 is another shard's)
    told = [(0, *a, None), (2, *a, "z"), (6, *a, "y"), (8, *b, None), (1, *b, None)]
    drop, add = reconcile(books_here, scope, told, known={7, 8})
    # 4 gone from the shard, 6 and 1 replaced (other figures), 7 and 8 known here better than the answer
    assert drop == [4, 6, 1] and add == [(2, *a, "z"), (6, *a, "y"), (1, *b, None)]
    assert decode_answer(answer(1, 0, told))["soldiers"] == told
    with pytest.raises(ValueError, match="books"):
        decode_answer(b"\x93\x01")


def test_a_books_answer_drops_only_the_soldiers_homed_and_animated_on_its_shard() -> None:
    """Shard 1 failed over to shard 0 after shard 0 answered: its soldiers (odd indices) are not in the
    answer, and must not be dropped for it (they were, on failover, in a CI run)."""
    live = np.arange(10)
    assert answer_scope(live, [0, 0], 0) == {0, 2, 4, 6, 8}
    assert answer_scope(live, [0, 1], 1) == {1, 3, 5, 7, 9}
    assert answer_scope(live, [0, 0], 1) == set()  # shard 1's own answer, failed over: none of them
