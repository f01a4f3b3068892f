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
(:func:`reconcile`). It keeps the answer's last request of each soldier it has none of, which its
fail-over hands on (:func:`learned_last`). Soldiers of another shard in the answer are a stand-in's: the
front-end never heard their shard, failed over before it started, and sends their requests to the
stand-in (:func:`stand_ins`). A sync carries the soldiers removed too (:func:`gone`). Until a shard
answers, the front-end allots no index that the shard's batches carried and its books lack (its own
soldiers before a restart; with one front-end, which allots the table's lowest free index, it creates none).

A shard's batch sent before it heard of a removal and re-creation at an index carries the old soldier's
codes there, and the front-end's books say the index lives: the front-end ends each message to a shard
that creates or removes soldiers with a *fence* (a serial per shard), a batch carries the newest fence
of each front-end the shard had taken, and until one carries the fence, the rows of those indices are
dropped (:class:`Fences`).
"""

from __future__ import annotations

import dataclasses
import heapq
from collections import deque
from collections.abc import Callable, Sequence
from typing import Any

import msgpack
import numpy as np

from protocol.entity import ENTITY_REQUEST_DTYPE
from server.fabric.batch import Batch

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


def answer(
    shard: int,
    front: int,
    soldiers: list[Soldier],
    last: np.ndarray | None = None,
    homes: Sequence[int] = (),
    gens: Sequence[int] = (),
) -> bytes:
    """A shard's answer to front-end ``front``'s ``books``: every soldier it animates, the last request of
    those that had one (``ENTITY_REQUEST_DTYPE`` rows), the other shards it stands in for (``homes``) and the
    generation of each soldier (``gens``: :func:`server.fabric.requests.sync`)."""
    rows = np.zeros(0, ENTITY_REQUEST_DTYPE) if last is None else last
    rows = np.ascontiguousarray(rows, ENTITY_REQUEST_DTYPE)
    body = {
        "soldiers": [list(s) for s in soldiers],
        "rows": rows.tobytes(),
        "homes": list(homes),
        "gens": list(gens),
    }
    # the body packed apart: every front-end hears every answer, and only the one it is for unpacks its
    # soldiers (at 12,000 soldiers over 2 shards and 6 front-ends, unpacking the others' answers was 38 % of
    # a front-end's CPU: :func:`addressee`)
    return bytes(msgpack.packb({"shard": shard, "front": front, "body": msgpack.packb(body)}))


def addressee(data: bytes) -> tuple[int, int]:
    """``(shard, front)`` of an answer without unpacking its body; ValueError if it is not one."""
    try:
        msg = msgpack.unpackb(data)
        return int(msg["shard"]), int(msg["front"])
    except (ValueError, TypeError, KeyError, msgpack.UnpackException) as exc:
        raise ValueError(f"not a books answer: {exc}") from exc


def decode_answer(data: bytes) -> dict[str, Any]:
    """The answer with ``soldiers`` as a list of :data:`Soldier` and ``rows`` as requests; ValueError if it
    is not one."""
    try:
        head = msgpack.unpackb(data)
        msg = msgpack.unpackb(head["body"])
        msg["shard"], msg["front"] = int(head["shard"]), int(head["front"])
        msg["soldiers"] = [
            (int(i), str(f), str(w), None if o is None else str(o)) for i, f, w, o in msg["soldiers"]
        ]
        msg["rows"] = np.frombuffer(msg.get("rows", b""), ENTITY_REQUEST_DTYPE)
        msg["homes"] = [int(h) for h in msg.get("homes", [])]
        msg["gens"] = [int(g) for g in msg.get("gens", [])]
    except (ValueError, TypeError, KeyError, AttributeError, msgpack.UnpackException) as exc:
        raise ValueError(f"not a books answer: {exc}") from exc
    return msg


def answer_scope(live: np.ndarray, route: list[int], k: int, stand_in: Sequence[int] = ()) -> set[int]:
    """The live soldiers (``live``) a books answer of shard ``k`` may drop: those homed on ``k`` (index modulo
    the shards, ``len(route)``) and animated there (``route``: each shard's animating shard), and those of
    the shards it stands in for by this answer (``stand_in``: this front-end never heard them; the removed
    start-up soldiers of a shard failed over stayed on as ghosts). One failed over to ``k`` by this
    front-end after it answered is missing from the answer: counting it in, the front-end removed a killed
    shard's soldiers (test_a_killed_shards_soldiers_go_on_in_the_survivor)."""
    live = np.asarray(live, np.int64)
    home = live % len(route)
    return set(live[((home == k) & (np.asarray(route)[home] == k)) | np.isin(home, list(stand_in))].tolist())


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


def stand_ins(
    told: list[Soldier], shard: int, shards: int, heard: list[bool], homes: Sequence[int] = ()
) -> dict[int, int]:
    """The shards ``shard``'s answer says it stands in for (``homes``, or whose soldiers it carries: home
    index modulo ``shards``) and which this front-end never heard: failed over to ``shard`` before it
    started, their requests go there (home -> ``shard``); a shard with no soldiers too (its creations went
    to its dead topic). A shard heard has its own route (it comes back, or this front-end failed it over)."""
    theirs = ({s[0] % shards for s in told} | {h for h in homes if 0 <= h < shards}) - {shard}
    return {h: shard for h in sorted(theirs) if not heard[h]}


def learned_last(rows: np.ndarray, live: np.ndarray, has_last: np.ndarray) -> np.ndarray:
    """The answer's last requests (``rows``) a front-end keeps for its fail-overs: those of soldiers live
    in its books (``live``: mask by index) with no last request of their own (a request sent through this
    front-end is as new as the shard's or newer)."""
    idx = rows["index"].astype(np.int64)
    ok = (idx < len(live)) & (idx < len(has_last))
    ok[ok] = live[idx[ok]] & ~has_last[idx[ok]]
    return rows[ok]


def gone(known: np.ndarray, live: np.ndarray, homes: list[int], shards: int) -> np.ndarray:
    """The soldiers homed on ``homes`` that a front-end removed, or was told were removed (``known`` and not
    ``live``: masks by index): a sync carries them, for a shard that listened after the removal went (its
    start-up script made them again, or it kept them while it was failed over)."""
    idx = np.flatnonzero(known)
    idx = idx[(idx >= len(live)) | ~live[np.minimum(idx, len(live) - 1)]] if len(live) else idx
    return idx[np.isin(idx % shards, homes)]


def rerouted(route: list[int], alive: list[int], heard: list[bool]) -> list[tuple[int, int, list[int]]]:
    """The fail-overs due, as ``(down, survivor, homes)``, ``route`` changed to match: each shard heard
    once and down now (not in ``alive``) that animates soldiers — its own, or as a stand-in another's: the
    homes routed to it (a stand-in that dies too) — hands them all to the living shard that animates the
    fewest homes. None while no shard lives."""
    out: list[tuple[int, int, list[int]]] = []
    for down in range(len(route)):
        homes = [h for h, r in enumerate(route) if r == down]
        if not alive or down in alive or not heard[down] or not homes:
            continue
        survivor = min(alive, key=lambda s: sum(r == s for r in route))
        for h in homes:
            route[h] = survivor
        out.append((down, survivor, homes))
    return out


class Elsewhere:
    """Front-end ``k`` of ``m``'s view of the others: which are on the fabric, and their open connections of
    each client id (each tells its own on ``ttes/fronts``). An id's soldiers wait for it while it is
    connected to any front-end (an IG that leaves one front-end still connected to another, or that
    reconnects through another); of a gone id's soldiers each front-end removes those of its share, and
    those of a front-end not on the fabric the lowest present one removes: one removal of each."""

    def __init__(self, k: int, m: int, block: int) -> None:
        self.k, self.block = k, block
        self.present = [j == k for j in range(m)]
        self.counts: dict[int, dict[str, int]] = {j: {} for j in range(m) if j != k}
        self.told: dict[str, int] = {}  # this front-end's own counts, as last told the others

    def total(self, client_id: str) -> int:
        """The id's connections to the other front-ends."""
        return sum(c.get(client_id, 0) for c in self.counts.values())

    def own(self, client_id: str, connected: int) -> dict[str, int] | None:
        """This front-end's count of ``client_id`` to tell the others (None: unchanged), from the id's
        connections counted here (``connected``: its own and the others')."""
        n = connected - self.total(client_id)
        if n == self.told.get(client_id, 0):
            return None
        if n:
            self.told[client_id] = n
        else:
            self.told.pop(client_id, None)
        return {client_id: n}

    def step(self, front: int, client_id: str, n: int) -> int:
        """Move front-end ``front``'s count of ``client_id`` one connection towards ``n``: +1 (joined), -1
        (left) or 0 (it is ``n``); counted first, so that :meth:`own` stays as it was."""
        counts = self.counts.get(front)
        if counts is None:
            return 0
        was = counts.get(client_id, 0)
        if was == n:
            return 0
        step = 1 if n > was else -1
        if was + step:
            counts[client_id] = was + step
        else:
            del counts[client_id]
        return step

    def removes(self, indices: list[int]) -> list[int]:
        """Of a gone id's soldiers, those this front-end removes."""
        m = len(self.present)
        first = self.present.index(True)
        return [
            i
            for i in indices
            if (j := (i // self.block) % m) == self.k or (not self.present[j] and first == self.k)
        ]


class Fences:
    """Front-end ``front``'s fences: for each index it created or removed (or synced elsewhere), the shard
    whose batches may carry it and the fence that shard must have taken first (issue 21 (d): the index
    removed and created again within a tick showed the old soldier's codes for a tick); for an index another
    front-end created or removed (mirrored), that front-end's fence, which it names on ``ttes/fronts``."""

    def __init__(self, front: int, n: int, shards: int) -> None:
        self.front = front
        self.shard = np.full(n, -1, np.int64)  # the shard the index's rows wait for (-1: none)
        self.serial = np.zeros(n, np.int64)  # the fence of that shard they wait for
        self.by = np.zeros(n, np.int64)  # the front-end whose fence it is
        self.next = [1] * shards  # per shard sent to, the serial of its next fence
        self.due = [False] * shards  # a fence ends the next message to it
        # per (front-end, shard): the indices marked, in the order of their fences
        self._marked: dict[tuple[int, int], deque[tuple[int, np.ndarray]]] = {}
        self.waiting = 0
        self.dropped = 0  # rows dropped (a test's count)

    def mark(self, indices: np.ndarray | list[int], shard: int) -> None:
        """The soldiers at ``indices`` were created or removed (or synced) by an operation queued for
        ``shard`` now: their rows count from the batch that carries the fence ending that message."""
        if self.wait(indices, self.front, shard, self.next[shard]):
            self.due[shard] = True

    def wait(self, indices: np.ndarray | list[int], front: int, shard: int, serial: int) -> bool:
        """The soldiers at ``indices`` were created or removed by front-end ``front``'s message to ``shard``
        that ends with fence ``serial``: their rows count from the batch that carries it. False: none."""
        idx = np.unique(np.asarray(indices, np.int64))
        idx = idx[(idx >= 0) & (idx < len(self.shard))]
        if not len(idx) or not 0 <= shard < len(self.next):
            return False
        self.waiting += int(np.count_nonzero(self.shard[idx] < 0))
        self.shard[idx], self.serial[idx], self.by[idx] = shard, serial, front
        self._marked.setdefault((front, shard), deque()).append((serial, idx))
        return True

    def moved(self, homes: list[int], shards: int, shard: int) -> None:
        """Shards ``homes``' soldiers are synced to ``shard`` now (a fail-over, a shard back): those
        waiting wait for ``shard``'s fence (another shard's never comes, or its rows are a stand-in's)."""
        idx = np.flatnonzero(self.shard >= 0) if self.waiting else np.zeros(0, np.int64)
        self.mark(idx[np.isin(idx % shards, homes)], shard)

    def fence(self, shard: int) -> int | None:
        """The serial of the fence that ends the message to ``shard`` sent now (None: none is due)."""
        if not self.due[shard]:
            return None
        self.due[shard] = False
        self.next[shard] += 1
        return self.next[shard] - 1

    def clean(self, b: Batch) -> Batch:
        """``b`` without the rows of the indices waiting for a fence it does not carry (or from another
        shard than the one they wait for); the indices whose fence it carries wait no more (the shard sends
        the rows of soldiers it created before a fence again after it)."""
        if not self.waiting:
            return b
        self._acked(b)
        if not self.waiting or not len(b.indices):
            return b
        idx = np.asarray(b.indices, np.int64)
        inside = idx < len(self.shard)
        wait = np.zeros(len(idx), bool)
        wait[inside] = self.shard[idx[inside]] >= 0
        if not wait.any():
            return b
        self.dropped += int(np.count_nonzero(wait))
        return dataclasses.replace(b, indices=b.indices[~wait], tables=b.tables[~wait], codes=b.codes[~wait])

    def _acked(self, b: Batch) -> None:
        """The indices marked for ``b``'s shard up to the fences it carries wait no more."""
        for (front, shard), marked in self._marked.items():
            if shard != b.shard:
                continue
            ack = b.fences[front] if front < len(b.fences) else 0
            while marked and marked[0][0] <= ack:
                idx = marked.popleft()[1]
                idx = idx[(self.shard[idx] == shard) & (self.by[idx] == front) & (self.serial[idx] <= ack)]
                self.shard[idx] = -1
                self.waiting -= len(idx)
