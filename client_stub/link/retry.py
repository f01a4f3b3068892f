"""When to try a lost server again: the stub, the replay window and the DIS reconnector share one schedule.

Attempts come after each delay of ``backoff`` (the last one repeats) counted from the loss, in whatever time
the caller passes in (stub seconds, trio time): frames drive it, nothing sleeps. After ``give_up_after``
seconds without a server the schedule says so once (the command then exits non-zero).
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Sequence
from typing import TypeVar

from client_stub.link.client import LinkError

log = logging.getLogger("ttes.reconnect")
T = TypeVar("T")

BACKOFF = (0.5, 1.0, 2.0, 4.0, 8.0)  # s between reconnection attempts (the last repeats)
GIVE_UP_AFTER = 120.0  # s without a server


class RetrySchedule:
    """Backoff bookkeeping for one lost link: :meth:`attempt` tries a connect when :meth:`due`, and says in
    ``gave_up`` why it stopped once :meth:`out_of_time`."""

    def __init__(self, backoff: Sequence[float] = BACKOFF, give_up_after: float = GIVE_UP_AFTER) -> None:
        if not backoff or min(backoff) < 0:
            raise ValueError(f"backoff must be non-negative delays, not {tuple(backoff)!r}")
        self.backoff = tuple(backoff)
        self.give_up_after = give_up_after
        self.lost_at: float | None = None  # when the attempts began (None: the link works)
        self.attempts = 0
        self._next_try = 0.0
        self.gave_up = ""  # why the attempts stopped ("" while they go on)

    def delay(self, attempt: int) -> float:
        """Seconds before attempt ``attempt`` (0-based) after the one before it."""
        return self.backoff[min(attempt, len(self.backoff) - 1)]

    def due(self, now: float) -> bool:
        """True when an attempt should be made at ``now`` (the first call only starts the clock)."""
        if self.lost_at is None:
            self.lost_at, self.attempts = now, 0
            self._next_try = now + self.delay(0)
            return False
        if now < self._next_try or self.out_of_time(now):
            return False
        self.attempts += 1
        self._next_try = now + self.delay(self.attempts)
        return True

    def out_of_time(self, now: float) -> bool:
        return self.lost_at is not None and now - self.lost_at > self.give_up_after

    def attempt(self, now: float, connect: Callable[[], T], why: str) -> T | None:
        """``connect()`` when an attempt is due at ``now`` (its LinkError: None, tried again later); out of
        time: None, and ``gave_up`` says so (``why``: what was lost)."""
        if self.gave_up:
            return None
        if self.out_of_time(now):
            assert self.lost_at is not None
            self.gave_up = f"gave up after {now - self.lost_at:.0f} s without a server ({why})"
            log.error("%s", self.gave_up)
            return None
        if not self.due(now):
            return None
        try:
            return connect()
        except LinkError as exc:
            log.info("reconnecting: %s", exc)
            return None

    def reset(self) -> None:
        """The link works again: the next loss starts a fresh schedule."""
        self.lost_at = None
        self.attempts = 0
        self.gave_up = ""
