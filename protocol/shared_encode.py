"""Encode once, send to many: a memo of joint-update encodes shared by the encoders of one server.

An :class:`~protocol.updates.UpdateEncoder`'s output is a pure function of its delta state (what the client
last received), the soldier rows it is given and their codes. Encoders whose states are known to be equal
therefore produce the same bytes for the same rows, and the server need diff and pack only once per group of
clients in that state (same subscription, same visibility, same history) per tick.

States are named, not hashed: every state gets an id, equal ids mean equal content. A fresh encoder's state
is :data:`FRESH`; an encode or a reset from state ``s`` leads to the id memoised for ``(s, what was done)``,
so clients that do the same thing from the same state stay together. Histories that differ but end in equal
content (a late joiner after its first full update) are joined by comparing the content once
(``UpdateEncoder._try_join``); a client that fails the comparison retries only after :data:`JOIN_RETRY`
encodes. Encoders in one state share its arrays copy-on-write (:class:`Held`): taking a memoised encode
costs a client no copy of the rows it sent.

The caller vouches for ``version``: equal versions with equal rows mean equal codes (the server passes the
pose board's publish serial). Lookups see the newest version only, but the encodes of the last :data:`KEEP`
versions stay, indexed by the state they started from, so that a writer that missed publishes catches up
through them (``UpdateEncoder.catch_up``): the frames its group was sent, in order, from the state it is in,
instead of an encode of its own that spans the missed ticks (which loses version 2's prediction and, on a
busy server, makes more writers late).
"""

from __future__ import annotations

import hashlib
import itertools
from dataclasses import dataclass

import numpy as np

FRESH = 0  # the state id of an encoder that knows nothing (new, or reset for every soldier)
JOIN_RETRY = 32  # encodes before a client whose content differed from its group's compares again
KEEP = 4  # versions whose encodes a late writer may catch up through


class Held:
    """An encoder's state array, shared copy-on-write by the encoders (and memo entries) in one state: a
    client that takes a memoised encode adopts its arrays instead of writing the sent rows into its own.
    ``writes`` counts the times a sole user was let write in place (a holder that is not a user sees its
    content changed)."""

    __slots__ = ("array", "users", "writes")

    def __init__(self, array: np.ndarray) -> None:
        self.array = array
        self.users = 1
        self.writes = 0

    def take(self) -> Held:
        self.users += 1
        return self

    def drop(self) -> None:
        self.users -= 1

    def writable(self) -> Held:
        """This holder if its one user is the caller, else the caller's own copy (the caller's use moves)."""
        if self.users <= 1:
            self.writes += 1
            return self
        self.users -= 1
        return Held(self.array.copy())


@dataclass
class Encoded:
    """One memoised encode: its frames, the rows asked for, and the state it led to (id and arrays).

    The memo is a user of the arrays while the encode's version is the newest (a hit adopts them). After
    that it only watches them (``marks``: their write counts when it let go): holding them would make the
    one encoder of a state copy them at every encode for a catch-up that may never come. A catch-up may end
    in a watched state while no encoder has written its arrays (:meth:`intact`), or by a memo hit at the
    newest version; the encodes of older versions keep their frames only."""

    payloads: tuple[bytes, ...]
    state: int
    held: tuple[Held, Held, Held] | None  # last, known, before (version 2's prediction; no rows in version 1)
    rows: np.ndarray  # the sorted soldier indices asked for (the client holds their codes after it)
    tick: int
    marks: tuple[int, ...] | None = None

    def let_go(self) -> None:
        if self.held is not None and self.marks is None:
            self.marks = tuple(h.writes for h in self.held)
            for h in self.held:
                h.drop()

    def release(self) -> None:
        self.let_go()
        self.held = None

    def intact(self) -> tuple[Held, Held, Held] | None:
        """The arrays of the state this encode led to, if they still hold it."""
        if self.held is None or (self.marks is not None and self.marks != tuple(h.writes for h in self.held)):
            return None
        return self.held


def digest(indices: np.ndarray) -> bytes:
    """A collision-resistant name for a set of rows (sorted int64 indices)."""
    return hashlib.blake2b(np.ascontiguousarray(indices, np.int64).tobytes(), digest_size=16).digest()


class SharedEncodes:
    """The memo of one server: encodes and resets by (state, table, rows, version), for one version; the
    encodes of the last :data:`KEEP` versions by (state, stream) for catching up."""

    def __init__(self) -> None:
        self._ids = itertools.count(FRESH + 1)
        self._version: object = None
        self._encodes: dict[tuple[object, ...], Encoded] = {}
        self._resets: dict[tuple[int, bytes], int] = {}
        self._groups: dict[tuple[object, ...], tuple[int, object]] = {}  # rows key -> (state, its owner)
        # version -> (state, table, format, max_soldiers, max_payload) -> the encodes from that state, by age
        self._kept: dict[object, dict[tuple[object, ...], list[Encoded]]] = {}
        self.hits = 0
        self.misses = 0
        self.caught_up = 0  # memoised encodes sent to writers that missed their publish
        self.rows_encoded = 0  # the rows of the misses (each one diffed and packed by its encoder)

    def new_id(self) -> int:
        return next(self._ids)

    def _at(self, version: object) -> None:
        if version != self._version:
            self._version = version
            self._encodes.clear()
            self._resets.clear()
            self._groups.clear()
            versions = list(self._kept)
            for k, v in enumerate(versions):  # the newest: watched; older: frames only; beyond KEEP: gone
                for entries in self._kept[v].values():
                    for e in entries:
                        if k == len(versions) - 1:
                            e.let_go()
                        else:
                            e.release()
            for v in versions[: max(0, len(versions) + 1 - KEEP)]:
                del self._kept[v]
            self._kept.pop(version, None)
            self._kept[version] = {}

    def lookup(self, state: int, rows: tuple[object, ...], version: object) -> Encoded | None:
        """The memoised encode of ``rows`` (table, format, max_soldiers, digest, tick, max_payload) from
        ``state``, or None."""
        self._at(version)
        hit = self._encodes.get((state, *rows))
        if hit is None:
            self.misses += 1
        else:
            self.hits += 1
        return hit

    def peek(self, state: int, rows: tuple[object, ...], version: object) -> Encoded | None:
        """Like :meth:`lookup`, counting nothing: whether a catch-up can end in a memo hit."""
        return self._encodes.get((state, *rows)) if version == self._version else None

    def store(self, state: int, rows: tuple[object, ...], encoded: Encoded) -> None:
        """Memoise an encode (after a :meth:`lookup` at its version); the memo is a user of its arrays
        (``take``) while its version is the newest."""
        assert encoded.held is not None
        for h in encoded.held:
            h.take()
        self._encodes[(state, *rows)] = encoded
        table, fmt, nmax, _, _, max_payload = rows
        self._kept[self._version].setdefault((state, table, fmt, nmax, max_payload), []).append(encoded)

    def kept(self, version: object, state: int, stream: tuple[object, ...]) -> list[Encoded]:
        """The encodes memoised at ``version`` (one of the last :data:`KEEP`) from ``state`` for ``stream``
        (table, format, max_soldiers, max_payload): frames a writer that missed that publish may send."""
        by_state = self._kept.get(version)
        return [] if by_state is None else by_state.get((state, *stream), [])

    def group(self, rows: tuple[object, ...], state: int, owner: object) -> tuple[int, object]:
        """The first (state, owner) that encoded these rows at this version; records this one if none did."""
        return self._groups.setdefault(rows, (state, owner))

    def reset(self, state: int, indices: np.ndarray | None) -> int:
        """The state id after forgetting ``indices`` (all if None) from ``state``."""
        if indices is None or state == FRESH:
            return FRESH
        key = (state, digest(np.unique(np.asarray(indices, np.int64))))
        new = self._resets.get(key)
        if new is None:
            new = self._resets[key] = self.new_id()
        return new
