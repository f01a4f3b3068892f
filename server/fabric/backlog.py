"""A shard's backlog of fabric requests: bounded, the entity requests coalesced per soldier (issue 21).

Under overload a shard's requests used to queue without bound (a 20,000-soldier run: a request waited 3.7 s
between arriving and being taken). An entity request is a DIS-like *state* (posture, weapon, velocity,
heading, position): a newer one for a soldier supersedes an older one not applied yet, as within one batch
(``SoldierManager.apply_requests``: the last row per soldier wins). So a soldier's new row overwrites its
queued one in place (taken as early as the old one was), unless an *event* for it (create, remove, react)
or a sync came in between: events are never coalesced, dropped or reordered, among themselves or against
a soldier's rows (a remove after a request stays after it). Without events the rows are at most one per
soldier; when the backlog is full anyway (``max_rows`` rows and events, ``max_bytes``), the oldest rows
that a later row of their soldier supersedes go first, then the oldest rows: counted and logged.

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

log = get_logger("fabric")
INDICES = 1 << 16  # soldier indices are uint16 in a request row
ROW_BYTES = ENTITY_REQUEST_DTYPE.itemsize
MAX_ROWS = 32768  # rows and events queued, at least: a shard's is two per soldier (max_soldiers)
MAX_BYTES = 8 << 20  # request rows (33 bytes each) and events (their size, estimated) queued
MERGE_ROWS = 256  # consecutive request rows taken as one batch (a batch costs ~2 ms whatever its size)
LOG_EVERY_S = 1.0  # a drop is logged at most this often (with the drops since the last log)


@dataclass
class _Block:
    """Request rows queued together (one message's, less those that went to older rows)."""

    id: int
    rows: np.ndarray


class Backlog:
    """The operations a shard has not taken yet, in order, the entity requests coalesced per soldier."""

    def __init__(
        self, max_rows: int = MAX_ROWS, max_bytes: int = MAX_BYTES, merge_rows: int = MERGE_ROWS
    ) -> None:
        self.max_rows, self.max_bytes, self.merge_rows = max_rows, max_bytes, merge_rows
        self._lock = threading.Lock()
        self._items: collections.deque[_Block | req.Op] = collections.deque()
        self._blocks: dict[int, _Block] = {}
        self._next_id = 0
        self._latest_block = np.full(INDICES, -1, np.int64)  # the block of each soldier's newest queued row
        self._latest_row = np.zeros(INDICES, np.int64)
        self._open = np.zeros(INDICES, bool)  # its newest row may take a newer one: no event for it since
        self.rows = 0  # request rows and events queued
        self.bytes = 0
        self.events = 0  # of which events (never dropped: the bounds are on the rows)
        self.event_bytes = 0
        self.coalesced = 0  # rows that replaced a queued row of their soldier
        self.dropped = 0  # rows dropped from a full backlog
        self._logged_drops, self._logged_at = 0, -np.inf

    def __bool__(self) -> bool:
        return bool(self._items)

    def __len__(self) -> int:
        return self.rows

    def describe(self) -> str:
        return (
            f"backlog {self.rows}/{self.max_rows} rows {self.bytes >> 10}/{self.max_bytes >> 10} KiB, "
            f"{self.coalesced} coalesced, {self.dropped} dropped"
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
            if self._over():
                self._trim()
        return empty

    def _over(self) -> bool:
        """Whether the request rows are over the bounds (events, never dropped, do not count: a backlog
        full of them would otherwise drop every new row, the newest state, on arrival)."""
        return self.rows - self.events > self.max_rows or self.bytes - self.event_bytes > self.max_bytes

    def take(self) -> req.Op | None:
        """The oldest operation: an event, or the request rows at the head (up to ``merge_rows`` whole
        blocks of them, the first whatever its size) as one ``requests`` operation; None when empty."""
        with self._lock:
            if not self._items:
                return None
            head = self._items.popleft()
            if not isinstance(head, _Block):
                self.rows -= 1
                self.events -= 1
                size = _event_bytes(head)
                self.bytes -= size
                self.event_bytes -= size
                return head
            blocks = [head]
            n = len(head.rows)
            while (
                self._items
                and isinstance(nxt := self._items[0], _Block)
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
        hit = self._open[idx]
        if hit.any():
            at_block, at_row = self._latest_block[idx[hit]], self._latest_row[idx[hit]]
            for b in np.unique(at_block).tolist():
                mine = at_block == b
                self._blocks[b].rows[at_row[mine]] = rows[hit][mine]
            self.coalesced += int(hit.sum())
            rows, idx = rows[~hit], idx[~hit]
        if not len(rows):
            return
        copy = np.array(rows, ENTITY_REQUEST_DTYPE)  # the message's rows are read-only
        block = _Block(self._next_id, copy)
        self._next_id += 1
        self._blocks[block.id] = block
        self._items.append(block)
        self._latest_block[idx], self._latest_row[idx], self._open[idx] = block.id, np.arange(len(idx)), True
        self.rows += len(idx)
        self.bytes += len(idx) * ROW_BYTES

    def _put_event(self, op: req.Op) -> None:
        index = op.get("index")
        if op["op"] == "key":
            pass  # no soldier's
        elif isinstance(index, int) and 0 <= index < INDICES:
            self._open[index] = False  # its next row goes after the event
        else:  # a sync (or a malformed event): no row crosses it
            self._open[:] = False
        self._items.append(op)
        size = _event_bytes(op)
        self.rows += 1
        self.bytes += size
        self.events += 1
        self.event_bytes += size

    def _release(self, block: _Block) -> None:
        """Forget a block taken or emptied: its soldiers' newer rows start a new block."""
        del self._blocks[block.id]
        idx = block.rows["index"].astype(np.int64)
        mine = idx[self._latest_block[idx] == block.id]
        self._latest_block[mine] = -1
        self._open[mine] = False
        self.rows -= len(idx)
        self.bytes -= len(idx) * ROW_BYTES

    def _trim(self) -> None:
        """Drop rows, the oldest first, until the backlog is within its bounds: first the rows a later row
        of their soldier supersedes, then any. Events stay (a backlog of events alone is logged)."""
        before = self.dropped
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
                rows=self.rows,
                bytes=self.bytes,
                events_over_bound=over,
            )
            self._logged_drops, self._logged_at = self.dropped, now

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
        n = int(drop.sum())
        self.dropped += n
        self.rows -= n
        self.bytes -= n * ROW_BYTES
        block.rows = block.rows[~drop]
        kept = idx[~drop]
        still = self._latest_block[kept] == block.id
        self._latest_row[kept[still]] = np.flatnonzero(still)
        if not len(block.rows):
            del self._blocks[block.id]


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
