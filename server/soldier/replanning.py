"""A posture request while a path plays re-plans it (issue 16): from the clip now playing, not the path's end.

A soldier asked for another posture while a posture change's path plays used to play the whole path first:
asked to crawl 1 s after he was told to go prone from standing, he lay down, came up again and crawled at
5.67 s. Now the path is planned again at once from the arc now playing: that arc plays to its end and the
quickest path from there follows, or, where the graph has the arc the other way too (the same clip played
backwards) and that is quicker, the arc turns back from the frame it shows and the quickest path from its
start follows (STAND asked half-way through ``ststow2crawl``: back up, not down and up again). A request for
the posture the path already ends in, or for one no path reaches from here, changes nothing. The pose
never jumps: the arc goes on (or back) from the frame it shows.
"""

from __future__ import annotations

import numpy as np

from server.soldier import root_motion
from server.soldier.core import _FIRING, MOVING_EPS, ManagerCore
from server.soldier.library import PathStep


class Replanning(ManagerCore):
    """The re-plan of a path under way when a request asks for another posture."""

    def _goal_from(self, i: int, node: int) -> int:
        """Soldier ``i``'s goal posture node if he were resting at ``node`` (of a posture with variant nodes,
        DEAD@..., the variant nearest from there); -1: none."""
        tb = self.table
        app = int(tb.appearance[i])
        kind = int(self._move[app]) if tb.speed[i] > MOVING_EPS else 0
        if kind:
            return int(self._base[kind])
        goal = int(self._goal[app, int(tb.weapon[i] == _FIRING)])
        return int(self.library.goal_node[node, goal]) if goal >= 0 else goal

    def _replan(self, idx: np.ndarray, t: np.ndarray) -> None:
        """Soldiers ``idx`` playing a path took a request at ``t``: those asked for another posture than the
        path's end go there from the arc now playing (:meth:`_replan_one`)."""
        for i, ti in zip(idx.tolist(), t.tolist(), strict=True):
            entry = self._paths.get(i)
            if entry is None:
                continue
            steps, k = entry
            step = steps[k]
            if self._goal_from(i, step.end) not in (-1, steps[-1].end):
                self._replan_one(i, ti, step)

    def _replan_one(self, i: int, t: float, step: PathStep) -> None:
        """Soldier ``i``'s path from arc ``step`` (playing at ``t``) on: the arc to its end and the quickest
        path from there, or the arc back from the frame shown and the quickest path from its start, whichever
        reaches the goal sooner; unreachable both ways: the path as it was."""
        tb, lib = self.table, self.library
        ahead = lib.path(step.end, self._goal_from(i, step.end))
        back = self._way_back(step)
        behind = lib.path(step.start, self._goal_from(i, step.start)) if back is not None else None
        done = min(max((t - float(tb.start[i])) / max(float(tb.dur[i]), 1e-9), 0.0), 1.0)
        on = float(tb.end[i]) - t + sum(s.duration for s in ahead) if ahead is not None else np.inf
        if (
            back is not None
            and behind is not None
            and done * back.duration + sum(s.duration for s in behind) < on
        ):
            self._paths[i] = [(back, *behind), 0]
            self._turn_back(i, t, back, done)
        elif ahead is not None:
            self._paths[i] = [(step, *ahead), 0]

    def _way_back(self, step: PathStep) -> PathStep | None:
        """The arc ``step`` the other way (its clip backwards), if the graph has it (a turn, a reaction or a
        clip played on request has none: they play to their end). A fall to DEAD plays to its end too: a
        trainee must never see a man half-killed get up again (once dead, DEAD's arcs replay it backwards)."""
        if self.library.postures[step.end].startswith("DEAD"):
            return None
        back = self.library.path(step.end, step.start)
        if not back or len(back) != 1 or back[0].clip != step.clip or back[0].forward == step.forward:
            return None
        return back[0]

    def _turn_back(self, i: int, t: float, back: PathStep, done: float) -> None:
        """Play arc ``back`` (the clip now playing, the other way) from the frame shown at ``t``: ``done`` of
        the arc played so far is ``done`` of ``back`` still to play."""
        tb, lib = self.table, self.library
        root_motion.fold1(tb, lib, i, t)
        dur = max(back.duration, 1e-9)
        tb.direc[i] = 1 if back.forward else -1
        tb.dur[i] = dur
        tb.start[i] = t - (1.0 - done) * dur
        tb.end[i] = t + done * dur
        root_motion.rebase1(tb, lib, i)
        tb.dirty[i] = True
        self._record(i, t)
