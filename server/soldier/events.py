"""Figure 12's per-soldier events: a request that changes what a soldier does, a clip that ends."""

from __future__ import annotations

import numpy as np

from server.soldier.core import (
    _CRAWL,
    _FIRING,
    _GAIT_STAY,
    _IDLE,
    _LOCO,
    _MOVE_CRAWL,
    _NONE,
    _TRANSITION,
    MAX_CHAIN,
    MIN_TURN_DEG,
    MOVING_EPS,
)
from server.soldier.lead_in import LeadIn
from server.soldier.library import PathStep
from server.soldier.locomotion import (
    conditions,
    is_fast,
    next_states,
    start_state,
)
from server.soldier.reactions import Reactions
from server.soldier.state import (
    Movement,
)
from server.soldier.stepping import Stepping
from server.soldier.turning import REVERSAL_TURN_SPEEDUP, Turning


class Events(Stepping, Turning, Reactions, LeadIn):
    """Per-soldier Python that runs only on events; :meth:`_advance` takes the clip ends up to each clock."""

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

    def _desired_many(self, idx: np.ndarray) -> np.ndarray:
        """:meth:`_desired` of soldiers ``idx`` (table lookups over arrays)."""
        tb = self.table
        app = tb.appearance[idx].astype(np.int64)
        kind = np.where(tb.speed[idx] > MOVING_EPS, self._move[app], 0).astype(np.int64)
        goal = self._goal[app, (tb.weapon[idx] == _FIRING).astype(np.int64)].astype(np.int64)
        variant = self.library.goal_node[tb.node[idx].astype(np.int64), np.maximum(goal, 0)]
        return np.where(kind != 0, self._base[kind], np.where(goal >= 0, variant, goal)).astype(np.int64)

    def _posture_changes(self, idx: np.ndarray, immediate: np.ndarray) -> np.ndarray:
        """Which events of soldiers ``idx`` ask a resting soldier for another posture (the common event: its
        :meth:`_decide` starts a path; :meth:`_start_changes` does them at once)."""
        desired = self._desired_many(idx)
        mode = self.table.mode[idx]
        decides = ~immediate & ((mode == _IDLE) | (mode == _LOCO) | (mode == _CRAWL))
        return decides & (desired >= 0) & (desired != self.table.node[idx])

    def _start_changes(
        self, idx: np.ndarray, t: np.ndarray, captured: dict[int, tuple[np.ndarray, np.ndarray]]
    ) -> None:
        """:meth:`_on_event` of soldiers asked for another posture, at once: a stepping one's step cancelled
        (``captured``: the poses to fade from), then per soldier only the path lookup; the first arcs start
        in one :meth:`_play_steps`."""
        tb = self.table
        mode = tb.mode[idx]
        cancelled = np.flatnonzero((mode == _LOCO) | (mode == _CRAWL))
        was_stepping = set(cancelled.tolist())
        for k in cancelled.tolist():
            s = int(idx[k])
            self._cancel_step(s, float(t[k]), captured.get(s))
        tb.dirty[idx] = True
        tb.root_yaw[idx] = 0.0  # a posture change faces the heading (no turn clips off STAND_STOWED)
        go: list[int] = []
        first: list[PathStep] = []
        for k, (node, goal) in enumerate(
            zip(tb.node[idx].tolist(), self._desired_many(idx).tolist(), strict=True)
        ):
            steps = self.library.path(node, goal)
            if not steps:
                self.stats["unreachable"] += 1
                if k in was_stepping:  # nowhere to go: rest in the base posture
                    self._rest(int(idx[k]), node, float(t[k]))
                continue
            self._paths[int(idx[k])] = [steps, 0]
            go.append(k)
            first.append(steps[0])
        if go:
            g = idx[go]
            tb.mode[g] = _TRANSITION
            self._play_steps(g, first, t[go])

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
            self._cancel_step(i, t, captured)
            self._decide(i, t)
            if tb.mode[i] == _IDLE:  # nowhere to go: rest in the base posture
                self._rest(i, int(tb.node[i]), t)
            return
        if mode == _IDLE:
            self._decide(i, t)

    def _cancel_step(self, i: int, t: float, captured: tuple[np.ndarray, np.ndarray] | None) -> None:
        """Cancel the step: fade from the pose shown now (``captured``) into whatever starts next."""
        tb = self.table
        if captured is not None:
            tb.blend_joints[i], tb.blend_figs[i] = captured
            tb.blend_t0[i] = t
            tb.blend_len[i] = self._settings.blend_time
        tb.mode[i] = _IDLE
        tb.loco[i] = _NONE
        self._record(i, t, "cancel")

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
        reversing = bool(tb.reversing[i])
        tb.reversing[i] = False
        turned_away = abs(tb.root_yaw[i]) >= MIN_TURN_DEG  # a start this far off pivots first, as a reversal
        if kind and (reversing or turned_away) and self._turn(i, t, REVERSAL_TURN_SPEEDUP):
            return  # stopped: the pivot, then (its end decides again) the walk away
        if not kind and abs(tb.root_yaw[i]) >= MIN_TURN_DEG and self._turn(i, t):
            return
        if not kind and node != self._home and not self.library.faces_world[node]:
            # no turn clip here: the figure faces the heading again
            tb.root_yaw[i] = 0.0
        if kind:
            fast = bool(tb.speed[i] > self._settings.walk_run_threshold)
            state = start_state(
                Movement(kind), bool(tb.backward[i]), fast, self.library.can_run, int(tb.side[i])
            )
            tb.mode[i] = _CRAWL if kind == _MOVE_CRAWL else _LOCO
            self._enter_one(i, int(state), t)

    def _loco_ended(self, idx: np.ndarray) -> None:
        tb = self.table
        t = tb.end[idx].copy()
        speed = tb.speed[idx]
        st = self._settings
        hysteresis = min(st.walk_run_hysteresis, 0.5 * st.walk_run_threshold)
        cond = conditions(
            tb.loco[idx],
            (speed > MOVING_EPS) & ~tb.reversing[idx],  # a reversing soldier stops first
            tb.backward[idx],
            is_fast(tb.loco[idx], speed, st.walk_run_threshold, hysteresis) | self._far_behind(idx, t),
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
        if k + 1 < len(steps) and self._turning(steps[k].clip):  # a prone turn's turn, on forearms and knees
            self._turned(i, steps[k].clip)
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
        if i in self._pending and int(tb.mode[i]) == _IDLE:
            self._react_pending(i, t)

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
