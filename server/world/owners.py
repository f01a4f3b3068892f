"""Who owns which soldier: the client ids of the owners, their caps and their grace after they leave.

Every soldier a client creates (CREATE_SOLDIER or JCL ``create_soldier_state``) belongs to that client's id
(HELLO ``client_id``), not to its connection: the same id reconnecting finds its soldiers and its count, so
reconnecting never resets the per-client cap. Soldiers of the start-up script (``caller`` None) belong to no
client: they are *shared*, as every soldier was in 1994 — any controller may drive them, only an operator
removes them.

Rights, by role (``protocol.events.ROLES``): an operator drives, removes and sees every soldier; a
controller drives and removes its own soldiers and the shared ones, and sees only those; an observer drives
nothing and sees every soldier. :meth:`Owners.visible` is what a session's subscriptions are filtered by.

When the last connection of an id closes its soldiers become *orphans*: :meth:`Owners.leave` starts their
grace period, :meth:`Owners.join` (the id is back) ends it, :meth:`Owners.expired` lists the ids whose grace
is over (the trio layer removes their soldiers). No clock here: times are passed in. With several front-ends
(``ttes front --front K/M``) an id's connections to the other front-ends count too: each tells the others
its own (:attr:`Owners.on_connections`), which join and leave here as the id's connections elsewhere.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

SHARED = -1  # owner code of a soldier no client owns (the start-up script's)
ANONYMOUS = "~anon-"  # + a session number: a client that gave no id (one connection of one process)
FULL_SIGHT = frozenset({"observer", "operator"})


class Owners:
    """Soldier index → owning client id, the live soldiers of each id, the grace deadlines of gone ids."""

    def __init__(self, max_soldiers: int, per_owner: int) -> None:
        self.per_owner = per_owner
        self.code = np.full(max_soldiers, SHARED, np.int32)  # per index: its owner's code, or SHARED
        self._codes: dict[str, int] = {}
        self._ids: list[str] = []
        self._free: list[int] = []  # codes of ids that own nothing and are not connected, for reuse
        self._soldiers: dict[str, set[int]] = {}
        self.connected: dict[str, int] = {}  # client id -> open connections
        self.deadline: dict[str, float] = {}  # gone client id -> when its soldiers are removed
        self.on_connections: Callable[[str], None] | None = None  # told after an id's connections change

    def code_of(self, client_id: str) -> int:
        """A small integer per client id that owns soldiers (given back when it owns none and is gone, so
        clients that come and go with fresh ids do not grow the table)."""
        code = self._codes.get(client_id)
        if code is None:
            if self._free:
                code = self._free.pop()
                self._ids[code] = client_id
            else:
                code = len(self._ids)
                self._ids.append(client_id)
            self._codes[client_id] = code
        return code

    def _release(self, client_id: str) -> None:
        """Forget an id that owns no soldier and has no connection (nothing refers to its code)."""
        if self._soldiers.get(client_id) or client_id in self.connected or client_id in self.deadline:
            return
        self._soldiers.pop(client_id, None)
        code = self._codes.pop(client_id, None)
        if code is not None:
            self._ids[code] = ""
            self._free.append(code)

    # -- soldiers ------------------------------------------------------------------------------------------
    def check_cap(self, owner: str | None) -> None:
        """ValueError when ``owner`` has created as many live soldiers as one client may."""
        if owner is not None and len(self._soldiers.get(owner, ())) >= self.per_owner:
            raise ValueError(f"client {owner!r} owns {self.per_owner} soldiers, as many as one client may")

    def add(self, index: int, owner: str | None) -> None:
        self.code[index] = SHARED if owner is None else self.code_of(owner)
        if owner is not None:
            self._soldiers.setdefault(owner, set()).add(index)

    def discard(self, index: int) -> None:
        owner = self.owner_of(index)
        self.code[index] = SHARED
        if owner is not None:
            self._soldiers.get(owner, set()).discard(index)
            self._release(owner)

    def owner_of(self, index: int) -> str | None:
        code = int(self.code[index])
        return None if code == SHARED else self._ids[code]

    def soldiers_of(self, owner: str) -> list[int]:
        return sorted(self._soldiers.get(owner, ()))

    # -- rights --------------------------------------------------------------------------------------------
    def may_drive(self, index: int, client_id: str, role: str) -> bool:
        """Whether a client may drive soldier ``index`` (live or not: liveness is checked later)."""
        return bool(self.drivable(np.array([index]), client_id, role)[0])

    def may_remove(self, index: int, client_id: str, role: str) -> bool:
        """Whether a client may remove soldier ``index``: an operator any, a controller only its own."""
        if role == "operator":
            return True
        return role == "controller" and int(self.code[index]) == self._codes.get(client_id, -2)

    def drivable(self, indices: np.ndarray, client_id: str, role: str) -> np.ndarray:
        """:meth:`may_drive` for an array of indices (a boolean array)."""
        if role == "operator":
            return np.ones(len(indices), bool)
        if role != "controller":
            return np.zeros(len(indices), bool)
        codes = self.code[indices]
        return (codes == SHARED) | (codes == self._codes.get(client_id, -2))

    def visible(self, indices: np.ndarray, client_id: str, role: str) -> np.ndarray:
        """The indices a client may see updates of: all for observers and operators, else the drivable."""
        if role in FULL_SIGHT:
            return indices
        return indices[self.drivable(indices, client_id, role)]

    # -- connections and grace -----------------------------------------------------------------------------
    def join(self, client_id: str) -> list[int]:
        """A connection of ``client_id`` opened: its grace (if any) ends; returns the soldiers it reclaims."""
        self.connected[client_id] = self.connected.get(client_id, 0) + 1
        self.deadline.pop(client_id, None)
        if self.on_connections is not None:
            self.on_connections(client_id)
        return self.soldiers_of(client_id)

    def leave(self, client_id: str, now: float, grace: float) -> float | None:
        """A connection of ``client_id`` closed; when it was the last and the id owns soldiers, returns the
        time they are removed at (else None)."""
        left = self.connected.get(client_id, 0) - 1
        if left > 0:
            self.connected[client_id] = left
        else:
            self.connected.pop(client_id, None)
        if self.on_connections is not None:
            self.on_connections(client_id)
        return None if left > 0 else self.orphaned(client_id, now, grace)

    def orphaned(self, client_id: str, now: float, grace: float) -> float | None:
        """When an id without connections that owns soldiers and has no deadline yet loses them (now +
        ``grace``; None for an id that is connected, owns none or waits already)."""
        if client_id in self.connected or client_id in self.deadline:
            return None
        if not self._soldiers.get(client_id):
            self._release(client_id)
            return None
        self.deadline[client_id] = now + grace
        return self.deadline[client_id]

    def owning(self) -> list[str]:
        """The ids that own soldiers."""
        return [cid for cid, soldiers in self._soldiers.items() if soldiers]

    def expired(self, now: float) -> list[str]:
        """The gone client ids whose grace is over (their deadlines are forgotten: remove their soldiers)."""
        gone = [cid for cid, t in self.deadline.items() if t <= now]
        for cid in gone:
            del self.deadline[cid]
        return gone

    @property
    def known(self) -> int:
        """Client ids with a code now (bounded by the owners of live soldiers and the connected)."""
        return len(self._codes)
