"""Locomotion steps (Figure 5, vectorised): which clip a step plays, for how long and with what stride."""

from __future__ import annotations

import numpy as np

from server.soldier import root_motion
from server.soldier.core import (
    _CRAWL_CYCLE,
    _SCALED,
    CATCH_UP_BEHIND_SECONDS,
    CATCH_UP_FASTER,
    CATCH_UP_RUN_CM,
    CATCH_UP_SECONDS,
    MAX_RATE,
    MAX_STRIDE,
    MIN_CLIP_SECONDS,
    MIN_RATE,
    MIN_STRIDE,
    MOVING_EPS,
    WALK_MAX_RATE,
    ManagerCore,
)
from server.soldier.locomotion import (
    HURRY_STATES,
    IS_BACKWARD,
    IS_RUN,
    IS_WALK,
    SCALED,
    is_fast,
)
from server.soldier.state import LocoState

# per Figure-5 state the rate a hurried start or end step plays at (locomotion.HURRY_STATES; 1 elsewhere):
# the gait's upper cadence, the walk's 1.02 s start step in 0.57 s
HURRY_RATE = np.array(
    [
        (WALK_MAX_RATE if s.name.startswith("WALK") else MAX_RATE) if s in HURRY_STATES else 1.0
        for s in LocoState
    ]
)
HURRY_BEHIND_CM = 30.0  # a start step whose figure is this far behind its stop lag hurries (after a pivot)


class Stepping(ManagerCore):
    """The pacing of walk, run, crawl and side-step clips: human cadence, the stride taking the rest."""

    def _step_duration(
        self, idx: np.ndarray, clip: np.ndarray, states: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """Play time and stride scale of ``clip`` in Figure-5 ``states`` for soldiers ``idx`` (root offsets
        folded to now).

        A cycle aims at the entity's speed plus what brings the root offset along the velocity to its stop lag
        (the figure trails the entity by what it would still travel if the entity stopped) in about
        CATCH_UP_SECONDS (CATCH_UP_BEHIND_SECONDS when it is behind that: after a pivot, metres), at most
        CATCH_UP_FASTER of its speed faster than the entity, within human cadence (MIN_RATE..MAX_RATE).
        When the entity's speed alone is beyond that cadence the stride length takes the rest (the feet slide
        by the difference), except in a gait the speed is about to leave (a walk step before walk→run): there
        the root offset takes it. Start and end steps and gait changes play at their recorded rate, except a
        hurried start or end (HURRY_RATE: a reversal's end step, a start or end far behind the entity)."""
        tb, lib = self.table, self.library
        st = np.asarray(states, np.int64)
        error = self._along(idx, tb.root_off[idx]) + self._stop_lag[st]  # cm ahead of where it should be
        if SCALED[st].any():
            rate, stride = self._cadence(idx, clip, st, error)
        else:  # start and end steps, gait changes (a batch's starts): their recorded rate
            rate = stride = np.ones(len(st))
        hurry = tb.reversing[idx] | (error < -HURRY_BEHIND_CM)  # stopping to turn back, or metres behind
        rate = np.where(hurry & (HURRY_RATE[st] > 1.0), HURRY_RATE[st], rate)
        return np.maximum(lib.clip_duration[clip] / rate, MIN_CLIP_SECONDS), stride

    def _cadence(
        self, idx: np.ndarray, clip: np.ndarray, st: np.ndarray, error: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`_step_duration`'s playback rate and stride scale of the cycles (1 elsewhere), ``error`` cm
        ahead of the stop lag."""
        tb, lib = self.table, self.library
        speed = tb.speed[idx]
        gs = lib.clip_ground_speed[clip]
        ok = SCALED[st] & (speed > MOVING_EPS) & (gs > 0)
        gs = np.where(gs > 0, gs, 1.0)
        cfg = self._settings
        hysteresis = min(cfg.walk_run_hysteresis, 0.5 * cfg.walk_run_threshold)
        fast = is_fast(st, speed, cfg.walk_run_threshold, hysteresis)
        leaving = (IS_RUN[st] & ~fast) | (IS_WALK[st] & fast & lib.can_run)
        ideal = speed / gs  # the entity's speed alone
        top = np.where(IS_WALK[st], WALK_MAX_RATE, MAX_RATE)
        scale = np.clip(ideal / np.clip(ideal, MIN_RATE, top), MIN_STRIDE, MAX_STRIDE)
        stride = np.where(ok & ~leaving, scale, 1.0)
        seconds = np.where(error < 0.0, CATCH_UP_BEHIND_SECONDS, CATCH_UP_SECONDS)  # behind: closes sooner
        want = speed + np.clip(-error / 100.0 / seconds, -0.5 * speed, CATCH_UP_FASTER * speed)
        return np.where(ok, np.clip(want / (gs * stride), MIN_RATE, top), 1.0), stride

    def _along(self, idx: np.ndarray, off: np.ndarray) -> np.ndarray:
        """``(n,)`` cm the root offsets ``off`` of soldiers ``idx`` lie ahead along their velocity."""
        v = self.table.vlocal[idx]
        return np.einsum("ij,ij->i", off, v) / np.maximum(np.hypot(v[:, 0], v[:, 1]), 1e-9)

    def _far_behind(self, idx: np.ndarray, off: np.ndarray) -> np.ndarray:
        """Whether walking (running) soldiers ``idx`` are so far behind their entity, root offsets ``off``,
        that their figure jogs to catch up (goes on jogging): CATCH_UP_RUN_CM behind their stop lag."""
        tb, lib = self.table, self.library
        st = tb.loco[idx].astype(np.int64)
        along = self._along(idx, off)
        behind = -(along + self._stop_lag[st])
        limit = np.where(IS_RUN[st], CATCH_UP_RUN_CM[1], CATCH_UP_RUN_CM[0])
        return (IS_WALK[st] | IS_RUN[st]) & ~IS_BACKWARD[st] & (behind > limit) & lib.can_run

    def _enter_states(
        self,
        idx: np.ndarray,
        states: np.ndarray,
        t: np.ndarray,
        exact: bool = False,
        known: root_motion.Offsets | None = None,
    ) -> None:
        """Start the clips of Figure-5 ``states`` at times ``t`` (the next step uses the other foot).
        ``exact``: the root offsets folded and rebased as :meth:`_enter_one` does (:func:`root_motion.fold1`,
        bit for bit): a group's starts from rest. ``known``: for the fold (not ``exact``), as
        :func:`root_motion.fold`'s."""
        if len(idx) == 0:
            return
        tb, lib = self.table, self.library
        st = states.astype(np.int64)
        foot = 1 - tb.foot[idx]
        clip = lib.loco_clip[st, foot]
        direc = lib.loco_dir[st].astype(np.int8)
        direc = np.where((st == _CRAWL_CYCLE) & tb.backward[idx], -direc, direc)
        if exact:
            root_motion.fold_exact(tb, lib, idx, t)
        else:
            root_motion.fold(tb, lib, idx, t, known)
        dur, tb.stride[idx] = self._step_duration(idx, clip, st)
        tb.loco[idx] = st
        tb.foot[idx] = foot
        tb.clip[idx] = clip
        tb.direc[idx] = direc
        tb.start[idx] = t
        tb.dur[idx] = dur
        tb.end[idx] = t + dur
        (root_motion.rebase_exact if exact else root_motion.rebase)(tb, lib, idx)
        if self._settings.record_clips:
            for k in range(len(idx)):
                self._record(int(idx[k]), float(t[k]))

    def _enter_one(self, i: int, state: int, t: float, folded: bool = False) -> None:
        """:meth:`_enter_states` for one soldier in scalar Python (a small group's starts: ~10x cheaper;
        ``folded``: his root offset is already folded to ``t``, with a group's)."""
        tb, lib = self.table, self.library
        foot = 1 - int(tb.foot[i])
        clip = int(lib.loco_clip[state, foot])
        direc = int(lib.loco_dir[state])
        if state == _CRAWL_CYCLE and tb.backward[i]:
            direc = -direc
        if not folded:
            root_motion.fold1(tb, lib, i, t)
        if _SCALED[state]:  # a side-step: the vectorised pacing
            durs, strides = self._step_duration(np.array([i], np.int64), np.array([clip]), np.array([state]))
            dur, tb.stride[i] = float(durs[0]), strides[0]
        else:  # a start step: its recorded pace, hurried when its figure is behind (after a pivot)
            dur = float(lib.clip_duration[clip]) / self._start_rate(i, state)
            dur, tb.stride[i] = max(dur, MIN_CLIP_SECONDS), 1.0
        tb.loco[i] = state
        tb.foot[i] = foot
        tb.clip[i] = clip
        tb.direc[i] = direc
        tb.start[i] = t
        tb.dur[i] = dur
        tb.end[i] = t + dur
        root_motion.rebase1(tb, lib, i)
        self._record(i, t)

    def _start_rate(self, i: int, state: int) -> float:
        """The rate start step ``state`` of soldier ``i`` plays at (root offset folded to now): its recorded
        one, or HURRY_RATE when the figure is more than HURRY_BEHIND_CM behind its stop lag (a pivot or a
        posture change left it behind its moving entity)."""
        rate = float(HURRY_RATE[state])
        if rate == 1.0:
            return 1.0
        (ox, oz), (vx, vz) = self.table.root_off[i].tolist(), self.table.vlocal[i].tolist()
        along = (ox * vx + oz * vz) / max(float(np.hypot(vx, vz)), 1e-9)
        return rate if along + float(self._stop_lag[state]) < -HURRY_BEHIND_CM else 1.0
