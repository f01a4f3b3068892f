"""Figure 10's double buffer, once: the link's reader writes the newest pose of each soldier, a consumer
(a renderer, possibly in another thread) swaps the fresh rows out."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from protocol.events import JointUpdates
from protocol.update_table import UpdateTable


@dataclass
class UpdateBatch:
    """Fresh poses of one update table since the last swap (server indices, protocol units)."""

    table: int
    indices: np.ndarray
    dofs: np.ndarray
    positions: np.ndarray
    orientations: np.ndarray


class UpdateBuffer:
    """Figure 10's double buffer (``buf[2]``, ``sflag``, ``buffer``) for every soldier of one update table:
    the reader writes the newest pose of each soldier into the *back* buffer and flags it; a flip makes it the
    front, whose flagged rows the consumer takes while the reader fills the other one."""

    def __init__(self, table: UpdateTable) -> None:
        self.table = table
        self.capacity = 0
        d, g = table.ndofs, table.nfigures
        self.dofs = np.zeros((2, 0, d))
        self.positions = np.zeros((2, 0, g, 3))
        self.orientations = np.zeros((2, 0, g, 4))
        self.fresh = np.zeros((2, 0), bool)
        self.back = 0

    def _grow(self, needed: int) -> None:
        """Bigger arrays; only the back buffer's flags carry over (the front's rows were handed out)."""
        cap = max(needed, 2 * self.capacity, 16)
        pad = cap - self.capacity
        self.dofs = np.concatenate([self.dofs, np.zeros((2, pad, *self.dofs.shape[2:]))], axis=1)
        self.positions = np.concatenate(
            [self.positions, np.zeros((2, pad, *self.positions.shape[2:]))], axis=1
        )
        self.orientations = np.concatenate(
            [self.orientations, np.zeros((2, pad, *self.orientations.shape[2:]))], axis=1
        )
        fresh = np.zeros((2, cap), bool)
        fresh[self.back, : self.capacity] = self.fresh[self.back]
        self.fresh = fresh
        self.capacity = cap

    def write(self, ev: JointUpdates) -> None:
        """Reader side: newest pose of each soldier into the back buffer."""
        idx = np.asarray(ev.indices, np.int64)
        if not len(idx):
            return
        if idx.max() >= self.capacity:
            self._grow(int(idx.max()) + 1)
        b = self.back
        self.dofs[b, idx] = ev.dofs
        self.positions[b, idx] = ev.positions
        self.orientations[b, idx] = ev.orientations
        self.fresh[b, idx] = True

    def flip(self) -> UpdateBatch | None:
        """Consumer side: make the back buffer the front and take its fresh rows (None if there are none)."""
        front = self.back
        self.back ^= 1
        rows = np.flatnonzero(self.fresh[front])
        if not len(rows):
            return None
        self.fresh[front, rows] = False
        return UpdateBatch(
            self.table.table_id,
            rows,
            self.dofs[front, rows],
            self.positions[front, rows],
            self.orientations[front, rows],
        )
