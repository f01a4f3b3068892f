"""Issue 21: a shard's backlog of fabric requests is bounded and coalesces each soldier's entity requests
(latest wins); events (create, remove, react, sync) are never coalesced, dropped or reordered, among
themselves or against a soldier's requests (``server.fabric.backlog``)."""

from __future__ import annotations

import collections
from typing import Any

import numpy as np
import trio
from hypothesis import given, settings
from hypothesis import strategies as st
from test_fabric_inprocess import Bus, MemoryFabric
from test_server_support import make_server

from protocol.entity import Appearance, make_entity_requests
from server.fabric import requests as req
from server.fabric.backlog import Backlog, activity
from server.fabric.nodes import PENDING_MAX, FrontNode, Sharding, ShardNode
from server.soldier.manager import REQUEST_OK


def row(index: int, speed: float) -> req.Op:
    """One message's requests op as a shard decodes it (``speed``: a marker of which request it is)."""
    return req.decode(
        req.pack([req.requests(make_entity_requests(index=[index], velocity=(speed, 0.0, 0.0)))])
    )[0]


def drain(backlog: Backlog) -> list[req.Op]:
    out = []
    while (op := backlog.take()) is not None:
        out.append(op)
    return out


def test_fifty_requests_then_a_remove_are_one_state_then_the_remove() -> None:
    backlog = Backlog()
    backlog.put([row(7, 1 + 0.01 * k) for k in range(50)] + [req.remove(7)])  # walking, speeds differ
    assert len(backlog) == 2 and backlog.coalesced == 49
    applied, removed = drain(backlog)
    assert applied["op"] == "requests" and applied["rows"]["index"].tolist() == [7]
    assert applied["rows"]["velocity"][0, 0] == np.float32(1 + 0.01 * 49)  # the newest
    assert removed == req.remove(7)


def test_a_request_after_an_event_of_its_soldier_stays_after_it() -> None:
    backlog = Backlog()
    backlog.put([row(7, 1.0), row(8, 1.0), req.react(7, "hit"), row(7, 2.0), row(8, 2.0)])
    ops = drain(backlog)
    assert [op["op"] for op in ops] == ["requests", "react", "requests"]
    first, _, last = ops
    assert dict(
        zip(first["rows"]["index"].tolist(), first["rows"]["velocity"][:, 0].tolist(), strict=True)
    ) == {
        7: 1.0,
        8: 2.0,  # no event of 8's between: its newer row took the older one's place
    }
    assert last["rows"]["index"].tolist() == [7] and last["rows"]["velocity"][0, 0] == 2.0


def test_a_fence_stays_after_its_messages_creation_and_lets_rows_pass() -> None:
    backlog = Backlog()
    backlog.put([row(7, 1.0), req.create(9, "DI.fig", "AK_47.fig", None), req.fence(0, 3)])
    backlog.put([row(7, 2.0), req.remove(9), req.fence(0, 4)])
    ops = drain(backlog)
    assert [op["op"] for op in ops] == ["requests", "create", "fence", "remove", "fence"]
    assert ops[0]["rows"]["velocity"][0, 0] == 2.0  # the newer row took the older one's place
    assert backlog.events_dropped == 0  # the create and remove cancel nothing across a fence


def posture(index: int, appearance: int, heading: float = 0.0) -> req.Op:
    rows = make_entity_requests(index=[index], appearance=appearance, heading=heading)
    return req.decode(req.pack([req.requests(rows)]))[0]


def test_a_request_that_changes_what_its_soldier_does_is_applied_not_overwritten() -> None:
    """Kneel, then stand again within one turn (issue 21's tail): coalesced, the kneel never showed and a
    client waited for the soldier's next change (seconds). Both apply, in order, in batches of their own
    (in one batch the last row per soldier wins); a newer heading of the same posture still coalesces."""
    backlog = Backlog()
    backlog.put(
        [posture(7, Appearance.KNEEL), posture(8, Appearance.KNEEL), posture(8, Appearance.KNEEL, 90)]
    )
    backlog.put([posture(7, Appearance.UPRIGHT), posture(9, Appearance.PRONE)])
    assert backlog.coalesced == 1 and len(backlog) == 4
    first, second = drain(backlog)
    assert first["rows"]["index"].tolist() == [7, 8] and first["rows"]["heading"].tolist() == [0.0, 90.0]
    assert first["rows"]["appearance"].tolist() == [Appearance.KNEEL] * 2
    assert second["rows"]["index"].tolist() == [7, 9]
    assert second["rows"]["appearance"].tolist() == [Appearance.UPRIGHT, Appearance.PRONE]


def test_a_flood_stays_within_the_bound_and_keeps_every_event_and_newest_row() -> None:
    """Soldiers 0..19 send requests for ever and react every other round: the backlog keeps at most
    ``max_rows`` request rows (the events besides), drops the oldest superseded rows (counted), keeps
    each soldier's newest reaction (a newer one replaces a queued one: events21) and newest row."""
    backlog = Backlog(max_rows=40)
    reacts = []
    for k in range(400):
        i, reacting = k % 20, (k // 20) % 2 == 0 and k < 200
        backlog.put([row(i, float(k))] + ([req.react(i, f"r{k}")] if reacting else []))
        reacts += [f"r{k}"] if reacting else []
        assert len(backlog) - backlog.events <= 40
    assert backlog.dropped > 0
    ops = drain(backlog)
    assert [op["kind"] for op in ops if op["op"] == "react"] == reacts[-20:]
    assert backlog.events_dropped == len(reacts) - 20
    newest = {
        int(r["index"]): float(r["velocity"][0]) for op in ops if op["op"] == "requests" for r in op["rows"]
    }
    assert newest == {k % 20: float(k) for k in range(380, 400)}


def test_a_flood_of_requests_alone_is_one_row_per_soldier() -> None:
    backlog = Backlog(max_rows=100)
    for k in range(5000):
        backlog.put([row(k % 50, float(k + 1))])  # one activity (moving), speeds differ
        assert len(backlog) <= 50
    assert backlog.dropped == 0 and backlog.coalesced == 4950


def test_a_backlog_under_its_byte_bound_drops_the_oldest_rows() -> None:
    backlog = Backlog(max_bytes=33 * 10)
    for k in range(30):
        backlog.put([row(k, 1.0)])
        assert backlog.bytes <= 33 * 10
    assert backlog.dropped == 20
    (op,) = drain(backlog)
    assert op["rows"]["index"].tolist() == list(range(20, 30))


def test_events_beyond_the_bound_are_kept_and_do_not_push_the_rows_out() -> None:
    """Events are never dropped: a backlog of events alone over its bound keeps them (and logs it), and
    the bound is on the request rows, so the rows among them stay (a backlog full of events dropped every
    new row on arrival: the newest state, found in review)."""
    backlog = Backlog(max_rows=10)
    creates = [req.create(10 + k, "DI.fig", "AK_47.fig", None) for k in range(12)]
    backlog.put([row(1, 1.0), row(2, 1.0), *creates, row(4, 1.0)])
    assert backlog.dropped == 0 and len(backlog) == 15 and backlog.events == 12
    ops = drain(backlog)
    assert [op for op in ops if op["op"] == "create"] == creates
    assert [r["index"] for op in ops if op["op"] == "requests" for r in op["rows"]] == [1, 2, 4]


def test_a_flood_of_reactions_keeps_one_per_soldier_the_last() -> None:
    """100,000 reactions for 10 soldiers between the shard's turns (a peer relaying a client that floods
    them, events21): a reaction replaces its soldier's queued one, so the backlog holds at most one per
    soldier (and a few dropped ones awaiting compaction), and the last one of each soldier applies."""
    backlog = Backlog()
    for m in range(1000):
        backlog.put([req.react(k % 10, f"r{m * 100 + k}") for k in range(100)])
        assert backlog.events == len(backlog) == 10 and len(backlog._items) <= 2 * 64 + 10
        if m % 97 == 0:
            backlog.take()
    assert backlog.events_dropped == 100_000 - 10 - 11  # 11 taken on the way
    assert [op["kind"] for op in drain(backlog)] == [f"r{99_990 + k}" for k in range(10)]
    assert backlog.rows == backlog.bytes == 0 and not backlog._reaction


def test_reactions_keep_their_place_among_their_soldiers_states() -> None:
    """A newer reaction goes where it arrived, after the states sent before it; the older one goes: the
    events left are in the order sent."""
    backlog = Backlog()
    backlog.put([req.react(1, "a"), posture(1, Appearance.KNEEL), req.react(2, "b"), req.react(1, "c")])
    ops = drain(backlog)
    assert [(op["op"], op.get("kind")) for op in ops] == [("requests", None), ("react", "b"), ("react", "c")]


def test_events_over_the_bound_drop_the_oldest_reactions_first(caplog: Any) -> None:
    backlog = Backlog(max_rows=10)
    creates = [req.create(100 + k, "DI.fig", "AK_47.fig", None) for k in range(6)]
    backlog.put([req.react(k, f"r{k}") for k in range(8)] + creates)
    assert backlog.events == 10 and backlog.events_dropped == 4
    assert "fabric_backlog_full" in caplog.text
    ops = drain(backlog)
    assert [op.get("kind") for op in ops if op["op"] == "react"] == ["r4", "r5", "r6", "r7"]
    assert [op for op in ops if op["op"] == "create"] == creates


def test_a_create_then_its_remove_cancel_and_the_rest_stays_in_order() -> None:
    """A soldier created (after a remove of it) and removed while both wait in the backlog lived and died
    unseen (the front-end removed it already and merges none of its poses): both go, with its reaction
    queued since; its rows stay (a shard rejects rows of a soldier it lacks). A create with no remove
    before it stays (it might fail: the shard might have the soldier). A create after a queued create, or
    a remove after a queued remove, fails on a shard, and goes too; a sync in between keeps them."""
    backlog = Backlog()
    c5, r5 = req.create(5, "DI.fig", "AK_47.fig", None), req.remove(5)
    backlog.put([req.remove(5), req.react(4, "x"), c5, row(5, 1.0), req.react(5, "y"), r5])
    assert backlog.events == 2 and backlog.events_dropped == 3
    assert [op["op"] for op in drain(backlog)] == ["remove", "react", "requests"]
    backlog.put([c5, r5])
    assert [op["op"] for op in drain(backlog)] == ["create", "remove"]
    c6 = req.create(6, "DI.fig", "AK_47.fig", None)
    sync = {"op": "sync", "soldiers": [], "rows": np.zeros(0, np.uint8)}
    backlog.put([c6, dict(c6), sync, req.remove(6), req.remove(6)])
    assert [op["op"] for op in drain(backlog)] == ["create", "sync", "remove"]


def test_a_flood_of_creations_and_removals_is_bounded_per_soldier() -> None:
    """Whatever a peer sends between two syncs, a soldier has at most one reaction and three creates or
    removes (create, remove, create) queued, and the backlog one key: its events are bounded by the
    soldier indices (65,536), not by how long the flood lasts. Here 50 soldiers, 200,000 events."""
    rng = np.random.default_rng(21)
    backlog = Backlog()
    kinds = rng.integers(0, 4, 200_000)
    who = rng.integers(0, 50, 200_000)
    for start in range(0, 200_000, 500):
        ops = []
        part = slice(start, start + 500)
        for kind, i in zip(kinds[part].tolist(), who[part].tolist(), strict=True):
            ops.append(
                req.create(i, "DI.fig", "AK_47.fig", None)
                if kind == 0
                else req.remove(i)
                if kind == 1
                else req.react(i, "flinch")
                if kind == 2
                else req.key()
            )
        backlog.put(ops)
        assert backlog.events <= 4 * 50 + 1 and len(backlog._items) <= 2 * (4 * 50 + 1) + 64
    assert backlog.events_dropped > 190_000


def test_a_shard_ends_as_if_it_applied_every_create_and_remove(caplog: Any) -> None:
    """A peer cycling a soldier's creation, request, reaction and removal (1,000 times) and creating one
    more: through the backlog the shard ends with the soldiers, and the states, of one that applied every
    operation, and none of what it takes fails (the first cycle stays: its create follows no remove)."""
    walk = make_entity_requests(index=[21], velocity=(1.0, 0.0, 0.0))
    ops = [
        op
        for _ in range(1000)
        for op in (
            req.create(20, "DI.fig", "AK_47.fig", None),
            req.decode(req.pack([req.requests(walk.copy())]))[0],
            req.react(20, "flinch"),
            req.remove(20),
        )
    ] + [req.create(21, "DI.fig", "AK_47.fig", None), req.decode(req.pack([req.requests(walk)]))[0]]
    every, backlogged = make_server(), make_server()
    for s in (every, backlogged):
        s.start_world()
        s.world.clock = lambda: 1.0
    every_node = ShardNode(every, MemoryFabric(Bus()), Sharding(0, 1))
    for op in ops:
        every_node.handle(op)
    node = ShardNode(backlogged, MemoryFabric(Bus()), Sharding(0, 1))
    node.backlog.put(ops)
    assert node.backlog.events == 3 and node.backlog.events_dropped == 2998
    caplog.clear()
    while (op := node.backlog.take()) is not None:
        node.handle(op)
    assert "fabric_request_failed" not in caplog.text
    a, b = every.world.manager, backlogged.world.manager
    assert a is not None and b is not None
    assert a.table.live.tolist() == b.table.live.tolist() == [*range(10), 21]
    for name in ("appearance", "weapon", "velocity", "heading", "position"):
        np.testing.assert_array_equal(getattr(a.table, name)[:22], getattr(b.table, name)[:22], err_msg=name)


def test_a_front_ends_queue_of_a_shards_batches_is_bounded() -> None:
    """The other side of the fabric: a front-end whose loop is far behind keeps at most ``PENDING_MAX`` ticks
    of each shard's batches (a pulse and a batch of each block; the oldest go; the seq gap asks for a key),
    and asks its loop once."""
    node = FrontNode(make_server(), MemoryFabric(Bus()), 2)
    woken: list[object] = []

    class Token:
        def run_sync_soon(self, fn: object, *args: object) -> None:
            woken.append(fn)

    for k in range(100_000):
        node._arrived(Token(), k % 2, b"batch %d" % k)  # type: ignore[arg-type]
    most = PENDING_MAX * (1 + node.blocks)
    assert {k: len(q) for k, q in node._pending.items()} == {0: most, 1: most}
    assert node._pending[1][-1] == b"batch 99999" and len(woken) == 2


# -- the order of a soldier's states and events: a model of a shard (the soldier's state: its newest row) --
_EVENTS = st.one_of(
    st.builds(req.react, st.integers(0, 4), st.just("hit")),
    st.builds(req.remove, st.integers(0, 4)),
    st.builds(lambda i: req.create(i, "DI.fig", "AK_47.fig", None), st.integers(0, 4)),
    st.builds(req.key),
    st.builds(lambda: {"op": "sync", "soldiers": [], "rows": np.zeros(0)}),
)
_MESSAGE = st.lists(
    st.one_of(st.lists(st.integers(0, 4), min_size=1, max_size=4), _EVENTS), min_size=1, max_size=5
)


def _model(ops: list[Any]) -> tuple[dict[int, tuple[str, object, object]], dict[int, float]]:
    """Each event (by identity) with what it sees when it applies (its soldier's state; a sync's: every
    soldier's), in order, and the final states."""
    state: dict[int, float] = {}
    events = {}
    for op in ops:
        if op["op"] == "requests":
            for r in op["rows"]:
                state[int(r["index"])] = float(r["velocity"][0])
        else:
            index = op.get("index")
            seen = dict(state) if op["op"] == "sync" else state.get(index) if index is not None else None
            events[id(op)] = (op["op"], index, seen)
    return events, state


def _lives(ops: list[Any]) -> dict[tuple[int, int], list[str]]:
    """Each soldier's creates and removes that a shard told them in order applies (a create of a soldier it
    has, or a remove of one it has not, fails), per stretch between syncs, a create then its remove as
    nothing (the soldier lived and died unseen: the backlog may cancel them)."""
    lives: dict[tuple[int, int], list[str]] = {}
    live: set[int] = set()
    syncs = 0
    for op in ops:
        syncs += op["op"] == "sync"
        i = op.get("index")
        if op["op"] not in ("create", "remove") or (op["op"] == "create") == (i in live):
            continue
        life = lives.setdefault((i, syncs), [])
        if op["op"] == "create":
            live.add(i)
            life.append("create")
        else:
            live.discard(i)
            if life and life[-1] == "create":
                life.pop()
            else:
                life.append("remove")
    return {k: life for k, life in lives.items() if life}


@settings(max_examples=150, deadline=None)
@given(st.lists(st.tuples(_MESSAGE, st.integers(0, 2)), min_size=1, max_size=25))
def test_coalesced_events_see_the_states_they_saw_in_order(stream: list[tuple[list[Any], int]]) -> None:
    """Whatever arrives and however many operations the shard takes between messages, the events taken
    are among those sent, in order, each applies with every soldier's newest state sent before it, the
    final states are the last ones sent, a shard applies the same creates and removes (a create then its
    remove aside), and each soldier's last reaction applies (unless a remove of it came after)."""
    backlog = Backlog()
    sent: list[req.Op] = []
    taken: list[req.Op] = []
    serial = 0
    for message, takes in stream:
        ops = []
        for item in message:
            if isinstance(item, list):
                rows = make_entity_requests(
                    index=item, velocity=[(serial + j, 0.0, 0.0) for j in range(len(item))]
                )
                serial += len(item)
                ops.append(req.decode(req.pack([req.requests(rows)]))[0])
            else:
                ops.append(item)
        sent += ops
        backlog.put(ops)
        for _ in range(takes):
            if (op := backlog.take()) is not None:
                taken.append(op)
    taken += drain(backlog)
    applied, asked = _model(taken), _model(sent)
    assert applied[1] == asked[1]
    assert list(applied[0]) == [id(op) for op in sent if id(op) in applied[0]]  # in the order sent
    assert all(asked[0][k] == seen for k, seen in applied[0].items())
    assert _lives(taken) == _lives(sent)  # the same creates and removes, as the shard applies them
    last: dict[int, int] = {}  # each soldier's last reaction sent, unless a remove of it came after
    for op in sent:
        if op["op"] == "react":
            last[op["index"]] = id(op)
        elif op["op"] == "remove":
            last.pop(op["index"], None)
    assert set(last.values()) <= applied[0].keys()
    assert backlog.rows == 0 and backlog.bytes == 0


_ACTIVITY = st.tuples(
    st.integers(0, 3),
    st.sampled_from([Appearance.UPRIGHT, Appearance.KNEEL]),
    st.sampled_from([0.0, 1.5]),
    st.integers(0, 1),
)


@settings(max_examples=150, deadline=None)
@given(st.lists(st.lists(_ACTIVITY, min_size=1, max_size=4), min_size=1, max_size=20), st.integers(0, 3))
def test_a_change_of_activity_is_kept_behind_a_queued_one(messages: list[list[Any]], every: int) -> None:
    """State-only streams, taken now and then: a row that arrives while its soldier has a row of another
    activity queued is applied after it, never over it, so each soldier passes through its activities in
    the order sent, the first and the last of them included; only a third activity while two rows are
    queued takes the newer one's place (a soldier's backlog is at most two rows). No batch holds two rows
    of one soldier (the last would win)."""
    backlog = Backlog()
    sent: list[np.ndarray] = []
    taken: list[np.ndarray] = []
    for k, message in enumerate(messages):
        ops = [
            req.decode(
                req.pack(
                    [
                        req.requests(
                            make_entity_requests(
                                index=[i],
                                appearance=int(a),
                                velocity=(0.0, v, 0.0),
                                heading=float(k),
                                immediate=bool(im),
                            )
                        )
                    ]
                )
            )[0]
            for i, a, v, im in message
        ]
        sent += [op["rows"] for op in ops]
        backlog.put(ops)
        assert all(n <= 2 for n in collections.Counter(backlog_soldiers(backlog)).values())
        if every and k % every == 0 and (op := backlog.take()) is not None:
            taken.append(op["rows"])
    taken += [op["rows"] for op in drain(backlog)]
    assert all(len(np.unique(rows["index"])) == len(rows) for rows in taken)
    applied, asked = path(taken), path(sent)
    assert applied.keys() == asked.keys()
    for i, seq in applied.items():
        assert seq[0] == asked[i][0] and seq[-1] == asked[i][-1]
        rest = iter(asked[i])
        assert all(a in rest for a in seq)  # in the order sent


@settings(max_examples=150, deadline=None)
@given(
    st.lists(st.lists(st.one_of(_ACTIVITY, _EVENTS), min_size=1, max_size=4), min_size=1, max_size=30),
    st.integers(0, 3),
)
def test_a_full_backlog_of_activities_keeps_its_books(messages: list[list[Any]], every: int) -> None:
    """Activity changes, events and a bound of 6 rows: within the bound after each message, no batch
    with two rows of one soldier, and nothing left on the books once drained."""
    backlog = Backlog(max_rows=6)
    for k, message in enumerate(messages):
        ops = [
            item
            if isinstance(item, dict)
            else req.decode(
                req.pack(
                    [
                        req.requests(
                            make_entity_requests(
                                index=[item[0]], appearance=int(item[1]), velocity=(0.0, item[2], 0.0)
                            )
                        )
                    ]
                )
            )[0]
            for item in message
        ]
        backlog.put(ops)
        assert len(backlog) - backlog.events <= 6
        if every and k % every == 0:
            backlog.take()
    for op in drain(backlog):
        if op["op"] == "requests":
            assert len(np.unique(op["rows"]["index"])) == len(op["rows"])
    assert backlog.rows == backlog.bytes == 0 and not backlog._queued.any() and not backlog._blocks
    assert not backlog._starts


def backlog_soldiers(backlog: Backlog) -> list[int]:
    return [i for item in backlog._items if not isinstance(item, dict) for i in item.rows["index"].tolist()]


def path(batches: list[np.ndarray]) -> dict[int, list[int]]:
    """Each soldier's activities in the order of ``batches``, repeats as one."""
    out: dict[int, list[int]] = {}
    for rows in batches:
        for i, a in zip(rows["index"].tolist(), activity(rows).tolist(), strict=True):
            seen = out.setdefault(i, [])
            if not seen or seen[-1] != a:
                seen.append(a)
    return out


# -- the shard: what it applies ---------------------------------------------------------------------------
async def test_a_shard_applies_a_burst_as_one_state_then_the_remove(autojump_clock: trio.abc.Clock) -> None:
    shard = make_server()
    node = ShardNode(shard, MemoryFabric(Bus()), Sharding(0, 1))
    async with trio.open_nursery() as nursery:
        await nursery.start(shard.serve)
        await trio.sleep(0.2)
        world = shard.world
        calls: list[Any] = []
        apply, remove = world.apply_requests, world.remove_soldier
        world.apply_requests = lambda rows: (calls.append(("requests", rows.copy())), apply(rows))[1]  # type: ignore[method-assign]
        world.remove_soldier = lambda i, why="": (calls.append(("remove", i)), remove(i, why))[1]  # type: ignore[method-assign]
        node.backlog.put([row(3, 1 + 0.02 * k) for k in range(50)] + [req.remove(3)])
        while node.backlog:
            node.take_turn()
        (what, rows), removed = calls
        assert (
            what == "requests"
            and rows["index"].tolist() == [3]
            and rows["velocity"][0, 0] == np.float32(1 + 0.02 * 49)
        )
        assert removed == ("remove", 3)
        assert shard.status_note is not None and "backlog 0/32768 rows" in shard.status_note()
        assert "49 coalesced, 0 dropped" in shard.status_note()
        shard.shutdown()


_STATE = st.tuples(
    st.integers(0, 9),
    st.sampled_from([Appearance.STAND, Appearance.KNEEL, Appearance.PRONE]),
    st.floats(-2.0, 2.0, width=32),
    st.floats(0.0, 359.0, width=32),
)


@settings(max_examples=15, deadline=None)
@given(st.lists(st.lists(_STATE, min_size=1, max_size=6), min_size=1, max_size=12))
def test_coalesced_requests_leave_the_soldiers_as_every_request_in_order(messages: list[list[Any]]) -> None:
    """State-only streams: the manager's soldiers end with the same requested state (posture, weapon,
    velocity, heading, position) whether it applies every message in order or the coalesced backlog."""
    ops = [
        req.decode(
            req.pack(
                [
                    req.requests(
                        make_entity_requests(
                            index=[s[0] for s in m],
                            appearance=[int(s[1]) for s in m],
                            velocity=[(s[2], 0.0, 0.0) for s in m],
                            heading=[s[3] for s in m],
                            position=[(s[2], s[3], 0.0) for s in m],
                        )
                    )
                ]
            )
        )[0]
        for m in messages
    ]
    every, coalesced = make_server(), make_server()
    for s in (every, coalesced):
        s.start_world()
        s.world.clock = lambda: 1.0
    for op in ops:  # all valid, as a front-end relays them
        assert (every.world.apply_requests(op["rows"]) == REQUEST_OK).all()
    backlog = Backlog()
    backlog.put(ops)
    for op in drain(backlog):
        coalesced.world.apply_requests(op["rows"])
    a, b = every.world.manager, coalesced.world.manager
    assert a is not None and b is not None
    for name in ("appearance", "weapon", "velocity", "heading", "position"):
        np.testing.assert_array_equal(getattr(a.table, name)[:10], getattr(b.table, name)[:10], err_msg=name)


async def test_a_kneel_undone_within_the_shards_turn_still_shows(autojump_clock: trio.abc.Clock) -> None:
    """A standing soldier asked to kneel and, in the same message, to stand: a single server applies a
    client's frames one by one and the soldier dips; the shard coalesced them (the last row won: nothing
    changed, nothing was sent), so a load test's probe of the kneel waited seconds for the soldier's next
    change (issue 21's 20,000-soldier tail). Now the shard applies both, and its pose changes."""
    shard = make_server()
    node = ShardNode(shard, MemoryFabric(Bus()), Sharding(0, 1), key_every=10**9)
    async with trio.open_nursery() as nursery:
        await nursery.start(shard.serve)
        await trio.sleep(2.0)  # the start-up script's soldiers stand at rest
        board = shard.board_ref.board
        assert board is not None
        before = int(board.version[3])
        await trio.sleep(0.5)
        assert board.version[3] == before
        node.backlog.put([posture(3, Appearance.KNEEL), posture(3, Appearance.UPRIGHT)])
        node.take_turn()
        await trio.sleep(0.2)
        assert board.version[3] > before
        shard.shutdown()
