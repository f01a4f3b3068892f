"""ServerSink: a Translation becomes CREATE_SOLDIER / REMOVE_SOLDIER / ENTITY_REQUESTS / REACT messages.

Server index = ``base + slot``: ``base`` is one past the soldiers the server's start-up script made (those of
READY), so a DIS entity's soldier keeps one server index for the whole replay, across re-appearances, and
never collides with a soldier someone else drives. The weapon figure comes from the entity type
(``protocol.dis.RIFLE_FIGURES``); when the server's motion library has no figure set for it (its update tables
say which it has) the first weapon it does have stands in, counted in ``stats["weapon_substituted"]``.

Works with any :class:`~client_stub.link.api.Link`: the trio-native client (replay, gateway) or the
stub's threaded one.
"""

from __future__ import annotations

import numpy as np

from client_stub.dis.translator import Translation
from client_stub.link.api import Link
from protocol.dis import RIFLE_FIGURES
from protocol.entity import Reaction

FIGURE = "DI.fig"


class ServerSink:
    """Applies translations to a link (see the module docstring)."""

    def __init__(self, link: Link, *, figure: str = FIGURE, subscribe: bool = False) -> None:
        self.link = link
        self.figure = figure
        self.subscribe = subscribe
        self.base = (max(link.ready_soldiers) + 1) if link.ready_soldiers else 0
        self.capacity = max(link.max_soldiers - self.base, 0)
        have = [t.weapon for t in link.tables.values() if t.figure == figure]
        self.weapons = {w: w if w in have else (have[0] if have else w) for w in RIFLE_FIGURES}
        self.weapon_of: dict[int, str] = {}  # server index -> weapon figure it was created with
        self.stats = {
            "created": 0,
            "removed": 0,
            "requests": 0,
            "reactions": 0,  # soldiers asked to react (REACT indices)
            "weapon_substituted": 0,
            "dropped": 0,
        }

    def server_index(self, slots: np.ndarray) -> np.ndarray:
        return np.asarray(slots, np.int64) + self.base

    def apply(self, tr: Translation) -> None:
        """Removals, then creations, then requests, then reactions (the server takes them in order on one
        stream: a shooter's FIRING request comes before his recoil, which the server plays once the rifle
        is up)."""
        for s in tr.removed.tolist():
            if s < self.capacity:
                self.link.remove(self.base + s)
                self.stats["removed"] += 1
        fresh = []
        for row in tr.created:
            slot = int(row["slot"])
            if slot >= self.capacity:
                self.stats["dropped"] += 1
                continue
            wanted = RIFLE_FIGURES[int(row["rifle"])]
            weapon = self.weapons[wanted]
            self.stats["weapon_substituted"] += weapon != wanted
            self.link.create(self.base + slot, self.figure, weapon)
            self.weapon_of[self.base + slot] = weapon
            fresh.append(self.base + slot)
            self.stats["created"] += 1
        if self.subscribe and fresh:
            self.link.subscribe(fresh)
        rows = tr.requests[tr.requests["index"] < self.capacity] if len(tr.requests) else tr.requests
        if len(rows):
            rows = rows.copy()
            rows["index"] = rows["index"].astype(np.int64) + self.base
            self.link.send_requests(rows)
            self.stats["requests"] += len(rows)
        for slots, kind in ((tr.recoils, Reaction.RECOIL), (tr.flinches, Reaction.FLINCH)):
            keep = slots[slots < self.capacity]
            if len(keep):
                self.link.react(self.server_index(keep), kind)
                self.stats["reactions"] += len(keep)
