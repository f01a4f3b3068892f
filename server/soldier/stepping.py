"""Locomotion steps (Figure 5, vectorised): which clip a step plays, for how long and with what stride."""

from __future__ import annotations

import numpy as np

from server.soldier import root_motion
from server.soldier.core import (
    _CRAWL_CYCLE,
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
        speed = tb.speed[idx]
        stored = lib.clip_duration[clip]
        gs = lib.clip_ground_speed[clip]
        ok = SCALED[st] & (speed > MOVING_EPS) & (gs > 0)
        along = self._along(idx, tb.root_off[idx])
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
        seconds = np.where(error < 0.0, CATCH_UP_BEHIND_SECONDS, CATCH_UP_SECONDS)  # behind: closes sooner
        want = speed + np.clip(-error / 100.0 / seconds, -0.5 * speed, CATCH_UP_FASTER * speed)
        rate = np.where(ok, np.clip(want / (gs * stride), MIN_RATE, top), 1.0)
        hurry = tb.reversing[idx] | (error < -HURRY_BEHIND_CM)  # stopping to turn back, or metres behind
        rate = np.where(hurry & (HURRY_RATE[st] > 1.0), HURRY_RATE[st], rate)
        return np.maximum(stored / rate, MIN_CLIP_SECONDS), stride

    def _along(self, idx: np.ndarray, off: np.ndarray) -> np.ndarray:
        """``(n,)`` cm the root offsets ``off`` of soldiers ``idx`` lie ahead along their velocity."""
        v = self.table.vlocal[idx]
        return np.einsum("ij,ij->i", off, v) / np.maximum(np.hypot(v[:, 0], v[:, 1]), 1e-9)

    def _far_behind(self, idx: np.ndarray, t: np.ndarray) -> np.ndarray:
        """Whether walking (running) soldiers ``idx`` are so far behind their entity at ``t`` that their
        figure jogs to catch up (goes on jogging): CATCH_UP_RUN_CM behind their stop lag."""
        tb, lib = self.table, self.library
        st = tb.loco[idx].astype(np.int64)
        along = self._along(idx, root_motion.offset_at(tb, lib, idx, t))
        behind = -(along + self._stop_lag[st])
        limit = np.where(IS_RUN[st], CATCH_UP_RUN_CM[1], CATCH_UP_RUN_CM[0])
        return (IS_WALK[st] | IS_RUN[st]) & ~IS_BACKWARD[st] & (behind > limit) & lib.can_run

    def _enter_states(self, idx: np.ndarray, states: np.ndarray, t: np.ndarray, exact: bool = False) -> None:
        """Start the clips of Figure-5 ``states`` at times ``t`` (the next step uses the other foot).
        ``exact``: the root offsets folded and rebased as the per-event paths do (:func:`root_motion.fold1`,
        bit for bit): starts from rest, decided with the soldiers' other events."""
        if len(idx) == 0:
            return
        tb, lib = self.table, self.library
        st = states.astype(np.int64)
        foot = 1 - tb.foot[idx]
        clip = lib.loco_clip[st, foot]
        direc = lib.loco_dir[st].astype(np.int8)
        direc = np.where((st == _CRAWL_CYCLE) & tb.backward[idx], -direc, direc)
        (root_motion.fold_exact if exact else root_motion.fold)(tb, lib, idx, t)
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
