"""What a front-end's clients watch, and the newest codes of the soldiers none of them watches (issue 21).

A front-end receives every shard's batches, but its clients subscribe to a part of the soldiers (each load
test client to its own). Merging every row into the pose board (a gather and compare of the 64 fields, the
versions, the scatter) cost each front-end O(all soldiers) a tick — 8.7 ms at 32,000 and 14.9 ms at 48,000
on the 16-core machine — so adding front-ends did not scale. Now only the rows some client watches go to
the board; the others' newest codes go to a plain array (one scatter, ~25 times cheaper) and are brought
onto the board when a client starts watching the soldier, before its writer encodes: a new subscription
gets the soldier's current pose in its next update, and the clients' bytes are those of before.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterable

import numpy as np

from server.fabric.batch import Batch
from server.pose_board import PoseBoard


class Watch:
    """The soldiers some client of this front-end subscribes to (``watched``: a superset, recounted after
    an unsubscription) and, for the others, the newest codes the board lacks (``held``)."""

    def __init__(self, n: int) -> None:
        self.watched = np.zeros(n, bool)
        self.held = np.zeros(n, bool)  # codes here newer than the board's row
        self.codes = np.zeros((n, 0), np.uint16)  # the width of the first batch's codes
        self.tables = np.zeros(n, np.uint8)
        self.stale = False  # a client stopped watching some: recount at the next merge
        self.rows_held = 0  # rows kept here rather than merged (a bench's count)

    def split(self, b: Batch) -> Batch:
        """Keep the codes of ``b``'s rows, held for those no client watches (every row of a batch that has
        any unwatched: one scatter of whole rows costs less than picking out the unwatched ones; none of a
        batch whose rows are all watched, a single front-end's usual case), and return the batch of the
        watched rows (and of indices beyond this front-end's count: the merge drops them)."""
        idx = b.indices
        if not len(idx):  # (its codes may be 0 wide: a shard before its first quantise)
            return b
        n, nf = len(self.watched), b.codes.shape[1]
        inside = idx < n
        every = bool(inside.all())
        rows = idx if every else idx[inside]
        near = self.watched[rows]
        if every and near.all():  # a watched soldier is never held (watch() clears it): nothing to keep
            return b
        if self.codes.shape[1] != nf:
            self.codes = np.zeros((n, nf), np.uint16)
            self.held[:] = False
        codes = np.ascontiguousarray(b.codes, np.uint16)
        _records(self.codes)[rows] = _records(codes) if every else _records(codes)[inside]
        self.tables[rows] = b.tables if every else b.tables[inside]
        self.held[rows] = ~near
        self.rows_held += len(rows) - int(np.count_nonzero(near))
        if not every:
            near = ~inside
            near[inside] = self.watched[rows]
        return dataclasses.replace(b, indices=idx[near], tables=b.tables[near], codes=b.codes[near])

    def watch(self, indices: np.ndarray, board: PoseBoard | None, alive: np.ndarray) -> int:
        """Clients now watch ``indices``: the held codes of the soldiers among them that no client watched
        go onto the board, labelled with its tick (one publish). Returns the soldiers whose codes changed."""
        idx = np.asarray(indices, np.int64)
        idx = idx[(idx >= 0) & (idx < len(self.watched))]
        new = np.unique(idx[~self.watched[idx]])
        self.watched[new] = True
        if board is None:  # (nothing merged yet either: nothing held)
            return 0
        rows = new[self.held[new]]
        self.held[rows] = False
        rows = rows[(rows < len(alive)) & alive[np.minimum(rows, len(alive) - 1)]]
        if not len(rows):
            return 0
        return board.publish_codes(rows, self.tables[rows], self.codes[rows], board.ticks)

    def recount(self, subscribed: Iterable[np.ndarray], board: PoseBoard | None, alive: np.ndarray) -> None:
        """After an unsubscription: ``watched`` becomes what the clients' subscriptions say (``subscribed``:
        each client's indices); the soldiers no longer watched are held from the next batch on."""
        now = np.zeros_like(self.watched)
        for sub in subscribed:
            now[sub[sub < len(now)]] = True
        self.stale = False
        added = np.flatnonzero(now & ~self.watched)
        self.watched &= now
        if len(added):
            self.watch(added, board, alive)

    def forget(self, index: int) -> None:
        """A soldier created or removed at ``index``: codes held for that index are another soldier's."""
        if 0 <= index < len(self.held):
            self.held[index] = False


def _records(codes: np.ndarray) -> np.ndarray:
    """A C-contiguous (n, F) array as n records of its rows' bytes: a fancy-indexed copy of whole rows."""
    return codes.view(np.dtype((np.void, codes.shape[1] * codes.itemsize))).reshape(len(codes))
