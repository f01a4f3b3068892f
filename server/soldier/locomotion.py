"""Figure 5 as data: the walking / running / crawling state machine, vectorised over soldiers.

Nodes are clips that play once (:class:`~server.soldier.state.LocoState`); arcs are *conditions* checked when
a clip ends (seed 002, 3.3 and footnote 1). The condition of a soldier at a clip end is one of

* ``STOP``   — speed back to zero, or the direction (forwards/backwards, from the angle between heading and
  velocity) no longer matches the gait: play the end step back to the base posture;
* ``FAST``   — speed above the walk/run threshold (forward gaits only: there is no backward running);
* ``NORMAL`` — keep the gait.

Walking starts with a start step (left or right: the foot after the one that stepped last, so starts
alternate), then cycles one step per clip (feet alternating) until STOP plays the end step; FAST takes the
walk→run step into running, and back below the threshold run→walk returns to walking. Starting at a run from
rest uses ``run_start``, stopping from a run ``run_end``. Crawling has a start, a cycle and an end that is the
start played backwards. ``NEXT[state, condition]`` and ``START[movement, condition]`` are the whole machine.
"""

from __future__ import annotations

from enum import IntEnum

import numpy as np

from server.soldier.state import LocoState as S
from server.soldier.state import Movement


class Cond(IntEnum):
    STOP = 0
    FAST = 1
    NORMAL = 2


_TABLE: dict[S, tuple[S, S, S]] = {  # state: (next on STOP, on FAST, on NORMAL)
    S.WALK_START: (S.WALK_END, S.WALK2RUN, S.WALK_CYCLE),
    S.WALK_CYCLE: (S.WALK_END, S.WALK2RUN, S.WALK_CYCLE),
    S.RUN2WALK: (S.WALK_END, S.WALK2RUN, S.WALK_CYCLE),
    S.WALK2RUN: (S.RUN_END, S.RUN_CYCLE, S.RUN2WALK),
    S.RUN_START: (S.RUN_END, S.RUN_CYCLE, S.RUN2WALK),
    S.RUN_CYCLE: (S.RUN_END, S.RUN_CYCLE, S.RUN2WALK),
    S.BWALK_START: (S.BWALK_END, S.BWALK_CYCLE, S.BWALK_CYCLE),
    S.BWALK_CYCLE: (S.BWALK_END, S.BWALK_CYCLE, S.BWALK_CYCLE),
    S.WALK_END: (S.NONE, S.NONE, S.NONE),
    S.RUN_END: (S.NONE, S.NONE, S.NONE),
    S.BWALK_END: (S.NONE, S.NONE, S.NONE),
    S.CRAWL_START: (S.CRAWL_END, S.CRAWL_CYCLE, S.CRAWL_CYCLE),
    S.CRAWL_CYCLE: (S.CRAWL_END, S.CRAWL_CYCLE, S.CRAWL_CYCLE),
    S.CRAWL_END: (S.NONE, S.NONE, S.NONE),
    S.NONE: (S.NONE, S.NONE, S.NONE),
}
NSTATES = len(S)
NEXT = np.zeros((NSTATES, 3), np.int8)
for _s, _row in _TABLE.items():
    NEXT[_s] = _row

BACKWARD_STATES = frozenset({S.BWALK_START, S.BWALK_CYCLE, S.BWALK_END})
CRAWL_STATES = frozenset({S.CRAWL_START, S.CRAWL_CYCLE, S.CRAWL_END})
END_STATES = frozenset({S.WALK_END, S.RUN_END, S.BWALK_END, S.CRAWL_END})
IS_BACKWARD = np.array([s in BACKWARD_STATES for s in S], bool)
IS_CRAWL = np.array([s in CRAWL_STATES for s in S], bool)
# end steps slow to a stop: they play at their recorded rate, every other step follows the ground speed
SCALED = np.array([s not in END_STATES and s != S.NONE for s in S], bool)

# (clip base name, footed, direction) per state; CRAWL_END plays crawl_start backwards
CLIP_OF: dict[S, tuple[str, bool, int]] = {
    S.WALK_START: ("walk_start", True, 1),
    S.WALK_CYCLE: ("walk_cycle", True, 1),
    S.WALK_END: ("walk_end", True, 1),
    S.BWALK_START: ("bwalk_start", True, 1),
    S.BWALK_CYCLE: ("bwalk_cycle", True, 1),
    S.BWALK_END: ("bwalk_end", True, 1),
    S.RUN_START: ("run_start", True, 1),
    S.RUN_CYCLE: ("run_cycle", True, 1),
    S.RUN_END: ("run_end", True, 1),
    S.WALK2RUN: ("walk2run", False, 1),
    S.RUN2WALK: ("run2walk", False, 1),
    S.CRAWL_START: ("crawl_start", False, 1),
    S.CRAWL_CYCLE: ("crawl_cycle", False, 1),
    S.CRAWL_END: ("crawl_start", False, -1),
}


# Gait transitions recorded with one swinging foot only (the shipped walk2run/run2walk start where the
# left foot lands and swing the right one) are entered only when that foot steps next, else after one more
# stride of the current gait: ``GAIT_STAY`` is that stride's state.
GAIT_STAY: dict[S, S] = {S.WALK2RUN: S.WALK_CYCLE, S.RUN2WALK: S.RUN_CYCLE}


def conditions(
    state: np.ndarray, moving: np.ndarray, backward: np.ndarray, fast: np.ndarray, can_run: bool = True
) -> np.ndarray:
    """Figure 5's arc conditions (:class:`Cond`) for soldiers in ``state`` with this velocity.

    Crawling has no direction condition: a backward crawler plays the crawl cycle backwards instead.
    """
    state = np.asarray(state, np.int64)
    reversed_ = (np.asarray(backward, bool) != IS_BACKWARD[state]) & ~IS_CRAWL[state]
    stop = ~np.asarray(moving, bool) | reversed_
    fast = np.asarray(fast, bool) & can_run
    return np.where(stop, Cond.STOP, np.where(fast, Cond.FAST, Cond.NORMAL)).astype(np.int8)


def next_states(state: np.ndarray, cond: np.ndarray) -> np.ndarray:
    """The state entered when the clip of ``state`` ends under ``cond`` (NONE = back at the base posture)."""
    return NEXT[np.asarray(state, np.int64), np.asarray(cond, np.int64)]


def start_state(kind: Movement, backward: bool, fast: bool, can_run: bool = True) -> S:
    """The first state when a resting soldier starts moving (velocity zero → non-zero)."""
    if kind == Movement.CRAWL:
        return S.CRAWL_START
    if backward:
        return S.BWALK_START
    return S.RUN_START if fast and can_run else S.WALK_START
