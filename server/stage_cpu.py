"""CPU time of the loop's stages (animate, quantise, fabric, merge, requests, encode), per tick.

On a shared machine wall-clock timings measure the neighbours; the loop thread's CPU time
(``time.thread_time``) per stage does not. A server's status line reports them in ms per tick of its own
loop, with the process's CPU per tick beside them: the rest is the fabric's threads, the sockets and trio.
Stages may nest: ``requests`` holds the publish of the answers it releases (their ``fabric`` too).
A stage costs two ``thread_time`` calls (≈ 9 µs on this project's VM: ≈ 0.1 ms of a tick in all).
"""

from __future__ import annotations

import contextlib
import time
from collections import defaultdict
from collections.abc import Iterator

# CPU seconds a loop gives one turn of queued work before it lets the tick and the other tasks run (a
# front-end reader's buffered events, a shard's fabric requests): a burst of thousands then costs the
# tick at most this much, and a turn is still long enough for a batch's fixed cost to be paid once
TURN_CPU_S = 0.004


class StageCpu:
    """Accumulates the loop thread's CPU seconds per stage between two reports."""

    def __init__(self) -> None:
        self.seconds: dict[str, float] = defaultdict(float)
        self._process = time.process_time()
        self._ticks = 0

    @contextlib.contextmanager
    def __call__(self, stage: str) -> Iterator[None]:
        t = time.thread_time()
        try:
            yield
        finally:
            self.seconds[stage] += time.thread_time() - t

    def report(self, ticks: int) -> dict[str, float]:
        """ms of CPU per tick of each stage since the last report (``process``: the whole process's), and
        start over; ``ticks`` is the loop's tick count now."""
        n = max(1, ticks - self._ticks)
        now = time.process_time()
        out = {k: round(1000 * v / n, 2) for k, v in sorted(self.seconds.items())}
        out["process"] = round(1000 * (now - self._process) / n, 2)
        self.seconds.clear()
        self._process, self._ticks = now, ticks
        return out
