"""The event paths fold soldiers' root offsets a group at a time where they folded one soldier at a time: arc
ends (``Events._fold_arc_ends``), turns in place and pivots (``Turning._turn_many``), a small group's gait
starts (``Events._start_gaits``), and a step's fold takes the offsets ``_far_behind`` computed. The load mix
on the shipped library (turns, pivots, reversals, posture paths) leaves the same table, paths and clip starts,
bit for bit, as the reference: each soldier's event folded on its own (``_fold_groups`` off: the paths as
they were), and every fold of a group done row by row."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pytest

from client_stub.loadtest.mix import MixDriver
from server.soldier import root_motion
from server.soldier.library import MotionLibrary
from server.soldier.manager import SoldierManager
from server.soldier.table import _COLUMNS, SoldierTable
from tests.test_request_batch import _rows, shipped_library

SOLDIERS = 120
HZ = 30.0


def _run(seed: int, one_by_one: bool = False) -> SoldierManager:
    m = SoldierManager(shipped_library(), throttle=0.0, tick_period=1 / HZ, record_clips=True)
    m._fold_groups = not one_by_one
    for _ in range(SOLDIERS):
        m.create_soldier()
    mix = MixDriver(SOLDIERS, seed=seed)
    m.apply_requests(mix.initial(), 0.0)
    for k in range(1, 6 * int(HZ) + 1):
        m.tick(k / HZ)
        if k % 3 == 0:  # the mix's 10 Hz, between ticks, in two batches
            now = (k + 0.5) / HZ
            rows = mix.step(now).rows
            for part in (rows[: len(rows) // 2], rows[len(rows) // 2 :]):
                m.apply_requests(part, now)
                m.answer(now, (k + 1) / HZ)
    return m


def _scripted(one_by_one: bool) -> SoldierManager:
    """Stowed soldiers walk, reverse (stop, pivot, walk away), then stop and turn in place, some on the
    ground (CRAWL: the turns on forearms and knees)."""
    m = SoldierManager(shipped_library(), throttle=0.0, tick_period=1 / HZ, record_clips=True)
    m._fold_groups = not one_by_one
    n = 24
    for _ in range(n):
        m.create_soldier()
    app = [2 if s % 4 else 5 for s in range(n)]  # STAND, a quarter CRAWL
    script = {
        3: [(s, app[s], 0, 1.4 if app[s] == 2 else 0.3, 10.0 * s, False, 1, 0.0) for s in range(n)],
        60: [(s, app[s], 0, 1.4 if app[s] == 2 else 0.3, 10.0 * s + 180.0, False, 1, 0.0) for s in range(n)],
        150: [(s, app[s], 0, 0.0, 10.0 * s + 90.0 + 5 * s, False, 1, 0.0) for s in range(n)],
    }
    for k in range(1, 300):
        m.tick(k / HZ)
        if k in script:
            now = (k + 0.5) / HZ
            m.apply_requests(_rows(script[k]), now)
            m.answer(now, (k + 1) / HZ)
    return m


def _row_by_row(fold: Callable[..., None]) -> Callable[..., None]:
    def each(tb: SoldierTable, lib: MotionLibrary, idx: np.ndarray, t: object, *_: object) -> None:
        times = np.broadcast_to(np.asarray(t, np.float64), np.shape(idx))
        for i, ti in zip(np.asarray(idx).tolist(), times.tolist(), strict=True):
            fold(tb, lib, np.array([i], np.int64), np.array([ti]))

    return each


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_group_folds_leave_each_row_as_its_own_fold(seed: int, monkeypatch: pytest.MonkeyPatch) -> None:
    run = _scripted if seed == 0 else lambda one_by_one: _run(seed, one_by_one)
    grouped = run(False)
    monkeypatch.setattr(root_motion, "fold", _row_by_row(root_motion.fold))
    monkeypatch.setattr(root_motion, "fold_exact", _row_by_row(root_motion.fold_exact))
    single = run(True)
    assert sum("turn" in c.clip for c in grouped.clip_log) >= 5  # turns in place, pivots, ground turns
    for name in (*_COLUMNS, "blend_joints", "blend_figs"):
        np.testing.assert_array_equal(getattr(grouped.table, name), getattr(single.table, name), err_msg=name)
    assert grouped._paths == single._paths
    assert grouped.clip_log == single.clip_log
