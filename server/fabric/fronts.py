"""Several front-ends (``ttes front --front K/M``): each allots soldier indices from its own share of the
one index space, and tells the others on ``ttes/fronts`` what it created and removed.

A front-end allots indices as a single server does, lowest free first, but only the indices of its share:
index ``i`` is front-end ``(i // B) % M``'s, B the fabric's block of indices (a pose topic's,
``--fabric-block``): the soldiers its clients make, and watch, are in blocks of its own, the only pose
topics it needs; they spread evenly over the shards (``i % N``) and two front-ends creating soldiers at
once never pick the same index. The
start-up script's soldiers are created before the share applies, at the same indices in every process.
An index asked for by number must be in the front-end's share (another front-end could allot it).

A front-end that starts late, or restarts, learns the soldiers from the shards: the first time it hears a
shard it sends it a sync of the soldiers it created itself (they may have gone before the shard listened)
and ``books`` (:mod:`server.fabric.requests`); the shard answers on ``ttes/books`` with every soldier it
animates (index, figure, weapon, owner; the table follows from figure and weapon), the truth: the
front-end takes them into its books (not relayed) and drops the ones the shard lacks (a start-up soldier
removed since), except those it created or removed itself or was told of by another front-end: it knows
better than the shard, whose answer may predate them or which missed them before it listened
(:func:`reconcile`). Until a shard
answers, the front-end allots no index that the shard's batches carried and its books lack (its own
soldiers before a restart; with one front-end, which allots the table's lowest free index, it creates none).
"""

from __future__ import annotations

import heapq
from collections.abc import Callable
from typing import Any

import msgpack
import numpy as np

Soldier = tuple[int, str, str, "str | None"]  # index, figure, weapon, owner


class IndexShare:
    """Front-end ``k`` of ``m``'s free indices below ``max_soldiers``, in blocks of ``block``."""

    def __init__(self, k: int, m: int, block: int, max_soldiers: int) -> None:
        self.k, self.m, self.block = k, m, block
        self._free = [i for i in range(max_soldiers) if self.mine(i)]  # ascending: a heap

    def mine(self, index: int) -> bool:
        return (int(index) // self.block) % self.m == self.k

    def allot(self, index: int | None, live: Callable[[int], bool]) -> int:
        """``index`` if it is in this share, else the lowest free one of the share (not taken until
        :meth:`taken`: a creation may still fail); ValueError if there is none, or ``index`` is another's."""
        if index is not None:
            if not self.mine(index):
                raise ValueError(f"soldier index {index} is another front-end's (this is {self.k}/{self.m})")
            return int(index)
        while self._free and live(self._free[0]):  # taken by number since (the start-up script's)
            heapq.heappop(self._free)
        if not self._free:
            raise ValueError(f"no free soldier index in front-end {self.k}/{self.m}'s share")
        return self._free[0]

    def taken(self, index: int) -> None:
        if self._free and self._free[0] == index:
            heapq.heappop(self._free)

    def freed(self, index: int) -> None:
        if self.mine(index):
            heapq.heappush(self._free, int(index))


def answer(shard: int, front: int, soldiers: list[Soldier]) -> bytes:
    """A shard's answer to front-end ``front``'s ``books``: every soldier it animates."""
    return bytes(msgpack.packb({"shard": shard, "front": front, "soldiers": [list(s) for s in soldiers]}))


def decode_answer(data: bytes) -> dict[str, Any]:
    """The answer with ``soldiers`` as a list of :data:`Soldier`; ValueError if it is not one."""
    try:
        msg = msgpack.unpackb(data)
        msg["soldiers"] = [
            (int(i), str(f), str(w), None if o is None else str(o)) for i, f, w, o in msg["soldiers"]
        ]
        msg["shard"], msg["front"] = int(msg["shard"]), int(msg["front"])
    except (ValueError, TypeError, KeyError, msgpack.UnpackException) as exc:
        raise ValueError(f"not a books answer: {exc}") from exc
    return msg


def answer_scope(live: np.ndarray, route: list[int], k: int) -> set[int]:
    """The live soldiers (``live``) a books answer of shard ``k`` may drop: those homed on ``k`` (index modulo
    the shards, ``len(route)``) and animated there (``route``: each shard's animating shard). One failed
    over to ``k`` after it answered is missing from the answer: counting it in, the front-end removed a
    killed shard's soldiers (test_a_killed_shards_soldiers_go_on_in_the_survivor)."""
    live = np.asarray(live, np.int64)
    home = live % len(route)
    return set(live[(home == k) & (np.asarray(route)[home] == k)].tolist())


def reconcile(
    books: dict[int, Soldier], scope: set[int], told: list[Soldier], known: set[int]
) -> tuple[list[int], list[Soldier]]:
    """What a front-end changes in its books from a shard's answer: ``(drop, add)``. ``books``: its
    soldiers; ``scope``: those of them the shard animates; ``known``: the soldiers it created or removed,
    or was told of, which the answer does not change. A soldier the books hold otherwise is replaced."""
    theirs = {s[0]: s for s in told}
    drop = [i for i in sorted(scope) if i not in known and theirs.get(i) != books[i]]
    drop += [i for i in theirs if i not in known and i not in scope and i in books and books[i] != theirs[i]]
    add = [s for i, s in theirs.items() if i not in known and books.get(i) != s]
    return drop, add
