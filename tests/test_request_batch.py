"""Property test: a batch of entity requests applied at once (the soldiers' decisions grouped in numpy:
posture-change starts, gait starts, stops, turns in place, snaps; unchanged re-sends skipped) leaves the same
soldier table, paths and clip starts, bit for bit, as its rows applied one by one, each soldier deciding on
its own in scalar Python."""

from __future__ import annotations

from functools import cache

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from protocol.coords import points_performer_to_jack
from protocol.entity import make_entity_requests
from server.soldier.library import MotionLibrary
from server.soldier.manager import ClipStart, SoldierManager
from server.soldier.synthetic import synthetic_motion_library
from server.soldier.table import _COLUMNS
from tests.test_gait_selection import shipped_library as _shipped

LIB = synthetic_motion_library()
SOLDIERS = 5
HZ = 30.0

row = st.tuples(
    st.integers(0, SOLDIERS),  # soldier (SOLDIERS: never created)
    st.integers(1, 5),  # appearance
    st.integers(0, 2),  # weapon
    st.sampled_from([0.0, 0.0, 0.5, 1.4, 2.9]),  # speed
    st.sampled_from([0.0, 0.0, 30.0, 90.0, 180.0, 275.5]),  # heading
    st.booleans(),  # backward
    st.integers(0, 12),  # immediate when 0
    st.sampled_from([0.0, 0.0, 0.0, 90.0, -90.0, 30.0]),  # velocity from the heading: side-steps
)


@cache
def shipped_library() -> MotionLibrary:
    """The library a plain server builds from this checkout, loaded once."""
    return _shipped()


def _rows(batch: list[tuple[int, int, int, float, float, bool, int, float]]) -> np.ndarray:
    out = []
    for idx, app, wpn, speed, heading, back, imm, across in batch:
        h = np.radians(heading + across)
        s = -speed if back else speed
        out.append(
            make_entity_requests(
                idx, app, wpn, (s * np.sin(h), s * np.cos(h), 0.0), heading, (1, 2, 0), imm == 0
            )
        )
    return np.concatenate(out)


def _manager(one_by_one: bool, lib: MotionLibrary = LIB) -> SoldierManager:
    m = SoldierManager(lib, throttle=0.0, tick_period=1 / HZ, record_clips=True)
    # the reference: every event on its own, each soldier deciding alone in scalar Python; the batch's
    # soldiers decide grouped (in numpy) however few they are
    m._group_min = 10**9 if one_by_one else 1  # type: ignore[misc]
    if one_by_one:
        m._posture_changes = lambda idx, imm: np.zeros(len(idx), bool)  # type: ignore[method-assign]
    for _ in range(SOLDIERS):
        m.create_soldier()
    return m


def _assert_same(a: SoldierManager, b: SoldierManager) -> None:
    for name in (*_COLUMNS, "blend_joints", "blend_figs"):
        np.testing.assert_array_equal(getattr(a.table, name), getattr(b.table, name), err_msg=name)
    assert a._paths == b._paths

    def by_soldier(m: SoldierManager) -> list[ClipStart]:
        return sorted(m.clip_log, key=lambda c: (c.index, c.time))  # stable: each soldier's own order kept

    assert by_soldier(a) == by_soldier(b)
    timing = ("tick_seconds", "last_tick_seconds")
    assert {k: v for k, v in a.stats.items() if k not in timing} == {
        k: v for k, v in b.stats.items() if k not in timing
    }


BATCHES = st.lists(st.lists(row, min_size=1, max_size=8), min_size=1, max_size=3)


@settings(deadline=None, max_examples=25)
@given(BATCHES, st.integers(1, 12))
def test_batch_applies_as_its_rows_one_by_one(batches, gap: int) -> None:
    _check(LIB, batches, gap)


# standing stowed (the turns in place), walking, running, side-stepping, crawling soldiers
standing = st.tuples(
    st.integers(0, 3),
    st.sampled_from([2, 2, 2, 5]),  # appearance: STAND, CRAWL
    st.sampled_from([0, 0, 1]),  # weapon: STOWED (turn clips), DEPLOYED
    st.sampled_from([0.0, 0.0, 0.5, 1.4, 2.9]),
    st.sampled_from([0.0, 45.0, 90.0, 180.0, 275.5]),
    st.booleans(),
    st.integers(0, 30),
    st.sampled_from([0.0, 0.0, 90.0, -90.0]),
)


@settings(deadline=None, max_examples=6)
@given(st.lists(st.lists(standing, min_size=1, max_size=6), min_size=2, max_size=4), st.integers(4, 20))
def test_batch_applies_as_its_rows_one_by_one_turning(batches, gap: int) -> None:
    """The shipped library: turns in place, pivots, side-steps, reversals (the synthetic one has none)."""
    _check(shipped_library(), batches, gap)


def _check(lib: MotionLibrary, batches, gap: int) -> None:  # type: ignore[no-untyped-def]
    batched, single = _manager(False, lib), _manager(True, lib)
    tick = 0
    for batch in batches:
        rows = _rows(batch)
        now = (tick + 0.5) / HZ
        status = batched.apply_requests(rows, now)
        # when several rows name one soldier the last one wins: the reference applies only that one
        last = {int(r["index"]): k for k, r in enumerate(rows)}
        for k in sorted(last.values()):
            single.apply_requests(rows[k : k + 1], now)
        assert status.tolist() == [1 if r["index"] >= SOLDIERS else 0 for r in rows]
        for m in (batched, single):
            m.stats["requests"] = m.stats["requests_unknown"] = 0  # counted per row, duplicates included
            m.answer(now, (tick + 1) / HZ)
        _assert_same(batched, single)
        for _ in range(gap):  # the soldiers step, change posture, end clips
            tick += 1
            batched.tick(tick / HZ)
            single.tick(tick / HZ)
        _assert_same(batched, single)


def test_an_unchanged_resend_only_moves_the_entity() -> None:
    m = _manager(False)
    rows = _rows([(0, 2, 1, 1.4, 90.0, False, 3, 0.0)])
    m.apply_requests(rows, 0.1)
    m.tick(1 / HZ)
    m.tick(2 / HZ)
    before = {name: getattr(m.table, name).copy() for name in _COLUMNS}
    events = m.stats["events"]
    rows["position"] = (5.0, 6.0, 0.0)
    m.apply_requests(rows, 2.5 / HZ)
    assert m.stats["events"] == events
    assert not m.table.requested[0]
    for name, was in before.items():
        if name != "position":
            np.testing.assert_array_equal(getattr(m.table, name), was, err_msg=name)
    np.testing.assert_array_equal(m.table.position[0], points_performer_to_jack(np.array([5.0, 6.0, 0.0])))


def test_turns_in_place_grouped_as_one_by_one() -> None:
    """Standing stowed soldiers whose heading changes turn in place (grouped: ``_turns``), then some walk,
    side-step or turn again before the turn ends."""
    still = [(s, 2, 0, 0.0, 0.0, False, 1, 0.0) for s in range(SOLDIERS)]
    turned = [(s, 2, 0, 0.0, h, False, 1, 0.0) for s, h in enumerate([45.0, 90.0, 180.0, 275.5, 130.0])]
    moved = [
        (0, 2, 0, 1.4, 45.0, False, 1, 0.0),
        (1, 2, 0, 0.5, 90.0, False, 1, 90.0),
        (2, 2, 0, 0.0, 0.0, False, 1, 0.0),
    ]
    for gap in (2, 40):
        _check(shipped_library(), [still, turned, moved, turned], gap)
