"""Issue 21: the holes a cluster had in what its front-ends and shards agree on, as real processes on
127.0.0.1 (Zenoh): a front-end and two shards, started, killed and restarted one by one.

* a removal sent before a shard listened reaches it with the front-end's sync (the shard animated a ghost);
* a front-end that starts while a shard is failed over learns from the stand-in's answer where that shard's
  soldiers live, and sends their requests there (not to the dead shard's topic); when the shard comes
  back, it takes every one of them back, not only those created through this front-end;
* a front-end that learned the soldiers from the shards learns their last requests too: its fail-over
  hands them on walking, not standing.
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
import test_fabric_inprocess as inprocess
import trio
from test_fabric_cluster import WALK, _soldiers_of
from test_fabric_fronts import two_fronts
from test_fabric_latefront import _moving
from test_server_support import Client, synthetic_dir

from client_stub.link.spawn import ServerProcess, free_port
from protocol.entity import ENTITY_REQUEST_DTYPE
from protocol.events import (
    CreateSoldier,
    Error,
    JointUpdates,
    Ready,
    RemoveSoldier,
    SoldierCreated,
    SoldierRemoved,
    Subscribe,
)
from server.fabric import Handler, settings
from server.fabric import requests as req
from server.fabric.batch import Batch
from server.fabric.fronts import (
    Fences,
    answer,
    answer_scope,
    decode_answer,
    gone,
    learned_last,
    rerouted,
    stand_ins,
)
from server.fabric.stamps import after
from server.session import Session

pytest.importorskip("zenoh")


def test_a_sync_carries_the_soldiers_removed_of_its_homes() -> None:
    known = np.zeros(12, bool)
    known[[3, 4, 6, 11]] = True  # removed here (3, 6, 11), or created here (4)
    live = np.zeros(10, bool)  # the table may be narrower than the index space
    live[[0, 1, 2, 4, 5]] = True
    assert gone(known, live, [1], 2).tolist() == [3, 11]
    assert gone(known, live, [0, 1], 2).tolist() == [3, 6, 11]
    assert gone(known, live, [0], 3).tolist() == [3, 6]
    op = req.decode(req.pack([req.sync([], np.zeros(0, ENTITY_REQUEST_DTYPE), gone=[3, 11])]))[0]
    assert op["gone"] == [3, 11]


def test_a_stamp_is_past_the_newest_held_and_the_wall_clocks_ms() -> None:
    now = after(0)  # a restarted front-end's first generation: past any given before this ms
    assert now > 1_700_000_000_000 and after(now) == now + 1 and after(10**15) == 10**15 + 1
    assert settings.stamp(settings.START, 1) > settings.START > settings.OWN_STAMP
    assert settings.stamp_of(req.settings({}, (5, 1))) == (5, 1)
    assert settings.stamp_of({"stamp": ["x", 1]}) == settings.stamp_of({}) == settings.START


def _rows(shard: int, indices: list[int], fences: tuple[int, ...]) -> Batch:
    n = len(indices)
    codes = np.arange(n * 2, dtype=np.uint16).reshape(n, 2)
    return Batch(
        shard, 2, 0, 0, 0.0, np.array(indices, np.uint32), np.ones(n, np.uint8), codes, False, fences=fences
    )


def test_the_rows_of_an_index_created_again_wait_for_the_shards_fence() -> None:
    fences = Fences(1, 12, 2)  # front-end 1
    assert fences.clean(b := _rows(1, [3, 5], ())) is b  # nothing waits: the batch as it came
    fences.mark([5], 1)
    fences.mark([7, 5], 1)  # one message: one fence
    assert fences.fence(0) is None and fences.fence(1) == 1 and fences.fence(1) is None
    fences.mark([9], 1)  # the next message's
    assert fences.fence(1) == 2
    assert fences.clean(_rows(1, [3, 5, 7, 9], (9,))).indices.tolist() == [3]  # front-end 0's fence
    assert fences.clean(_rows(0, [5], (0, 1))).indices.tolist() == []  # another shard's rows
    kept = fences.clean(_rows(1, [5, 9, 11], (0, 1)))  # shard 1 took the first message, not the second
    assert kept.indices.tolist() == [5, 11] and kept.codes.tolist() == [[0, 1], [4, 5]]
    assert fences.clean(_rows(1, [5, 7, 9], (0, 1))).indices.tolist() == [5, 7]
    assert fences.waiting == 1 and fences.dropped == 6
    fences.moved([1], 2, 0)  # shard 1 failed over to 0: index 9 waits for shard 0's fence
    assert fences.fence(0) == 1
    assert fences.clean(_rows(1, [9], (0, 2))).indices.tolist() == []
    assert fences.clean(_rows(0, [9], (0, 1))).indices.tolist() == [9] and fences.waiting == 0
    fences.mark([3], 0)
    assert fences.fence(0) == 2 and fences.waiting == 1
    assert fences.clean(_rows(0, [], (0, 2))).indices.tolist() == [] and fences.waiting == 0  # no rows: done


def test_the_rows_of_an_index_another_front_end_created_again_wait_for_its_fence() -> None:
    fences = Fences(1, 12, 2)  # front-end 1 mirrors front-end 0's creation at 5, which ends with fence 3
    assert fences.wait([5], 0, 1, 3) and fences.due == [False, False]  # no fence of its own is due
    assert fences.clean(_rows(1, [3, 5], (2, 9))).indices.tolist() == [3]  # front-end 0's fence 2 only
    assert fences.clean(_rows(0, [5], (3, 0))).indices.tolist() == []  # shard 0's fence says nothing
    assert fences.clean(_rows(1, [5], (3,))).indices.tolist() == [5] and fences.waiting == 0


def test_a_shard_down_hands_its_own_and_the_homes_it_stood_in_for_to_the_least_busy_survivor() -> None:
    route = [0, 1, 0, 3]  # 2 failed over to 0
    assert rerouted(route, [0, 1, 2, 3], [True] * 4) == [] and route == [0, 1, 0, 3]
    assert rerouted(route, [1, 3], [True] * 4) == [(0, 1, [0, 2])] and route == [1, 1, 1, 3]
    assert rerouted(route, [3], [True] * 4) == [(1, 3, [0, 1, 2])] and route == [3, 3, 3, 3]
    assert rerouted(route, [], [True] * 4) == [] and route == [3, 3, 3, 3]  # none left to take them
    route = [0, 1, 2]
    assert rerouted(route, [2], [True, False, True]) == [(0, 2, [0])]  # 1 never heard: not failed over
    assert rerouted(route, [0], [True, True, True]) == [(1, 0, [1]), (2, 0, [0, 2])] and route == [0, 0, 0]


def test_an_answer_with_another_shards_soldiers_names_a_stand_in_for_a_shard_never_heard() -> None:
    di = ("DI.fig", "AK_47.fig")
    told = [(0, *di, None), (3, *di, "a"), (4, *di, None)]
    assert stand_ins(told, 0, 2, [True, False]) == {1: 0}
    assert stand_ins(told, 0, 2, [True, True]) == {}  # heard: it comes back, or failed over here
    assert stand_ins(told, 1, 3, [False, False, False]) == {0: 1}  # 3 and 0 homed on 0; 4 is shard 1's
    assert stand_ins([], 0, 3, [True, False, False], homes=[2]) == {2: 0}  # it says so: soldiers or none
    assert answer_scope(np.arange(10), [0, 0], 0, stand_in=[1]) == set(range(10))
    assert decode_answer(answer(0, 0, [], homes=[2]))["homes"] == [2]
    assert decode_answer(answer(0, 0, [(3, *di, None)], gens=[4]))["gens"] == [4]  # (generations: a sync's)


def test_a_front_end_keeps_the_answers_last_requests_of_its_soldiers_without_one() -> None:
    rows = np.zeros(4, ENTITY_REQUEST_DTYPE)
    rows["index"] = [1, 3, 5, 11]
    rows["velocity"][:, 1] = 1.4
    live = np.zeros(10, bool)
    live[[1, 3, 5]] = True
    has_last = np.zeros(12, bool)
    has_last[3] = True  # asked through this front-end: as new as the shard's
    assert learned_last(rows, live, has_last)["index"].tolist() == [1, 5]
    msg = decode_answer(answer(1, 0, [(1, "DI.fig", "AK_47.fig", None)], rows))
    assert msg["rows"].tobytes() == rows.tobytes()
    assert not len(decode_answer(answer(1, 0, []))["rows"])


ODD = 11  # a soldier created on shard 1 (index 11 modulo 2)


class Cluster:
    """A front-end (``ttes front --shards 2``) and shards started one by one; all stopped on exit."""

    def __init__(self) -> None:
        d = synthetic_dir()
        self.data = ["--data-dir", str(d.path), "--startup-script", d.startup_script]
        self.endpoint = f"127.0.0.1:{free_port()}"
        self.shards: dict[int, ServerProcess] = {}
        self.front = self._front()

    def _front(self) -> ServerProcess:
        p = ServerProcess([*self.data, "--shards", "2", "--fabric-listen", self.endpoint], command="front")
        p.wait_ready()
        return p

    def shard(self, k: int) -> ServerProcess:
        p = ServerProcess([*self.data, "--shard", f"{k}/2", "--fabric-connect", self.endpoint])
        self.shards[k] = p
        p.wait_ready()
        return p

    def kill(self, p: ServerProcess) -> None:
        p.proc.kill()
        p.proc.wait()
        p.stop()

    def restart_front(self) -> ServerProcess:
        self.kill(self.front)
        self.front = self._front()  # the same endpoint: the shards connect to it again
        return self.front

    def stop(self) -> None:
        for p in (self.front, *self.shards.values()):
            p.stop()


@contextlib.contextmanager
def cluster() -> Iterator[Cluster]:
    c = Cluster()
    try:
        yield c
    finally:
        c.stop()


async def _until_soldiers(port: int, want: list[int], deadline: float = 60) -> list[int]:
    """The soldiers a server's READY lists, once they are ``want`` or at the deadline (not a timing)."""
    have: list[int] = []
    with trio.move_on_after(deadline):
        while (have := await _soldiers_of(port)) != want:
            await trio.sleep(0.2)
    return have


async def _walker(port: int) -> Client:
    """Client ``alpha`` with soldier ``ODD`` walking (on shard 1)."""
    c = await Client.open(port, "ig", client_id="alpha")
    await c.expect(Ready)
    await c.send(CreateSoldier(1, "DI.fig", "AK_47.fig", ODD))
    assert (await c.expect(SoldierCreated)).index == ODD
    await c.requests(index=[ODD], velocity=WALK)
    return c


async def test_a_removal_sent_before_a_shard_listened_reaches_it() -> None:
    with cluster() as c:
        c.shard(0)
        await _moving(c.front.port, [0], frames=1)  # shard 0 heard
        op = await Client.open(c.front.port, "op", role="operator")
        await op.expect(Ready)
        await op.send(RemoveSoldier(3))  # a start-up soldier of shard 1, which does not listen yet
        await op.aclose()
        shard1 = c.shard(1)  # its start-up script makes soldier 3 again
        await _moving(c.front.port, [1], frames=1)  # shard 1 heard: the front-end synced it
        assert await _until_soldiers(shard1.port, [1, 5, 7, 9]) == [1, 5, 7, 9]


async def test_a_front_end_started_while_a_shard_is_failed_over_routes_to_the_stand_in() -> None:
    with cluster() as c:
        c.shard(0)
        c.shard(1)
        alpha = await _walker(c.front.port)
        await _moving(c.front.port, [ODD], frames=2)  # shard 1 heard (else no fail-over: under load, flaky)
        await alpha.requests(index=[ODD], velocity=(0.0, 0.0, 0.0))  # it stands
        c.kill(c.shards[1])
        assert await _until_soldiers(c.shards[0].port, [*range(10), ODD]) == [*range(10), ODD]
        await alpha.aclose()
        late = c.restart_front()  # it never hears shard 1: shard 0 animates its soldiers
        assert await _until_soldiers(late.port, [*range(10), ODD]) == [*range(10), ODD]
        alpha = await Client.open(late.port, "ig", client_id="alpha")
        await alpha.expect(Ready)
        await alpha.requests(index=[ODD], velocity=WALK)  # to shard 0, the stand-in
        await _moving(late.port, [ODD], frames=10)
        back = c.shard(1)  # takes every one of its soldiers back from the stand-in, walking on
        assert await _until_soldiers(back.port, [1, 3, 5, 7, 9, ODD]) == [1, 3, 5, 7, 9, ODD]
        assert await _until_soldiers(c.shards[0].port, [0, 2, 4, 6, 8]) == [0, 2, 4, 6, 8]
        await _moving(late.port, [ODD], frames=10)
        await alpha.aclose()


async def test_a_late_front_ends_fail_over_hands_on_the_last_requests_it_learned() -> None:
    with cluster() as c:
        c.shard(0)
        c.shard(1)
        alpha = await _walker(c.front.port)
        await _moving(c.front.port, [ODD], frames=3)
        late = c.restart_front()  # learns ODD walking from shard 1, with its last request
        assert await _until_soldiers(late.port, [*range(10), ODD]) == [*range(10), ODD]
        await _moving(late.port, [ODD], frames=3)
        with contextlib.suppress(trio.BrokenResourceError, trio.ClosedResourceError):
            await alpha.aclose()
        c.kill(c.shards[1])
        assert await _until_soldiers(c.shards[0].port, [*range(10), ODD]) == [*range(10), ODD]
        obs = await Client.open(late.port, "obs", role="observer")
        await obs.expect(Ready)
        await obs.send(Subscribe((ODD,)))
        seen = 0
        with trio.fail_after(60):  # a deadline, not a timing: a soldier standing is sent once
            while seen < 10:
                seen += ODD in (await obs.expect(JointUpdates)).indices.tolist()
        await obs.aclose()


async def test_a_hung_shard_that_resumes_lets_go_of_a_soldier_removed_while_it_was_away(
    autojump_clock: trio.abc.Clock,
) -> None:
    """In one process (test_fabric_inprocess's fabric): shard 1 hangs, the walker goes to shard 0 and is
    removed there; shard 1, which still has it, resumes: the sync that takes its soldiers back removes it."""
    async with inprocess.cluster() as (front, node, shards, fabrics):
        c = await inprocess.walker(front, ODD)
        await inprocess.moving(c, ODD, 3)
        fabrics[1].closed = True  # it publishes nothing more, yet its presence stays
        with trio.fail_after(30):
            while ODD not in inprocess.live(shards[0]):
                await trio.sleep(0.1)
        await c.send(RemoveSoldier(ODD))
        await c.expect(SoldierRemoved)
        fabrics[1].closed = False  # it resumes, with the walker it had
        with trio.fail_after(30):
            while node.route != [0, 1] or ODD in inprocess.live(shards[1]):
                await trio.sleep(0.1)
        assert ODD not in inprocess.live(shards[0])
        await c.aclose()


async def _none_of_the_old_soldiers_codes(
    c: Client, node: inprocess.FrontNode, put: Handler, held: list[bytes]
) -> None:
    """While shard 1 has not heard the removal and re-creation of ``ODD`` (``node``'s messages to it are
    ``held``), ``c`` gets shard 1's batches (``ODD - 2`` walks) and no row of ``ODD``; then they go."""
    updates = [e for e in await c.drain(2.0) if isinstance(e, JointUpdates)]
    assert [u for u in updates if ODD - 2 in u.indices.tolist()], "shard 1's batches come"
    assert not [u.tick for u in updates if ODD in u.indices.tolist()]
    node._puts[1] = put
    for data in held:
        put(data)


async def test_an_index_removed_and_created_again_shows_none_of_the_old_soldiers_codes(
    autojump_clock: trio.abc.Clock,
) -> None:
    """In one process: the walker is removed and a soldier created again at its index while shard 1 has
    not heard either (its requests held): the shard's batches still carry the old walker (and another, whose
    updates go on), and the client gets none of the old walker's codes for the new soldier (on main it got
    them every tick: [7, 8, 9, ...]); once the shard hears, the new soldier's pose arrives."""
    async with inprocess.cluster() as (front, node, shards, _):
        c = await inprocess.walker(front, ODD)
        await c.requests(index=[ODD - 2], velocity=WALK)  # a start-up soldier of shard 1 walks too
        await inprocess.moving(c, ODD, 3)
        held: list[bytes] = []
        put, node._puts[1] = node._puts[1], held.append  # the fabric is slow to shard 1
        await c.send(RemoveSoldier(ODD))
        await c.expect(SoldierRemoved)
        await c.send(CreateSoldier(2, "DI.fig", "AK_47.fig", ODD))
        assert (await c.expect(SoldierCreated)).index == ODD
        await _none_of_the_old_soldiers_codes(c, node, put, held)
        with trio.fail_after(30):
            while ODD not in inprocess.live(shards[1]):
                await trio.sleep(0.1)
        await c.expect(JointUpdates, lambda u: ODD in u.indices.tolist(), timeout=30)
        await c.aclose()


async def test_a_shards_walker_walks_on_when_its_stand_in_dies_too(autojump_clock: trio.abc.Clock) -> None:
    """In one process, three shards: shard 2 dies and its walker goes on in shard 0, which then dies too:
    the walker goes on in shard 1, the one left (on main shard 2 stayed routed to the dead shard 0)."""
    async with inprocess.cluster(shards_n=3) as (front, node, shards, fabrics):
        c = await inprocess.walker(front, ODD)  # 11: home shard 2
        await inprocess.moving(c, ODD, 3)
        fabrics[2].close()
        with trio.fail_after(30):
            while ODD not in inprocess.live(shards[0]):
                await trio.sleep(0.1)
        assert node.route == [0, 1, 0]
        fabrics[0].close()
        with trio.fail_after(30):
            while ODD not in inprocess.live(shards[1]):
                await trio.sleep(0.1)
        assert node.route == [1, 1, 1]
        await inprocess.moving(c, ODD, 3)  # walking, from its last request
        await c.aclose()


async def test_a_hung_stand_in_that_resumes_lets_go_of_the_soldiers_it_stood_in_for(
    autojump_clock: trio.abc.Clock,
) -> None:
    """Shard 2 dies and its walker goes on in shard 0, which hangs: the walker goes to shard 1; shard 0
    resumes with the walker it had, and the sync that gives it its own soldiers back removes the walker."""
    async with inprocess.cluster(shards_n=3) as (front, node, shards, fabrics):
        c = await inprocess.walker(front, ODD)
        await inprocess.moving(c, ODD, 3)
        fabrics[2].close()
        with trio.fail_after(30):
            while ODD not in inprocess.live(shards[0]):
                await trio.sleep(0.1)
        fabrics[0].closed = True  # it publishes nothing more, yet its presence stays
        with trio.fail_after(30):
            while ODD not in inprocess.live(shards[1]):
                await trio.sleep(0.1)
        fabrics[0].closed = False
        with trio.fail_after(30):
            while node.route != [0, 1, 1] or ODD in inprocess.live(shards[0]):
                await trio.sleep(0.1)
        await inprocess.moving(c, ODD, 3)
        await c.aclose()


GRACE = 12.0  # the default orphan_grace: a gone client id's soldiers wait this long for it


async def _client(front: inprocess.TtesServer, client_id: str = "alpha") -> Client:
    c = await Client.open(front.addresses[0][1], "ig", client_id=client_id)
    await c.expect(Ready)
    return c


async def _made(c: Client, rid: int = 1) -> int:
    """A soldier created through ``c``'s front-end (the lowest free index of that front-end's share)."""
    await c.send(CreateSoldier(rid, "DI.fig", "AK_47.fig", None))
    return int((await c.expect(SoldierCreated)).index)


def _everywhere(c: inprocess.Fronts, index: int) -> list[bool]:
    """Whether soldier ``index`` lives in each front-end's books and in its shard."""
    return [index in inprocess.live(s) for s in (*c.servers, c.shards[index % len(c.shards)])]


async def test_a_client_id_still_connected_to_another_front_end_keeps_its_soldiers(
    autojump_clock: trio.abc.Clock,
) -> None:
    """Client id alpha is connected to both front-ends and leaves the one it created its soldier through:
    the soldier stays past the grace (on main each front-end counted only its own connections, and the
    soldier went 12 s later), and goes once alpha has left the other front-end too, after its grace."""
    async with inprocess.fronts() as c:
        here, there = await _client(c.servers[0]), await _client(c.servers[1])
        index = await _made(here)
        await trio.sleep(1)
        assert _everywhere(c, index) == [True, True, True]
        await here.aclose()
        await trio.sleep(3 * GRACE)
        assert _everywhere(c, index) == [True, True, True]
        await there.aclose()
        await trio.sleep(GRACE / 2)
        assert _everywhere(c, index) == [True, True, True]  # its grace runs
        await trio.sleep(GRACE)
        assert _everywhere(c, index) == [False, False, False]


async def test_a_client_id_that_comes_back_through_another_front_end_keeps_its_soldiers(
    autojump_clock: trio.abc.Clock,
) -> None:
    """Alpha leaves front-end 0 and reconnects through front-end 1 within the grace: its soldier stays; when
    front-end 1 goes from the fabric (its process died), alpha's connection went with it: the grace runs."""
    async with inprocess.fronts() as c:
        here = await _client(c.servers[0])
        index = await _made(here)
        await here.aclose()
        await trio.sleep(GRACE / 2)
        there = await _client(c.servers[1])
        await trio.sleep(3 * GRACE)
        assert _everywhere(c, index) == [True, True, True]
        c.fabrics[1].close()
        await trio.sleep(GRACE / 2)
        assert _everywhere(c, index)[::2] == [True, True]
        await trio.sleep(GRACE)
        assert _everywhere(c, index)[::2] == [False, False]  # front-end 0 removed it, in the shard too
        await there.aclose()


async def test_the_orphans_of_a_front_end_gone_are_removed_by_another(autojump_clock: trio.abc.Clock) -> None:
    """Alpha's soldier was made through front-end 1, which dies with alpha's connection: front-end 0 removes
    the soldier after the grace (on main none did: the shard animated it for good)."""
    async with inprocess.fronts() as c:
        there = await _client(c.servers[1])
        index = await _made(there)
        assert index // 4096 % 2 == 1  # front-end 1's share
        await trio.sleep(1)
        assert _everywhere(c, index) == [True, True, True]
        c.fabrics[1].close()
        await trio.sleep(GRACE / 2)
        assert _everywhere(c, index)[::2] == [True, True]
        await trio.sleep(GRACE)
        assert _everywhere(c, index)[::2] == [False, False]
        await there.aclose()


async def test_a_front_end_started_while_a_shard_without_soldiers_is_failed_over_routes_to_the_stand_in(
    autojump_clock: trio.abc.Clock,
) -> None:
    """Shard 1's soldiers are removed, shard 1 dies and is failed over to shard 0 with none; the front-end
    dies and a new one starts: shard 0's answer names no soldier of shard 1, yet the new front-end sends a
    soldier created at shard 1's index to shard 0, which animates it (on main it went to shard 1's topic,
    which nobody hears: the soldier never moved)."""
    async with inprocess.fronts(fronts_n=1) as c:
        op = await Client.open(c.servers[0].addresses[0][1], "op", role="operator")
        await op.expect(Ready)
        for i in (1, 3, 5, 7, 9):
            await op.send(RemoveSoldier(i))
            await op.expect(SoldierRemoved)
        await op.aclose()
        with trio.fail_after(30):
            while inprocess.live(c.shards[1]):
                await trio.sleep(0.1)
        c.shard_fabrics[1].close()
        with trio.fail_after(30):
            while c.nodes[0].route != [0, 0]:
                await trio.sleep(0.1)
        c.fabrics[0].close()  # the front-end dies
        c.servers[0].shutdown()
        late = await c.start_front(inprocess.Sharding(0, 1))
        with trio.fail_after(30):  # shard 0 answered its books
            while c.nodes[1].heard_at[0] < 0 or c.nodes[1]._asked:
                await trio.sleep(0.1)
        walker = await inprocess.walker(late, ODD)
        await inprocess.moving(walker, ODD, 3)
        assert ODD in inprocess.live(c.shards[0]) and c.nodes[1].route == [0, 0]
        assert inprocess.live(late) == [0, 2, 4, 6, 8, ODD]  # and none of shard 1's removed start-up soldiers
        await walker.aclose()


async def test_a_front_end_that_mirrors_an_index_created_again_shows_none_of_the_old_soldiers_codes(
    autojump_clock: trio.abc.Clock,
) -> None:
    """Two front-ends: the walker is removed and created again at its index through front-end 0 while shard 1
    has not heard either; an observer of front-end 1, which only mirrors both, gets none of the old walker's
    codes for the new soldier (on main it had no fence for them and got them every tick), and the new
    soldier's pose once the shard hears."""
    async with inprocess.fronts() as c:
        made = await inprocess.walker(c.servers[0], ODD)
        await made.requests(index=[ODD - 2], velocity=WALK)  # a start-up soldier of shard 1 walks too
        obs = await Client.open(c.servers[1].addresses[0][1], "obs", role="observer")
        await obs.expect(Ready)
        await obs.send(Subscribe((ODD - 2, ODD)))
        await inprocess.moving(obs, ODD, 3)
        held: list[bytes] = []
        node = c.nodes[0]
        put, node._puts[1] = node._puts[1], held.append  # the fabric is slow from front-end 0 to shard 1
        await made.send(RemoveSoldier(ODD))
        await made.expect(SoldierRemoved)
        await obs.expect(SoldierRemoved)
        await made.send(CreateSoldier(2, "DI.fig", "AK_47.fig", ODD))
        assert (await made.expect(SoldierCreated)).index == ODD
        with trio.fail_after(30):  # front-end 1 mirrors the creation
            while ODD not in inprocess.live(c.servers[1]):
                await trio.sleep(0.01)
        await _none_of_the_old_soldiers_codes(obs, node, put, held)
        await obs.expect(JointUpdates, lambda u: ODD in u.indices.tolist(), timeout=30)
        await made.aclose()
        await obs.aclose()


async def test_the_settings_an_operator_changes_through_a_front_end_reach_the_shards(
    autojump_clock: trio.abc.Clock,
) -> None:
    """An operator's JCL that changes server-wide settings, and the front-end's own (``--throttle``,
    ``--report-interval``), reach the shards that animate the soldiers (on main only the front-end's world,
    which animates none, changed); a shard heard later gets them with its sync."""
    async with inprocess.fronts(fronts_n=1) as c:
        op = await Client.open(c.servers[0].addresses[0][1], "op", role="operator")
        await op.expect(Ready)
        await op.jcl("set_ttes_heading_offset(10, 20, 30);", 1)
        await op.jcl("set_ttes_blend_time(0.5);", 2)
        c.servers[0].world.set_throttle(0.25)
        c.servers[0].world.set_report_interval(7.0)
        await trio.sleep(1)
        for shard in c.shards:
            s = shard.world.settings
            assert (s.heading_offsets, s.blend_time, s.throttle) == ((10.0, 20.0, 30.0), 0.5, 0.25)
            assert shard.world.report_interval == 7.0 and s.tick_period == 1 / 30
        c.shards[0].world.soldiers.configure(throttle=0.5)  # (its sync says the front-end's again)
        c.shard_fabrics[1].close()  # shard 1 dies: shard 0 stands in for it, synced
        with trio.fail_after(30):
            while c.nodes[0].route != [0, 0]:
                await trio.sleep(0.1)
        await trio.sleep(1)
        assert c.shards[0].world.settings.throttle == 0.25
        await op.aclose()


async def test_the_settings_changed_through_one_front_end_reach_the_other_and_one_that_starts_later(
    autojump_clock: trio.abc.Clock,
) -> None:
    """An operator changes the blend time through front-end 0: it reaches front-end 1 (its syncs, a
    fail-over's, would hand the shards its old settings otherwise). Front-end 1 restarts (a front-end that
    starts later): its first syncs handed the shards its start-up settings on main, undoing the operator's
    change (blend time 0.5 -> 0.2 in both shards). The change has a stamp newer than any start-up settings:
    the shards keep it, and the new front-end learns it from their answers."""
    async with inprocess.fronts() as c:
        op = await Client.open(c.servers[0].addresses[0][1], "op", role="operator")
        await op.expect(Ready)
        await op.jcl("set_ttes_blend_time(0.5);", 1)
        await trio.sleep(1)
        assert [s.world.settings.blend_time for s in (*c.servers, *c.shards)] == [0.5] * 4
        c.fabrics[1].close()  # front-end 1 dies and starts again
        c.servers[1].shutdown()
        late = await c.start_front(inprocess.Sharding(1, 2))
        with trio.fail_after(30):  # both shards answered its books
            while c.nodes[2].heard_at[0] < 0 or c.nodes[2].heard_at[1] < 0 or c.nodes[2]._asked:
                await trio.sleep(0.1)
        await trio.sleep(1)
        assert [s.world.settings.blend_time for s in (c.servers[0], late, *c.shards)] == [0.5] * 4
        await op.jcl("set_ttes_blend_time(0.3);", 2)  # a later change still reaches every one
        await trio.sleep(1)
        assert [s.world.settings.blend_time for s in (c.servers[0], late, *c.shards)] == [0.3] * 4
        await op.aclose()


async def test_a_sync_does_not_remove_a_soldier_created_again_that_its_front_end_has_not_heard_of(
    autojump_clock: trio.abc.Clock,
) -> None:
    """Front-end 1 removes the walker; front-end 0 creates a soldier again at its index, and shard 1 (which
    has it) restarts before front-end 1 hears of the creation: front-end 1's sync says the index was removed,
    yet the shard keeps the new soldier (on main it removed it: every front-end showed a soldier that no
    shard animated)."""
    async with inprocess.fronts() as c:
        made = await inprocess.walker(c.servers[0], ODD)
        op = await Client.open(c.servers[1].addresses[0][1], "op", role="operator")
        await op.expect(Ready)
        with trio.fail_after(30):
            while ODD not in inprocess.live(c.servers[1]):
                await trio.sleep(0.01)
        await op.send(RemoveSoldier(ODD))
        await op.expect(SoldierRemoved)
        with trio.fail_after(30):
            while ODD in inprocess.live(c.shards[1]) or ODD in inprocess.live(c.servers[0]):
                await trio.sleep(0.01)
        held: list[bytes] = []
        told = c.nodes[0]._books
        assert told is not None
        c.nodes[0]._books = held.append  # front-end 1 hears front-end 0 late
        await made.send(CreateSoldier(2, "DI.fig", "AK_47.fig", ODD))
        assert (await made.expect(SoldierCreated)).index == ODD
        with trio.fail_after(30):
            while ODD not in inprocess.live(c.shards[1]):
                await trio.sleep(0.01)
        await trio.sleep(1)
        c.shard_nodes[1].seq = 0  # shard 1 restarts (its count goes back): both front-ends sync it
        await trio.sleep(1)
        c.nodes[0]._books = told
        for data in held:
            told(data)
        await made.requests(index=[ODD], velocity=WALK)
        await inprocess.moving(made, ODD, 3)
        assert ODD in inprocess.live(c.shards[1]) and ODD in inprocess.live(c.servers[1])
        await made.aclose()
        await op.aclose()


async def test_a_restarted_shard_that_missed_its_sync_gets_it_again(autojump_clock: trio.abc.Clock) -> None:
    """Shard 1 restarts without the walker, and its first pulses reach the front-ends before its
    subscription to its requests does (Zenoh drops the sync they send it). On main no front-end knew: the
    books kept the walker, no shard animated it (its key pulses lack it, but a soldier a front-end was
    told of is not the shards' to judge). Each front-end asks for the books with its sync, and asks again
    with the sync until the shard answers: the walker is back, walking."""
    async with inprocess.fronts() as c:
        made = await inprocess.walker(c.servers[0], ODD)
        await inprocess.moving(made, ODD, 3)
        c.shard_fabrics[1].deaf = ("ttes/requests",)
        c.shards[1].world.remove_soldier(ODD, "a restart")  # its start-up script's soldiers alone
        c.shard_nodes[1].seq = 0  # its count goes back: both front-ends sync it
        await trio.sleep(3)
        assert ODD not in inprocess.live(c.shards[1])
        c.shard_fabrics[1].deaf = ()
        await made.requests(index=[ODD], velocity=WALK)
        await inprocess.moving(made, ODD, 3)
        assert ODD in inprocess.live(c.shards[1]) and ODD in inprocess.live(c.servers[1])
        await made.aclose()


async def test_a_restarted_front_ends_creation_is_not_removed_by_an_older_removal(
    autojump_clock: trio.abc.Clock,
) -> None:
    """Front-end 0 creates the walker and removes it (generation 2 of its index), dies and starts again (its
    generations start again too), and creates the index anew; front-end 1 has not heard of that creation
    when shard 1 restarts, and its sync (after the new front-end's) says the index was removed at generation
    2: on main the shard removed the new soldier (generation 1), which every front-end kept showing. A
    creation's generation is past the wall clock's ms as well, newer than any removal made before it."""
    async with inprocess.fronts() as c:
        made = await inprocess.walker(c.servers[0], ODD)
        await made.send(RemoveSoldier(ODD))
        await made.expect(SoldierRemoved)
        await made.aclose()
        with trio.fail_after(30):
            while ODD in inprocess.live(c.shards[1]) or ODD in inprocess.live(c.servers[1]):
                await trio.sleep(0.01)
        c.fabrics[0].close()  # front-end 0 dies and starts again
        c.servers[0].shutdown()
        late = await c.start_front(inprocess.Sharding(0, 2))
        with trio.fail_after(30):  # both shards answered its books
            while min(c.nodes[2].heard_at) < 0 or c.nodes[2]._asked:
                await trio.sleep(0.1)
        held: list[bytes] = []
        told = c.nodes[2]._books
        assert told is not None
        c.nodes[2]._books = held.append  # front-end 1 hears the new front-end 0 late
        again = await inprocess.walker(late, ODD)
        with trio.fail_after(30):
            while ODD not in inprocess.live(c.shards[1]):
                await trio.sleep(0.01)
        slow: list[bytes] = []
        put, c.nodes[1]._puts[1] = c.nodes[1]._puts[1], slow.append  # front-end 1's sync comes last
        c.shard_nodes[1].seq = 0  # shard 1 restarts (its count goes back): both front-ends sync it
        await trio.sleep(1)
        c.nodes[1]._puts[1] = put
        for data in slow:
            put(data)
        await trio.sleep(1)
        c.nodes[2]._books = told
        for data in held:
            told(data)
        with trio.fail_after(30):  # front-end 1 mirrors the creation
            while ODD not in inprocess.live(c.servers[1]):
                await trio.sleep(0.01)
        await again.drain(1.0)
        await inprocess.moving(again, ODD, 3)
        assert ODD in inprocess.live(c.shards[1])
        await again.aclose()


async def test_a_front_end_fails_a_shard_over_when_another_does(autojump_clock: trio.abc.Clock) -> None:
    """Shard 1 hangs; front-end 0 fails it over after its 5 s, front-end 1 (whose loop heard its last pulse
    later: here a longer limit) has not yet: it follows front-end 0's fail-over, so a request for the standing
    walker sent through front-end 1 goes to the stand-in and the walker walks (on main it went to the hung
    shard until front-end 1's own limit: the walker stood)."""
    async with inprocess.fronts() as c:
        c.nodes[1].hung_s = 60.0
        made = await inprocess.walker(c.servers[0], ODD)
        await made.requests(index=[ODD], velocity=(0.0, 0.0, 0.0))  # it stands
        there = await _client(c.servers[1])
        await there.send(Subscribe((ODD,)))
        await trio.sleep(1)
        c.shard_fabrics[1].closed = True  # it publishes nothing more, yet its presence stays
        with trio.fail_after(30):
            while ODD not in inprocess.live(c.shards[0]):
                await trio.sleep(0.1)
        await there.drain(3.0)  # it stands in shard 0 (a standing soldier is sent once)
        await there.requests(index=[ODD], velocity=WALK)
        await inprocess.moving(there, ODD, 10)
        assert c.nodes[1].route == [0, 0]
        await made.aclose()
        await there.aclose()


async def _split(c: inprocess.Fronts) -> tuple[Client, Client]:
    """The standing walker, made through front-end 0, and a client of front-end 1 that watches it; then a
    split fabric: front-end 0 hears shard 1 no more, front-end 1 does."""
    made = await inprocess.walker(c.servers[0], ODD)
    await made.requests(index=[ODD], velocity=(0.0, 0.0, 0.0))
    there = await _client(c.servers[1])
    await there.send(Subscribe((ODD,)))
    await trio.sleep(1)
    c.fabrics[0].deaf = ("ttes/poses/1",)
    return made, there


async def test_a_front_end_that_still_hears_a_shard_another_failed_over_routes_to_the_stand_in(
    autojump_clock: trio.abc.Clock,
) -> None:
    """A split fabric: front-end 0 no longer hears shard 1 and fails it over to shard 0; front-end 1 still
    hears shard 1. On main front-end 1 kept routing to shard 1, so a walk request through it never reached
    the walker that front-end 0's clients see (shard 0's): it stood. Now front-end 1 follows the fail-over
    and keeps it while it stands (it merges no rows of shard 1's soldiers from shard 1), until front-end 0
    hears shard 1 again and takes the soldiers back: then both route to shard 1."""
    async with inprocess.fronts() as c:
        made, there = await _split(c)
        with trio.fail_after(30):
            while ODD not in inprocess.live(c.shards[0]):
                await trio.sleep(0.1)
        await trio.sleep(1)
        assert c.nodes[0].route == [0, 0]
        await made.drain(1.0)
        await there.requests(index=[ODD], velocity=WALK)
        await inprocess.moving(made, ODD, 10)  # shard 0's walker walks, as front-end 0's clients see
        assert c.nodes[1].route == [0, 0]
        c.fabrics[0].deaf = ()  # the fabric is whole again: front-end 0 takes shard 1's soldiers back
        with trio.fail_after(30):
            while ODD in inprocess.live(c.shards[0]):
                await trio.sleep(0.1)
        await trio.sleep(1)
        assert c.nodes[0].route == [0, 1] and c.nodes[1].route == [0, 1]
        await there.drain(1.0)
        await inprocess.moving(there, ODD, 10)  # it walks on in shard 1
        await made.aclose()
        await there.aclose()


async def test_a_fail_over_followed_ends_when_the_front_end_that_made_it_is_gone(
    autojump_clock: trio.abc.Clock,
) -> None:
    """Front-end 0, deaf to shard 1, fails it over and dies before it hears shard 1 again: front-end 1,
    which followed, takes shard 1's soldiers back itself (nobody else would end that fail-over)."""
    async with inprocess.fronts() as c:
        made, there = await _split(c)
        with trio.fail_after(30):
            while c.nodes[1].route != [0, 0]:
                await trio.sleep(0.1)
        c.fabrics[0].close()
        with trio.fail_after(30):
            while c.nodes[1].route != [0, 1] or ODD in inprocess.live(c.shards[0]):
                await trio.sleep(0.1)
        await there.requests(index=[ODD], velocity=WALK)  # to shard 1
        await inprocess.moving(there, ODD, 10)
        await made.aclose()
        await there.aclose()


async def test_an_anonymous_clients_soldiers_go_after_its_grace_whatever_the_other_front_ends_serve(
    autojump_clock: trio.abc.Clock,
) -> None:
    """A client without an id gets its connection's (``~anon-``, its server's mark and the session's
    number): a connection of that id told by another front-end keeps nothing alive here."""
    async with inprocess.fronts() as c:
        here = await _client(c.servers[0], "")
        assert here.accept is not None and here.accept.client_id.startswith("~anon-")
        index = await _made(here)
        # front-end 1's process has a session of the same number (here, in one process, they are numbered
        # apart): it tells its connection (a front-end of this code does not), which counts for nothing here
        told = {**req.clients({here.accept.client_id: 1}), "front": 1}
        c.nodes[0].mirror(req.pack([told]))
        await here.aclose()
        await trio.sleep(GRACE * 1.5)
        assert _everywhere(c, index) == [False, False, False]


async def test_anonymous_clients_of_two_front_end_processes_are_two_clients(
    autojump_clock: trio.abc.Clock, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Each process numbers its sessions from 1 (a restarted front-end too): on main the first anonymous
    client of front-end 0 and the first of front-end 1 were both ``~anon-1``, one owner in every front-end's
    books, so the client of front-end 1 could remove (and drive) the soldier the other made. Their ids differ
    now, and it may not."""
    async with inprocess.fronts() as c:
        first = Session._ids
        here = await _client(c.servers[0], "")
        index = await _made(here)
        monkeypatch.setattr(Session, "_ids", first)  # front-end 1's process numbers its sessions from 1 too
        there = await _client(c.servers[1], "")
        assert here.accept is not None and there.accept is not None
        assert here.accept.client_id.startswith("~anon-") and there.accept.client_id.startswith("~anon-")
        assert here.accept.client_id != there.accept.client_id
        with trio.fail_after(30):
            while index not in inprocess.live(c.servers[1]):
                await trio.sleep(0.01)
        await there.send(RemoveSoldier(index))
        await there.expect(Error)
        await trio.sleep(1)
        assert _everywhere(c, index) == [True, True, True]
        await here.aclose()
        await there.aclose()


@pytest.mark.parametrize("fabric", ["zenoh", "dds"])
async def test_two_front_end_processes_keep_a_client_ids_soldiers_while_it_is_connected_to_either(
    tmp_path: Path, fabric: str
) -> None:
    """As real processes on both engines (each front-end announces itself and tells the other its
    connections), with a grace of 1 s: alpha leaves the front-end its soldier was made through and stays on
    the other; the soldier stays for 3 graces, and goes once alpha has left both."""
    if fabric == "dds":
        pytest.importorskip("cyclonedds")
    config = tmp_path / "grace.toml"
    config.write_text("orphan_grace = 1.0\n", encoding="utf-8")
    with two_fronts(fabric, front_args=("--config", str(config))) as (fronts, _):
        here = await Client.open(fronts[0].port, "ig", client_id="alpha")
        await here.expect(Ready)
        there = await Client.open(fronts[1].port, "ig", client_id="alpha")
        await there.expect(Ready)
        index = await _made(here)
        assert await _until_soldiers(fronts[1].port, [*range(10), index]) == [*range(10), index]
        await here.aclose()
        await trio.sleep(3.0)  # (real time: three graces)
        assert await _soldiers_of(fronts[0].port) == [*range(10), index]
        await there.aclose()
        assert await _until_soldiers(fronts[0].port, [*range(10)]) == [*range(10)]
        assert await _until_soldiers(fronts[1].port, [*range(10)]) == [*range(10)]
