"""ServerSink: a Translation becomes CREATE_SOLDIER / REMOVE_SOLDIER / ENTITY_REQUESTS / REACT messages.

Slot ``k`` of the translator is the ``k``-th server index no start-up soldier (those of READY) holds, so a
DIS entity's soldier keeps one server index for the whole replay, across re-appearances, never collides with a
soldier of the start-up script, and one soldier at the last index (16383) leaves every other index usable
(issue 17). At most ``max_soldiers`` slots are used (the server's ``max_soldiers_per_client``, 4096 unless it
is told otherwise): creations beyond are dropped, counted in ``stats["dropped"]``, never sent to be refused.
The weapon figure comes from the entity type (``protocol.dis.RIFLE_FIGURES``); when the server's motion
library has no figure set for it (its update tables say which it has) the first weapon it does have stands in,
counted in ``stats["weapon_substituted"]``.

A lost link never raises out of :meth:`ServerSink.apply`: the sink keeps what its soldiers are (alive, their
rifle, their last request) and :meth:`ServerSink.rebind` gives them to a new link (a restarted server):
created again, subscribed again, their last requests sent again (:func:`client_stub.dis.reconnect.keep_linked`
reconnects with backoff and calls it). The slots keep their server indices; a soldier whose index the new
link's READY lists is taken back, not created (the same server kept it for our client id; a restarted server
whose start-up script made a soldier at that index hands us a shared soldier instead: READY does not say whose
a soldier is).

Works with any :class:`~client_stub.link.api.Link`: the trio-native client (replay, gateway) or the
stub's threaded one.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from client_stub.dis.translator import Translation
from client_stub.link.api import Link
from client_stub.link.client import LinkError
from protocol.dis import RIFLE_FIGURES
from protocol.entity import ENTITY_REQUEST_DTYPE, Reaction

FIGURE = "DI.fig"
MAX_SOLDIERS_PER_CLIENT = 4096  # the server's default max_soldiers_per_client


class ServerSink:
    """Applies translations to a link (see the module docstring)."""

    def __init__(
        self,
        link: Link,
        *,
        figure: str = FIGURE,
        subscribe: bool = False,
        max_soldiers: int = MAX_SOLDIERS_PER_CLIENT,
    ) -> None:
        self.figure = figure
        self.subscribe = subscribe
        self.max_soldiers = max_soldiers
        self.stats = {
            "created": 0,
            "removed": 0,
            "requests": 0,
            "reactions": 0,  # soldiers asked to react (REACT indices)
            "weapon_substituted": 0,
            "dropped": 0,
            "while_lost": 0,  # translations kept but not sent: the link was lost
            "relinked": 0,
            "reclaimed": 0,  # soldiers the server kept for our client id across a reconnect
        }
        self.lost = ""  # why the link was lost ("" while it works)
        self.rifle_of: dict[int, int] = {}  # live slot -> its entity's rifle (RIFLE_FIGURES index)
        self._last = np.zeros(max_soldiers, ENTITY_REQUEST_DTYPE)  # each slot's last request
        self._has_last = np.zeros(max_soldiers, bool)
        self._bind(link)

    def _bind(self, link: Link, ours: frozenset[int] = frozenset()) -> None:
        self.link = link
        taken = np.fromiter((i for i in link.ready_soldiers if i not in ours), np.int64)
        free = np.setdiff1d(np.arange(link.max_soldiers, dtype=np.int64), taken)
        self.indices = free[: self.max_soldiers]
        self.capacity = len(self.indices)
        self.base = int(self.indices[0]) if self.capacity else link.max_soldiers  # the first slot's index
        have = [t.weapon for t in link.tables.values() if t.figure == self.figure]
        self.weapons = {w: w if w in have else (have[0] if have else w) for w in RIFLE_FIGURES}
        self.weapon_of: dict[int, str] = {}  # server index -> weapon figure it was created with

    def server_index(self, slots: np.ndarray) -> np.ndarray:
        return self.indices[np.asarray(slots, np.int64)]

    def apply(self, tr: Translation) -> None:
        """Removals, then creations, then requests, then reactions (the server takes them in order on one
        stream: a shooter's FIRING request comes before his recoil, which the server plays once the rifle
        is up). Reactions are moments: a lost link loses them (the rest is kept for :meth:`rebind`)."""
        removed = [s for s in tr.removed.tolist() if s < self.capacity]
        for s in removed:
            self.rifle_of.pop(s, None)
            self._has_last[s] = False
        born = []
        for row in tr.created:
            slot = int(row["slot"])
            if slot >= self.capacity:
                self.stats["dropped"] += 1
                continue
            self.rifle_of[slot] = int(row["rifle"])
            born.append(slot)
        rows = tr.requests[tr.requests["index"] < self.capacity] if len(tr.requests) else tr.requests
        if len(rows):
            slots = rows["index"].astype(np.int64)
            self._last[slots] = rows
            self._has_last[slots] = True
        if self.lost:
            self.stats["while_lost"] += 1
            return
        reactions = [(slots[slots < self.capacity], kind) for slots, kind in
                     ((tr.recoils, Reaction.RECOIL), (tr.flinches, Reaction.FLINCH))]  # fmt: skip
        try:
            self._send(removed, born, rows, reactions)
        except LinkError as exc:
            self.lost = str(exc) or "connection lost"
            self.stats["while_lost"] += 1

    def live_slots(self) -> np.ndarray:
        """The translator slots of the live soldiers (those :meth:`live_requests` lists, in its order)."""
        return np.array(sorted(s for s in self.rifle_of if self._has_last[s]), np.int64)

    def live_requests(self) -> np.ndarray:
        """The last request of every live soldier, ``index`` its server index (what a viewer that does not
        drive them needs to place them: ``ttes web --replay``)."""
        live = self.live_slots()
        rows = self._last[live].copy()
        rows["index"] = self.indices[live] if len(live) else rows["index"]
        return rows

    def rebind(self, link: Link) -> None:
        """A new link: every live soldier created again (a restarted server) or taken back (the same server
        kept them for our client id: they are in its READY), then subscribed and requested again."""
        ours = frozenset(int(self.indices[s]) for s in self.rifle_of)
        weapon_of = self.weapon_of
        self._bind(link, ours)  # our old indices count as free: the slots keep their indices
        gone = [s for s in self.rifle_of if s >= self.capacity]
        for s in gone:
            del self.rifle_of[s]
            self.stats["dropped"] += 1
        live = sorted(self.rifle_of)
        kept = [s for s in live if int(self.indices[s]) in link.ready_soldiers]
        for s in kept:  # taken back as they were made
            index = int(self.indices[s])
            if index in weapon_of:
                self.weapon_of[index] = weapon_of[index]
        rows = self._last[live][self._has_last[live]]
        self.lost = ""
        self.stats["relinked"] += 1
        self.stats["reclaimed"] += len(kept)
        try:
            if self.subscribe and kept:
                self.link.subscribe(self.indices[kept])
            self._send([], [s for s in live if s not in set(kept)], rows)
        except LinkError as exc:
            self.lost = str(exc) or "connection lost"

    def _send(
        self,
        removed: list[int],
        born: list[int],
        rows: np.ndarray,
        reactions: Sequence[tuple[np.ndarray, Reaction]] = (),
    ) -> None:
        for s in removed:
            self.link.remove(int(self.indices[s]))
            self.stats["removed"] += 1
        fresh = []
        for slot in born:
            index = int(self.indices[slot])
            wanted = RIFLE_FIGURES[self.rifle_of[slot]]
            weapon = self.weapons[wanted]
            self.stats["weapon_substituted"] += weapon != wanted
            self.link.create(index, self.figure, weapon)
            self.weapon_of[index] = weapon
            fresh.append(index)
            self.stats["created"] += 1
        if self.subscribe and fresh:
            self.link.subscribe(fresh)
        if len(rows):
            rows = rows.copy()
            rows["index"] = self.indices[rows["index"].astype(np.int64)]
            self.link.send_requests(rows)
            self.stats["requests"] += len(rows)
        for slots, kind in reactions:
            if len(slots):
                self.link.react(self.server_index(slots), kind)
                self.stats["reactions"] += len(slots)
