"""Turns in place (issue 16): a standing figure that faces away from its heading turns on the spot.

A walking or running soldier whose entity reverses (its heading turns by REVERSAL_DEG or more at once, as a
DIS entity's does when it walks back the way it came) does what a person does: he stops (the step he is in
ends, then the end step at his upper cadence, the figure still facing the old way: no turning over the
steps), pivots on the spot (the turn in place that fits, played REVERSAL_TURN_SPEEDUP times faster: a
pivot, not a slow about-face; its in-place steps then take ~0.2 s, a sprinter's cadence) and walks away
(the start step hurried too: ``stepping.HURRY_RATE``). His feet stay planted in the world throughout; the
figure trails the entity by what it did not travel meanwhile and catches up with faster cadence
(``stepping``), as after any start, jogging while it is more than CATCH_UP_RUN_CM behind (a 180° reversal
leaves it 3.3 m behind; 4.6 m with the end and start steps at their recorded pace).

A standing soldier asked to walk off MIN_TURN_DEG or more from where his figure faces pivots the same way
first, then starts (turning the body over the start step twisted the planted foot 20 cm). A velocity
straight back faster than BACKWARD_MAX_SPEED is walked forwards: the figure's frame turns by ``face`` = 180°
from the heading (the root placement carries it, docs/PROTOCOL.md), so a standing soldier pivots and walks
away and a walking one reverses.

On the ground the turns in place are those on forearms and knees (CRAWL): a soldier there plays the ones
that fit, one after the other (:meth:`Turning._ground_turns`), at GROUND_TURN_RATE; lying prone he comes up
onto forearms and knees, turns so and lies down again, up and down at the recorded pace (the way down swings
his body ~55° onto PRONE_STOWED, which lies at an angle to the line of fire: twice as fast it spun in three
frames); crawling, CRAWL_REVERSAL_DEG or more from his heading, he stops, turns with the turns that carry
him forward as they turn (``node_arcs``: he keeps up with his entity; reversing, the U-turn that carries him
along his new heading, at his entity's pace: :meth:`Turning._arc_rate`) and crawls on (turned while crawling
or at once, his planted forearms, knees and toes slid 13-116 cm; turned on the spot at the recorded pace,
he ended 1.3 m behind his entity).
"""

from __future__ import annotations

import functools
import math
from itertools import combinations_with_replacement

import numpy as np

from server.soldier import root_motion
from server.soldier.core import (
    _CRAWL,
    _IDLE,
    _LOCO,
    _TRANSITION,
    MAX_RATE,
    MIN_RATE,
    ManagerCore,
)
from server.soldier.library import PathStep
from server.soldier.state import CRAWL_NODE, LocoState

REVERSAL_DEG = 120.0  # a walking figure this far from its new heading stops, pivots and walks away
# ... a side-stepping one already this far: it turns 10° a stance (root_motion.side_turns), side-stepping
# meanwhile the old way: a 90° heading change left it 1.0-1.2 m from its entity after the stop
SIDE_REVERSAL_DEG = 45.0
BACKWARD_MAX_SPEED = 1.0  # m/s: a velocity straight back faster than people walk backwards is walked forwards
BACKWARD_HYSTERESIS = 0.2  # m/s: walking away forwards, he faces his velocity down to the limit - this
# a pivot may turn more or less than its clip, about the flat carrying foot while one foot alone is down: at
# most this much per such stance (each degree twists that foot's heel and ball ~0.2 cm: 9° -> 1.8 cm)
PIVOT_REST_PER_STANCE_DEG = 9.0
# a crawling figure this far from its new heading stops, turns in place on forearms and knees and crawls on:
# turned while crawling at 90°/s about the root its planted toes and knees slid 13-94 cm at 45-90°; a smaller
# change it turns while it crawls, at root_motion.CRAWL_TURN_RATE (3°/s: 22.5° in 7.5 s, toes 2.3 cm)
CRAWL_REVERSAL_DEG = 22.5
MAX_GROUND_TURNS = 4  # turn clips on the ground one after the other at most (180°: the 90° twice)
GROUND_TURN_SLACK_DEG = 7.5  # ... chosen by what they leave unturned in steps of this much, then the fewest
# a crawler whose heading changes by this much or less from a U-turn's (crawlarc_r135..r180, l135..l165) plays
# it and turns the rest as he crawls on (root_motion.CRAWL_TURN_RATE, under CRAWL_REVERSAL_DEG): 165° as the
# 90° and 45° on the spot and the 30° arc left him 125 cm from his entity, 76 after the stop (150°: 108 and
# 52)
U_TURN_SLACK_DEG = 15.0
# ... for a change of at least this much (half-way from the 90° arc to the shortest U-turn, 135°): 120° as the
# 135° U-turn and 15° crawling on ended the turn 42 cm from his entity but 57 after the stop (the crawl does
# not steer back sideways), the 90° on the spot and the 30° arc 87 and 16
U_TURN_MIN_DEG = 127.5
# a turn on the ground plays this much faster than recorded: the crawl's upper cadence (core.MAX_RATE; a
# forearm's 25 cm in 0.25 s, the crawl's 26 in 0.225 s); a 90° turn in 2.2 s instead of 3.5
GROUND_TURN_RATE = MAX_RATE
REVERSAL_TURN_SPEEDUP = 2.5  # the pivot plays the 180° turn in place this many times faster (3.4 s -> 1.4 s)


def facing(backward: np.ndarray, speed: np.ndarray, face: np.ndarray) -> np.ndarray:
    """Compass degrees of the figure's frame from the heading (0 or 180): 180 walks a velocity straight back
    forwards when it is faster than people walk backwards (``face``: the soldiers' present ones)."""
    limit = np.where(face != 0.0, BACKWARD_MAX_SPEED - BACKWARD_HYSTERESIS, BACKWARD_MAX_SPEED)
    return np.where(backward & (speed > limit), 180.0, 0.0)


@functools.lru_cache(maxsize=16)
def _ground_combos(
    clips: tuple[tuple[int, float], ...],
) -> tuple[list[tuple[tuple[int, float], ...]], np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Every run of 1..MAX_GROUND_TURNS of turn ``clips`` (clip, compass degrees) of one node, after ``()``
    (no turn), in the order :meth:`Turning._ground_turns` prefers on a tie (its stable sort keeps the first):
    the runs, their degrees, their lengths (a clip turning against the run's own way counts twice: 160°
    is the 90°, 45° and 30° arcs, not the U-turn and the 30° back) and how many of their clips turn by
    negative and by positive degrees; computed once per node, not for every soldier that turns (~0.2 ms
    of Python each)."""
    runs = (c for k in range(1, MAX_GROUND_TURNS + 1) for c in combinations_with_replacement(clips, k))
    # never the long way round (-150°: the U-turn and 30° more the other way, 210°)
    combos: list[tuple[tuple[int, float], ...]] = [
        (),
        *(c for c in runs if abs(sum(d for _, d in c)) <= 180.0),
    ]
    total = np.array([sum(d for _, d in c) for c in combos], np.float64)
    count = np.array([len(c) for c in combos], np.int64)
    negative = np.array([sum(d < 0 for _, d in c) for c in combos], np.int64)
    positive = np.array([sum(d > 0 for _, d in c) for c in combos], np.int64)
    back = np.where(total < 0, positive, np.where(total > 0, negative, 0))  # turning against the rest
    return combos, total, count + back, negative, positive


class Turning(ManagerCore):
    """The turn-in-place path: pick the turn clip that fits, then fold its own move into the root offset."""

    def _turning(self, clip: int) -> bool:
        return self.library.clip_end_offset[clip, 2] != 0.0 and self.library.clip_graph[clip] != 0

    def _mark_reversals(self, idx: np.ndarray, mode: np.ndarray) -> None:
        """After requests to soldiers ``idx`` (``mode`` before them): a walking or running one whose figure
        now faces REVERSAL_DEG or more away from his heading reverses (stopping too: he stops facing the old
        way, then turns in place); a crawling one CRAWL_REVERSAL_DEG or more, where he can turn in place; one
        whose heading came back no longer does. Other modes keep the mark (a reversal under way ends in
        ``_decide``)."""
        lib = self.library
        loco = mode == _LOCO
        if lib.turn_clips and loco.any():
            i = idx[loco]
            loco = self.table.loco[i]
            side = (loco == LocoState.SIDESTEP_L) | (loco == LocoState.SIDESTEP_R)
            limit = np.where(side, SIDE_REVERSAL_DEG, REVERSAL_DEG)
            self.table.reversing[i] = np.abs(self.table.root_yaw[i]) >= limit
        crawl = mode == _CRAWL
        if lib.has_node(CRAWL_NODE) and lib.node(CRAWL_NODE) in lib.node_turns and crawl.any():
            i = idx[crawl]
            self.table.reversing[i] = np.abs(self.table.root_yaw[i]) >= CRAWL_REVERSAL_DEG

    def _turn(self, i: int, t: float, moving: bool = False) -> bool:
        """A resting soldier whose figure faces away from its heading plays the turn in place that fits:
        standing, the nearest turn (``moving``, one that walks off after it: the pivot, REVERSAL_TURN_SPEEDUP
        times faster than recorded), on forearms and knees those that fit at GROUND_TURN_RATE (``moving``,
        one that crawls on: those that carry him forward), prone up to CRAWL, the turn, and down again
        (:meth:`_turn_via`)."""
        plan = self._turn_plan(i, moving)
        if plan is not None:
            self._turn_start(i, plan, t)
        return plan is not None

    def _turn_many(self, idx: np.ndarray, t: np.ndarray, moving: bool = False) -> np.ndarray:
        """:meth:`_turn` of soldiers ``idx`` at times ``t``, one by one but their folds at once
        (:func:`root_motion.fold_exact`, bit for bit: a turned figure's fold of one row was ~100 µs of numpy
        calls, a group's costs about as much); which of them turn."""
        if not self._fold_groups:
            pairs = zip(idx.tolist(), t.tolist(), strict=True)
            return np.array([self._turn(i, ti, moving) for i, ti in pairs], bool)
        plans = [self._turn_plan(i, moving) for i in idx.tolist()]
        go = [k for k, plan in enumerate(plans) if plan is not None]
        if go:
            root_motion.fold_exact(self.table, self.library, idx[go], t[go])
        for k in go:
            plan = plans[k]
            assert plan is not None
            self._turn_start(int(idx[k]), plan, float(t[k]), folded=True)
        turns = np.zeros(len(idx), bool)
        turns[go] = True
        return turns

    def _turn_start(
        self, i: int, plan: tuple[tuple[PathStep, ...], float | None], t: float, folded: bool = False
    ) -> None:
        """Start the turn :meth:`_turn_plan` chose for soldier ``i`` (``folded``: as ``_play_step``)."""
        steps, rest = plan
        self._turn_path(i, steps, t, folded=folded)
        if rest is not None:
            self.table.pivot_rest[i] = rest

    def _turn_plan(self, i: int, moving: bool = False) -> tuple[tuple[PathStep, ...], float | None] | None:
        """:meth:`_turn`'s choice for soldier ``i``, changing nothing: the path of turns and (standing) the
        pivot's rest of turn; None: he does not turn."""
        tb, lib = self.table, self.library
        node = int(tb.node[i])
        if int(tb.mode[i]) != _IDLE:
            return None
        if node in lib.turn_via:
            return self._turn_via(i, lib.turn_via[node])
        clips = lib.node_turns.get(node)
        if not clips:
            return None
        want = -float(tb.root_yaw[i])  # compass degrees to turn
        if node != self._home:  # on the ground
            ahead = -float(tb.root_off[i, 1])  # cm the figure is ahead of its entity (-Z: ahead)
            turns = self._ground_turns(node, want, moving, float(np.hypot(*tb.vlocal[i])), ahead)
            return (turns, None) if turns else None
        clip, turn = (self._pivot_clip if moving else self._nearest_turn)(want, clips)
        if abs((turn - want + 180.0) % 360.0 - 180.0) >= abs(want):
            return None
        # the turn turns by the clip's turn and a rest too small for another turn clip (a 58° turn after an
        # end step: the 45° clip and 13° over its stances; it ended 13° off the heading); else another after
        rest = (float(lib.clip_end_offset[clip, 2]) - float(tb.root_yaw[i]) + 180.0) % 360.0 - 180.0
        rest = rest if self._pivot_fits(clip, abs(rest)) else 0.0
        speedup = 1.0
        if moving:  # a pivot: turning more, it turns no faster than the clip
            speedup = REVERSAL_TURN_SPEEDUP * min(1.0, abs(turn) / abs(want))
        return (PathStep(clip, True, float(lib.clip_duration[clip]) / speedup, node, node),), rest

    def _turns(self, idx: np.ndarray, t: np.ndarray) -> np.ndarray:
        """:meth:`_turn` (not a pivot) of soldiers ``idx`` at times ``t``, the standing ones grouped (a small
        group one by one; those on the ground one by one); which of them turn."""
        if len(idx) < self._group_min:
            return self._turn_many(idx, t)
        tb, lib = self.table, self.library
        ground = np.flatnonzero(tb.node[idx] != self._home)
        turns = (tb.mode[idx] == _IDLE) & bool(lib.turn_clips)
        clip, off = self._nearest_turns(-tb.root_yaw[idx])
        turns &= off < np.abs(tb.root_yaw[idx])
        turns[ground] = False
        g, tg, clip = idx[turns], t[turns], clip[turns]
        rest = (lib.clip_end_offset[clip, 2] - tb.root_yaw[g] + 180.0) % 360.0 - 180.0
        rest = np.where(np.abs(rest) <= PIVOT_REST_PER_STANCE_DEG * lib.travel.stances[clip], rest, 0.0)
        home = self._home
        durations = lib.clip_duration[clip].tolist()
        steps = [PathStep(c, True, d, home, home) for c, d in zip(clip.tolist(), durations, strict=True)]
        tb.blend_len[g] = 0.0
        tb.mode[g] = _TRANSITION
        for i, step in zip(g.tolist(), steps, strict=True):
            self._paths[i] = [(step,), 0]
        self._play_steps(g, steps, tg)
        tb.dirty[g] = True
        tb.pivot_rest[g] = rest
        if len(ground):  # on the ground: the turns there that fit (or up, turn and down again)
            turns[ground] = self._turn_many(idx[ground], t[ground])
        return turns

    def _nearest_turns(self, want: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`_nearest_turn` of ``want`` compass degrees each: the clips, and how far each turns from
        ``want``."""
        clips = np.array([c for c, _ in self.library.turn_clips] or [0], np.int64)
        degs = np.array([d for _, d in self.library.turn_clips] or [0.0], np.float64)
        off = np.abs((degs[None, :] - want[:, None] + 180.0) % 360.0 - 180.0)
        near = off == off.min(axis=1, keepdims=True)
        right = near & ~(degs[None, :] * want[:, None] < 0)  # of two as near the one turning the asked way
        k = np.where(right.any(axis=1), right.argmax(axis=1), near.argmax(axis=1))
        return clips[k], off[np.arange(len(want)), k]

    def _ground_turns(
        self, node: int, want: float, moving: bool = False, speed: float = 0.0, ahead: float = 0.0
    ) -> tuple[PathStep, ...]:
        """The turns on the ground at ``node`` (CRAWL), one after the other (the larger first, each
        GROUND_TURN_RATE times faster than recorded, MAX_GROUND_TURNS at most), that come nearest to turning
        ``want`` compass degrees, what is left judged in steps of GROUND_TURN_SLACK_DEG, then the fewest, then
        those turning the asked way: 180° is the 90° twice (without lying down between), 60° the 30° twice
        (the 45° left it 15° off), 100° the 90° alone. ``moving``: of the turns that carry him forward, where
        the node has them (a crawler keeps up with his entity; 180°: the U-turn carried along the new
        heading, played no faster than keeps pace with an entity at ``speed`` cm/s: :meth:`_arc_rate`; the
        figure ``ahead`` cm ahead of it: :meth:`_u_turn`)."""
        lib = self.library
        clips = lib.node_arcs.get(node) if moving else None
        c = self._u_turn(clips or [], want, speed, ahead)
        if c is not None:  # the rest he turns as he crawls on
            return (PathStep(c, True, float(lib.clip_duration[c]) / self._arc_rate(c, speed), node, node),)
        # the U-turns alone or not at all (the 135° one was 127° as the 90° and the 30° arc are 120°)
        turns = tuple(c for c in clips or lib.node_turns[node] if abs(c[1]) <= 90.0)
        combos, total, count, negative, positive = _ground_combos(turns)
        left = (want - total + 180.0) % 360.0 - 180.0
        left[0] = want  # (no turn at all)
        wrong = negative if want > 0 else positive if want < 0 else np.zeros_like(count)
        best = combos[int(np.lexsort((wrong, count, np.round(np.abs(left) / GROUND_TURN_SLACK_DEG)))[0])]
        order = [c for c, _ in sorted(best, key=lambda c: -abs(c[1]))]
        if clips and len(order) > 1:  # all but the last on the spot: each carries him along the way it
            # turns to, and a U-turn of arcs ends beside his entity's path (180°: 75 cm aside, 20 ahead)
            spot = {d: c for c, d in lib.node_turns[node]}
            order = [spot.get(d, c) for c, d in sorted(best, key=lambda c: -abs(c[1]))[:-1]] + order[-1:]
        rates = [GROUND_TURN_RATE] * len(order)
        if clips and len(order) == 1:
            rates = [self._arc_rate(order[0], speed)]
        return tuple(
            PathStep(c, True, float(lib.clip_duration[c]) / r, node, node)
            for c, r in zip(order, rates, strict=True)
        )

    def _u_turn(
        self, arcs: list[tuple[int, float]], want: float, speed: float = 0.0, ahead: float = 0.0
    ) -> int | None:
        """Of a crawler's turns that carry him forward (``arcs``: clip, compass degrees) the U-turn (more than
        90°) nearest ``want`` compass degrees (U_TURN_MIN_DEG or more), if it is within U_TURN_SLACK_DEG of it
        (the 180° one serves either way, the shorter ones each way); of two as near the one that ends nearest
        an entity at ``speed`` cm/s, the figure ``ahead`` cm ahead of it along its new heading (a crawler
        trailing it before it reversed: 18 cm at 0.3 m/s); 0.45 m/s: the one carrying him further,
        ``crawlarc_r180_far``."""
        off = [(abs((d - want + 180.0) % 360.0 - 180.0), c) for c, d in arcs if abs(d) > 90.0]
        near = min(off, default=None)
        if near is None or near[0] > U_TURN_SLACK_DEG or abs(want) < U_TURN_MIN_DEG:
            return None
        ties = [c for o, c in off if o == near[0]]

        def short(c: int) -> float:  # cm he ends behind his entity (rounded: of two as near, the first)
            went = speed * float(self.library.clip_duration[c]) / self._arc_rate(c, speed)
            return round(abs(went - self._carry(c) - ahead), 1)

        return min(ties, key=short)

    def _carry(self, clip: int) -> float:
        """cm turn ``clip`` carries a crawler along the heading it ends on."""
        x, z, yaw = self.library.clip_end_offset[clip].tolist()
        a = math.radians(yaw)
        return -x * math.sin(a) - z * math.cos(a)

    def _arc_rate(self, clip: int, speed: float) -> float:
        """How much faster than recorded a crawler's turn ``clip`` plays: GROUND_TURN_RATE, or slower (down
        to MIN_RATE) for an entity at ``speed`` cm/s that the turn's carry along its end heading would
        overtake (a U-turn at 0.2 m/s ended 25 cm ahead of his entity, 33 after the stop)."""
        along = self._carry(clip)
        if speed <= 0.0 or along <= 0.0:
            return GROUND_TURN_RATE
        pace = float(self.library.clip_duration[clip]) * speed / along
        return min(max(pace, MIN_RATE), GROUND_TURN_RATE)

    def _turn_via(self, i: int, via: int) -> tuple[tuple[PathStep, ...], None] | None:
        """A prone soldier's turn (:meth:`_turn_plan`) on forearms and knees: the path up to ``via`` (CRAWL),
        the turns there that fit, the path back down (lying prone, forearms and thighs on the ground, he
        cannot turn on the spot without dragging them). Up and down play at their recorded pace, as when he
        goes prone or gets up to crawl: played twice as fast (a 90° turn in 3.8 s instead of 5.4) the way
        down swung his body 55° at 471°/s and flung a foot out at 11 m/s, a spin in three frames of a 30 Hz
        picture."""
        tb, lib = self.table, self.library
        node = int(tb.node[i])
        turns = self._ground_turns(via, -float(tb.root_yaw[i]))
        up, down = lib.path(node, via), lib.path(via, node)
        if not turns or not up or not down:
            return None
        return (*up, *turns, *down), None

    def _turn_path(self, i: int, steps: tuple[PathStep, ...], t: float, folded: bool = False) -> None:
        """Start the path ``steps`` that turns soldier ``i`` in place (``folded``: as ``_play_step``)."""
        tb = self.table
        tb.blend_len[i] = 0.0
        tb.mode[i] = _TRANSITION
        self._paths[i] = [steps, 0]
        self._play_step(i, steps[0], t, folded=folded)
        tb.dirty[i] = True

    def _nearest_turn(self, want: float, clips: list[tuple[int, float]] | None = None) -> tuple[int, float]:
        """The turn clip (of ``clips``, the standing ones if None) nearest ``want`` compass degrees; of two as
        near (180 both ways) the one turning the asked way."""
        return min(
            self.library.turn_clips if clips is None else clips,
            key=lambda c: (abs((c[1] - want + 180.0) % 360.0 - 180.0), c[1] * want < 0),
        )

    def _pivot_fits(self, clip: int, rest: float) -> bool:
        """Whether turn ``clip`` may turn ``rest`` degrees more or less than it does, as a pivot."""
        return rest <= PIVOT_REST_PER_STANCE_DEG * float(self.library.travel.stances[clip])

    def _pivot_clip(self, want: float, clips: list[tuple[int, float]] | None = None) -> tuple[int, float]:
        """A pivot's turn clip: of those turning the asked way that fit (:meth:`_pivot_fits`) the one whose
        rest (what it turns too much or too little) is least per stance. A 140° reversal: the 180° pivot less
        40° over its five stances (1.6 cm), not the 180° and then a 45° turn back. None fits (118-134°: the
        90° clip would turn 10° and more per stance, 2-2.7 cm): the nearest, and another turn after it."""

        def rest(c: tuple[int, float]) -> float:
            return abs((c[1] - want + 180.0) % 360.0 - 180.0)

        clips = self.library.turn_clips if clips is None else clips
        fits = [c for c in clips if c[1] * want > 0 and self._pivot_fits(c[0], rest(c))]
        if not fits:
            return self._nearest_turn(want, clips)
        return min(fits, key=lambda c: rest(c) / float(self.library.travel.stances[c[0]]))

    def _turn_end(self, i: int, t: float, folded: bool = False) -> None:
        """The turn's own move (``end_offset``) joins the root offset; the figure rests in its new heading
        (``folded``: its pivot bit and fold were done with a group's, ``Events._fold_arc_ends``)."""
        tb, lib = self.table, self.library
        if tb.pivot_rest[i] != 0.0:  # the pivot's last bit of turn, about where the figure ends
            root_motion.pivot(tb, lib, np.array([i], np.int64), t)
            tb.pivot_rest[i] = 0.0
        clip = int(tb.clip[i])
        self._rest(i, int(tb.node[i]), t, folded=folded)
        self._turned(i, clip)

    def _turned(self, i: int, clip: int) -> None:
        """Turn ``clip``'s own move (``end_offset``) joins soldier ``i``'s root offset and yaw (its end)."""
        tb = self.table
        x, z, yaw = self.library.clip_end_offset[clip]
        a = -math.radians(float(tb.root_yaw[i]))  # as blend.yaw_rotate turns the clip's placements
        tb.root_off[i, 0] += math.cos(a) * x + math.sin(a) * z
        tb.root_off[i, 1] += math.cos(a) * z - math.sin(a) * x
        tb.root_yaw[i] = (float(tb.root_yaw[i]) - yaw + 180.0) % 360.0 - 180.0
