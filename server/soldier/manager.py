"""The soldier manager (seed 002, Figure 12) over a struct-of-arrays soldier table.

Figure 12 runs "every iteration, for each soldier". Here the per-soldier Python runs only on *events* — a
request that changes what a soldier does, or a clip that ends a posture-change arc or the locomotion — and
:meth:`SoldierManager.tick` is vectorised: it advances every soldier's clock, handles the clip ends (the
Figure 5 table for all walking/crawling soldiers at once, Python only for finished posture-change arcs), then
samples every soldier that is due for an update in one :meth:`ClipLibrary.sample` call per figure set.

Figure 12, and where each line lives:

=============================================  ============================================================
new packet: copy, convert TTES → Jack          :meth:`apply_requests` (vectorised, ``protocol.coords``)
compute velocity / heading                     :meth:`apply_requests` (speed, forwards or backwards)
transitioning: grab heading, continue          requests only stored; the path's arcs chain in ``tick``;
                                               a changed posture is taken up when the path ends
posture or weapon different: cancel the step,  :meth:`_on_event`: step cancelled (cross-faded), quickest
start a posture change                         path to the goal posture (:meth:`MotionLibrary.path`)
moving and PRONE: continue crawling            ``Mode.CRAWL`` + :mod:`~server.soldier.locomotion`
moving and STANDING: walk or run               ``Mode.LOCO`` + :mod:`~server.soldier.locomotion`
only the heading changed: resend last update   ``TickUpdate.heading_only``
=============================================  ============================================================

Times: every method takes ``now`` (seconds, non-decreasing) — the manager reads no clock. Clip changes chain
at the exact end time of the previous clip, not at the tick that notices it, so nothing drifts with the tick
rate. Settings are one frozen :class:`~server.soldier.settings.SoldierSettings`, replaced whole by
:meth:`SoldierManager.configure`; ``every_frame`` (``set_channelset_parameters("yes")``) replaces real time by
one stored frame per tick.
"""

from __future__ import annotations

import math
import time
from collections import deque
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from protocol import coords
from protocol.entity import Appearance, WeaponState, make_entity_requests
from protocol.events import DEFAULT_MAX_SOLDIERS
from server.soldier import report, root_motion
from server.soldier.blend import blend_into, smoothstep, yaw_rotate
from server.soldier.library import MotionLibrary, PathStep
from server.soldier.locomotion import (
    GAIT_STAY,
    IS_RUN,
    IS_WALK,
    NEXT,
    SCALED,
    Cond,
    Side,
    conditions,
    direction,
    is_fast,
    next_states,
    start_state,
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
    request_for,
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


@dataclass(frozen=True)
class ClipStart:
    """A clip a soldier started (kept when ``record_clips`` is on): for tests and traces."""

    time: float
    index: int
    clip: str
    forward: bool
    duration: float
    mode: str
    state: str


class SoldierManager:
    """All soldier states of one server: requests in, vectorised ticks out."""

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
            "answers": 0,  # out-of-cycle updates (answer)
        }

    # -- settings (one frozen value; the JCL commands replace it) ----------------------------------------
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

    # -- soldiers ----------------------------------------------------------------------------------------
    def create_soldier(
        self,
        name: str | None = None,
        figure: str = "DI.fig",
        weapon: str = "AK_47.fig",
        index: int | None = None,
        now: float = 0.0,
    ) -> int:
        """A new soldier state resting in STAND_STOWED; returns its index. ValueError if impossible."""
        if name is not None and name in self._by_name:
            raise ValueError(f"soldier name {name!r} is in use")
        try:
            fset = self.library.set_index(figure, weapon)
        except KeyError as exc:
            raise ValueError(str(exc.args[0])) from None
        i = self.table.allocate(index)
        t = self.table
        t.fset[i] = fset
        t.clock[i] = now
        t.created[i] = now
        t.appearance[i] = Appearance.UPRIGHT
        t.weapon[i] = WeaponState.DEPLOYED
        t.foot[i] = 1
        t.root_t[i] = now
        self._rest(i, self._home, float(now))
        nm = name if name is not None else f"s{i}"
        if nm in self._by_name:  # a generated name clashing with a user's: make it unique
            nm = f"{nm}#{i}"
        self.names[i] = nm
        self._by_name[nm] = i
        return i

    def remove_soldier(self, index: int) -> None:
        """Forget a soldier (KeyError if there is none); its index is reused by later creates."""
        self.table.free(index)
        self._paths.pop(index, None)
        nm = self.names.pop(index, None)
        if nm is not None:
            self._by_name.pop(nm, None)

    def index_of(self, name: str) -> int:
        return self._by_name[name]

    @property
    def count(self) -> int:
        return self.table.count

    # -- requests (Figure 12's first half) ---------------------------------------------------------------
    def apply_requests(self, batch: np.ndarray, now: float) -> np.ndarray:
        """Take a batch of entity requests (``protocol.entity.ENTITY_REQUEST_DTYPE``, Performer coordinates).

        Returns a per-row status: REQUEST_OK, REQUEST_UNKNOWN_SOLDIER or REQUEST_BAD_VALUE (enum values out of
        range, non-finite numbers, speed above MAX_SPEED). Never raises on the rows' contents; when several
        rows name one soldier the last one wins.
        """
        rows = np.asarray(batch)
        n = len(rows)
        status = np.zeros(n, np.uint8)
        if n == 0:
            return status
        tb = self.table
        idx = rows["index"].astype(np.int64)
        app = rows["appearance"].astype(np.int64)
        wpn = rows["weapon"].astype(np.int64)
        imm = rows["immediate"].astype(np.int64)
        with np.errstate(invalid="ignore", over="ignore"):  # garbage floats (signalling NaNs) are bad values
            vel = np.asarray(rows["velocity"], np.float64).reshape(n, 3)
            hdg = np.asarray(rows["heading"], np.float64).reshape(n)
            pos = np.asarray(rows["position"], np.float64).reshape(n, 3)
            finite = np.isfinite(vel).all(1) & np.isfinite(hdg) & np.isfinite(pos).all(1)
            bad = (
                (app < Appearance.DEAD)
                | (app > Appearance.CRAWL)
                | (wpn < 0)
                | (wpn > WeaponState.FIRING)
                | (imm < 0)
                | (imm > 1)
                | ~finite
                | ~(np.linalg.norm(np.where(finite[:, None], vel, 0.0), axis=1) <= MAX_SPEED)
            )
        live = tb.live_mask(idx)
        status[~live] = REQUEST_UNKNOWN_SOLDIER
        status[live & bad] = REQUEST_BAD_VALUE
        self.stats["requests"] += n
        self.stats["requests_unknown"] += int((~live).sum())
        self.stats["requests_bad"] += int((live & bad).sum())
        ok = np.flatnonzero(status == REQUEST_OK)
        if len(ok) == 0:
            return status
        if len(ok) > 1:  # the last row per soldier wins
            rev = ok[::-1]
            _, first = np.unique(idx[rev], return_index=True)
            ok = np.sort(rev[first])
        i = idx[ok]
        app, wpn, imm, vel, hdg, pos = app[ok], wpn[ok], imm[ok].astype(bool), vel[ok], hdg[ok], pos[ok]
        if not self._settings.every_frame:
            tb.clock[i] = now
        self._advance(i)  # clips that ended before the request end first (the next tick would do it later)
        t = tb.clock[i]
        speed = np.hypot(vel[:, 0], vel[:, 1])  # Performer: Z up
        moving = speed > MOVING_EPS
        fwd = coords.compass_to_direction(hdg)
        ahead = np.einsum("ij,ij->i", vel[:, :2], fwd[:, :2])
        left = vel[:, 1] * fwd[:, 0] - vel[:, 0] * fwd[:, 1]  # Performer Z up: (fwd x vel).z
        backward, side = direction(ahead, left, self.library.can_side)
        backward &= moving
        side = np.where(moving, side, Side.AHEAD)
        mode = tb.mode[i]
        changed_pw = (app != tb.appearance[i]) | (wpn != tb.weapon[i])
        heading_changed = hdg != tb.heading[i]
        speed_changed = speed != tb.speed[i]
        kind = self._move[app]
        event = (
            imm | (changed_pw & (mode != _TRANSITION)) | ((mode == _IDLE) & moving & (kind != Movement.NONE))
        )
        # the root offset up to now under the old velocity; a turned entity turns a world-fixed offset
        root_motion.fold(tb, self.library, i, t)
        turned = np.where(tb.has_heading[i], hdg - tb.heading[i], 0.0)
        tb.has_heading[i] = True
        root_motion.turn_offsets(tb, i, turned)
        # a standing figure keeps its orientation in the world (it turns in place, below); a moving one
        # turns with the entity at once
        keeps = (mode == _LOCO) | (mode == _CRAWL) | (tb.node[i] == self._home) | moving
        tb.root_yaw[i] = np.where(keeps, (tb.root_yaw[i] - turned + 180.0) % 360.0 - 180.0, 0.0)
        # store the request (Jack coordinates)
        tb.appearance[i] = app
        tb.weapon[i] = wpn
        tb.velocity[i] = coords.vectors_performer_to_jack(vel)
        tb.position[i] = coords.points_performer_to_jack(pos)
        tb.heading[i] = hdg
        tb.yaw[i] = coords.compass_to_jack_yaw(hdg)
        tb.speed[i] = speed
        tb.backward[i] = backward
        tb.side[i] = side
        tb.vlocal[i] = np.stack([-left, -ahead], axis=1) * 100.0  # soldier frame: forwards -Z, left -X
        # a speed change within a gait: keep the phase, change the playback rate
        stepping = (mode == _LOCO) | (mode == _CRAWL)
        rescale = ~event & stepping & moving & speed_changed & SCALED[tb.loco[i]]
        if rescale.any():
            r = i[rescale]
            tr = t[rescale]
            new_dur, tb.stride[r] = self._step_duration(r, tb.clip[r], tb.loco[r])
            u = np.clip((tr - tb.start[r]) / np.maximum(tb.dur[r], _EPS_T), 0.0, 1.0)
            tb.start[r] = tr - u * new_dur
            tb.dur[r] = new_dur
            tb.end[r] = tb.start[r] + new_dur
        hp = ~event & (mode == _IDLE) & ~moving & heading_changed
        tb.heading_pending[i[hp]] = True
        for k in np.flatnonzero(hp & (np.abs(tb.root_yaw[i]) >= MIN_TURN_DEG)).tolist():
            self._turn(int(i[k]), float(t[k]))
        tb.requested[i[event | hp | rescale]] = True  # what :meth:`answer` answers between ticks
        ev = np.flatnonzero(event)
        if len(ev):
            self.stats["events"] += len(ev)
            cap = ev[stepping[ev] & ~imm[ev]] if self._settings.blend_time > 0 else ev[:0]
            captured: dict[int, int] = {}
            cj = cf = np.zeros(0, np.float32)
            if len(cap):
                cj, cf, _, _ = self._pose(i[cap])
                captured = {int(s): k for k, s in enumerate(i[cap])}
            for k in ev.tolist():
                s = int(i[k])
                c = captured.get(s)
                self._on_event(s, float(t[k]), bool(imm[k]), None if c is None else (cj[c], cf[c]))
        return status

    # -- the JCL debugging commands (seed 3.4.1-3.4.2), on one soldier -----------------------------------
    def posture_change(self, index: int, posture: str, now: float) -> list[str]:
        """``posture_change``: the soldier goes to ``posture`` along the quickest path, exactly as a standing
        still request for that posture would take it (heading and position kept; a soldier in a transition
        finishes it first). Returns the postures of the path playing now; KeyError for an unknown soldier or
        posture."""
        if not self.table.is_live(index):
            raise KeyError(f"no soldier {index}")
        appearance, weapon = request_for(posture)
        tb = self.table
        row = make_entity_requests(
            index,
            appearance,
            weapon,
            heading=float(tb.heading[index]),
            position=coords.points_jack_to_performer(tb.position[index].astype(np.float64)),
        )
        if self.apply_requests(row, now)[0] != REQUEST_OK:
            raise KeyError(f"soldier {index} refused posture {posture!r}")
        return [self.library.posture_names[s.end] for s in self._paths.get(index, [()])[0]]

    def play_clip(
        self, index: int, clip: int, forward: bool = True, duration: float = -1.0, now: float = 0.0
    ) -> float:
        """``play_bound_channelset``: the soldier plays ``clip`` once (over ``duration`` s, <= 0: the stored
        time), then takes up its last request again from the posture the clip ends in (a static arc's end,
        else where it was). Returns the play time; KeyError / ValueError for a bad soldier or clip."""
        tb, lib = self.table, self.library
        if not tb.is_live(index):
            raise KeyError(f"no soldier {index}")
        if not 0 <= clip < lib.nclips:
            raise ValueError(f"no clip {clip}")
        if not math.isfinite(duration):
            raise ValueError(f"play time must be finite, not {duration}")
        i = int(index)
        if not self._settings.every_frame:
            tb.clock[i] = now
        self._advance(np.array([i], np.int64))
        t = float(tb.clock[i])
        node = int(tb.node[i])
        end = lib.clip_end_node(clip, forward, node)
        step = PathStep(
            clip, forward, float(duration) if duration > 0 else float(lib.clip_duration[clip]), node, end
        )
        tb.blend_len[i] = 0.0
        tb.loco[i] = _NONE
        tb.mode[i] = _TRANSITION
        self._paths[i] = [(step,), 0]
        self._play_step(i, step, t)
        tb.dirty[i] = True
        return step.duration

    def _desired(self, i: int) -> int:
        """Figure 12's goal posture node: the gait's base posture while moving, else the requested posture."""
        tb = self.table
        app = int(tb.appearance[i])
        kind = int(self._move[app]) if tb.speed[i] > MOVING_EPS else 0
        if kind:
            return int(self._base[kind])
        goal = int(self._goal[app, int(tb.weapon[i] == _FIRING)])
        # a posture with variant nodes (DEAD@...): the variant nearest from here (table lookup)
        return int(self.library.goal_node[int(tb.node[i]), goal]) if goal >= 0 else goal

    def _on_event(
        self, i: int, t: float, immediate: bool, captured: tuple[np.ndarray, np.ndarray] | None
    ) -> None:
        tb = self.table
        if immediate:
            self._snap(i, t)
            return
        mode = int(tb.mode[i])
        if mode in (_LOCO, _CRAWL):
            desired = self._desired(i)
            if desired == int(tb.node[i]) or desired < 0:
                return  # same base posture: the gait goes on (Figure 5 handles speed and direction)
            # cancel the step: fade from the pose shown now into whatever starts next
            if captured is not None:
                tb.blend_joints[i], tb.blend_figs[i] = captured
                tb.blend_t0[i] = t
                tb.blend_len[i] = self._settings.blend_time
            tb.mode[i] = _IDLE
            tb.loco[i] = _NONE
            self._record(i, t, "cancel")
            self._decide(i, t)
            if tb.mode[i] == _IDLE:  # nowhere to go: rest in the base posture
                self._rest(i, int(tb.node[i]), t)
            return
        if mode == _IDLE:
            self._decide(i, t)

    def _snap(self, i: int, t: float) -> None:
        """``immediate``: jump to the goal posture's pose (no path, no fade)."""
        tb = self.table
        self._paths.pop(i, None)
        tb.blend_len[i] = 0.0
        tb.mode[i] = _IDLE
        tb.loco[i] = _NONE
        desired = self._desired(i)
        if desired >= 0:
            tb.node[i] = desired
        self._rest(i, int(tb.node[i]), t)
        self._decide(i, t)

    def _decide(self, i: int, t: float) -> None:
        """A resting soldier: start the posture change or the gait its last request asks for."""
        tb = self.table
        tb.dirty[i] = True
        desired = self._desired(i)
        node = int(tb.node[i])
        if desired < 0:
            return
        if desired != node:
            tb.root_yaw[i] = 0.0  # a posture change faces the heading (no turn clips off STAND_STOWED)
            steps = self.library.path(node, desired)
            if not steps:
                self.stats["unreachable"] += 1
                return
            self._paths[i] = [steps, 0]
            tb.mode[i] = _TRANSITION
            self._play_step(i, steps[0], t)
            return
        kind = int(self._move[int(tb.appearance[i])]) if tb.speed[i] > MOVING_EPS else 0
        if not kind and abs(tb.root_yaw[i]) >= MIN_TURN_DEG and self._turn(i, t):
            return
        if not kind and node != self._home:  # no turn clip here: the figure faces the heading again
            tb.root_yaw[i] = 0.0
        if kind:
            fast = bool(tb.speed[i] > self._settings.walk_run_threshold)
            state = start_state(
                Movement(kind), bool(tb.backward[i]), fast, self.library.can_run, int(tb.side[i])
            )
            tb.mode[i] = _CRAWL if kind == _MOVE_CRAWL else _LOCO
            self._enter_one(i, int(state), t)

    # -- reactions (issue 16) ----------------------------------------------------------------------------
    def react(self, index: int, kind: str, now: float) -> str | None:
        """A Fire PDU's ``"recoil"`` or a near detonation's ``"flinch"``: a soldier resting in a posture
        with that reaction plays it once (soldier_react.graph) and rests there again. A soldier stepping or
        changing posture, or with no such clip for its posture, does not react (None); else the clip."""
        tb, lib = self.table, self.library
        if not tb.is_live(index):
            raise KeyError(f"no soldier {index}")
        if not self._settings.every_frame:
            tb.clock[index] = now
        self._advance(np.array([index], np.int64))
        if int(tb.mode[index]) != _IDLE:
            return None
        clip = lib.reaction.get((lib.posture_names[int(tb.node[index])], kind))
        if clip is None:
            return None
        node = int(tb.node[index])
        step = PathStep(clip, True, float(lib.clip_duration[clip]), node, node)
        tb.blend_len[index] = 0.0
        tb.mode[index] = _TRANSITION
        self._paths[index] = [(step,), 0]
        self._play_step(index, step, float(tb.clock[index]))
        tb.dirty[index] = True
        return lib.clip_names[clip]

    # -- turns in place (issue 16) ------------------------------------------------------------------------
    def _turning(self, clip: int) -> bool:
        return self.library.clip_end_offset[clip, 2] != 0.0 and self.library.clip_graph[clip] != 0

    def _turn(self, i: int, t: float) -> bool:
        """A standing soldier whose figure faces away from its heading plays the turn in place that fits."""
        tb, lib = self.table, self.library
        if not lib.turn_clips or int(tb.node[i]) != self._home or int(tb.mode[i]) != _IDLE:
            return False
        want = -float(tb.root_yaw[i])  # compass degrees to turn
        clip, turn = min(  # the nearest turn; of two as near (180 both ways) the one turning the asked way
            lib.turn_clips, key=lambda c: (abs((c[1] - want + 180.0) % 360.0 - 180.0), c[1] * want < 0)
        )
        if abs((turn - want + 180.0) % 360.0 - 180.0) >= abs(want):
            return False
        step = PathStep(clip, True, float(lib.clip_duration[clip]), self._home, self._home)
        tb.blend_len[i] = 0.0
        tb.mode[i] = _TRANSITION
        self._paths[i] = [(step,), 0]
        self._play_step(i, step, t)
        tb.dirty[i] = True
        return True

    def _turn_end(self, i: int, t: float) -> None:
        """The turn's own move (``end_offset``) joins the root offset; the figure rests in its new heading."""
        tb, lib = self.table, self.library
        x, z, yaw = lib.clip_end_offset[int(tb.clip[i])]
        a = -math.radians(float(tb.root_yaw[i]))  # as blend.yaw_rotate turns the clip's placements
        self._rest(i, self._home, t)
        tb.root_off[i, 0] += math.cos(a) * x + math.sin(a) * z
        tb.root_off[i, 1] += math.cos(a) * z - math.sin(a) * x
        tb.root_yaw[i] = (float(tb.root_yaw[i]) - yaw + 180.0) % 360.0 - 180.0

    def _play_step(self, i: int, step: PathStep, t: float) -> None:
        tb = self.table
        root_motion.fold1(tb, self.library, i, t)
        tb.stride[i] = 1.0
        tb.clip[i] = step.clip
        tb.direc[i] = 1 if step.forward else -1
        tb.start[i] = t
        dur = max(step.duration, MIN_CLIP_SECONDS)
        tb.dur[i] = dur
        tb.end[i] = t + dur
        root_motion.rebase1(tb, self.library, i)
        self._record(i, t)

    def _rest(self, i: int, node: int, t: float) -> None:
        """Show posture ``node``'s pose: its clip held at the frame that is that posture."""
        tb = self.table
        lib = self.library
        root_motion.fold1(tb, lib, i, t)  # the offset stays where the last step left it (feet planted)
        tb.stride[i] = 1.0
        clip = int(lib.rest_clip[node])
        tb.node[i] = node
        tb.clip[i] = clip
        tb.direc[i] = lib.rest_dir[node]
        tb.dur[i] = lib.clip_duration[clip]
        tb.start[i] = t - tb.dur[i]
        tb.end[i] = t
        tb.dirty[i] = True
        root_motion.rebase1(tb, lib, i)

    # -- locomotion (Figure 5, vectorised) ---------------------------------------------------------------
    def _step_duration(
        self, idx: np.ndarray, clip: np.ndarray, states: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """Play time and stride scale of ``clip`` in Figure-5 ``states`` for soldiers ``idx`` (root offsets
        folded to now).

        A cycle aims at the entity's speed plus what brings the root offset along the velocity to its stop lag
        (the figure trails the entity by what it would still travel if the entity stopped) in about
        CATCH_UP_SECONDS, within human cadence (MIN_RATE..MAX_RATE). When the entity's speed alone is beyond
        that cadence the stride length takes the rest (the feet slide by the difference), except in a gait
        the speed is about to leave (a walk step before walk→run): there the root offset takes it. Start and
        end steps and gait changes play at their recorded rate."""
        tb, lib = self.table, self.library
        st = np.asarray(states, np.int64)
        speed = tb.speed[idx]
        stored = lib.clip_duration[clip]
        gs = lib.clip_ground_speed[clip]
        ok = SCALED[st] & (speed > MOVING_EPS) & (gs > 0)
        v = tb.vlocal[idx]
        along = np.einsum("ij,ij->i", tb.root_off[idx], v) / np.maximum(np.hypot(v[:, 0], v[:, 1]), 1e-9)
        gs = np.where(gs > 0, gs, 1.0)
        cfg = self._settings
        hysteresis = min(cfg.walk_run_hysteresis, 0.5 * cfg.walk_run_threshold)
        fast = is_fast(st, speed, cfg.walk_run_threshold, hysteresis)
        leaving = (IS_RUN[st] & ~fast) | (IS_WALK[st] & fast & lib.can_run)
        ideal = speed / gs  # the entity's speed alone
        top = np.where(IS_WALK[st], WALK_MAX_RATE, MAX_RATE)
        scale = np.clip(ideal / np.clip(ideal, MIN_RATE, top), MIN_STRIDE, MAX_STRIDE)
        stride = np.where(ok & ~leaving, scale, 1.0)
        error = along + self._stop_lag[st]  # cm ahead of where the figure should be
        want = speed + np.clip(-error / 100.0 / CATCH_UP_SECONDS, -0.5 * speed, 0.5 * speed)
        rate = np.where(ok, np.clip(want / (gs * stride), MIN_RATE, top), 1.0)
        return np.maximum(stored / rate, MIN_CLIP_SECONDS), stride

    def _enter_states(self, idx: np.ndarray, states: np.ndarray, t: np.ndarray) -> None:
        """Start the clips of Figure-5 ``states`` at times ``t`` (the next step uses the other foot)."""
        if len(idx) == 0:
            return
        tb, lib = self.table, self.library
        st = states.astype(np.int64)
        foot = 1 - tb.foot[idx]
        clip = lib.loco_clip[st, foot]
        direc = lib.loco_dir[st].astype(np.int8)
        direc = np.where((st == _CRAWL_CYCLE) & tb.backward[idx], -direc, direc)
        root_motion.fold(tb, lib, idx, t)
        dur, tb.stride[idx] = self._step_duration(idx, clip, st)
        tb.loco[idx] = st
        tb.foot[idx] = foot
        tb.clip[idx] = clip
        tb.direc[idx] = direc
        tb.start[idx] = t
        tb.dur[idx] = dur
        tb.end[idx] = t + dur
        root_motion.rebase(tb, lib, idx)
        if self._settings.record_clips:
            for k in range(len(idx)):
                self._record(int(idx[k]), float(t[k]))

    def _enter_one(self, i: int, state: int, t: float) -> None:
        """:meth:`_enter_states` for one soldier in scalar Python (the per-event path, ~10x cheaper)."""
        tb, lib = self.table, self.library
        foot = 1 - int(tb.foot[i])
        clip = int(lib.loco_clip[state, foot])
        direc = int(lib.loco_dir[state])
        if state == _CRAWL_CYCLE and tb.backward[i]:
            direc = -direc
        root_motion.fold1(tb, lib, i, t)
        if _SCALED[state]:  # a side-step: the vectorised pacing
            durs, strides = self._step_duration(np.array([i], np.int64), np.array([clip]), np.array([state]))
            dur, tb.stride[i] = float(durs[0]), strides[0]
        else:  # a start step: its recorded pace
            dur, tb.stride[i] = max(float(lib.clip_duration[clip]), MIN_CLIP_SECONDS), 1.0
        tb.loco[i] = state
        tb.foot[i] = foot
        tb.clip[i] = clip
        tb.direc[i] = direc
        tb.start[i] = t
        tb.dur[i] = dur
        tb.end[i] = t + dur
        root_motion.rebase1(tb, lib, i)
        self._record(i, t)

    def _loco_ended(self, idx: np.ndarray) -> None:
        tb = self.table
        t = tb.end[idx].copy()
        speed = tb.speed[idx]
        st = self._settings
        hysteresis = min(st.walk_run_hysteresis, 0.5 * st.walk_run_threshold)
        cond = conditions(
            tb.loco[idx],
            speed > MOVING_EPS,
            tb.backward[idx],
            is_fast(tb.loco[idx], speed, st.walk_run_threshold, hysteresis),
            self.library.can_run,
            tb.side[idx],
        )
        nxt = next_states(tb.loco[idx], cond)
        # a one-footed gait transition waits for its foot: one more stride of the current gait first
        want = self.library.transition_foot[nxt]
        wrong_foot = (want >= 0) & ((1 - tb.foot[idx]) != want)
        if wrong_foot.any():
            nxt = np.where(wrong_foot, _GAIT_STAY[nxt], nxt)
        done = nxt == _NONE
        cont = ~done
        self._enter_states(idx[cont], nxt[cont], t[cont])
        for k in np.flatnonzero(done).tolist():
            i = int(idx[k])
            tb.mode[i] = _IDLE
            tb.loco[i] = _NONE
            tb.dirty[i] = True
            self._decide(i, float(t[k]))

    def _transition_end(self, i: int, t: float) -> None:
        tb = self.table
        entry = self._paths.get(i)
        if entry is None:  # cannot happen; keep the soldier consistent anyway
            tb.mode[i] = _IDLE
            return
        steps, k = entry
        tb.node[i] = steps[k].end
        k += 1
        if k < len(steps):
            entry[1] = k
            self._play_step(i, steps[k], t)
            return
        del self._paths[i]
        tb.mode[i] = _IDLE
        if self._turning(int(tb.clip[i])):
            self._turn_end(i, t)
        self._decide(i, t)

    def _advance(self, cand: np.ndarray) -> None:
        """Handle every clip end up to each soldier's clock, in time order per soldier."""
        tb = self.table
        for _ in range(MAX_CHAIN):
            ended = (tb.mode[cand] != _IDLE) & (tb.clock[cand] >= tb.end[cand])
            cand = cand[ended]
            if len(cand) == 0:
                return
            self.stats["clip_ends"] += len(cand)
            mode = tb.mode[cand]
            stepping = cand[(mode == _LOCO) | (mode == _CRAWL)]
            if len(stepping):
                self._loco_ended(stepping)
            for i in cand[mode == _TRANSITION].tolist():
                self._transition_end(i, float(tb.end[i]))

    # -- ticks -------------------------------------------------------------------------------------------
    def tick(self, now: float) -> TickUpdate:
        """Advance every soldier to ``now`` and return the poses of those due for an update.

        A soldier is due when its last update by a tick is at least ``settings.min_interval`` old (the
        throttle as a rate cap on the tick grid; an :meth:`answer` between ticks does not move the soldier
        off that grid) and its pose may have changed (playing a clip, cross-fading, a new resting
        pose, or a pending heading-only change).
        """
        t0 = time.perf_counter()
        self.ticks += 1
        tb = self.table
        live = tb.live
        if len(live):
            if self._settings.every_frame:
                nfr = self.library.clip_nframes[tb.clip[live]]
                tb.clock[live] += tb.dur[live] / np.maximum(nfr - 1, 1)
            else:
                tb.clock[live] = now
            self._advance(live)
            active = (
                (tb.mode[live] != _IDLE)
                | tb.dirty[live]
                | tb.heading_pending[live]
                | (tb.blend_len[live] > 0)
            )
            due = live[active & self._due(tb.tick_sent[live], now)]
        else:
            due = live
        out = self._emit(due, now)
        tb.tick_sent[due] = now
        dt = time.perf_counter() - t0
        self.stats["tick_seconds"] += dt
        self.stats["last_tick_seconds"] = dt
        return out

    def answer(self, now: float, at: float | None = None) -> TickUpdate:
        """An out-of-cycle update, between ticks, for just the soldiers whose requests changed what they show.

        Requests are applied when they arrive (:meth:`apply_requests`: a new clip, rate or heading), so the
        pose the next tick would send is known now: this releases that update early. The soldiers are
        sampled at ``at`` (the next tick's time; never before ``now``), so the update that reflects a request
        shows its motion already (a posture change eases in: at the request instant the pose is still the old
        one on the wire) and the tick at ``at`` finds nothing new to send. It is the next tick's update, so
        the throttle is the tick's: a soldier not due at ``at`` waits for its tick. Nothing in every-frame
        mode (its clock steps one frame per tick).
        """
        tb = self.table
        at = now if at is None else max(now, at)
        idx = np.flatnonzero(tb.requested).astype(np.int64)
        if self._settings.every_frame or len(idx) == 0:
            return self._emit(idx[:0], now)
        tb.clock[idx] = np.maximum(tb.clock[idx], now)
        self._advance(idx)
        due = idx[self._due(tb.tick_sent[idx], at)]
        self.stats["answers"] += len(due)
        out = self._emit(due, at)
        tb.tick_sent[due] = at
        return out

    def _due(self, tick_sent: np.ndarray, at: float) -> np.ndarray:
        """The throttle: a tick's update ``min_interval`` after the last one, or that same tick's again."""
        return (at - tick_sent >= self._settings.min_interval - _EPS_T) | (tick_sent >= at - _EPS_T)

    def _emit(self, due: np.ndarray, now: float) -> TickUpdate:
        """The poses of ``due`` at ``now`` as a :class:`TickUpdate`; clears the flags that asked for it."""
        tb = self.table
        joints, figures, clips, frames = self._pose(due, now)
        heading_only = tb.heading_pending[due] & ~tb.dirty[due] & (tb.mode[due] == _IDLE)
        heading_only &= tb.blend_len[due] <= 0
        out = TickUpdate(
            due.copy(), joints, figures, heading_only, clips, frames, tb.heading[due].copy(), now, self.ticks
        )
        tb.last_sent[due] = now
        tb.dirty[due] = False
        tb.heading_pending[due] = False
        tb.requested[due] = False
        self.stats["updates"] += len(due)
        return out

    def snapshot(self, indices: np.ndarray | list[int] | None = None) -> TickUpdate:
        """The current poses of live soldiers (all if None), ignoring the throttle: for a new subscriber."""
        tb = self.table
        idx = tb.live if indices is None else np.asarray(indices, np.int64)
        idx = np.unique(idx[tb.live_mask(idx)])
        joints, figures, clips, frames = self._pose(idx)
        return TickUpdate(
            idx,
            joints,
            figures,
            np.zeros(len(idx), bool),
            clips,
            frames,
            tb.heading[idx].copy(),
            float(tb.clock[idx].max()) if len(idx) else 0.0,
            self.ticks,
        )

    def _pose(
        self, idx: np.ndarray, at: float | None = None
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Poses shown by soldiers ``idx`` at their clocks (or at ``at``, if later: an :meth:`answer`): one
        sample per figure set, heading offsets, cross-fades."""
        tb, lib = self.table, self.library
        n = len(idx)
        clip = tb.clip[idx]
        clock = tb.clock[idx] if at is None or self._settings.every_frame else np.maximum(tb.clock[idx], at)
        args = (clip, tb.start[idx], tb.direc[idx], tb.dur[idx], clock)
        if len(lib.sets) == 1 or n == 0:
            s = lib.sets[0].sample(*args, interpolate=self._settings.interpolate)
            joints, figures, frames = s.joints, s.figures, s.position
        else:
            joints = np.empty((n, lib.ndof), np.float32)
            figures = np.empty((n, lib.nfig, 7), np.float32)
            frames = np.empty(n, np.float64)
            fset = tb.fset[idx]
            for k in np.unique(fset).tolist():
                sel = np.flatnonzero(fset == k)
                s = lib.sets[k].sample(*(a[sel] for a in args), interpolate=self._settings.interpolate)
                joints[sel], figures[sel], frames[sel] = s.joints, s.figures, s.position
        if n:  # the root offset and yaw: every figure of the soldier moves with it (docs/PROTOCOL.md)
            mode = tb.mode[idx]
            turning = (tb.root_yaw[idx] != 0.0) & ((mode == _LOCO) | (mode == _CRAWL))
            root_motion.fold(tb, lib, idx[turning], clock[turning])
            yawed = np.flatnonzero(tb.root_yaw[idx] != 0.0)
            if len(yawed):
                f = figures[yawed]
                yaw_rotate(f, tb.root_yaw[idx[yawed]])
                figures[yawed] = f
            off = root_motion.offset_at(tb, lib, idx, clock, frames).astype(np.float32)
            figures[:, :, 0] += off[:, None, 0]
            figures[:, :, 2] += off[:, None, 1]
        if n and self._offsets.any():
            off = self._offsets[lib.clip_graph[clip]]
            turn = np.flatnonzero(off != 0.0)
            if len(turn):
                f = figures[turn]
                yaw_rotate(f, off[turn])
                figures[turn] = f
        if n:
            blending = np.flatnonzero(tb.blend_len[idx] > 0)
            if len(blending):
                b = idx[blending]
                u = (clock[blending] - tb.blend_t0[b]) / tb.blend_len[b]
                j, f = joints[blending], figures[blending]
                blend_into(j, f, tb.blend_joints[b], tb.blend_figs[b], smoothstep(u))
                joints[blending], figures[blending] = j, f
                tb.blend_len[b[u >= 1.0]] = 0.0
        return joints, figures, clip.astype(np.int32), frames

    # -- reporting ---------------------------------------------------------------------------------------
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

    def clips_of(self, index: int) -> list[ClipStart]:
        """The recorded clip starts of one soldier (``record_clips=True``), oldest first."""
        return [c for c in self.clip_log if c.index == index]

    def path_steps(self, index: int) -> tuple[PathStep, ...]:
        """The posture-change path a soldier is playing (empty unless in TRANSITION)."""
        entry = self._paths.get(index)
        return tuple(entry[0]) if entry is not None else ()

    def goal_node(self, index: int) -> int:
        """The posture node the soldier's last request asks for (-1: none in this graph)."""
        return self._desired(index)

    def soldier_info(self, index: int) -> dict[str, Any]:
        """One soldier's state, for status reports and tests (:func:`server.soldier.report.soldier_info`)."""
        return report.soldier_info(self, index)

    def status(self) -> dict[str, Any]:
        """The periodic status report (:func:`server.soldier.report.status`)."""
        return report.status(self)
