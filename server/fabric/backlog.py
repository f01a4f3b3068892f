"""A shard's backlog of fabric requests: bounded, the entity requests coalesced per soldier (issue 21).

Under overload a shard's requests used to queue without bound (a 20,000-soldier run: a request waited 3.7 s
between arriving and being taken). An entity request is a DIS-like *state* (posture, weapon, velocity,
heading, position): a newer one for a soldier supersedes an older one not applied yet, as within one batch
(``SoldierManager.apply_requests``: the last row per soldier wins). So a soldier's new row overwrites its
queued one in place (taken as early as the old one was), unless an *event* for it (create, remove, react)
or a sync came in between: events are never coalesced or reordered, among themselves or against a
soldier's rows (a remove after a request stays after it).

Events are dropped only where the shard would end the same (events21: a peer flooding reactions or
create/remove cycles grew a shard's memory without bound). A reaction (a transient) drops its soldier's
queued one, and stays where it arrived; a key drops when one is queued (it asks for the same batch); a
remove drops its soldier's create queued right after a remove of it since the last sync (so the create
succeeds), with the reaction queued since (the soldier lived and died in the backlog: the front-end
removed it already, and merges no poses of a soldier it lacks; its rows stay, and the shard rejects
them); a create after a queued create, or a remove after a queued remove, would fail on the shard. So
between two syncs a soldier has at most one reaction and three creates or removes queued (create, remove,
create): events are bounded by the soldier indices (uint16), whatever a peer sends, and syncs come from
the front-end's own joins and failovers. Events over the
bounds drop the oldest reactions; the rest is logged. Dropped events are counted (``events_dropped``).

A row overwrites only a row of the same *activity* (:func:`activity`: posture, weapon, moving or still,
not ``immediate``): a newer heading, speed or position of what the soldier does. A row that changes what
it does (kneel, then stand again) is kept and applied on its own, after the older one, as a single server
applies a client's frames one by one (issue 21: coalesced, a kneel undone within one turn never showed,
and the request waited for the soldier's next change, seconds). Without events and activity changes the
rows are at most one per soldier; when the backlog is full anyway (``max_rows`` rows and events,
``max_bytes``), the oldest rows that a later row of their soldier supersedes go first, then the oldest
rows: counted and logged.

Filled on the fabric's thread (:meth:`Backlog.put`), taken on the shard's loop (:meth:`Backlog.take`).
"""

from __future__ import annotations

import collections
import threading
import time
from dataclasses import dataclass

import numpy as np

from protocol.entity import ENTITY_REQUEST_DTYPE
from server.fabric import requests as req
from server.logging import get_logger
from server.soldier.core import MOVING_EPS

log = get_logger("fabric")
INDICES = 1 << 16  # soldier indices are uint16 in a request row
ROW_BYTES = ENTITY_REQUEST_DTYPE.itemsize
MAX_ROWS = 32768  # rows and events queued, at least: a shard's is two per soldier (max_soldiers)
MAX_BYTES = 8 << 20  # request rows (33 bytes each) and events (their size, estimated) queued
MERGE_ROWS = 256  # consecutive request rows taken as one batch (a batch costs ~2 ms whatever its size)
LOG_EVERY_S = 1.0  # a drop is logged at most this often (with the drops since the last log)


@dataclass(eq=False)
class _Event:
    """An event queued (``queued`` False once taken or dropped: it stays in the queue, skipped, until the
    queue is compacted); ``prev``: its soldier's create or remove queued right before it, since the last
    sync (:attr:`Backlog._life`), taken since or not."""

    op: req.Op
    serial: int
    queued: bool = True
    prev: _Event | None = None


@dataclass
class _Block:
    """Request rows queued together (one message's, less those that went to older rows)."""

    id: int
    rows: np.ndarray
    repeats: bool = (
        False  # it starts a batch: its soldiers may have rows in older blocks (the last would win)
    )


class Backlog:
    """The operations a shard has not taken yet, in order, the entity requests coalesced per soldier."""

    def __init__(
        self, max_rows: int = MAX_ROWS, max_bytes: int = MAX_BYTES, merge_rows: int = MERGE_ROWS
    ) -> None:
        self.max_rows, self.max_bytes, self.merge_rows = max_rows, max_bytes, merge_rows
        self._lock = threading.Lock()
        self._items: collections.deque[_Block | _Event] = collections.deque()
        self._blocks: dict[int, _Block] = {}
        self._next_id = 0
        self._latest_block = np.full(INDICES, -1, np.int64)  # the block of each soldier's newest queued row
        self._latest_row = np.zeros(INDICES, np.int64)
        self._open = np.zeros(INDICES, bool)  # its newest row may take a newer one: no event for it since
        self._activity = np.zeros(INDICES, np.int32)  # the activity of its newest row (:func:`activity`)
        self._queued = np.zeros(INDICES, np.int32)  # its rows queued
        self._starts: list[int] = []  # the blocks that start a batch (``repeats``), in order
        self.rows = 0  # request rows and events queued
        self.bytes = 0
        self.events = 0  # of which events (never dropped: the bounds are on the rows)
        self.event_bytes = 0
        self.coalesced = 0  # rows that replaced a queued row of their soldier
        self.dropped = 0  # rows dropped from a full backlog
        self.events_dropped = 0  # events dropped: superseded reactions and keys, cancelled creations
        self._serial = 0  # of the events queued
        self._dead = 0  # events dropped but still in ``_items`` (skipped when taken)
        self._reaction: dict[int, _Event] = {}  # each soldier's reaction queued, the oldest first
        self._life: dict[int, _Event] = {}  # each soldier's newest create or remove queued since a sync
        self._key: _Event | None = None  # a key queued
        self._logged_drops, self._logged_at = 0, -np.inf
        self._logged_event_drops = 0

    def __bool__(self) -> bool:
        return bool(self._items)

    def __len__(self) -> int:
        return self.rows

    def describe(self) -> str:
        return (
            f"backlog {self.rows}/{self.max_rows} rows {self.bytes >> 10}/{self.max_bytes >> 10} KiB, "
            f"{self.coalesced} coalesced, {self.dropped} dropped, {self.events_dropped} events dropped"
        )

    def put(self, ops: list[req.Op]) -> bool:
        """Queue a message's operations; True if the backlog was empty (the loop is to be woken)."""
        with self._lock:
            empty = not self._items
            for op in ops:
                if op["op"] == "requests":
                    self._put_rows(op["rows"])
                else:
                    self._put_event(op)
            if self._over() or self._events_over():
                self._trim()
        return empty

    def _over(self) -> bool:
        """Whether the request rows are over the bounds (events, never dropped, do not count: a backlog
        full of them would otherwise drop every new row, the newest state, on arrival)."""
        return self.rows - self.events > self.max_rows or self.bytes - self.event_bytes > self.max_bytes

    def _events_over(self) -> bool:
        return self.events > self.max_rows or self.event_bytes > self.max_bytes

    def take(self) -> req.Op | None:
        """The oldest operation: an event, or the request rows at the head (up to ``merge_rows`` whole
        blocks of them, the first whatever its size) as one ``requests`` operation; None when empty."""
        with self._lock:
            while self._items and isinstance(self._items[0], _Event) and not self._items[0].queued:
                self._items.popleft()  # dropped
                self._dead -= 1
            if not self._items:
                return None
            head = self._items.popleft()
            if isinstance(head, _Event):
                self._unqueue(head)
                return head.op
            blocks = [head]
            n = len(head.rows)
            while (
                self._items
                and isinstance(nxt := self._items[0], _Block)
                and not nxt.repeats
                and n + len(nxt.rows) <= self.merge_rows
            ):
                self._items.popleft()
                blocks.append(nxt)
                n += len(nxt.rows)
            for b in blocks:
                self._release(b)
            rows = blocks[0].rows if len(blocks) == 1 else np.concatenate([b.rows for b in blocks])
            return {"op": "requests", "rows": rows}

    def _put_rows(self, rows: np.ndarray) -> None:
        idx = rows["index"].astype(np.int64)
        if len(idx) > 1:  # the last row per soldier wins within the message
            _, first = np.unique(idx[::-1], return_index=True)
            if len(first) < len(idx):
                keep = np.sort(len(idx) - 1 - first)
                self.coalesced += len(idx) - len(keep)
                rows, idx = rows[keep], idx[keep]
        act = activity(rows)
        # the newest row takes a row of its activity, or any once the soldier has an older row queued
        hit = self._open[idx] & ((self._activity[idx] == act) | (self._queued[idx] > 1))
        if hit.any():
            at_block, at_row = self._latest_block[idx[hit]], self._latest_row[idx[hit]]
            for b in np.unique(at_block).tolist():
                mine = at_block == b
                self._blocks[b].rows[at_row[mine]] = rows[hit][mine]
            self._activity[idx[hit]] = act[hit]
            self.coalesced += int(hit.sum())
            rows, idx, act = rows[~hit], idx[~hit], act[~hit]
        if not len(rows):
            return
        rows = np.array(rows, ENTITY_REQUEST_DTYPE)  # the message's rows are read-only
        # a soldier with a row of another activity queued: its row goes to the next batch after that row's
        # (the first block after it that starts a batch), the others' to a new block at the end
        last = self._latest_block[idx]
        again = self._open[idx]
        at = np.searchsorted(self._starts, last[again], side="right")
        after = np.full(len(idx), self._next_id)
        after[again] = np.asarray([*self._starts, self._next_id])[at]
        for b in np.unique(after).tolist():
            mine = after == b
            self._append(b, rows[mine], idx[mine], act[mine], repeats=bool(again[mine].any()))

    def _append(self, b: int, rows: np.ndarray, idx: np.ndarray, act: np.ndarray, repeats: bool) -> None:
        """Queue rows in block ``b``, or in a new block at the end if there is none (``repeats``: one that
        starts a batch)."""
        block = self._blocks.get(b)
        if block is None:
            block = _Block(b, rows[:0], repeats)
            self._next_id += 1
            self._blocks[b] = block
            self._items.append(block)
            if repeats:
                self._starts.append(b)
        start = len(block.rows)
        block.rows = np.concatenate([block.rows, rows]) if start else rows
        self._latest_block[idx], self._latest_row[idx], self._open[idx] = b, start + np.arange(len(idx)), True
        self._activity[idx] = act
        self._queued[idx] += 1  # (a soldier has one row in a message, and in a block)
        self.rows += len(idx)
        self.bytes += len(idx) * ROW_BYTES

    def _put_event(self, op: req.Op) -> None:
        index = _soldier(op)
        kind = op["op"]
        if kind == "key":
            if self._key is not None:  # the queued one asks for the same key batch, no earlier
                self.events_dropped += 1
                return
        elif kind == "fence":  # it follows its message's creations and removals; rows may pass it
            pass
        elif index is not None:
            if kind in ("create", "remove") and self._cancels(index, kind):
                return
            self._open[index] = False  # its next row goes after the event
        else:  # a sync (or a malformed event): no row crosses it
            self._open[:] = False
            self._life.clear()  # it may create any soldier
        event = _Event(op, self._serial)
        self._serial += 1
        if kind == "key":
            self._key = event
        elif index is not None and kind == "react":
            if (old := self._reaction.pop(index, None)) is not None:
                self._drop_event(old)  # a transient: the newer one says what the soldier reacts to now
            self._reaction[index] = event
        elif index is not None and kind in ("create", "remove"):
            event.prev = self._life.get(index)
            self._life[index] = event
        self._items.append(event)
        size = _event_bytes(op)
        self.rows += 1
        self.bytes += size
        self.events += 1
        self.event_bytes += size

    def _cancels(self, index: int, kind: str) -> bool:
        """Whether a create or remove of ``index`` goes without being queued: a remove cancels the soldier's
        create queued right after a remove of it (so the create succeeds: the soldier lived and died in the
        backlog, and the front-end, which removed it already, would merge none of its poses), with the
        reaction queued since; a create after a queued create, or a remove after a queued remove, would
        fail on the shard anyway (the front-end checked the create's figure and weapon: its own manager
        created the soldier from the same data)."""
        last = self._life.get(index)
        if last is None or not last.queued:
            return False
        if last.op["op"] == kind:
            self.events_dropped += 1
            return True
        if kind == "create" or last.prev is None:  # the create may fail: the soldier may be on the shard
            return False
        self._drop_event(last)
        reaction = self._reaction.get(index)
        if reaction is not None and reaction.serial > last.serial:
            del self._reaction[index]
            self._drop_event(reaction)
        self.events_dropped += 1  # the remove
        return True

    def _unqueue(self, event: _Event) -> None:
        """Take an event off the books (taken, or dropped)."""
        event.queued = False
        index = _soldier(event.op)
        if index is not None and self._reaction.get(index) is event:
            del self._reaction[index]
        if index is not None and self._life.get(index) is event:
            prev = event.prev
            if prev is not None and prev.queued:
                self._life[index] = prev
            else:
                del self._life[index]
        if self._key is event:
            self._key = None
        size = _event_bytes(event.op)
        self.rows -= 1
        self.bytes -= size
        self.events -= 1
        self.event_bytes -= size

    def _drop_event(self, event: _Event) -> None:
        """Drop a queued event: it stays in the queue, skipped, until over half the queue is such."""
        self._unqueue(event)
        self.events_dropped += 1
        self._dead += 1
        if self._dead > 64 and 2 * self._dead > len(self._items):
            self._compact()

    def _compact(self) -> None:
        """Forget the dropped events, but one between two blocks: it keeps them apart (a block after an
        event may hold rows of soldiers the block before it holds too)."""
        items: collections.deque[_Block | _Event] = collections.deque()
        dead = 0
        for x in self._items:
            if isinstance(x, _Event) and not x.queued:
                if not items or not isinstance(items[-1], _Block):
                    continue
                dead += 1
            items.append(x)
        self._items, self._dead = items, dead

    def _release(self, block: _Block) -> None:
        """Forget a block taken or emptied: its soldiers' newer rows start a new block."""
        self._forget(block)
        idx = block.rows["index"].astype(np.int64)
        mine = idx[self._latest_block[idx] == block.id]
        self._latest_block[mine] = -1
        self._open[mine] = False
        np.subtract.at(self._queued, idx, 1)
        self.rows -= len(idx)
        self.bytes -= len(idx) * ROW_BYTES

    def _trim(self) -> None:
        """Drop rows, the oldest first, until the backlog is within its bounds: first the rows a later row
        of their soldier supersedes, then any; and while the events alone are over the bounds, the oldest
        reactions (transients). Other events stay (a backlog of them over the bounds is logged)."""
        before, events_before = self.dropped, self.events_dropped
        while self._events_over() and self._reaction:
            self._drop_event(self._reaction.pop(next(iter(self._reaction))))
        for superseded_only in (True, False):
            for block in [b for b in self._items if isinstance(b, _Block)]:
                if not self._over():
                    break
                self._drop(block, superseded_only)
        dropped = self.dropped - before
        if dropped:
            self._items = collections.deque(
                b for b in self._items if not isinstance(b, _Block) or len(b.rows)
            )
        over = self.events > self.max_rows or self.event_bytes > self.max_bytes
        now = time.monotonic()
        if now - self._logged_at >= LOG_EVERY_S:
            log.warning(
                "fabric_backlog_full",
                dropped=self.dropped - self._logged_drops,
                dropped_now=dropped,
                events_dropped=self.events_dropped - self._logged_event_drops,
                events_dropped_now=self.events_dropped - events_before,
                rows=self.rows,
                bytes=self.bytes,
                events_over_bound=over,
            )
            self._logged_drops, self._logged_at = self.dropped, now
            self._logged_event_drops = self.events_dropped

    def _drop(self, block: _Block, superseded_only: bool) -> None:
        idx = block.rows["index"].astype(np.int64)
        newest = self._latest_block[idx] == block.id
        drop = ~newest if superseded_only else np.ones(len(idx), bool)
        rows, size = self.rows - self.events, self.bytes - self.event_bytes
        excess = max(rows - self.max_rows, -(-(size - self.max_bytes) // ROW_BYTES))
        drop &= np.cumsum(drop) <= excess  # the oldest of them, as many as it takes
        if not drop.any():
            return
        gone = idx[drop & newest]
        self._latest_block[gone] = -1
        self._open[gone] = False
        np.subtract.at(self._queued, idx[drop], 1)
        n = int(drop.sum())
        self.dropped += n
        self.rows -= n
        self.bytes -= n * ROW_BYTES
        block.rows = block.rows[~drop]
        kept = idx[~drop]
        still = self._latest_block[kept] == block.id
        self._latest_row[kept[still]] = np.flatnonzero(still)
        if not len(block.rows):
            self._forget(block)

    def _forget(self, block: _Block) -> None:
        del self._blocks[block.id]
        if block.repeats:
            self._starts.remove(block.id)


def activity(rows: np.ndarray) -> np.ndarray:
    """What each request row asks its soldier to do, as one number: posture, weapon, moving or still, and
    ``immediate``. Rows of one activity differ in heading, speed or position only: the newer says all."""
    speed = np.hypot(rows["velocity"][:, 0], rows["velocity"][:, 1])  # Performer: Z up
    return (
        rows["appearance"].astype(np.int32)
        | rows["weapon"].astype(np.int32) << 8
        | (speed > MOVING_EPS).astype(np.int32) << 16
        | (rows["immediate"] != 0).astype(np.int32) << 17
    )


def _soldier(op: req.Op) -> int | None:
    """The soldier an event is for; None for a key, a sync (or a malformed event)."""
    index = op.get("index")
    return index if isinstance(index, int) and 0 <= index < INDICES and op["op"] != "key" else None


def _event_bytes(op: req.Op) -> int:
    """An event's size in the backlog, estimated: a sync's rows and soldiers, else a small map."""
    if op["op"] != "sync":
        return 64
    rows = op.get("rows")
    soldiers = op.get("soldiers")
    return (
        64
        + (rows.nbytes if isinstance(rows, np.ndarray) else 0)
        + 48 * (len(soldiers) if isinstance(soldiers, list) else 0)
    )
