"""The pose board: every soldier's newest wire-ready pose, written and quantised once per tick.

The tick loop publishes each tick's poses here once; every session's writer encodes from it whenever its
socket can take bytes (latest-wins, see :mod:`server.session`), so no client repeats the quantising and a
stalled client never holds more than one batch.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from typing import TYPE_CHECKING

import numpy as np

from protocol import fused
from protocol.bitpack import scratch, set_rows, take_rows
from protocol.shared_encode import SharedEncodes
from protocol.update_table import UpdateTable
from protocol.updates import _cols as _span  # a run of rows as a slice
from protocol.updates import quantise
from server.logging import get_logger
from server.soldier.manager import TickUpdate

if TYPE_CHECKING:
    from server.startup import ServerWorld

log = get_logger("pose_board")


class PoseBoard:
    """The newest wire-ready pose of every soldier (Performer units, table order), written once per tick.

    The tick also quantises each pose once (``codes``, the update table's field values) so that no client
    repeats that work: a session's encoder only diffs and packs the shared codes. ``version[i]`` is the board
    publish (``serial``) at which soldier ``i``'s *codes* last changed (a pose that moved less than one
    quantisation step keeps its version), so sessions send — and encode — only what changed on the wire
    since the publish of their last write; an idle soldier costs a client nothing. All figure sets of one
    library share the pose shape, so one set of arrays serves every update table (``table_of`` says which).

    ``tick`` is the wire's tick number, the tick whose poses the board holds: it counts the tick loop's
    publishes. An out-of-cycle publish (:meth:`TtesServer.answer_requests`: the next tick's update of the
    soldiers with new requests, released early) bumps ``serial`` and labels its frames with that next tick,
    so a client sees every tick once, in order, and the tick that follows sends those soldiers only if their
    pose changed again. ``tick_serial`` is the serial of the tick loop's last publish: a writer that encodes
    after an answer was published labels the rows of that tick with ``ticks`` and only the answered rows
    (``version > tick_serial``) with the next tick (:meth:`labels`).
    """

    def __init__(self, ndofs: int, nfigs: int, capacity: int = 64, *, poses: bool = True) -> None:
        self.ndofs, self.nfigs = ndofs, nfigs
        # the Jack-unit poses (``dofs``, ``positions``, ``orientations``) kept beside the codes: only tests
        # and tools read them; a shard's board goes without (:meth:`drop_poses`: 0.6-0.9 ms a tick at 10,000)
        self.poses = poses
        self.tick = 0
        self.ticks = 0  # the tick loop's publishes
        self.serial = 0  # publishes, in and out of cycle: what versions count
        self.tick_serial = 0  # the serial of the tick loop's last publish
        self.capacity = 0
        self.dofs = np.zeros((0, ndofs))
        self.positions = np.zeros((0, nfigs, 3))
        self.orientations = np.zeros((0, nfigs, 4))
        # quantised fields, width set by the first table quantised: int32, or uint16 on a board fed codes
        # (a front-end's: its batches carry 16-bit codes), half the bytes for its merges and gathers
        self.codes = np.zeros((0, 0), np.int32)
        self.version = np.zeros(0, np.int64)
        self.valid = np.zeros(0, bool)
        self.table_of = np.zeros(0, np.int32)
        self.rows_published = 0  # soldiers the ticks handed in
        self.rows_changed = 0  # of which had new codes (what clients are sent)
        self._gathered: tuple[int, np.ndarray, np.ndarray] | None = None  # codes_of: (serial, rows, codes)
        self._grow(capacity)

    def _grow(self, n: int) -> None:
        old = self.capacity
        if n <= old:
            return

        def pad(a: np.ndarray, fill: float = 0) -> np.ndarray:
            out = np.full((n, *a.shape[1:]), fill, a.dtype)
            out[:old] = a
            return out

        if self.poses:
            self.dofs, self.positions, self.orientations = (
                pad(self.dofs),
                pad(self.positions),
                pad(self.orientations),
            )
        self.codes = pad(self.codes)
        self.version, self.valid, self.table_of = pad(self.version), pad(self.valid), pad(self.table_of, -1)
        self.capacity = n

    def _code_width(self, nfields: int, dtype: type = np.int32) -> None:
        if self.codes.shape[1] != nfields or self.codes.dtype != dtype:
            if not self.valid.any():
                self.codes = np.zeros((self.capacity, nfields), dtype)
            elif self.codes.shape[1] != nfields:
                raise ValueError(f"update tables of {self.codes.shape[1]} and {nfields} fields on one board")

    def drop_poses(self) -> None:
        """Keep the codes alone from now on: ``dofs``, ``positions`` and ``orientations`` are emptied and no
        publish writes them (a shard's board: its batches carry codes, and nothing on it reads the poses)."""
        self.poses = False
        self.dofs, self.positions, self.orientations = (
            a[:0].copy() for a in (self.dofs, self.positions, self.orientations)
        )

    def ensure(self, index: int) -> None:
        if index >= self.capacity:
            self._grow(max(index + 1, 2 * self.capacity))

    def add(self, index: int, table: int) -> None:
        """A soldier (possibly a reused index): no pose until its first tick."""
        self.ensure(index)
        self.valid[index] = False
        self.table_of[index] = table

    def remove(self, index: int) -> None:
        if index < self.capacity:
            self.valid[index] = False
            self.table_of[index] = -1

    def unknown(self, rows: np.ndarray) -> None:
        """These soldiers' poses are not known here any more (a front-end stopped hearing their block, its
        rows go stale): none is sent until the next publish of it brings it."""
        rows = np.asarray(rows, np.int64)
        self.valid[rows[rows < self.capacity]] = False

    def labels(self, indices: np.ndarray) -> np.ndarray:
        """The wire tick of each soldier's pose on the board: the tick loop's last tick, or the next tick for
        a soldier answered since (an out-of-cycle publish)."""
        return self.ticks + (self.version[indices] > self.tick_serial)

    def codes_of(self, rows: np.ndarray) -> np.ndarray:
        """``codes[rows]``, read-only, one gather per publish for every session that asks for the same rows
        (the clients of one group, whose encodes the memo shares: a memo hit never reads the codes, and a
        10,000-soldier gather per client per tick cost each extra client about as much as its memo hit)."""
        hit = self._gathered
        if hit is not None and hit[0] == self.serial and np.array_equal(hit[1], rows):
            return hit[2]
        codes = take_rows(self.codes, rows)
        codes.setflags(write=False)
        self._gathered = (self.serial, np.array(rows, copy=True), codes)
        return codes

    def publish(
        self, update: TickUpdate, world: ServerWorld, *, between: bool = False, again: bool = False
    ) -> int:
        """Take one tick's poses (converted and quantised per figure set); returns the number of soldiers
        whose codes changed (0: nothing for any client to send). ``between``: an out-of-cycle update, the
        next tick's, released early; ``again``: more of the tick just published (the soldiers whose requests
        arrived while it sampled, or the rest of the tick after them, ``TtesServer.run_tick``), labelled
        with its number."""
        self.serial += 1
        if not between:
            self.ticks += 0 if again else 1
            self.tick_serial = self.serial
        self.tick = self.ticks + 1 if between else self.ticks
        n = len(update)
        if n == 0:
            return 0
        assert world.manager is not None
        idx = np.asarray(update.indices, np.int64)
        self.ensure(int(idx.max()))
        fset = world.manager.table.fset[idx]
        sets = world.sets
        groups = [np.arange(n)] if len(sets) == 1 else [np.flatnonzero(fset == k) for k in range(len(sets))]
        changed = 0
        for k, sel in enumerate(groups):
            if len(sel) == 0:
                continue
            part = update if len(sel) == n else update.select(sel)
            table = sets[k].table
            rows = idx[sel]
            q = None if self.poses else sets[k].converter.codes(part)  # work buffers: copied below
            if q is not None:  # (a board without poses keeps no Jack-unit arrays: the codes in one pass)
                self._code_width(q.shape[1])
                changed += self._store(rows, q, table.table_id)
                continue
            ju = sets[k].converter.convert(part, reuse=True)
            dofs, positions, orientations = ju.dofs, ju.positions, ju.orientations
            q, ok = _quantise_rows(table, dofs, positions, orientations)
            self._code_width(q.shape[1])
            if not ok.all():  # a bug upstream (non-finite pose): never let it reach a client or stop the tick
                log.error("bad_pose", soldiers=rows[~ok][:8].tolist(), count=int((~ok).sum()))
                self.valid[rows[~ok]] = False
                rows, q, dofs, positions, orientations = (
                    a[ok] for a in (rows, q, dofs, positions, orientations)
                )
            if self.poses:
                at = _span(rows)
                self.dofs[at] = dofs
                self.positions[at] = positions
                self.orientations[at] = orientations
            changed += self._store(rows, q, table.table_id)
        self.rows_published += n
        self.rows_changed += changed
        return changed

    def publish_codes(self, rows: np.ndarray, tables: np.ndarray, codes: np.ndarray, tick: int) -> int:
        """Take poses already quantised elsewhere (a front-end's batches from the shards,
        :mod:`server.fabric`), labelled ``tick`` on the wire (several publishes may share one tick, as an
        out-of-cycle publish shares the next tick's); returns the soldiers whose codes changed. The board's
        Jack-unit arrays keep their last values for these rows."""
        self.serial += 1
        self.ticks = self.tick = tick
        self.tick_serial = self.serial  # every row of it is labelled ``tick`` (labels)
        if len(rows) == 0:
            return 0
        rows = np.asarray(rows, np.int64)
        self.ensure(int(rows.max()))
        self._code_width(codes.shape[1], np.uint16 if codes.dtype == np.uint16 else np.int32)
        changed = 0
        tables = np.asarray(tables, np.int32)
        first = int(tables[0])
        if (tables == first).all():  # one table (the usual crowd): no copies of the rows and codes per table
            changed = self._store(rows, codes, first)
        else:
            for t in np.unique(tables).tolist():
                sel = tables == t
                changed += self._store(rows[sel], codes[sel], t)
        self.rows_published += len(rows)
        self.rows_changed += changed
        return changed

    def _as_codes(self, q: np.ndarray) -> np.ndarray:
        """``q`` in the board's dtype: a uint16 board given codes past 16 bits turns int32 first."""
        if self.codes.dtype == np.uint16 and not _fits_u16(q):
            self.codes = self.codes.astype(np.int32)
        return np.ascontiguousarray(q, self.codes.dtype)

    def _store(self, rows: np.ndarray, q: np.ndarray, table_id: int) -> int:
        """Write codes of one table; bump the version of the rows whose codes (or table) changed."""
        at = _span(rows)  # a run of rows (every soldier due, the usual moving crowd): views, not gathers
        if q.dtype != self.codes.dtype:
            q = self._as_codes(q)
        new = ~self.valid[at] | (self.table_of[at] != table_id)
        if isinstance(at, slice):
            new |= _rows_differ(self.codes[at], q)
            self.codes[at] = q
        elif fused.AVAILABLE and q.dtype == self.codes.dtype and q.shape[1] == self.codes.shape[1]:
            differ = np.empty(len(at), bool)  # (scattered rows: compared and written in one pass)
            fused.kernel("store_rows")(self.codes, at, q, differ)
            new |= differ
        else:  # a shard's soldiers (every N-th index), a front-end's merge: each row moved whole
            new |= _rows_differ(take_rows(self.codes, at), q)
            set_rows(self.codes, at, q)
        self.table_of[at] = table_id
        self.valid[at] = True
        moved = rows[new] if not new.all() else rows
        self.version[moved] = self.serial
        return len(moved)


def _fits_u16(q: np.ndarray) -> bool:
    return not q.size or (int(q.min()) >= 0 and int(q.max()) <= 0xFFFF)


def _rows_differ(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(n,) bool: ``(a != b).any(axis=1)`` of (n, F) arrays, compared eight bytes at a time where the rows
    allow, the rows' comparisons OR-ed as 8-byte words one column at a time (numpy's reduction along a short
    last axis costs about twice as much)."""
    words = a.shape[1] and (a.shape[1] * a.itemsize) % 8 == 0 and a.dtype == b.dtype
    if words and a.flags.c_contiguous and b.flags.c_contiguous:  # eight bytes a comparison: half the passes
        a, b = a.view(np.uint64), b.view(np.uint64)
    d = a != b
    if d.shape[1] == 0 or d.shape[1] % 8 or not d.flags.c_contiguous:
        return d.any(axis=1)
    words = d.view(np.uint64)
    out = words[:, 0].copy()
    for k in range(1, words.shape[1]):
        out |= words[:, k]
    return out != 0


def _quantise_rows(
    table: UpdateTable, dofs: np.ndarray, positions: np.ndarray, orientations: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """``(codes, ok)``: the poses quantised for ``table`` (a work buffer, valid until the next publish);
    ``ok`` is False for rows that cannot be (non-finite values, zero quaternion), whose codes are 0. The row
    check runs only when quantising fails."""
    out = scratch().get("board.codes", (len(dofs), table.layout.nfields), np.int32)  # copied by _store
    try:
        return quantise(table, dofs, positions, orientations, out), np.ones(len(dofs), bool)
    except ValueError:
        norm = np.linalg.norm(orientations, axis=-1)
        ok = np.isfinite(dofs).all(axis=1) & np.isfinite(positions).all(axis=(1, 2))
        ok &= np.isfinite(norm).all(axis=1) & (norm >= 1e-9).all(axis=1)
        q = quantise(table, dofs[ok], positions[ok], orientations[ok])
        full = np.zeros((len(dofs), q.shape[1]), np.int32)
        full[ok] = q
        return full, ok


class BoardRef:
    """Where sessions find the board (it exists once the motion library does), and the server's one memo of
    joint-update encodes: clients in the same delta state share one encode per publish."""

    def __init__(self) -> None:
        self.board: PoseBoard | None = None
        # a front-end's: told what a client subscribes to (None: a client unsubscribed or left), so that the
        # soldiers no client watched are brought onto the board before its writer encodes them
        self.on_watch: Callable[[np.ndarray | None], None] | None = None
        # TTES_SHARED_ENCODES=0: every client encodes on its own (the A/B switch of bench/bench_fanout.py)
        self.encodes = None if os.environ.get("TTES_SHARED_ENCODES") == "0" else SharedEncodes()
