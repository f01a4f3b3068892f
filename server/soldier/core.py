"""The soldier manager's state: its tables, settings, lookups and the two ways a clip starts (a step of
a path, a resting pose). The manager's other parts (stepping, turning, events, ticking, requests, reactions)
are mixins over it, one module each, so :class:`~server.soldier.manager.SoldierManager` reads as Figure 12."""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from protocol.entity import Appearance, WeaponState
from protocol.events import DEFAULT_MAX_SOLDIERS
from server.soldier import root_motion
from server.soldier.library import MotionLibrary, PathStep
from server.soldier.locomotion import (
    GAIT_STAY,
    NEXT,
    SCALED,
    Cond,
)
from server.soldier.settings import SoldierSettings
from server.soldier.state import (
    BASE_POSTURE,
    STAND_STOWED,
    LocoState,
    Mode,
    Movement,
    goal_posture,
    movement,
)
from server.soldier.table import SoldierTable

REQUEST_OK = 0
REQUEST_UNKNOWN_SOLDIER = 1
REQUEST_BAD_VALUE = 2

MOVING_EPS = 1e-3  # m/s: slower than this is standing still
MAX_SPEED = 100.0  # m/s: faster is a bad value
# playback rate limits of a locomotion clip (speed / ground speed): human cadence stays within about
# 0.6-1.6 times the recorded one (walk 1.1-2.9 steps/s, run 1.7-4.6); beyond, the stride length takes the rest
# (a walk up to 1.8, 3.3 steps/s, race walking: a walker keeps walking up to the walk->run switch, 2.4 m/s)
MIN_RATE, MAX_RATE, WALK_MAX_RATE = 0.6, 1.6, 1.8
MIN_STRIDE, MAX_STRIDE = 0.5, 2.0  # stride scale limits (a scaled stride slides the feet by the difference)
CATCH_UP_SECONDS = 1.5  # a stepping soldier's figure closes its root offset over about this long
CATCH_UP_BEHIND_SECONDS = 1.0  # ... a figure behind that lag: this long (a pivot left it metres behind)
CATCH_UP_FASTER = 1.0  # ... going at most this fraction faster than its entity (cadence within MAX_RATE)
# a walking figure this far (cm) behind its stop lag (a pivot left it metres behind) jogs to catch up;
# jogging, it walks again once within the second of the run's (run2walk closes ~30 cm more, the walk the rest)
CATCH_UP_RUN_CM = (200.0, 80.0)
MIN_TURN_DEG = 22.5  # a standing soldier whose figure is this far from its heading turns in place
MAX_CHAIN = 64  # clip ends handled per soldier per tick (a longer backlog is taken up next tick)
MIN_CLIP_SECONDS = 1e-3  # a one-frame clip still takes this long, so clip ends cannot chain forever
_EPS_T = 1e-9
_CRAWL_CYCLE = int(LocoState.CRAWL_CYCLE)
# plain ints for the per-event Python paths (enum attribute access costs a few hundred ns each)
_IDLE, _TRANSITION, _LOCO, _CRAWL = (int(m) for m in (Mode.IDLE, Mode.TRANSITION, Mode.LOCO, Mode.CRAWL))
_NONE = int(LocoState.NONE)
_GAIT_STAY = np.arange(len(LocoState), dtype=np.int8)  # state -> itself, but a gait transition -> its stay
for _t, _stay in GAIT_STAY.items():
    _GAIT_STAY[_t] = _stay
_FIRING = int(WeaponState.FIRING)
_MOVE_CRAWL = int(Movement.CRAWL)
_SCALED: tuple[bool, ...] = tuple(SCALED.tolist())
# soldiers: a smaller group decides one by one in scalar Python (~12 µs a soldier), a larger one grouped
# by decision in numpy (~0.1 ms a group, whatever its size: a shard's creation burst, a batch of starts)
GROUP_MIN = 10


@dataclass
class TickUpdate:
    """What one tick produced: the poses of the soldiers due for an update.

    ``joints`` are pose vectors (soldier figure then weapon, ``MotionLibrary.sets[k].figure_slice``), radians
    (translational DOFs in cm); ``figures`` each figure's root placement ``(x, y, z, qw, qx, qy, qz)`` in Jack
    axes and centimetres relative to the soldier's feet (local motion only; the client owns heading and
    position). ``heading_only`` rows repeat the last pose (the seed's "send the last update packet with
    heading change"). ``server.soldier.wire.to_joint_updates`` converts to the protocol's units.
    """

    indices: np.ndarray  # (n,) int64, ascending
    joints: np.ndarray  # (n, ndof) float32
    figures: np.ndarray  # (n, nfig, 7) float32
    heading_only: np.ndarray  # (n,) bool
    clips: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int32))  # (n,) clip id shown
    frames: np.ndarray = field(default_factory=lambda: np.zeros(0))  # (n,) fractional frame within the clip
    headings: np.ndarray = field(default_factory=lambda: np.zeros(0))  # (n,) compass degrees last requested
    now: float = 0.0
    tick: int = 0

    def __len__(self) -> int:
        return len(self.indices)

    def select(self, rows: np.ndarray) -> TickUpdate:
        """The update of its rows ``rows`` only (the optional per-row arrays where present)."""

        def part(a: np.ndarray) -> np.ndarray:
            return a[rows] if len(a) == len(self.indices) else a

        return TickUpdate(
            self.indices[rows],
            self.joints[rows],
            self.figures[rows],
            self.heading_only[rows],
            part(self.clips),
            part(self.frames),
            part(self.headings),
            now=self.now,
            tick=self.tick,
        )

    def take(self, other: TickUpdate) -> None:
        """Overwrite the rows of the soldiers that ``other`` (a later sample of some of them) holds too."""
        at = np.searchsorted(self.indices, other.indices)
        hit = at < len(self.indices)
        hit[hit] = self.indices[at[hit]] == other.indices[hit]
        dst, src = at[hit], np.flatnonzero(hit)
        for mine, theirs in (
            (self.joints, other.joints),
            (self.figures, other.figures),
            (self.heading_only, other.heading_only),
            (self.clips, other.clips),
            (self.frames, other.frames),
            (self.headings, other.headings),
        ):
            if len(mine) == len(self.indices) and len(theirs) == len(other.indices):
                mine[dst] = theirs[src]


@dataclass(frozen=True)
class ClipStart:
    """A clip a soldier started (kept when ``record_clips`` is on): for tests and traces. ``skipped``: the
    seconds of its still lead-in a request's start skipped (:mod:`server.soldier.lead_in`); it showed from
    ``time`` and ended ``duration - skipped`` later."""

    time: float
    index: int
    clip: str
    forward: bool
    duration: float
    mode: str
    state: str
    skipped: float = 0.0


class ManagerCore:
    """What every part of the soldier manager shares: the table, the library, the settings, the lookups."""

    _group_min = GROUP_MIN  # (tests set it per manager: 1 always grouped, a large one always one by one)
    # fold the root offsets of an event's soldiers at once (False, the tests' reference: each on its own)
    _fold_groups = True

    def __init__(
        self,
        library: MotionLibrary,
        settings: SoldierSettings | None = None,
        *,
        max_soldiers: int = DEFAULT_MAX_SOLDIERS,
        record_limit: int = 100_000,
        **changes: Any,
    ) -> None:
        """``changes`` are :class:`SoldierSettings` fields (``throttle=0.0``) applied over ``settings``."""
        self.library = library
        self.table = SoldierTable(library.ndof, library.nfig, 16, max_soldiers)
        self.settings = (settings or SoldierSettings()).replace(**changes)
        self.names: dict[int, str] = {}
        self._by_name: dict[str, int] = {}
        self._paths: dict[int, list[Any]] = {}  # soldier -> [steps, arc index] while in TRANSITION
        self._pending: dict[
            int, tuple[str, float]
        ] = {}  # soldier -> (reaction, time asked) kept in TRANSITION
        self.clip_log: deque[ClipStart] = deque(maxlen=record_limit)
        self._build_lookups()
        self.ticks = 0
        self.stats = {
            "tick_seconds": 0.0,
            "last_tick_seconds": 0.0,
            "updates": 0,
            "requests": 0,
            "requests_unknown": 0,
            "requests_bad": 0,
            "events": 0,
            "clip_ends": 0,
            "unreachable": 0,
            "reactions": 0,  # reaction requests (react), played or kept
            "answers": 0,  # out-of-cycle updates (answer)
        }

    @property
    def settings(self) -> SoldierSettings:
        return self._settings

    @settings.setter
    def settings(self, value: SoldierSettings) -> None:
        if not isinstance(value, SoldierSettings):
            raise TypeError(f"settings must be SoldierSettings, not {type(value).__name__}")
        self._settings = value
        # what the vectorised pose path reads, per clip graph (turn and react clips: the static offset)
        o = value.heading_offsets
        self._offsets = np.array((*o, o[0], o[0]), np.float64)

    def configure(self, **changes: Any) -> SoldierSettings:
        """Replace the settings by a validated copy with ``changes`` (ValueError: nothing changes)."""
        self.settings = self._settings.replace(**changes)
        return self._settings

    def _build_lookups(self) -> None:
        lib = self.library
        # GOAL[appearance, firing] -> posture node (-1: not in this graph)
        self._goal = np.full((len(Appearance) + 1, 2), -1, np.int16)
        for app in Appearance:
            for firing in (False, True):
                name = goal_posture(app, WeaponState.FIRING if firing else WeaponState.DEPLOYED)
                self._goal[app, int(firing)] = lib.node(name) if lib.has_node(name) else -1
        # what moving means per appearance, given the clips this library has
        self._move = np.zeros(len(Appearance) + 1, np.int8)
        for app in Appearance:
            kind = movement(app)
            if (kind == Movement.WALK and lib.can_walk) or (kind == Movement.CRAWL and lib.can_crawl):
                self._move[app] = kind
        self._base = np.full(3, -1, np.int16)
        for kind, name in BASE_POSTURE.items():
            if lib.has_node(name):
                self._base[kind] = lib.node(name)
        self._home = lib.node(STAND_STOWED) if lib.has_node(STAND_STOWED) else 0
        # per Figure-5 state, how far behind the entity its figure walks (cm): what it still travels when the
        # entity stops, on average (half a step and the end step), so a stop ends near the entity
        travel = np.hypot(*lib.travel.total.T)
        self._stop_lag = np.zeros(len(LocoState))
        for state in LocoState:
            clip, end = lib.loco_clip[state, 0], lib.loco_clip[NEXT[state, Cond.STOP], 0]
            if clip >= 0:
                self._stop_lag[state] = 0.5 * travel[clip] + (
                    travel[end] if end >= 0 and NEXT[state, Cond.STOP] else 0.0
                )

    def _play_step(self, i: int, step: PathStep, t: float, folded: bool = False) -> None:
        """Soldier ``i`` plays arc ``step`` from ``t`` (``folded``: his root offset is already folded to
        ``t``, with a group's, :func:`root_motion.fold_exact`)."""
        tb = self.table
        if not folded:
            root_motion.fold1(tb, self.library, i, t)
        tb.stride[i] = 1.0
        tb.pivot_rest[i] = 0.0  # (a reversal's pivot sets its own after this)
        tb.clip[i] = step.clip
        tb.direc[i] = 1 if step.forward else -1
        tb.start[i] = t
        dur = max(step.duration, MIN_CLIP_SECONDS)
        tb.dur[i] = dur
        tb.end[i] = t + dur
        root_motion.rebase1(tb, self.library, i)
        self._record(i, t)

    def _play_steps(self, idx: np.ndarray, steps: list[PathStep], t: np.ndarray) -> None:
        """:meth:`_play_step` of soldiers ``idx``, one step each, at once: what it stores, bit for bit."""
        tb = self.table
        root_motion.fold_exact(tb, self.library, idx, t)
        tb.stride[idx] = 1.0
        tb.pivot_rest[idx] = 0.0
        tb.clip[idx] = [s.clip for s in steps]
        tb.direc[idx] = [1 if s.forward else -1 for s in steps]
        tb.start[idx] = t
        dur = np.maximum([s.duration for s in steps], MIN_CLIP_SECONDS)
        tb.dur[idx] = dur
        tb.end[idx] = t + dur
        root_motion.rebase_exact(tb, self.library, idx)
        if self._settings.record_clips:
            for i, ti in zip(idx.tolist(), t.tolist(), strict=True):
                self._record(i, ti)

    def _rest(self, i: int, node: int, t: float, folded: bool = False) -> None:
        """Show posture ``node``'s pose: its clip held at the frame that is that posture (``folded``: as
        :meth:`_play_step`)."""
        tb, lib = self.table, self.library
        if not folded:
            root_motion.fold1(tb, lib, i, t)  # the offset stays where the last step left it (feet planted)
        tb.node[i] = node
        self._hold_rest(i, node, t)
        root_motion.rebase1(tb, lib, i)

    def _rest_many(self, idx: np.ndarray, t: np.ndarray) -> None:
        """:meth:`_rest` of soldiers ``idx`` in their posture nodes, at once (bit for bit)."""
        tb, lib = self.table, self.library
        root_motion.fold_exact(tb, lib, idx, t)
        self._hold_rest(idx, tb.node[idx], t)
        root_motion.rebase_exact(tb, lib, idx)

    def _hold_rest(self, i: int | np.ndarray, node: int | np.ndarray, t: float | np.ndarray) -> None:
        """The columns of soldiers ``i`` (one, or an array) holding posture ``node``'s rest frame from ``t``
        on (their root offsets folded to ``t``)."""
        tb, lib = self.table, self.library
        tb.stride[i] = 1.0
        tb.pivot_rest[i] = 0.0
        clip = lib.rest_clip[node]
        tb.clip[i] = clip
        tb.direc[i] = lib.rest_dir[node]
        tb.dur[i] = lib.clip_duration[clip]
        tb.start[i] = t - tb.dur[i]
        tb.end[i] = t
        tb.dirty[i] = True

    def _record(self, i: int, t: float, what: str | None = None) -> None:
        if not self._settings.record_clips:
            return
        tb = self.table
        self.clip_log.append(
            ClipStart(
                t,
                i,
                what or self.library.clip_names[int(tb.clip[i])],
                bool(tb.direc[i] > 0),
                float(tb.dur[i]),
                Mode(int(tb.mode[i])).name,
                LocoState(int(tb.loco[i])).name,
            )
        )
