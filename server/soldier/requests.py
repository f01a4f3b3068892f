"""Figure 12's first half: entity requests in (vectorised), and the JCL debugging commands on one soldier."""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from protocol import coords
from protocol.entity import Appearance, WeaponState, make_entity_requests
from server.soldier import root_motion
from server.soldier.core import (
    _CRAWL,
    _EPS_T,
    _IDLE,
    _LOCO,
    _NONE,
    _TRANSITION,
    MAX_SPEED,
    MIN_TURN_DEG,
    MOVING_EPS,
    REQUEST_BAD_VALUE,
    REQUEST_OK,
    REQUEST_UNKNOWN_SOLDIER,
)
from server.soldier.library import PathStep
from server.soldier.locomotion import (
    SCALED,
    Side,
    direction,
)
from server.soldier.state import (
    Movement,
    request_for,
)
from server.soldier.ticking import Ticking
from server.soldier.turning import facing

# plain ints: numpy compares an IntEnum member slower (these run on every request batch)
_APP_LOW, _APP_HIGH, _WPN_HIGH = int(Appearance.DEAD), int(Appearance.CRAWL), int(WeaponState.FIRING)
_MOVE_WALK, _MOVE_NONE, _AHEAD = int(Movement.WALK), int(Movement.NONE), int(Side.AHEAD)


class _Columns(NamedTuple):
    """A batch of entity requests' columns: index, appearance, weapon, immediate (int64), velocity,
    heading, position (float64, Performer)."""

    idx: np.ndarray
    app: np.ndarray
    wpn: np.ndarray
    imm: np.ndarray
    vel: np.ndarray
    hdg: np.ndarray
    pos: np.ndarray


def _columns(rows: np.ndarray) -> _Columns:
    """A batch's columns as the event path reads them."""
    n = len(rows)
    with np.errstate(invalid="ignore", over="ignore"):  # garbage floats (signalling NaNs) are bad values
        return _Columns(
            rows["index"].astype(np.int64),
            rows["appearance"].astype(np.int64),
            rows["weapon"].astype(np.int64),
            rows["immediate"].astype(np.int64),
            np.asarray(rows["velocity"], np.float64).reshape(n, 3),
            np.asarray(rows["heading"], np.float64).reshape(n),
            np.asarray(rows["position"], np.float64).reshape(n, 3),
        )


def _bad(c: _Columns) -> np.ndarray:
    """(n,) bool: the rows with a value a request may not have (enums out of range, non-finite numbers, a
    speed over MAX_SPEED): REQUEST_BAD_VALUE where the soldier is live."""
    with np.errstate(invalid="ignore", over="ignore"):
        finite = np.isfinite(c.vel).all(1) & np.isfinite(c.hdg) & np.isfinite(c.pos).all(1)
        return (
            (c.app < _APP_LOW)
            | (c.app > _APP_HIGH)
            | (c.wpn < 0)
            | (c.wpn > _WPN_HIGH)
            | (c.imm < 0)
            | (c.imm > 1)
            | ~finite
            | ~(np.linalg.norm(np.where(finite[:, None], c.vel, 0.0), axis=1) <= MAX_SPEED)
        )


class Requests(Ticking):
    """Requests in: stored (TTES → Jack) and turned into events where they change what a soldier does."""

    def check_requests(self, batch: np.ndarray) -> np.ndarray:
        """The per-row status :meth:`apply_requests` would return, applying nothing: a front-end's check
        (its shards animate the soldiers; running the event path here too cost it most of its core)."""
        return self._checked(np.asarray(batch))[0]

    def has_bad_values(self, batch: np.ndarray) -> bool:
        """Whether :meth:`apply_requests` would find a REQUEST_BAD_VALUE row in ``batch`` (a live soldier's
        row with a value out of range): a session holds a client's next request frame with it only when
        not (``Session.handle``). Counts nothing."""
        cols = _columns(np.asarray(batch))
        return bool((_bad(cols) & self.table.live_mask(cols.idx)).any())

    def _checked(self, rows: np.ndarray) -> tuple[np.ndarray, _Columns]:
        """Each row's status (and the stats counted) and the rows' columns as the event path reads them."""
        n = len(rows)
        status = np.zeros(n, np.uint8)
        cols = _columns(rows)
        idx, bad = cols.idx, _bad(cols)
        live = self.table.live_mask(idx)
        status[~live] = REQUEST_UNKNOWN_SOLDIER
        status[live & bad] = REQUEST_BAD_VALUE
        self.stats["requests"] += n
        self.stats["requests_unknown"] += int((~live).sum())
        self.stats["requests_bad"] += int((live & bad).sum())
        return status, cols

    def apply_requests(self, batch: np.ndarray, now: float) -> np.ndarray:
        """Take a batch of entity requests (``protocol.entity.ENTITY_REQUEST_DTYPE``, Performer coordinates).

        Returns a per-row status: REQUEST_OK, REQUEST_UNKNOWN_SOLDIER or REQUEST_BAD_VALUE (enum values out of
        range, non-finite numbers, speed above MAX_SPEED). Never raises on the rows' contents; when several
        rows name one soldier the last one wins.
        """
        status, cols = self._checked(np.asarray(batch))
        tb = self.table
        idx, app, wpn, imm, vel, hdg, pos = cols
        ok = np.flatnonzero(status == REQUEST_OK)
        if len(ok) == 0:
            return status
        if len(ok) > 1:  # the last row per soldier wins
            rev = ok[::-1]
            _, first = np.unique(idx[rev], return_index=True)
            ok = np.sort(rev[first])
        keep = self._changing(idx[ok], app[ok], wpn[ok], imm[ok], vel[ok], hdg[ok], pos[ok])
        if not keep.any():
            return status
        ok = ok[keep]
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
        # the figure's frame: the heading, or about from it to walk a fast velocity straight back forwards
        walks = moving & (self._move[app] == _MOVE_WALK) & bool(self.library.turn_clips)  # it can pivot
        face = facing(backward & walks, speed, tb.face[i])
        about = face != 0.0
        ahead, left = np.where(about, -ahead, ahead), np.where(about, -left, left)
        backward, side = direction(ahead, left, self.library.can_side)
        backward &= moving
        side = np.where(moving, side, _AHEAD)
        mode = tb.mode[i]
        changed_pw = (app != tb.appearance[i]) | (wpn != tb.weapon[i])
        heading_changed = hdg + face != tb.heading[i] + tb.face[i]
        speed_changed = speed != tb.speed[i]
        kind = self._move[app]
        # one playing a path asked for another posture, or to move or stop, re-plans it (replanning.py)
        replans = (mode == _TRANSITION) & (changed_pw | (moving != (tb.speed[i] > MOVING_EPS)))
        event = imm | (changed_pw & (mode != _TRANSITION)) | replans
        event |= (mode == _IDLE) & moving & (kind != _MOVE_NONE)
        # the root offset up to now under the old velocity; a turned entity turns a world-fixed offset
        root_motion.fold(tb, self.library, i, t)
        turned = np.where(tb.has_heading[i], hdg + face - tb.heading[i] - tb.face[i], 0.0)
        tb.has_heading[i] = True
        root_motion.turn_offsets(tb, i, turned)
        # a standing figure keeps its orientation in the world (it turns in place, below); a moving one
        # turns with the entity at once
        keeps = (mode == _LOCO) | (mode == _CRAWL) | (tb.node[i] == self._home) | moving
        keeps |= self.library.faces_world[tb.node[i]]  # (on the ground too: CRAWL, prone)
        tb.root_yaw[i] = np.where(keeps, (tb.root_yaw[i] - turned + 180.0) % 360.0 - 180.0, 0.0)
        # store the request (Jack coordinates)
        tb.appearance[i] = app
        tb.weapon[i] = wpn
        tb.velocity[i] = coords.vectors_performer_to_jack(vel)
        tb.position[i] = coords.points_performer_to_jack(pos)
        tb.heading[i] = hdg
        tb.face[i] = face
        tb.yaw[i] = coords.compass_to_jack_yaw(hdg)
        tb.speed[i] = speed
        tb.backward[i] = backward
        tb.side[i] = side
        tb.vlocal[i] = np.stack([-left, -ahead], axis=1) * 100.0  # soldier frame: forwards -Z, left -X
        # a speed change within a gait: keep the phase, change the playback rate
        stepping = (mode == _LOCO) | (mode == _CRAWL)
        self._mark_reversals(i, mode)
        # (a reversing soldier's step ends at its pace: the new velocity is not his step's)
        rescale = ~event & stepping & moving & speed_changed & SCALED[tb.loco[i]] & ~tb.reversing[i]
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
        turn = hp & (np.abs(tb.root_yaw[i]) >= MIN_TURN_DEG)
        if turn.any():
            self._turns(i[turn], t[turn])
        tb.requested[i[event | hp | rescale]] = True  # what :meth:`answer` answers between ticks
        self._events(i, t, event, imm, stepping)
        starts = (event & ~replans) | hp  # (a re-planned arc goes on from the frame it shows)
        self._skip_lead_in(i[starts], t[starts])
        return status

    def _changing(
        self,
        i: np.ndarray,
        app: np.ndarray,
        wpn: np.ndarray,
        imm: np.ndarray,
        vel: np.ndarray,
        hdg: np.ndarray,
        pos: np.ndarray,
    ) -> np.ndarray:
        """The requests that change more than the position: a DIS entity re-sent unchanged (a heartbeat, the
        common case) only moves its entity, so its position is stored here and the rest of the request path
        (the clock, clip ends, root offset fold) is left to the next tick, as if it had not come. Rows of
        soldiers whose figure is off its heading (turning, steering, reversing) or an idle one asked to move
        go the whole way (their request re-decides something)."""
        tb = self.table
        speed = np.hypot(vel[:, 0], vel[:, 1])
        same = (
            (imm == 0)
            & (app == tb.appearance[i])
            & (wpn == tb.weapon[i])
            & (hdg == tb.heading[i])
            & (speed == tb.speed[i])
            & (coords.vectors_performer_to_jack(vel).astype(np.float32) == tb.velocity[i]).all(1)
            & tb.has_heading[i]
            & (tb.root_yaw[i] == 0.0)
            & ~tb.reversing[i]
            & ~((tb.mode[i] == _IDLE) & (speed > MOVING_EPS) & (self._move[app] != _MOVE_NONE))
        )
        if same.any():
            tb.position[i[same]] = coords.points_performer_to_jack(pos[same])
        return ~same

    def _events(
        self, i: np.ndarray, t: np.ndarray, event: np.ndarray, imm: np.ndarray, stepping: np.ndarray
    ) -> None:
        """The per-soldier event path of the requests that change what a soldier does (a stepping one's pose
        captured first, for the cross-fade)."""
        ev = np.flatnonzero(event)
        if len(ev):
            self.stats["events"] += len(ev)
            cap = ev[stepping[ev] & ~imm[ev]] if self._settings.blend_time > 0 else ev[:0]
            captured: dict[int, tuple[np.ndarray, np.ndarray]] = {}
            if len(cap):
                cj, cf, _, _ = self._pose(i[cap], folded=True)  # folded to ``t`` above
                captured = {int(s): (cj[k], cf[k]) for k, s in enumerate(i[cap])}
            changes = self._posture_changes(i[ev], imm[ev])
            if changes.any():
                self._start_changes(i[ev[changes]], t[ev[changes]], captured)
                ev = ev[~changes]
            self._on_events(i[ev], t[ev], imm[ev], captured)

    def posture_change(self, index: int, posture: str, now: float) -> list[str]:
        """``posture_change``: the soldier goes to ``posture`` along the quickest path, exactly as a standing
        still request for that posture would take it (heading and position kept; one playing a path re-plans
        it from the arc playing: :mod:`server.soldier.replanning`). Returns the postures of the path playing
        now; KeyError for an unknown soldier or posture."""
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

    def react(self, index: int, kind: str, now: float) -> str | None:
        """A Fire PDU's ``"recoil"`` or a near detonation's ``"flinch"`` (REACT, ``react_soldier_state``):
        a soldier resting in a posture with that reaction plays it once (soldier_react.graph) and rests there
        again; returns the clip. One changing posture, turning or reacting plays it when that ends
        (:mod:`server.soldier.reactions`); a stepping one, or one whose posture has no such clip, does not
        react. Both return None. KeyError for an unknown soldier."""
        tb = self.table
        if not tb.is_live(index):
            raise KeyError(f"no soldier {index}")
        if not self._settings.every_frame:
            tb.clock[index] = now
        self._advance(np.array([index], np.int64))
        self.stats["reactions"] += 1
        t = float(tb.clock[index])
        clip = self._react_now(int(index), kind, t)
        if clip is not None:
            tb.requested[index] = True  # what :meth:`answer` answers between ticks
            self._skip_lead_in(np.array([index], np.int64), np.array([t]))
        return clip
