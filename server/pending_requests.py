"""Entity requests the readers took but have not applied yet: applied together, as one batch (issue 16).

Applying a batch of requests costs the server about 2 ms of CPU whatever its size (the many small numpy calls
of ``SoldierManager.apply_requests`` and of the answer; ``bench/bench_answer_cost.py``: 175 rows 3.3 ms, two
batches of 88 rows 5.4 ms). Two clients that send their requests at the same moment used to be applied and
answered one after the other, and the first client's update waited for the second's answer too. Under the
trio app a session *holds* its requests here instead (:meth:`hold`); the reader lets the other readers
in (``TtesServer.take_requests``), and the first to come back applies what they all hold in one call
(:meth:`apply`) and answers it once. Arrival order is kept (the last row per soldier wins, as in one batch),
and anything else a client sends (a REACT, a REMOVE_SOLDIER, a JCL frame) applies the held requests first
(``Session.handle``), so nothing overtakes a request. A client's next request frames join its held ones
(:meth:`may_join`) unless those hold a bad value, whose error closes the session before its next frame is
handled: frames that queued up in a socket while the server could not run (a loaded machine) are applied
as one batch, not one by one. One by one, each frame paid for bringing its soldiers up over the whole wait
(rounds of clip and step ends, each mostly a fixed cost): 40 frames queued in a 4-s spell at 5,000
soldiers took 329 ms of CPU in one reader turn, against 42 ms as one batch, and the tick starved behind
such turns (issue 16's spike).
The tick, and a writer woken by a tick's publish, apply what is held before they sample or encode, so
holding never delays a request past the point where it was applied before.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from server.session import Session
    from server.startup import ServerWorld


class PendingRequests:
    """The requests held by the sessions of one server, in the order their readers took them."""

    def __init__(self, world: ServerWorld) -> None:
        self.world = world
        self._held: list[tuple[Session, np.ndarray, np.ndarray]] = []
        self._bad: set[int] = set()  # the sessions (ids) whose held rows have a bad value

    def __bool__(self) -> bool:
        return bool(self._held)

    def holds(self, session: Session) -> bool:
        """Whether ``session`` has requests held."""
        return any(s is session for s, _, _ in self._held)

    def may_join(self, session: Session) -> bool:
        """Whether ``session``'s next request frame may be held with what it holds: none of its held rows
        has a bad value (that error closes it before its next frame is handled)."""
        return session.id not in self._bad

    def hold(self, session: Session, kept: np.ndarray, rows: np.ndarray) -> None:
        """Hold a session's request rows (``kept``: their row numbers in its frame, for its errors)."""
        self._held.append((session, kept, rows))
        m = self.world.manager
        if m is not None and m.has_bad_values(rows):
            self._bad.add(session.id)

    def apply(self) -> None:
        """Apply every held request in one batch (stamped now) and give each session its rows' status."""
        if not self._held:
            return
        held, self._held = self._held, []
        self._bad.clear()
        rows = held[0][2] if len(held) == 1 else np.concatenate([r for _, _, r in held])
        status = self.world.apply_requests(rows)
        at = 0
        for session, kept, r in held:
            session.requests_done(kept, r, status[at : at + len(r)])
            at += len(r)
