"""Issue 21: a shard's batches carry only the soldiers whose codes changed, with a key batch (every soldier)
now and then and when a front-end asks; merged in order they rebuild exactly the board full batches give."""

from __future__ import annotations

from types import SimpleNamespace
from typing import Any

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from server.fabric import Kind
from server.fabric.batch import Batch, decode_batch
from server.fabric.nodes import Sharding, ShardNode, merge
from server.pose_board import PoseBoard

N, F = 40, 64


class Wire:
    """A fabric node that keeps what its shard publishes."""

    engine = "memory"

    def __init__(self) -> None:
        self.sent: list[bytes] = []

    def publisher(self, topic: str, kind: Kind) -> Any:
        return self.sent.append


def shard(key_every: int = 1000) -> tuple[ShardNode, Wire, PoseBoard]:
    wire = Wire()
    # what a key request touches: nothing; the backlog's bound: max_soldiers
    server = SimpleNamespace(world=SimpleNamespace(manager=None), config=SimpleNamespace(max_soldiers=8))
    node = ShardNode(server, wire, Sharding(0, 1), key_every=key_every)  # type: ignore[arg-type]
    return node, wire, PoseBoard(3, 2)


def full(board: PoseBoard) -> Batch:
    """What a shard sent before: every soldier, every tick."""
    rows = np.flatnonzero(board.valid)
    return Batch(0, 1, 0, board.tick, 0.0, rows, board.table_of[rows], board.codes[rows])


def same(a: PoseBoard, b: PoseBoard) -> bool:
    return bool(np.array_equal(a.valid, b.valid) and np.array_equal(a.codes[a.valid], b.codes[b.valid]))


def tick(node: ShardNode, board: PoseBoard, rng: np.random.Generator, t: int, moving: float) -> None:
    """One shard tick: every soldier's codes, ``moving`` of them new (the rest as they were)."""
    codes = board.codes[:N].copy() if t > 1 else rng.integers(0, 4096, (N, F))
    move = rng.random(N) < moving
    codes[move] = rng.integers(0, 4096, (int(move.sum()), F))
    board.publish_codes(np.arange(N), np.ones(N, np.int32), codes, t)
    node.publish(board)


ALIVE = np.ones(N, bool)


@settings(max_examples=25, deadline=None)
@given(
    seed=st.integers(0, 2**31),
    moving=st.floats(0.0, 1.0),
    lost=st.lists(st.integers(2, 30), max_size=4),
    queued=st.integers(1, 4),
)
def test_changed_only_batches_rebuild_the_board_full_batches_give(
    seed: int, moving: float, lost: list[int], queued: int
) -> None:
    """Ticks of random motion; some batches lost on the way (the front-end asks for a key at the gap) and
    the rest merged ``queued`` at a time: after each merge the board is the one full batches build, except
    from a loss until the key it asked for."""
    rng = np.random.default_rng(seed)
    node, wire, board = shard()
    by_changes, by_full = PoseBoard(3, 2), PoseBoard(3, 2)
    waiting: list[Batch] = []
    healing = False
    for t in range(1, 31):
        tick(node, board, rng, t, moving)
        merge(by_full, [full(board)], t, ALIVE)
        b = decode_batch(wire.sent[-1])
        assert b.key == (t == 1) or healing
        if t in lost:
            healing = True
            node._apply({"op": "key"})  # the front-end saw the seq gap at its next batch
            continue
        waiting.append(b)
        if len(waiting) < queued and t < 30:
            continue
        merge(by_changes, waiting, t, ALIVE)
        healing = healing and not any(w.key for w in waiting)
        waiting = []
        assert healing or same(by_changes, by_full)
    assert same(by_changes, by_full)


def test_a_batch_carries_the_changed_soldiers_and_a_key_all_of_them() -> None:
    rng = np.random.default_rng(1)
    node, wire, board = shard(key_every=5)
    sizes = []
    for t in range(1, 12):
        tick(node, board, rng, t, 0.25)
        b = decode_batch(wire.sent[-1])
        sizes.append(len(b.indices) if not b.key else -1)
    assert sizes[0] == sizes[5] == sizes[10] == -1  # the first, then every 5th tick: a key
    assert all(0 < n < N for i, n in enumerate(sizes) if i % 5)  # the others: about a quarter


def test_a_sync_asks_for_a_key_at_the_next_tick() -> None:
    """A front-end that joined late, or a take-over, brings a sync: the next batch holds every soldier."""
    rng = np.random.default_rng(2)
    node, wire, board = shard()
    for t in (1, 2):
        tick(node, board, rng, t, 0.0)
    assert decode_batch(wire.sent[-1]).indices.tolist() == []  # nothing moved: an empty tick batch
    node._apply({"op": "key"})
    tick(node, board, rng, 3, 0.0)
    b = decode_batch(wire.sent[-1])
    assert b.key and b.indices.tolist() == list(range(N))
