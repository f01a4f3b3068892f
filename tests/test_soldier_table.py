"""SoldierTable: struct-of-arrays rows, capacity growth, free-list reuse of indices."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from server.soldier.table import SoldierTable


def test_allocate_takes_lowest_free_and_grows() -> None:
    t = SoldierTable(ndof=5, nfig=2, capacity=2, max_soldiers=100)
    assert [t.allocate() for _ in range(5)] == [0, 1, 2, 3, 4]
    assert t.capacity == 8 and t.count == 5
    assert t.blend_joints.shape == (8, 5) and t.blend_figs.shape == (8, 2, 7)
    t.free(1)
    t.free(3)
    assert t.allocate() == 1 and t.allocate() == 3 and t.allocate() == 5
    assert t.live.tolist() == [0, 1, 2, 3, 4, 5]


def test_columns_survive_growth_and_rows_reset_on_reuse() -> None:
    t = SoldierTable(3, 1, capacity=1, max_soldiers=64)
    i = t.allocate()
    t.speed[i] = 2.5
    t.velocity[i] = (1, 2, 3)
    t.allocate(40)  # forces growth past 40
    assert t.capacity >= 41 and t.speed[i] == 2.5 and t.velocity[i].tolist() == [1, 2, 3]
    t.free(i)
    assert t.allocate() == i and t.speed[i] == 0.0 and not t.velocity[i].any()


def test_explicit_index_errors_and_limits() -> None:
    t = SoldierTable(1, 1, capacity=4, max_soldiers=10)
    assert t.allocate(7) == 7
    with pytest.raises(ValueError, match="in use"):
        t.allocate(7)
    with pytest.raises(ValueError, match="outside"):
        t.allocate(10)
    with pytest.raises(ValueError, match="outside"):
        t.allocate(-1)
    for _ in range(9):
        t.allocate()
    with pytest.raises(ValueError, match="full"):
        t.allocate()
    with pytest.raises(KeyError):
        SoldierTable(1, 1).free(3)


def test_live_mask_accepts_any_integers() -> None:
    t = SoldierTable(1, 1, capacity=4)
    t.allocate(2)
    mask = t.live_mask(np.array([-5, 0, 2, 3, 10**9]))
    assert mask.tolist() == [False, False, True, False, False]


@given(st.lists(st.tuples(st.booleans(), st.integers(0, 40)), max_size=80))
def test_matches_a_set_model(ops: list[tuple[bool, int]]) -> None:
    t = SoldierTable(2, 1, capacity=1, max_soldiers=41)
    model: set[int] = set()
    for alloc, k in ops:
        if alloc:
            if len(model) == 41:
                continue
            i = t.allocate()
            assert i == min(set(range(41)) - model)
            model.add(i)
        elif model:
            victim = sorted(model)[k % len(model)]
            t.free(victim)
            model.remove(victim)
        assert t.live.tolist() == sorted(model) and t.count == len(model)


@given(st.lists(st.tuples(st.integers(0, 2), st.integers(0, 40)), max_size=120))
def test_indices_taken_by_number_match_a_set_model(ops: list[tuple[int, int]]) -> None:
    """A shard takes every index by number (its front-end's): the lowest free index stays the lowest one
    not live, and the heap that finds it stays within twice the capacity however often a soldier is
    removed and made again by number (its stale entries are skipped, then dropped)."""
    t = SoldierTable(2, 1, capacity=1, max_soldiers=41)
    model: set[int] = set()
    for kind, k in ops:
        free = sorted(set(range(41)) - model)
        if kind == 0 and free:
            i = t.allocate()
            assert i == free[0]
            model.add(i)
        elif kind == 1 and free:
            model.add(t.allocate(free[k % len(free)]))
        elif kind == 2 and model:
            victim = sorted(model)[k % len(model)]
            t.free(victim)
            model.remove(victim)
        assert t.live.tolist() == sorted(model) and t.count == len(model)
        assert len(t._free) <= 2 * t.capacity


def test_a_soldier_made_again_by_number_does_not_grow_the_free_heap() -> None:
    t = SoldierTable(1, 1, capacity=64, max_soldiers=64)
    for _ in range(1000):
        t.allocate(5)
        t.free(5)
    assert len(t._free) <= 2 * t.capacity and t.allocate() == 0
