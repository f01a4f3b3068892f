"""Figure 5 as a table: the arcs between walking, running, backward walking and crawling states."""

from __future__ import annotations

import numpy as np

from server.soldier.locomotion import NEXT, Cond, conditions, next_states, start_state
from server.soldier.state import LocoState as S
from server.soldier.state import Movement


def nxt(state: S, moving: bool = True, backward: bool = False, fast: bool = False, can_run: bool = True) -> S:
    c = conditions(np.array([state]), np.array([moving]), np.array([backward]), np.array([fast]), can_run)
    return S(int(next_states(np.array([state]), c)[0]))


def test_walking_cycle_and_end() -> None:
    assert start_state(Movement.WALK, backward=False, fast=False) == S.WALK_START
    assert nxt(S.WALK_START) == S.WALK_CYCLE
    assert nxt(S.WALK_CYCLE) == S.WALK_CYCLE
    assert nxt(S.WALK_CYCLE, moving=False) == S.WALK_END
    assert nxt(S.WALK_START, moving=False) == S.WALK_END
    assert nxt(S.WALK_END) == S.NONE and nxt(S.WALK_END, moving=False) == S.NONE


def test_walk_run_threshold_both_ways() -> None:
    assert nxt(S.WALK_CYCLE, fast=True) == S.WALK2RUN
    assert nxt(S.WALK2RUN, fast=True) == S.RUN_CYCLE
    assert nxt(S.RUN_CYCLE, fast=True) == S.RUN_CYCLE
    assert nxt(S.RUN_CYCLE) == S.RUN2WALK
    assert nxt(S.RUN2WALK) == S.WALK_CYCLE
    assert nxt(S.RUN_CYCLE, moving=False) == S.RUN_END
    assert start_state(Movement.WALK, backward=False, fast=True) == S.RUN_START
    assert start_state(Movement.WALK, backward=False, fast=True, can_run=False) == S.WALK_START
    assert nxt(S.WALK_CYCLE, fast=True, can_run=False) == S.WALK_CYCLE


def test_no_backward_running_and_direction_changes_end_the_gait() -> None:
    assert start_state(Movement.WALK, backward=True, fast=True) == S.BWALK_START
    assert nxt(S.BWALK_START, backward=True, fast=True) == S.BWALK_CYCLE
    assert nxt(S.BWALK_CYCLE, backward=True, fast=True) == S.BWALK_CYCLE
    assert nxt(S.BWALK_CYCLE, backward=False) == S.BWALK_END  # reversed: back to the base posture first
    assert nxt(S.WALK_CYCLE, backward=True) == S.WALK_END
    assert nxt(S.RUN_CYCLE, backward=True, fast=True) == S.RUN_END


def test_crawling_start_cycle_end() -> None:
    assert start_state(Movement.CRAWL, backward=False, fast=True) == S.CRAWL_START
    assert nxt(S.CRAWL_START) == S.CRAWL_CYCLE
    assert nxt(S.CRAWL_CYCLE, backward=True, fast=True) == S.CRAWL_CYCLE  # no direction condition
    assert nxt(S.CRAWL_CYCLE, moving=False) == S.CRAWL_END
    assert nxt(S.CRAWL_END) == S.NONE


def test_table_is_vectorised_and_closed() -> None:
    states = np.arange(len(S))
    for cond in Cond:
        out = next_states(states, np.full(len(S), cond))
        assert out.shape == states.shape and set(out.tolist()) <= {int(s) for s in S}
    assert (NEXT[S.NONE] == S.NONE).all()


def test_side_steps_repeat_and_any_other_direction_stops_them() -> None:
    from server.soldier.locomotion import Side, direction

    back, side = direction(np.array([1.0, -1.0, 0.2, 0.2, -0.5]), np.array([0.2, 0.1, 1.0, -1.0, 0.0]))
    assert back.tolist() == [False, True, False, False, True]
    assert side.tolist() == [Side.AHEAD, Side.AHEAD, Side.LEFT, Side.RIGHT, Side.AHEAD]
    _, no_side = direction(np.array([0.2]), np.array([1.0]), can_side=False)
    assert no_side.tolist() == [Side.AHEAD]
    assert start_state(Movement.WALK, False, False, side=Side.LEFT) == S.SIDESTEP_L
    assert start_state(Movement.CRAWL, False, False, side=Side.LEFT) == S.CRAWL_START

    def step(state: S, side: int, moving: bool = True) -> S:
        c = conditions(
            np.array([state]),
            np.array([moving]),
            np.array([False]),
            np.array([False]),
            True,
            np.array([side], np.int8),
        )
        return S(int(next_states(np.array([state]), c)[0]))

    assert step(S.SIDESTEP_L, Side.LEFT) == S.SIDESTEP_L
    assert step(S.SIDESTEP_L, Side.RIGHT) == S.NONE  # back to the base posture, then the other way
    assert step(S.SIDESTEP_R, Side.AHEAD) == S.NONE
    assert step(S.SIDESTEP_R, Side.RIGHT, moving=False) == S.NONE
    assert step(S.WALK_CYCLE, Side.LEFT) == S.WALK_END


def test_walk_run_hysteresis() -> None:
    from server.soldier.locomotion import is_fast

    states = np.array([S.WALK_CYCLE, S.RUN_CYCLE, S.WALK_CYCLE, S.RUN_CYCLE, S.WALK2RUN])
    speeds = np.array([2.2, 2.2, 2.6, 1.8, 2.1])
    assert is_fast(states, speeds, 2.4, 0.4).tolist() == [False, True, True, False, True]
