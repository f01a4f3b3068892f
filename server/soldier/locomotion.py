"""Figure 5 as data: the walking / running / crawling state machine, vectorised over soldiers.

Nodes are clips that play once (:class:`~server.soldier.state.LocoState`); arcs are *conditions* checked when
a clip ends (seed 002, 3.3 and footnote 1). The condition of a soldier at a clip end is one of

* ``STOP``   — speed back to zero, or the direction (forwards, backwards, left or right: :func:`direction`
  from the angle between heading and velocity) no longer matches the gait: play the end step back to the
  base posture;
* ``FAST``   — speed above the walk/run threshold (forward gaits only: there is no backward running);
* ``NORMAL`` — keep the gait.

Walking starts with a start step (left or right: the foot after the one that stepped last, so starts
alternate), then cycles one step per clip (feet alternating) until STOP plays the end step; FAST takes the
walk→run step into running, and back below the threshold run→walk returns to walking. Starting at a run from
rest uses ``run_start``, stopping from a run ``run_end``. Crawling has a start, a cycle and an end that is the
start played backwards. Side-steps (velocity sideways to the heading) repeat one side-step clip, which
starts and ends in the base posture. ``NEXT[state, condition]`` and :func:`start_state` are the whole machine.

Walk → run has hysteresis (:func:`is_fast`): a walking soldier runs above the walk/run threshold, a running
one walks again only below the threshold minus the hysteresis, so a speed near the threshold does not flip
gaits.
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
    S.SIDESTEP_L: (S.NONE, S.SIDESTEP_L, S.SIDESTEP_L),
    S.SIDESTEP_R: (S.NONE, S.SIDESTEP_R, S.SIDESTEP_R),
    S.NONE: (S.NONE, S.NONE, S.NONE),
}
NSTATES = len(S)
NEXT = np.zeros((NSTATES, 3), np.int8)
for _s, _row in _TABLE.items():
    NEXT[_s] = _row

BACKWARD_STATES = frozenset({S.BWALK_START, S.BWALK_CYCLE, S.BWALK_END})
CRAWL_STATES = frozenset({S.CRAWL_START, S.CRAWL_CYCLE, S.CRAWL_END})
END_STATES = frozenset({S.WALK_END, S.RUN_END, S.BWALK_END, S.CRAWL_END})
RUN_STATES = frozenset({S.RUN_START, S.RUN_CYCLE, S.WALK2RUN})
IS_BACKWARD = np.array([s in BACKWARD_STATES for s in S], bool)
IS_CRAWL = np.array([s in CRAWL_STATES for s in S], bool)
IS_RUN = np.array([s in RUN_STATES for s in S], bool)
IS_WALK = np.array([s in (S.WALK_START, S.WALK_CYCLE, S.RUN2WALK) for s in S], bool)


class Side(IntEnum):
    """Which way a standing soldier moves relative to its heading (crawling knows only forwards/backwards)."""

    AHEAD = 0  # forwards or backwards (see ``backward``)
    LEFT = 1
    RIGHT = 2


_AHEAD, _LEFT, _RIGHT = int(Side.AHEAD), int(Side.LEFT), int(Side.RIGHT)  # plain ints: np.where is faster

SIDE_OF = np.array(
    [Side.LEFT if s == S.SIDESTEP_L else Side.RIGHT if s == S.SIDESTEP_R else Side.AHEAD for s in S], np.int8
)
START_STATES = frozenset({S.WALK_START, S.RUN_START, S.BWALK_START, S.CRAWL_START})
GAIT_CHANGES = frozenset({S.WALK2RUN, S.RUN2WALK})
# start and end steps and the gait changes play at their recorded rate (natural timing: the root offset
# keeps their feet planted while the entity moves at another speed), the cycles follow the ground speed
SCALED = np.array([s not in END_STATES | START_STATES | GAIT_CHANGES and s != S.NONE for s in S], bool)
# ... except in a hurry: the end step of a walk, run or crawl that reverses (a crawler turns on the ground),
# and a start step whose figure is metres behind its entity (after a pivot or a turn on the ground), play at
# the gait's upper cadence (a person stopping to turn back, or setting off after the turn, steps quicker; the
# root offset keeps the feet planted at any rate)
HURRY_STATES = frozenset({S.WALK_START, S.WALK_END, S.RUN_START, S.RUN_END, S.CRAWL_START, S.CRAWL_END})

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
    S.SIDESTEP_L: ("sidestep_l", False, 1),
    S.SIDESTEP_R: ("sidestep_r", False, 1),
}


# Gait transitions recorded with one swinging foot only (the shipped walk2run/run2walk start where the
# left foot lands and swing the right one) are entered only when that foot steps next, else after one more
# stride of the current gait: ``GAIT_STAY`` is that stride's state.
GAIT_STAY: dict[S, S] = {S.WALK2RUN: S.WALK_CYCLE, S.RUN2WALK: S.RUN_CYCLE}


def direction(forward: np.ndarray, left: np.ndarray, can_side: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """``(backward, side)`` of velocities with ``forward`` / ``left`` components along the heading.

    Sideways means more across the heading than along it (45-135 degrees either side); without side-step
    clips (``can_side`` False) the soldier walks forwards or backwards whatever the angle.
    """
    forward, left = np.asarray(forward, np.float64), np.asarray(left, np.float64)
    sideways = (np.abs(left) > np.abs(forward)) & can_side
    side = np.where(sideways, np.where(left > 0, _LEFT, _RIGHT), _AHEAD).astype(np.int8)
    return forward < 0.0, side


def is_fast(state: np.ndarray, speed: np.ndarray, threshold: float, hysteresis: float) -> np.ndarray:
    """FAST with hysteresis: running states stay fast down to ``threshold - hysteresis`` m/s."""
    state = np.asarray(state, np.int64)
    return np.asarray(speed) > np.where(IS_RUN[state], threshold - hysteresis, threshold)


def conditions(
    state: np.ndarray,
    moving: np.ndarray,
    backward: np.ndarray,
    fast: np.ndarray,
    can_run: bool = True,
    side: np.ndarray | None = None,
) -> np.ndarray:
    """Figure 5's arc conditions (:class:`Cond`) for soldiers in ``state`` with this velocity.

    Crawling has no direction condition: a backward crawler plays the crawl cycle backwards instead. A
    sideways soldier (``side`` not AHEAD) has no forwards/backwards direction.
    """
    state = np.asarray(state, np.int64)
    side_ = np.zeros(state.shape, np.int8) if side is None else np.asarray(side, np.int8)
    ahead = side_ == Side.AHEAD
    wrong_way = ahead & (np.asarray(backward, bool) != IS_BACKWARD[state])
    reversed_ = ((side_ != SIDE_OF[state]) | wrong_way) & ~IS_CRAWL[state]
    stop = ~np.asarray(moving, bool) | reversed_
    fast = np.asarray(fast, bool) & can_run
    return np.where(stop, Cond.STOP, np.where(fast, Cond.FAST, Cond.NORMAL)).astype(np.int8)


def next_states(state: np.ndarray, cond: np.ndarray) -> np.ndarray:
    """The state entered when the clip of ``state`` ends under ``cond`` (NONE = back at the base posture)."""
    return NEXT[np.asarray(state, np.int64), np.asarray(cond, np.int64)]


def _first_state(crawl: bool, side: int, backward: bool, fast: bool) -> S:
    """The first state when a resting soldier starts moving (velocity zero → non-zero)."""
    if crawl:
        return S.CRAWL_START
    if side != Side.AHEAD:
        return S.SIDESTEP_L if side == Side.LEFT else S.SIDESTEP_R
    if backward:
        return S.BWALK_START
    return S.RUN_START if fast else S.WALK_START


# START[crawl, side, backward, fast]: :func:`_first_state` as a table (a batch's starts: one lookup)
START = np.array(
    [
        [[[_first_state(c, sd, b, f) for f in (False, True)] for b in (False, True)] for sd in Side]
        for c in (False, True)
    ],
    np.int64,
)


def start_state(
    kind: np.ndarray | int,
    backward: np.ndarray | bool,
    fast: np.ndarray | bool,
    can_run: bool = True,
    side: np.ndarray | int = Side.AHEAD,
) -> np.ndarray:
    """The first states when resting soldiers (Movement ``kind``) start moving, over arrays (or one
    soldier's scalars: a 0-d array)."""
    crawl = np.asarray(kind) == int(Movement.CRAWL)
    fast = (np.asarray(fast) & can_run).astype(np.int64)
    return START[crawl.astype(np.int64), np.asarray(side, np.int64), np.asarray(backward, np.int64), fast]
