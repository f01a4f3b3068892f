"""Pacing a DIS log: which PDUs are due at a given replay time, the replay clock, and the entity filter.

A replay is paced by the capture's receipt times: wall (or trio) time ``w`` after the start shows the log at
``t0 + start + speed * w``. ``LogCursor.take(t)`` hands out, in receipt order, every lifeform Entity State
PDU and weapon event whose time is ``<= t`` that it has not handed out yet (two ``searchsorted`` calls, no
per-PDU Python). Looping restarts the log; the translator's clock keeps running (``ReplayClock.offset``),
so dead reckoning and timeouts never see time go backwards. With ``max_gap`` the cursor's clock is the log's
with every silence longer than ``max_gap`` seconds cut down to ``max_gap`` (:class:`GapSqueeze`): a log of a
few PDUs spread over a quarter of an hour does not replay a quarter of an hour of nothing.
"""

from __future__ import annotations

import dataclasses
import math
import re
from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from protocol.dis import DisEvent, DisLog, EntityStateBatch, RemoveEntity

LOOP_GAP = 1.0  # s of replay time between the end of a log and its restart


class FilterError(ValueError):
    """A bad ``--entities`` filter; ``position`` is the character offset of the bad term."""

    def __init__(self, message: str, position: int) -> None:
        super().__init__(f"entity filter, character {position}: {message}")
        self.message = message
        self.position = position


_FORCES = {"friendly": 1, "opposing": 2, "neutral": 3, "other": 0}
_ID_TERM = re.compile(r"(\*|\d{1,5}):(\*|\d{1,5}):(\*|\d{1,5})")


@dataclass(frozen=True)
class EntityFilter:
    """Which entities a replay keeps: a comma-separated union of terms.

    ``SITE:APP:ENTITY`` (each a number or ``*``), ``force=N`` or ``friendly`` / ``opposing`` / ``neutral``,
    ``marking=TEXT`` (exact) or ``marking=PREFIX*``. Example: ``1:*:*,force=2,marking=SQD4*``.
    """

    ids: tuple[tuple[int, int, int], ...] = ()  # -1 = any
    forces: tuple[int, ...] = ()
    markings: tuple[tuple[bytes, bool], ...] = ()  # (text, is_prefix)

    @classmethod
    def parse(cls, text: str) -> EntityFilter:
        ids, forces, markings = [], [], []
        pos = 0
        for term in text.split(","):
            t = term.strip()
            at = pos + (len(term) - len(term.lstrip()))
            pos += len(term) + 1
            if not t:
                raise FilterError("empty term", at)
            low = t.lower()
            if m := _ID_TERM.fullmatch(t):
                parts = [-1 if g == "*" else int(g) for g in m.groups()]
                if any(p > 0xFFFF for p in parts):
                    raise FilterError(f"{t!r}: numbers are 0..65535", at)
                ids.append((parts[0], parts[1], parts[2]))
            elif low in _FORCES:
                forces.append(_FORCES[low])
            elif low.startswith("force="):
                v = low[6:]
                if v in _FORCES:
                    forces.append(_FORCES[v])
                elif v.isdigit() and int(v) <= 255:
                    forces.append(int(v))
                else:
                    raise FilterError(f"{t!r}: force is 0..255 or friendly/opposing/neutral", at)
            elif low.startswith("marking="):
                v = t[8:]
                prefix = v.endswith("*")
                raw = v[:-1] if prefix else v
                try:
                    data = raw.encode("ascii")
                except UnicodeEncodeError:
                    raise FilterError(f"{t!r}: markings are ASCII", at) from None
                if len(data) > 11 or (not data and not prefix):
                    raise FilterError(f"{t!r}: a marking is 1..11 characters", at)
                markings.append((data, prefix))
            else:
                raise FilterError(f"{t!r}: expected SITE:APP:ENTITY, force=N, friendly/opposing/neutral "
                                  "or marking=TEXT", at)  # fmt: skip
        return cls(tuple(ids), tuple(forces), tuple(markings))

    def mask(self, records: NDArray[np.void]) -> NDArray[np.bool_]:
        """Which Entity State records pass (vectorised over records; one pass per term)."""
        keep = np.zeros(len(records), bool)
        eid = records["entity_id"]
        for site, app, ent in self.ids:
            m = np.ones(len(records), bool)
            for value, name in ((site, "site"), (app, "application"), (ent, "entity")):
                if value >= 0:
                    m &= eid[name] == value
            keep |= m
        if self.forces:
            keep |= np.isin(records["force_id"], self.forces)
        if self.markings:
            text = np.char.rstrip(records["marking"], b"\x00 ")
            for data, prefix in self.markings:
                keep |= np.char.startswith(text, data) if prefix else text == data
        return keep


@dataclass(frozen=True)
class GapSqueeze:
    """Log time -> replay time with every silence between successive PDUs longer than ``max_gap`` cut to
    ``max_gap`` (monotone; PDU times keep their order and every gap up to ``max_gap`` its length)."""

    knots: NDArray[np.float64]  # the PDU times (sorted, unique)
    cut: NDArray[np.float64]  # seconds removed before each knot

    @classmethod
    def of(cls, times: NDArray[np.float64], max_gap: float) -> GapSqueeze:
        knots = np.unique(np.asarray(times, np.float64))
        excess = np.maximum(np.diff(knots) - max_gap, 0.0)
        return cls(knots, np.concatenate(([0.0], np.cumsum(excess))))

    @property
    def skipped(self) -> float:
        """Seconds of silence cut from the whole log."""
        return float(self.cut[-1]) if len(self.cut) else 0.0

    def __call__(self, t: NDArray[np.float64]) -> NDArray[np.float64]:
        t = np.asarray(t, np.float64)
        if not len(self.knots):
            return t.copy()
        k = np.clip(np.searchsorted(self.knots, t, side="right") - 1, 0, len(self.knots) - 1)
        nxt = np.minimum(k + 1, len(self.knots) - 1)
        out = t - self.cut[k]
        return np.minimum(out, np.where(nxt > k, self.knots[nxt] - self.cut[nxt], np.inf))


class LogCursor:
    """The PDUs of a log in receipt order, handed out by time (see the module docstring)."""

    def __init__(
        self, log: DisLog, entity_filter: EntityFilter | None = None, max_gap: float | None = None
    ) -> None:
        order = np.argsort(log.times, kind="stable")
        batch = log.batch.select(order) if len(order) and (np.diff(order) != 1).any() else log.batch
        times = log.times[order]
        if entity_filter is not None and len(batch):
            keep = entity_filter.mask(batch.records)
            batch, times = batch.select(keep), times[keep]
        self.batch = batch
        self.times = np.asarray(times, np.float64)
        self.events: list[DisEvent] = sorted(log.events, key=lambda e: e.t)
        self.event_times = np.array([e.t for e in self.events], np.float64)
        self.pdu_times = np.sort(np.asarray(log.pdus["t"], np.float64)) if len(log.pdus) else np.zeros(0)
        if max_gap is not None and not (math.isfinite(max_gap) and max_gap > 0):
            raise ValueError("max_gap must be a positive number of seconds (None: keep the silences)")
        self.skipped = 0.0  # seconds of silence cut (max_gap)
        self.squeeze: GapSqueeze | None = None  # log time -> cursor time, with max_gap
        if max_gap is not None:
            self._squeeze(max_gap)
        starts = [a[0] for a in (self.times, self.event_times, self.pdu_times) if len(a)]
        ends = [a[-1] for a in (self.times, self.event_times, self.pdu_times) if len(a)]
        self.t0 = float(min(starts)) if starts else float(log.t0)
        self.t_end = float(max(ends)) if ends else self.t0
        self.rewind()

    def _squeeze(self, max_gap: float) -> None:
        """Cut the silences longer than ``max_gap`` out of every time the cursor hands out."""
        every = np.concatenate([self.pdu_times, self.times, self.event_times])
        squeeze = GapSqueeze.of(every, max_gap)
        self.skipped = squeeze.skipped
        if not self.skipped:
            return
        self.squeeze = squeeze
        self.times = squeeze(self.times)
        self.pdu_times = squeeze(self.pdu_times)
        self.event_times = squeeze(self.event_times)
        self.events = [
            dataclasses.replace(e, t=float(t)) for e, t in zip(self.events, self.event_times, strict=True)
        ]

    @property
    def duration(self) -> float:
        return self.t_end - self.t0

    def cursor_time(self, t_log: float) -> float:
        """A log time (``--start``) on the cursor's clock: the same, less the silences cut before it."""
        return t_log if self.squeeze is None else float(self.squeeze(np.array([t_log]))[0])

    def rewind(self) -> None:
        self._es = 0
        self._ev = 0
        self._pdu = 0

    @property
    def position(self) -> int:
        """Entity State records handed out so far."""
        return self._es

    @property
    def done(self) -> bool:
        return (
            self._es >= len(self.times) and self._ev >= len(self.events) and self._pdu >= len(self.pdu_times)
        )

    @property
    def next_time(self) -> float:
        """Log time of the next PDU not handed out (inf at the end)."""
        heads = ((self.times, self._es), (self.event_times, self._ev), (self.pdu_times, self._pdu))
        cand = [a[i] for a, i in heads if i < len(a)]  # fmt: skip
        return float(min(cand)) if cand else math.inf

    def skip_to(self, t: float) -> tuple[EntityStateBatch, NDArray[np.float64], list[DisEvent], int]:
        """Everything before ``t`` (``--start``): the entity states and removals (old weapon events are
        dropped: nobody reacts to a shot long gone, but a removed entity stays removed)."""
        batch, times, events, npdus = self.take(t, inclusive=False)
        return batch, times, [e for e in events if isinstance(e, RemoveEntity)], npdus

    def take(
        self, t: float, inclusive: bool = True
    ) -> tuple[EntityStateBatch, NDArray[np.float64], list[DisEvent], int]:
        """Entity states, their times, events (Fire, Detonation, Remove Entity) and the number of DIS PDUs
        (all types) due by ``t``."""
        side: Literal["left", "right"] = "right" if inclusive else "left"
        es_end = max(int(np.searchsorted(self.times, t, side=side)), self._es)
        ev_end = max(int(np.searchsorted(self.event_times, t, side=side)), self._ev)
        pdu_end = max(int(np.searchsorted(self.pdu_times, t, side=side)), self._pdu)
        batch = self.batch.select(slice(self._es, es_end)) if es_end > self._es else EntityStateBatch.empty()
        times = self.times[self._es : es_end]
        events = self.events[self._ev : ev_end]
        npdus = pdu_end - self._pdu
        self._es, self._ev, self._pdu = es_end, ev_end, pdu_end
        return batch, times, events, npdus


@dataclass
class ReplayClock:
    """Maps replay (wall or trio) seconds to log time, and log time to the translator's monotonic time."""

    t_begin: float  # log time shown at replay time 0
    speed: float = 1.0  # inf: unlimited
    offset: float = 0.0  # translator time = log time + offset (grows by each loop)

    def log_time(self, elapsed: float) -> float:
        return self.t_begin + elapsed * self.speed if math.isfinite(self.speed) else math.inf
