"""The async replay driver (no stub): a Replayer paced by trio's clock, its translations sent to the server.

Pacing sleeps until the next PDU is due (or the next housekeeping tick, for timeouts and the end of Fire
reactions), so PDUs reach the server at their capture times scaled by ``--speed``; under trio's autojump
clock a test replays a minute of exercise in moments. Unlimited speed sends chunk after chunk, waiting only
for the socket to take the bytes (back-pressure).
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TextIO

import trio

from client_stub.dis.replayer import Replayer
from client_stub.dis.sink import ServerSink

HOUSEKEEPING = 0.1  # s between steps when no PDU is due (timeouts, Fire reactions)


@dataclass
class ProgressLine:
    """``replay 12.3 / 60.0 s | 8 alive | 240 PDU/s | ETA 0:48`` on one terminal line, refreshed about once a
    second. ``total`` is the log's length (None when looping: no total, no ETA); the ETA is the wall-clock
    time (``clock``) the rest takes at the pace so far, so it holds for --speed, unlimited replays and
    headless runs under a virtual clock alike."""

    out: TextIO | None = field(default_factory=lambda: sys.stderr)
    every: float = 1.0
    total: float | None = None
    clock: Callable[[], float] = time.monotonic
    _last_t: float | None = None
    _last_pdus: int = 0
    _start: tuple[float, float] | None = None  # (wall clock, replay time) at the first update
    rate: float = 0.0

    def update(self, now: float, replay_time: float, alive: int, pdus: int, force: bool = False) -> None:
        if self._last_t is None:
            self._last_t, self._last_pdus = now, pdus
            self._start = (self.clock(), replay_time)
            return
        dt = now - self._last_t
        if dt < self.every and not force:
            return
        if dt > 0:
            self.rate = (pdus - self._last_pdus) / dt
        self._last_t, self._last_pdus = now, pdus
        if self.out is not None:
            end = "\n" if force or not self.out.isatty() else ""
            self.out.write(f"\r{self.text(replay_time, alive)}{end}")
            self.out.flush()

    def eta(self, replay_time: float) -> float | None:
        """Wall-clock seconds left at the pace so far (None: no total, or no progress yet)."""
        if self.total is None or self._start is None:
            return None
        wall0, t0 = self._start
        if replay_time >= self.total:
            return 0.0
        if replay_time <= t0:
            return None
        return (self.total - replay_time) * (self.clock() - wall0) / (replay_time - t0)

    def text(self, replay_time: float, alive: int) -> str:
        when = ""
        if self.total is not None:
            replay_time, when = min(replay_time, self.total), f" / {self.total:.1f}"
        eta = self.eta(replay_time)
        left = "" if eta is None else f" | ETA {int(eta) // 60}:{int(eta) % 60:02d}"
        return f"replay {replay_time:7.1f}{when} s | {alive:5d} alive | {self.rate:9.0f} PDU/s{left}"


async def replay_to_server(
    replayer: Replayer,
    sink: ServerSink,
    *,
    progress: ProgressLine | None = None,
    drain: Callable[[], object] | None = None,
    finish: bool = True,
) -> dict[str, object]:
    """Run the replay to its end (forever with ``loop``); returns the replay's status.

    ``drain`` (e.g. ``Client.drain``) is awaited after each unlimited-speed chunk for back-pressure.
    ``finish`` removes every soldier at the end.
    """
    t0 = trio.current_time()
    while not replayer.finished:
        now = trio.current_time()
        if replayer.unlimited:
            sink.apply(replayer.advance_chunk())
            if drain is not None:
                await drain()  # type: ignore[misc]
            else:
                await trio.sleep(0)
        else:
            sink.apply(replayer.advance(now - t0))
            due = t0 + replayer.next_due()
            await trio.sleep_until(max(min(due, now + HOUSEKEEPING), now))
        if progress is not None:
            progress.update(
                trio.current_time(), replayer.replay_time, replayer.translator.alive, replayer.pdus
            )
    if finish:
        sink.apply(replayer.finish())
    if progress is not None:
        progress.update(
            trio.current_time(), replayer.replay_time, replayer.translator.alive, replayer.pdus, True
        )
    return {**replayer.status(), **{f"sink_{k}": v for k, v in sink.stats.items()}}
