"""Figure 12's per-soldier events: a request that changes what a soldier does, a clip that ends."""

from __future__ import annotations

import numpy as np

from server.soldier import root_motion
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
    START,
    conditions,
    is_fast,
    next_states,
    start_state,
)
from server.soldier.reactions import Reactions
from server.soldier.replanning import Replanning
from server.soldier.stepping import Stepping
from server.soldier.turning import Turning


class Events(Stepping, Turning, Reactions, LeadIn, Replanning):
    """The Python that runs only on events, grouped by decision over each batch of soldiers: requests that
    change what soldiers do, and (:meth:`_advance`) the clip ends up to each clock."""

    def _desired(self, i: int) -> int:
        """:meth:`_desired_many` of one soldier in scalar Python."""
        return self._goal_from(i, int(self.table.node[i]))

    def _desired_many(self, idx: np.ndarray) -> np.ndarray:
        """Figure 12's goal posture nodes of soldiers ``idx``: the gait's base posture while moving, else the
        requested posture (of one with variant nodes, DEAD@..., the variant nearest from here); -1: none."""
        tb = self.table
        app = tb.appearance[idx].astype(np.int64)
        kind = np.where(tb.speed[idx] > MOVING_EPS, self._move[app], 0).astype(np.int64)
        goal = self._goal[app, (tb.weapon[idx] == _FIRING).astype(np.int64)].astype(np.int64)
        variant = self.library.goal_node[tb.node[idx].astype(np.int64), np.maximum(goal, 0)]
        return np.where(kind != 0, self._base[kind], np.where(goal >= 0, variant, goal)).astype(np.int64)

    def _posture_changes(self, idx: np.ndarray, immediate: np.ndarray) -> np.ndarray:
        """Which events of soldiers ``idx`` ask a resting or stepping soldier for another posture (the common
        event: :meth:`_start_changes` does them at once)."""
        desired = self._desired_many(idx)
        mode = self.table.mode[idx]
        decides = ~immediate & ((mode == _IDLE) | (mode == _LOCO) | (mode == _CRAWL))
        return decides & (desired >= 0) & (desired != self.table.node[idx])

    def _start_changes(
        self, idx: np.ndarray, t: np.ndarray, captured: dict[int, tuple[np.ndarray, np.ndarray]]
    ) -> None:
        """Soldiers asked for another posture: a stepping one's step cancelled (``captured``: the poses to
        fade from), then the paths start (:meth:`_decide`); a cancelled one with nowhere to go rests in its
        base posture."""
        tb = self.table
        mode = tb.mode[idx]
        cancelled = (mode == _LOCO) | (mode == _CRAWL)
        for k in np.flatnonzero(cancelled).tolist():
            s = int(idx[k])
            self._cancel_step(s, float(t[k]), captured.get(s))
        self._decide(idx, t)
        for k in np.flatnonzero(cancelled & (tb.mode[idx] == _IDLE)).tolist():
            self._rest(int(idx[k]), int(tb.node[idx[k]]), float(t[k]))

    def _on_events(
        self,
        idx: np.ndarray,
        t: np.ndarray,
        immediate: np.ndarray,
        captured: dict[int, tuple[np.ndarray, np.ndarray]],
    ) -> None:
        """The events of soldiers ``idx`` other than the posture changes :meth:`_posture_changes` found:
        ``immediate`` ones snap, resting ones decide, one playing a path re-plans it (:meth:`_replan`); a
        stepping one in the same base posture steps on (Figure 5 handles speed and direction)."""
        tb = self.table
        mode = tb.mode[idx]
        if immediate.any():
            self._snap(idx[immediate], t[immediate])
        stepping = np.flatnonzero(~immediate & ((mode == _LOCO) | (mode == _CRAWL)))
        if len(stepping):
            desired = self._desired_many(idx[stepping])
            j = stepping[(desired >= 0) & (desired != tb.node[idx[stepping]])]
            if len(j):
                self._start_changes(idx[j], t[j], captured)
        idle = ~immediate & (mode == _IDLE)
        self._decide(idx[idle], t[idle])
        path = ~immediate & (mode == _TRANSITION)
        if path.any():
            self._replan(idx[path], t[path])

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

    def _snap(self, idx: np.ndarray, t: np.ndarray) -> None:
        """``immediate``: jump to the goal postures' poses (no path, no fade), then decide."""
        tb = self.table
        if len(idx) < self._group_min:
            for i, ti in zip(idx.tolist(), t.tolist(), strict=True):
                self._snap_one(i, ti)
            return
        for i in idx.tolist():
            self._paths.pop(i, None)
        tb.blend_len[idx] = 0.0
        tb.mode[idx] = _IDLE
        tb.loco[idx] = _NONE
        desired = self._desired_many(idx)
        tb.node[idx] = np.where(desired >= 0, desired, tb.node[idx])
        self._rest_many(idx, t)
        self._decide(idx, t)

    def _snap_one(self, i: int, t: float) -> None:
        """:meth:`_snap` of one soldier in scalar Python."""
        tb = self.table
        self._paths.pop(i, None)
        tb.blend_len[i] = 0.0
        tb.mode[i] = _IDLE
        tb.loco[i] = _NONE
        desired = self._desired(i)
        if desired >= 0:
            tb.node[i] = desired
        self._rest(i, int(tb.node[i]), t)
        self._decide_one(i, t)

    def _decide(self, idx: np.ndarray, t: np.ndarray) -> None:
        """Resting soldiers ``idx`` (at times ``t``): start the posture change or the gait their last requests
        ask for. Grouped by decision: the paths' first arcs in one :meth:`_play_steps`, the gait starts in one
        :meth:`_enter_states`; per soldier only the path lookup and a turn in place (a small group: one by
        one, :meth:`_decide_one`)."""
        if len(idx) < self._group_min:
            for i, ti in zip(idx.tolist(), t.tolist(), strict=True):
                self._decide_one(i, ti)
            return
        tb = self.table
        tb.dirty[idx] = True
        desired = self._desired_many(idx)
        here = desired == tb.node[idx]
        change = (desired >= 0) & ~here
        if change.any():
            self._start_paths(idx[change], desired[change], t[change])
        idx, t = idx[here], t[here]
        if len(idx) == 0:
            return
        kind = np.where(tb.speed[idx] > MOVING_EPS, self._move[tb.appearance[idx]], 0).astype(np.int64)
        reversing = tb.reversing[idx].copy()
        tb.reversing[idx] = False
        # a start this far off pivots first, as a reversal; a standing figure turns in place
        turns = (np.abs(tb.root_yaw[idx]) >= MIN_TURN_DEG) | ((kind != 0) & reversing)
        if turns.any():
            standing = np.flatnonzero(turns & (kind == 0))
            turns[standing] = self._turns(idx[standing], t[standing])
            pivots = np.flatnonzero(turns & (kind != 0))
            if len(pivots):  # a pivot stops, turns, then (its end decides again) walks away
                turns[pivots] = self._turn_many(idx[pivots], t[pivots], moving=True)
            idx, t, kind = idx[~turns], t[~turns], kind[~turns]
        node = tb.node[idx]
        still = idx[(kind == 0) & (node != self._home) & ~self.library.faces_world[node]]
        tb.root_yaw[still] = 0.0  # no turn clip here: the figure faces the heading again
        go = kind != 0
        if go.any():
            self._start_gaits(idx[go], kind[go], t[go])

    def _decide_one(self, i: int, t: float) -> None:
        """:meth:`_decide` of one soldier in scalar Python."""
        tb = self.table
        tb.dirty[i] = True
        desired = self._desired(i)
        node = int(tb.node[i])
        if desired < 0:
            return
        if desired != node:  # a posture change faces the heading (no turn clips off STAND_STOWED)
            tb.root_yaw[i] = 0.0
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
        if (turned_away or (kind and reversing)) and self._turn(i, t, moving=bool(kind)):
            return  # a pivot stops, turns, then (its end decides again) walks away
        if not kind and node != self._home and not self.library.faces_world[node]:
            # no turn clip here: the figure faces the heading again
            tb.root_yaw[i] = 0.0
        if kind:
            fast = bool(tb.speed[i] > self._settings.walk_run_threshold) and self.library.can_run
            state = int(START[int(kind == _MOVE_CRAWL), int(tb.side[i]), int(tb.backward[i]), int(fast)])
            tb.mode[i] = _CRAWL if kind == _MOVE_CRAWL else _LOCO
            self._enter_one(i, state, t)

    def _start_paths(self, idx: np.ndarray, goal: np.ndarray, t: np.ndarray) -> None:
        """Resting soldiers ``idx`` start the quickest paths to posture nodes ``goal`` (their first arcs at
        once); a posture change faces the heading (no turn clips off STAND_STOWED)."""
        tb = self.table
        tb.root_yaw[idx] = 0.0
        go: list[int] = []
        first: list[PathStep] = []
        for k, (node, g) in enumerate(zip(tb.node[idx].tolist(), goal.tolist(), strict=True)):
            steps = self.library.path(node, g)
            if not steps:
                self.stats["unreachable"] += 1
                continue
            self._paths[int(idx[k])] = [steps, 0]
            go.append(k)
            first.append(steps[0])
        if go:
            g = idx[go]
            tb.mode[g] = _TRANSITION
            self._play_steps(g, first, t[go])

    def _start_gaits(self, idx: np.ndarray, kind: np.ndarray, t: np.ndarray) -> None:
        """Resting soldiers ``idx`` start moving (Movement ``kind``): Figure 5's start states at once."""
        tb = self.table
        fast = tb.speed[idx] > self._settings.walk_run_threshold
        states = start_state(kind, tb.backward[idx], fast, self.library.can_run, tb.side[idx])
        tb.mode[idx] = np.where(kind == _MOVE_CRAWL, _CRAWL, _LOCO)
        if len(idx) >= self._group_min:
            self._enter_states(idx, states, t, exact=True)
            return
        # one by one, but the turned figures' folds at once (each a vectorised fold: ~100 µs of numpy calls)
        turned = (tb.root_yaw[idx] != 0.0) | (tb.pivot_rest[idx] != 0.0)
        if np.count_nonzero(turned) >= 2 and self._fold_groups:  # (what fold1 does with a turned one)
            root_motion.fold(tb, self.library, idx[turned], t[turned])
        else:  # none or one: each folds its own (an empty fold is still a few dozen numpy calls)
            turned[:] = False
        rows = zip(idx.tolist(), states.tolist(), t.tolist(), turned.tolist(), strict=True)
        for i, state, ti, folded in rows:
            self._enter_one(i, state, ti, folded=folded)

    def _loco_ended(self, idx: np.ndarray) -> None:
        tb = self.table
        t = tb.end[idx].copy()
        speed = tb.speed[idx]
        st = self._settings
        hysteresis = min(st.walk_run_hysteresis, 0.5 * st.walk_run_threshold)
        known = root_motion.offsets(tb, self.library, idx, t)  # (the steps that go on fold with these)
        fast = is_fast(tb.loco[idx], speed, st.walk_run_threshold, hysteresis)
        fast |= self._far_behind(idx, known.off)
        cond = conditions(
            tb.loco[idx],
            (speed > MOVING_EPS) & ~tb.reversing[idx],  # a reversing soldier stops first
            tb.backward[idx],
            fast,
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
        known_cont = known.take(np.flatnonzero(cont)) if self._fold_groups else None
        self._enter_states(idx[cont], nxt[cont], t[cont], known=known_cont)
        if done.any():  # stopped: at rest, then what the last request asks for
            stopped = idx[done]
            tb.mode[stopped] = _IDLE
            tb.loco[stopped] = _NONE
            tb.dirty[stopped] = True
            self._decide(stopped, t[done])

    def _transition_end(self, i: int, t: float, folded: bool = False) -> bool:
        """The arc of soldier ``i``'s path ended at ``t``: the next arc starts, or (True) the path ended and
        the soldier rests, to decide what next. ``folded``: the fold it starts with was done with a group's
        (:meth:`_fold_arc_ends`)."""
        tb = self.table
        entry = self._paths.get(i)
        if entry is None:  # cannot happen; keep the soldier consistent anyway
            tb.mode[i] = _IDLE
            return False
        steps, k = entry
        tb.node[i] = steps[k].end
        if k + 1 < len(steps) and self._turning(steps[k].clip):  # a prone turn's turn, on forearms and knees,
            # or a pivot a posture request re-planned: its last share of turn too, before its own joins
            if not folded:
                root_motion.fold1(tb, self.library, i, t)
            self._turned(i, steps[k].clip)
            folded = False  # turned since: the next arc's own fold follows
        k += 1
        if k < len(steps):
            entry[1] = k
            self._play_step(i, steps[k], t, folded=folded)
            return False
        del self._paths[i]
        tb.mode[i] = _IDLE
        if self._turning(int(tb.clip[i])):
            self._turn_end(i, t, folded=folded)
        return True

    def _fold_arc_ends(self, idx: np.ndarray, t: np.ndarray) -> None:
        """The fold that :meth:`_transition_end` of soldiers ``idx`` (arcs ending at ``t``) starts with, of
        them all at once (:func:`root_motion.fold_exact`, bit for bit; at a turn path's end the pivot's last
        bit first, as :meth:`_turn_end` does): a turned figure's fold of one row was ~100 µs of numpy calls,
        a group's costs about as much. Only those whose arc end folds: the next arc plays, or a turn ends."""
        tb, lib = self.table, self.library
        folds: list[int] = []
        ends: list[bool] = []
        for k, i in enumerate(idx.tolist()):
            entry = self._paths.get(i)
            if entry is None:
                continue
            steps, j = entry
            if j + 1 < len(steps) or self._turning(int(tb.clip[i])):
                folds.append(k)
                ends.append(j + 1 == len(steps))
        if not folds:
            return
        g, tg = idx[folds], t[folds]
        p = np.asarray(ends, bool) & (tb.pivot_rest[g] != 0.0)
        if p.any():
            root_motion.pivot(tb, lib, g[p], tg[p])
            tb.pivot_rest[g[p]] = 0.0
        root_motion.fold_exact(tb, lib, g, tg)

    def _paths_ended(self, idx: np.ndarray, t: np.ndarray) -> None:
        """Soldiers ``idx`` whose paths ended at ``t`` decide, then play a reaction kept for their rest."""
        self._decide(idx, t)
        for i, ti in zip(idx.tolist(), t.tolist(), strict=True):
            if i in self._pending and int(self.table.mode[i]) == _IDLE:
                self._react_pending(i, ti)

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
            transition = cand[mode == _TRANSITION]
            ends = tb.end[transition].copy()
            folded = self._fold_groups
            if folded:
                self._fold_arc_ends(transition, ends)
            rest = [
                k
                for k, i in enumerate(transition.tolist())
                if self._transition_end(i, float(ends[k]), folded=folded)
            ]
            if rest:
                self._paths_ended(transition[rest], ends[rest])
