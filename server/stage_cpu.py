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

import numpy as np
import trio

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


class DeafSpans(trio.abc.Instrument):
    """The loop thread's CPU from one poll of the sockets to the next (trio runs a batch of tasks between
    two IO waits): a request or a fabric message that arrives meanwhile is not seen before the span ends.
    On for a bench (``TTES_DEAF=1``, :mod:`server.app`: two ``thread_time`` calls a batch). Reported as the
    span that a busy instant falls in (spans weighted by their length: what a message arriving while the
    loop is busy waits behind, at most), p50 / p99 / max in ms of CPU."""

    def __init__(self) -> None:
        self.spans: list[float] = []
        self._since: float | None = None

    def after_io_wait(self, timeout: float) -> None:
        self._since = time.thread_time()

    def before_io_wait(self, timeout: float) -> None:
        if self._since is not None:
            self.spans.append(time.thread_time() - self._since)
            self._since = None

    def report(self) -> dict[str, float]:
        spans, self.spans = np.asarray(self.spans), []
        if not len(spans) or spans.sum() <= 0:
            return dict.fromkeys(("p50", "p99", "max"), 0.0)
        order = np.sort(spans)
        weight = np.cumsum(order) / order.sum()  # a busy instant's span: by CPU share
        at = [order[min(int(np.searchsorted(weight, q)), len(order) - 1)] for q in (0.5, 0.99)]
        ms = [round(1000 * float(v), 2) for v in (*at, order[-1])]
        return dict(zip(("p50", "p99", "max"), ms, strict=True))
