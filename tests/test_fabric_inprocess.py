"""Issue 21 in one process: a front-end and two shards (``TtesServer`` each) over an in-memory fabric, on
trio's autojump clock — the routing, the sync of a late shard and the failover, without processes."""

from __future__ import annotations

import contextlib
from collections import defaultdict
from collections.abc import AsyncIterator
from dataclasses import dataclass, field

import msgpack
import numpy as np
import trio
from test_server_support import Client, make_server

from protocol.entity import ENTITY_REQUEST_DTYPE
from protocol.events import (
    CreateSoldier,
    Error,
    FigureMsg,
    JointUpdates,
    Ready,
    RequestFigure,
    SoldierCreated,
    SoldierRemoved,
    Subscribe,
    UpdateTableMsg,
)
from server.app import TtesServer
from server.fabric import BLOCK, Handler, Kind, Presence, Unsubscribe
from server.fabric import requests as req
from server.fabric.batch import PULSE, Batch
from server.fabric.nodes import ASK_AGAIN_S, KEY_EVERY, FrontNode, Sharding, ShardNode

WALK = (0.0, 1.4, 0.0)
RUN = (0.0, 3.5, 0.0)


@dataclass
class Bus:
    """One process's in-memory fabric: topics and their handlers, presences and their watchers."""

    topics: dict[str, list[Handler]] = field(default_factory=lambda: defaultdict(list))
    present: set[str] = field(default_factory=set)
    watchers: dict[str, list[Presence]] = field(default_factory=lambda: defaultdict(list))
    matchers: dict[str, list[Presence]] = field(default_factory=lambda: defaultdict(list))  # publishers'

    def matched(self, topic: str) -> None:
        """A topic gained its first subscriber or lost its last: its publishers' matching listeners hear."""
        for on_match in self.matchers[topic]:
            on_match(bool(self.topics[topic]))


class MemoryFabric:
    """A node on a :class:`Bus`: a message reaches the handlers at once."""

    engine = "memory"

    def __init__(self, bus: Bus) -> None:
        self.bus = bus
        self.mine: list[tuple[str, Handler]] = []
        self.announced: list[str] = []
        self.closed = False
        self.deaf: tuple[str, ...] = ()  # topics (prefixes) it no longer hears: a split fabric

    def publisher(self, topic: str, kind: Kind, on_match: Presence | None = None) -> Handler:
        def put(data: bytes) -> None:
            if not self.closed:
                for handler in list(self.bus.topics[topic]):
                    handler(data)

        if on_match is not None:
            self.bus.matchers[topic].append(on_match)
            on_match(bool(self.bus.topics[topic]))
        return put

    def subscribe(self, topic: str, kind: Kind, on_message: Handler) -> Unsubscribe:
        def heard(data: bytes) -> None:
            if not topic.startswith(self.deaf):
                on_message(data)

        self.bus.topics[topic].append(heard)
        self.mine.append((topic, heard))
        if len(self.bus.topics[topic]) == 1:
            self.bus.matched(topic)

        def unsubscribe() -> None:
            self.bus.topics[topic].remove(heard)
            self.mine.remove((topic, heard))
            if not self.bus.topics[topic]:
                self.bus.matched(topic)

        return unsubscribe

    def announce(self, key: str) -> None:
        self.announced.append(key)
        self.bus.present.add(key)
        for watcher in self.bus.watchers[key]:
            watcher(True)

    def watch(self, key: str, on_change: Presence) -> None:
        self.bus.watchers[key].append(on_change)
        if key in self.bus.present:
            on_change(True)

    def close(self) -> None:
        """A dead process: it neither publishes nor hears anything more, and is gone from the fabric."""
        self.closed = True
        for topic, handler in self.mine:
            self.bus.topics[topic].remove(handler)
            if not self.bus.topics[topic]:
                self.bus.matched(topic)
        for key in self.announced:
            self.bus.present.discard(key)
            for watcher in self.bus.watchers[key]:
                watcher(False)


@dataclass
class Fronts:
    """Several front-ends (``ttes front --front K/M``) and the shards behind them, on one :class:`Bus`."""

    bus: Bus
    nursery: trio.Nursery
    shards_n: int
    block: int
    servers: list[TtesServer] = field(default_factory=list)
    nodes: list[FrontNode] = field(default_factory=list)
    fabrics: list[MemoryFabric] = field(default_factory=list)  # the front-ends'
    shards: list[TtesServer] = field(default_factory=list)
    shard_fabrics: list[MemoryFabric] = field(default_factory=list)
    shard_nodes: list[ShardNode] = field(default_factory=list)

    async def start_front(self, front: Sharding, deaf: tuple[str, ...] = ()) -> TtesServer:
        """Front-end ``front`` (K/M) started now (a late one, or one of several at the start), deaf to the
        topics of ``deaf`` (prefixes) until told otherwise."""
        server, fabric = make_server(), MemoryFabric(self.bus)
        fabric.deaf = deaf
        server.start_world()  # before it joins the fabric, as `ttes front` does: the script's are no relay's
        node = FrontNode(server, fabric, self.shards_n, front=front, block=self.block)
        await self.nursery.start(server.serve)
        node.start(trio.lowlevel.current_trio_token())
        self.servers.append(server)
        self.nodes.append(node)
        self.fabrics.append(fabric)
        return server


@contextlib.asynccontextmanager
async def fronts(
    bus: Bus | None = None,
    key_every: int = KEY_EVERY,
    shards_n: int = 2,
    block: int = BLOCK,
    fronts_n: int = 2,
    deaf: tuple[str, ...] = (),
) -> AsyncIterator[Fronts]:
    """``fronts_n`` front-ends and ``shards_n`` shards; every node deaf to the topics of ``deaf`` at first
    (messages published before a subscription is known to the publisher, which Zenoh drops)."""
    token = trio.lowlevel.current_trio_token()
    async with trio.open_nursery() as nursery:
        c = Fronts(bus or Bus(), nursery, shards_n, block)
        for k in range(fronts_n):
            await c.start_front(Sharding(k, fronts_n), deaf)
        for k in range(shards_n):
            shard, fabric = make_server(), MemoryFabric(c.bus)
            fabric.deaf = deaf
            shard.codes_only()  # as `ttes server --shard` makes it
            shard_node = ShardNode(shard, fabric, Sharding(k, shards_n), key_every=key_every, block=block)
            await nursery.start(shard.serve)
            shard_node.keep_own()
            shard_node.start(token)
            c.shards.append(shard)
            c.shard_fabrics.append(fabric)
            c.shard_nodes.append(shard_node)
        yield c
        for s in (*c.servers, *c.shards):
            s.shutdown()


@contextlib.asynccontextmanager
async def cluster(
    bus: Bus | None = None, key_every: int = KEY_EVERY, shards_n: int = 2, block: int = BLOCK
) -> AsyncIterator[tuple[TtesServer, FrontNode, list[TtesServer], list[MemoryFabric]]]:
    """One front-end and ``shards_n`` shards."""
    async with fronts(bus, key_every, shards_n, block, fronts_n=1) as c:
        yield c.servers[0], c.nodes[0], c.shards, c.shard_fabrics


def live(server: TtesServer) -> list[int]:
    assert server.world.manager is not None
    return server.world.manager.table.live.tolist()


async def walker(front: TtesServer, index: int) -> Client:
    c = await Client.open(front.addresses[0][1], "ig", client_id="alpha")
    await c.expect(Ready)
    await c.send(CreateSoldier(1, "DI.fig", "AK_47.fig", index))
    assert (await c.expect(SoldierCreated)).index == index
    await c.send(Subscribe(tuple(range(12))))
    await c.requests(index=[index], velocity=WALK)
    return c


async def crowd(front: TtesServer, count: int, watched: tuple[int, ...]) -> Client:
    """A client that creates ``count`` soldiers (10 on: the start-up script's are 0..9), watches
    ``watched`` and walks them all (their updates are coming)."""
    c = await Client.open(front.addresses[0][1], "ig", client_id="alpha")
    await c.expect(Ready)
    for rid in range(count):
        await c.send(CreateSoldier(rid + 1, "DI.fig", "AK_47.fig", None))
    made = sorted([(await c.expect(SoldierCreated)).index for _ in range(count)])
    assert made == list(range(10, 10 + count))
    await c.send(Subscribe(watched))
    await c.requests(index=made, velocity=WALK)
    await moving(c, 10, 3)
    return c


async def moving(c: Client, index: int, updates: int = 10) -> list[int]:
    """The ticks of the next ``updates`` joint updates of ``index`` (they keep coming while it walks)."""
    ticks: list[int] = []
    with trio.fail_after(30):  # one that stands still is sent once: it would never come
        while len(ticks) < updates:
            ju = await c.expect(JointUpdates)
            if index in ju.indices:
                ticks.append(ju.tick)
    return ticks


async def test_each_soldier_lives_in_its_shard_and_reaches_the_client(autojump_clock: trio.abc.Clock) -> None:
    async with cluster() as (front, _, shards, _):
        assert live(shards[0]) == [0, 2, 4, 6, 8] and live(shards[1]) == [1, 3, 5, 7, 9]
        c = await walker(front, 11)
        assert 11 in live(shards[1]) and 11 not in live(shards[0])
        ticks = await moving(c, 11)
        assert ticks == sorted(ticks)  # in order (a shard tick and an answer may share the front's tick)
        assert live(front) == [*range(10), 11]  # the front-end keeps the books: one index space
        # its STATUS says who animates (a front-end's own tick time read "tick 0 us mean"); a shard's its tick
        assert "animated by its shards" in front.status_text()[2]
        assert "us mean" not in front.status_text()[2] and "us mean" in shards[0].status_text()[2]


async def test_the_front_end_checks_requests_and_leaves_the_animation_to_the_shard(
    autojump_clock: trio.abc.Clock,
) -> None:
    """The front-end's manager keeps the books but never runs the event path (that cost its core most of
    its time): the walk is the shard's; a bad request is still refused by the front-end itself."""
    async with cluster() as (front, _, shards, _):
        c = await walker(front, 11)
        await moving(c, 11, 3)
        fm, sm = front.world.manager, shards[1].world.manager
        assert fm is not None and sm is not None
        assert sm.soldier_info(11)["speed"] > 1.0 and fm.soldier_info(11)["speed"] == 0.0
        assert fm.stats["requests"] == 1 and fm.stats["events"] == 0
        await c.requests(index=[11], velocity=(0.0, 150.0, 0.0))  # beyond MAX_SPEED
        err = await c.expect(Error)
        assert "speed above" in err.message and sm.soldier_info(11)["speed"] < 2.0


async def test_a_late_front_end_gets_every_soldier_from_a_key_batch(autojump_clock: trio.abc.Clock) -> None:
    """Batches carry only what changed and the shards' periodic keys are off: a front-end that comes late
    gets the soldiers that stand still too, from the key its subscription to their block asks for, as the
    first has them."""
    bus = Bus()
    async with cluster(bus, key_every=10**9) as (front, node, _, _):
        c = await walker(front, 11)
        await moving(c, 11, 3)
        late = make_server()
        late_node = FrontNode(late, MemoryFabric(bus), 2)
        async with trio.open_nursery() as nursery:
            await nursery.start(late.serve)
            late_node.start(trio.lowlevel.current_trio_token())
            assert late.board_ref.on_watch is not None
            late.board_ref.on_watch(np.arange(10))  # as a client's subscription: it hears their block
            with trio.fail_after(30):
                while late_node.keys < 2:  # one per shard
                    await trio.sleep(0.1)
            await trio.sleep(0.1)
            a, b = front.board_ref.board, late.board_ref.board
            assert a is not None and b is not None
            still = list(range(10))  # the start-up script's soldiers, standing
            assert b.valid[still].all() and (a.codes[still] == b.codes[still]).all()
            assert node.keys > 2  # after the first batches of each shard, keys only when a sync asked
            late.shutdown()
        await c.aclose()


async def test_a_silent_shards_walker_walks_on_in_the_survivor(autojump_clock: trio.abc.Clock) -> None:
    async with cluster() as (front, node, shards, fabrics):
        c = await walker(front, 11)
        await moving(c, 11, 3)
        fabrics[1].close()  # shard 1 dies (as far as anyone can hear)
        shards[1].shutdown()
        await moving(c, 11)  # walking on in shard 0, from its last request
        assert node.failovers == 1 and live(shards[0]) == [*range(10), 11]
        assert not [e for e in c.events if isinstance(e, SoldierRemoved)]
        assert front.status_text()[2].endswith("front-end of 2 shards: 0 up, 1 on 0 (gone)")
        await c.aclose()


async def test_a_shard_that_hears_late_gets_its_soldiers_by_sync(autojump_clock: trio.abc.Clock) -> None:
    """A creation and a request sent while no shard listened are not lost: the shard's first batch brings a
    sync, and the soldier walks."""
    bus = Bus()
    token = trio.lowlevel.current_trio_token()
    front = make_server()
    FrontNode(front, MemoryFabric(bus), 1).start(token)
    async with trio.open_nursery() as nursery:
        await nursery.start(front.serve)
        c = await walker(front, 11)  # no shard yet: the creation goes nowhere
        shard = make_server()
        node = ShardNode(shard, MemoryFabric(bus), Sharding(0, 1))
        await nursery.start(shard.serve)
        node.start(token)
        await moving(c, 11)
        assert live(shard) == [*range(10), 11]
        front.shutdown()
        shard.shutdown()


async def test_a_hung_shard_fails_over_after_its_silence(autojump_clock: trio.abc.Clock) -> None:
    """Present on the fabric but sending nothing (a hung process): failed over after ``hung_s``."""
    async with cluster() as (front, node, _, fabrics):
        c = await walker(front, 11)
        await moving(c, 11, 3)
        fabrics[1].closed = True  # it publishes nothing more, yet its presence stays
        hung_at = trio.current_time()
        await moving(c, 11)
        assert node.failovers == 1 and trio.current_time() - hung_at >= node.hung_s
        await c.aclose()


async def test_a_hung_shard_that_resumes_takes_its_soldiers_back_with_their_requests(
    autojump_clock: trio.abc.Clock,
) -> None:
    """Shard 1 hangs, shard 0 stands in and gets the walker's new request (run instead of walk); shard 1
    resumes: the soldier goes home, the stand-in lets go, and the home shard replays the last request."""
    async with cluster() as (front, node, shards, fabrics):
        c = await walker(front, 11)
        await moving(c, 11, 3)
        fabrics[1].closed = True
        with trio.fail_after(30):
            while node.failovers == 0:
                await trio.sleep(0.1)
        await c.requests(index=[11], velocity=RUN)
        await moving(c, 11, 3)
        fabrics[1].closed = False  # it resumes
        with trio.fail_after(30):
            while 11 in live(shards[0]):
                await trio.sleep(0.1)
        assert 11 in live(shards[1]) and node.route == [0, 1]
        m = shards[1].world.manager
        assert m is not None and m.soldier_info(11)["speed"] > 2.0  # the run it was asked for while away
        await moving(c, 11)
        await c.aclose()


async def test_a_client_cannot_tell_the_front_end_from_a_server(autojump_clock: trio.abc.Clock) -> None:
    """Same ACCEPT, update tables, READY soldiers (the start-up script's) and FIGURE as a single server."""
    async with cluster() as (front, _, _, _):
        alone = make_server()
        async with trio.open_nursery() as nursery:
            await nursery.start(alone.serve)
            seen = []
            for server in (front, alone):
                c = await Client.open(server.addresses[0][1], "ig", client_id="alpha")
                tables = [(await c.expect(UpdateTableMsg)).table for _ in server.world.tables]
                ready = await c.expect(Ready)
                await c.send(RequestFigure(5, tables[0].table_id))
                figure = await c.expect(FigureMsg)
                seen.append((c.accept, tables, ready.soldiers, repr(figure)))  # repr: its numpy arrays
                await c.aclose()
            assert seen[0] == seen[1]
            alone.shutdown()


async def test_the_load_tester_names_the_shards_behind_a_front_end(autojump_clock: trio.abc.Clock) -> None:
    """`ttes loadtest` against a front-end: its report names the shards and where each one's soldiers live
    (from the front-end's STATUS), as a run against one server says it was one."""
    from client_stub.loadtest.session import LoadTestConfig, _run

    async with cluster() as (front, _, _, fabrics):
        port = front.addresses[0][1]
        cfg = LoadTestConfig(soldiers=4, clients=2, seconds=1.0, warmup_s=0.5, port=port, mix="moving")
        out = await _run(cfg, "127.0.0.1", port, None, True)
        assert out["delivered_pct"] > 0  # the run was driven through the front-end
        shards = [{"shard": k, "animated_by": k, "present": True} for k in range(2)]
        assert out["server"] == {"role": "front-end", "shards": shards, "status": out["server"]["status"]}
        fabrics[1].close()  # shard 1 dies: the next run says its soldiers live on shard 0
        out = await _run(cfg, "127.0.0.1", port, None, True)
        assert out["server"]["shards"][1] == {"shard": 1, "animated_by": 0, "present": False}


def _pulse(k: int, shards: int, seq: int) -> Batch:
    """Shard ``k``'s tick pulse (no soldiers)."""
    none = np.zeros(0, np.uint32)
    return Batch(
        k, shards, seq, seq, 0.0, none, none.astype(np.uint8), np.zeros((0, 4), np.uint16), False, PULSE
    )


def test_a_sync_asked_again_keeps_the_soldiers_of_a_home_routed_to_the_shard_since() -> None:
    """Shard 0 stood in for home 1, hung, and both homes went to shard 2; back, it gets its own soldiers
    and lets home 1's go (the sync's ``gone``). It does not answer ``books``, and shard 2 fails meanwhile:
    home 1 is routed to shard 0 again. The sync asked again with ``books`` (its answer acknowledges both)
    names home 1 among those shard 0 animates: it must not tell it to let home 1's soldiers go too (they
    would live nowhere: a key pulse that lacks a soldier the books hold is not the shard's to judge)."""
    server = make_server()
    server.start_world()  # the start-up script's soldiers 0-9: home 1's are 1, 4, 7 of 3 shards
    node = FrontNode(server, MemoryFabric(Bus()), 3)
    sent: list[bytes] = []
    node._puts[0] = sent.append
    node.heard_at, node.last_seq = [0.0] * 3, [5] * 3
    node._stood_for[0] = {1}
    node.route = [2, 2, 2]
    node._pulse(_pulse(0, 3, 6), 10.0)  # back from its hang
    syncs = [op for data in sent for op in req.decode(data) if op["op"] == "sync"]
    assert syncs[-1]["homes"] == [0] and syncs[-1]["gone"] == [1, 4, 7]
    node.route[1] = 0  # shard 2's fail-over
    node._pulse(_pulse(0, 3, 7), 13.0)  # no answer after 2 s: asked again, the sync first
    syncs = [op for data in sent for op in req.decode(data) if op["op"] == "sync"]
    assert len(syncs) == 2 and syncs[-1]["homes"] == [0, 1] and syncs[-1]["gone"] == []


def test_a_shard_asked_for_its_books_grows_the_soldiers_not_in_them_by_the_index_space_at_most() -> None:
    """Until a shard asked for its books answers, the soldiers its batches carry that the books lack are
    kept (no index of them is allotted here); asked again until it answers, the ask may stand a long time:
    an index past the index space (a peer's bad batch) is not kept."""
    server = make_server()
    server.start_world()  # soldiers 0-9
    node = FrontNode(server, MemoryFabric(Bus()), 2)
    node._pulse(_pulse(1, 2, 0), 0.0)  # heard for the first time: asked for its books
    assert 1 in node._asked
    n = len(node.known)
    indices = np.array([3, 11, n - 1, n, n + 5, 2**32 - 1], np.uint32)
    codes = np.zeros((len(indices), 4), np.uint16)
    node._heard(Batch(1, 2, 1, 1, 0.0, indices, np.ones(len(indices), np.uint8), codes, False, 0), 0.1)
    assert node._unknown[1] == {11, n - 1}


def test_a_shard_that_restarts_while_asked_for_its_books_is_asked_anew() -> None:
    """Asked again, a shard that has not answered ``books`` waits twice as long each time (up to
    ASK_AGAIN_MAX_S); one that restarts meanwhile gets a new sync and ``books``, asked again after the first
    wait (on main after twice the last: its new sync, as likely lost as the first, waited 8 s here)."""
    server = make_server()
    server.start_world()
    node = FrontNode(server, MemoryFabric(Bus()), 2)
    node._pulse(_pulse(1, 2, 10), 0.0)  # heard for the first time: synced and asked
    node._pulse(_pulse(1, 2, 11), 2.0)  # no answer: asked again
    assert node._asked[1].wait == 2 * ASK_AGAIN_S and node._asked[1].again == 2.0 + 2 * ASK_AGAIN_S
    node._pulse(_pulse(1, 2, 0), 3.0)  # restarted (its count went back)
    assert node._asked[1].wait == ASK_AGAIN_S and node._asked[1].again == 3.0 + ASK_AGAIN_S


def _ops(sent: list[bytes], name: str) -> list[req.Op]:
    return [op for data in sent for op in req.decode(data) if op["op"] == name]


def test_a_sync_sent_again_to_a_shard_that_took_it_replays_nothing_again() -> None:
    """Shard 0 comes back from a fail-over: its soldiers come home with their last requests replayed, and
    ``books``. Its answer is late (it is busy), so the front-end sends both again: the shard takes the sync
    once (on main it replayed every soldier's last request twice, and an ``immediate`` one snapped the
    figure again; a sync that keeps going unanswered did so every 32 s)."""
    server = make_server()
    server.start_world()  # the start-up script's soldiers 0-9: shard 0's are the even ones
    node = FrontNode(server, MemoryFabric(Bus()), 2)
    sent: list[bytes] = []
    node._puts[0] = sent.append
    node.heard_at, node.last_seq = [0.0] * 2, [5] * 2
    node.route = [1, 1]  # shard 0 failed over to shard 1
    row = np.zeros(1, ENTITY_REQUEST_DTYPE)
    row["index"], row["velocity"], row["immediate"] = 2, WALK, 1
    node.last[2], node.has_last[2] = row[0], True
    node._pulse(_pulse(0, 2, 6), 10.0)  # back: its soldiers come home, their last requests replayed
    node._pulse(_pulse(0, 2, 7), 10.0 + ASK_AGAIN_S)  # no answer yet: the sync and books again
    syncs = _ops(sent, "sync")
    assert len(syncs) == 2 and all(s["replay"] for s in syncs)
    shard = make_server()
    shard.start_world()
    shard_node = ShardNode(shard, MemoryFabric(Bus()), Sharding(0, 2))
    shard_node.keep_own()
    replayed: list[list[int]] = []
    apply = shard.world.apply_requests

    def applied(rows: np.ndarray) -> np.ndarray:
        replayed.append(rows["index"].tolist())
        return apply(rows)

    shard.world.apply_requests = applied  # type: ignore[method-assign]
    for data in sent:  # both arrive: the first was late, not lost
        for op in req.decode(data):
            shard_node.handle(op)
    assert replayed == [[2]]
    assert len(_ops(sent, "books")) == 2  # (it answers each: the front-end takes the first)


def test_a_refused_books_answer_ends_the_ask_and_its_sync_goes_no_more() -> None:
    """The answer to ``books`` follows the sync in the same message: refused (``learn`` cannot read it),
    it still says the shard took the sync. On main the ask stood, and the sync and ``books`` went again
    every 32 s for ever."""
    server = make_server()
    server.start_world()
    node = FrontNode(server, MemoryFabric(Bus()), 2)
    sent: list[bytes] = []
    node._puts[1] = sent.append
    node._pulse(_pulse(1, 2, 0), 0.0)  # heard for the first time: synced and asked
    assert len(_ops(sent, "sync")) == 1 and len(_ops(sent, "books")) == 1
    body = msgpack.packb({"soldiers": 5})  # not a list of soldiers
    node.learn(msgpack.packb({"shard": 1, "front": 0, "body": body}))
    for seq in range(1, 200):
        node._pulse(_pulse(1, 2, seq), float(seq))
    assert 1 not in node._asked and 1 not in node._unknown
    assert len(_ops(sent, "sync")) == 1 and len(_ops(sent, "books")) == 1


def test_a_sync_does_not_bring_back_a_soldier_removed_at_a_newer_generation() -> None:
    """Front-end 0 created soldier 11 (generation 5); front-end 1 removed it (6); front-end 0's sync, made
    before it heard of the removal (sent again while the shard had not answered ``books``: 2 to 32 s
    later), names it: the shard does not create it again (on main it did: a soldier nobody's books held,
    animated for ever). A sync made after a newer creation (7) does; a removal of a soldier the shard
    never had (its creation's sync was lost) counts too."""
    shard = make_server()
    shard.start_world()
    node = ShardNode(shard, MemoryFabric(Bus()), Sharding(1, 2))
    node.keep_own()
    soldier = (11, "DI.fig", "AK_47.fig", "alpha")

    def take(*ops: req.Op) -> None:
        for op in req.decode(req.pack(list(ops))):
            node.handle(op)

    def sync(index: int, gen: int) -> req.Op:
        return req.sync([(index, *soldier[1:])], np.zeros(0, ENTITY_REQUEST_DTYPE), gens=[gen])

    take(req.create(*soldier, 5), req.remove(11, 6))
    take(sync(11, 5))
    assert 11 not in live(shard)
    take(sync(11, 7))  # created again through front-end 1, which synced it
    assert 11 in live(shard)
    take(req.remove(13, 9), sync(13, 8))  # removed before its creation's sync came
    assert 13 not in live(shard)
