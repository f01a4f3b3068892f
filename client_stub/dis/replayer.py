"""Replayer: a DIS log, paced by its receipt times, through the DisTranslator.

Sync and clock-free: the caller says how many replay seconds have passed (:meth:`Replayer.advance`) or asks
for the next chunk as fast as it can go (:meth:`Replayer.advance_chunk`, ``--speed`` unlimited) and gets the
:class:`~client_stub.dis.translator.Translation` to apply. The async server driver, the gateway's tests,
the stub window and the headless renderer all share it.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from client_stub.dis.cursor import LOOP_GAP, LogCursor
from client_stub.dis.translator import DIS_TIMEOUT, DisTranslator, Translation, sane_records
from protocol.dis import DisEvent, DisLog, EntityStateBatch, LocalFrame
from protocol.events import DEFAULT_MAX_SOLDIERS

UNLIMITED_CHUNK = 0.1  # s of log time per step when --speed is unlimited ...
UNLIMITED_PDUS = 2048  # ... or this many Entity State PDUs, whichever is more


class Replayer:
    """One log replay: cursor, clock, translator (see the module docstring)."""

    def __init__(
        self,
        log: DisLog | LogCursor,
        *,
        speed: float = 1.0,
        loop: bool = False,
        start: float = 0.0,
        origin: LocalFrame | None = None,
        timeout: float = DIS_TIMEOUT,
        capacity: int = DEFAULT_MAX_SOLDIERS,
    ) -> None:
        """``log``: a whole log, or a :class:`LogCursor` over it that filters entities and cuts silences
        (``max_gap``). ``start`` counts log seconds, silences included."""
        if not (speed > 0):
            raise ValueError("speed must be positive (inf: unlimited)")
        if not (math.isfinite(start) and start >= 0):
            raise ValueError("start must be a finite number of seconds >= 0")
        self.cursor = log if isinstance(log, LogCursor) else LogCursor(log)
        if origin is None:  # the first entity of the log, wherever the replay starts
            usable = np.flatnonzero(sane_records(self.cursor.batch.records))
            if len(usable):
                origin = LocalFrame.at_ecef(self.cursor.batch.records["location"][usable[0]])
        self.translator = DisTranslator(origin, timeout=timeout, capacity=capacity)
        self.speed = float(speed)
        self.loop = loop
        self.start = float(start)
        self.t_begin = self.cursor.cursor_time(self.cursor.t0 + self.start)
        self.offset = 0.0  # translator time = log time + offset
        self.loops = 0
        self.pdus = 0  # DIS PDUs (every type) replayed
        self.log_now = self.t_begin
        self.finished = False
        self.epoch = 0.0  # replay seconds at the last (re)start
        self._skipped = False

    @property
    def unlimited(self) -> bool:
        return not math.isfinite(self.speed)

    @property
    def replay_time(self) -> float:
        """Seconds into the log of the newest PDU time handed out."""
        return max(self.log_now - self.cursor.t0, 0.0)

    @property
    def now(self) -> float:
        """The translator's clock (monotonic across loops)."""
        return self.log_now + self.offset

    def advance(self, elapsed: float) -> Translation:
        """Everything due ``elapsed`` replay seconds after the start (paced by ``speed``)."""
        if self.unlimited:
            return self.advance_chunk()
        return self._to(self.t_begin + (elapsed - self.epoch) * self.speed, elapsed)

    def next_due(self) -> float:
        """Replay seconds (as passed to :meth:`advance`) at which the next PDU is due; inf if none."""
        nxt = self.cursor.next_time
        if not math.isfinite(nxt) or self.unlimited:
            return math.inf
        return self.epoch + (max(nxt, self.t_begin) - self.t_begin) / self.speed

    def advance_chunk(self, seconds: float = UNLIMITED_CHUNK, pdus: int = UNLIMITED_PDUS) -> Translation:
        """The next stretch of log, however long it took to record (``--speed`` unlimited): ``seconds`` of log
        time, stretched to take about ``pdus`` Entity State PDUs at once (the translator's cost is mostly per
        step). Within one step only the last PDU of each entity shows."""
        nxt = self.cursor.next_time
        if math.isinf(nxt):
            return self._to(self.log_now + seconds, None)
        target = max(nxt, self.log_now) + seconds
        times, at = self.cursor.times, self.cursor.position
        if pdus > 0 and at + pdus <= len(times):
            target = max(target, float(times[at + pdus - 1]))
        return self._to(target, None)

    def _to(self, t_log: float, elapsed: float | None) -> Translation:
        parts: list[Translation] = []
        if not self._skipped:
            self._skipped = True
            if self.start > 0:
                batch, times, events, n = self.cursor.skip_to(self.t_begin)
                self.pdus += n
                parts.append(
                    self.translator.step(self.t_begin + self.offset, *self._shift(batch, times, events))
                )
        t_log = max(t_log, self.log_now)
        if self.finished:  # nothing left to read; soldiers still time out
            self.log_now = t_log if math.isfinite(t_log) else self.log_now
            return Translation.merge([*parts, self.translator.advance(self.log_now + self.offset)])
        batch, times, events, n = self.cursor.take(t_log)
        self.pdus += n
        self.log_now = t_log
        parts.append(self.translator.step(t_log + self.offset, *self._shift(batch, times, events)))
        if self.cursor.done and t_log >= self.cursor.t_end + (LOOP_GAP if self.loop else 0.0):
            if self.loop:
                parts.append(self.translator.reset())
                self.offset += t_log - self.t_begin
                self.loops += 1
                self.cursor.rewind()
                self._skipped = False
                self.log_now = self.t_begin
                self.epoch = elapsed if elapsed is not None else 0.0
            else:
                self.finished = True
        return Translation.merge(parts)

    def _shift(
        self, batch: EntityStateBatch, times: np.ndarray, events: list[DisEvent]
    ) -> tuple[EntityStateBatch, np.ndarray, list[DisEvent]]:
        if self.offset == 0.0:
            return batch, times, events
        return batch, times + self.offset, [dataclasses.replace(e, t=e.t + self.offset) for e in events]

    def finish(self) -> Translation:
        """Remove every soldier (the end of a replay)."""
        self.finished = True
        return self.translator.reset()

    def status(self) -> dict[str, object]:
        return {
            "replay_time": round(self.replay_time, 3),
            "alive": self.translator.alive,
            "entities": self.translator.count,
            "pdus": self.pdus,
            "loops": self.loops,
            "finished": self.finished,
            "silence_skipped_s": round(self.cursor.skipped, 3),
            **self.translator.stats,
        }
