"""Property test: any sequence of requests at any times keeps every soldier state consistent."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from protocol.entity import make_entity_requests
from server.soldier.manager import SoldierManager
from server.soldier.state import CRAWL_NODE, STAND_STOWED, Mode
from server.soldier.synthetic import synthetic_motion_library

LIB = synthetic_motion_library()
THROTTLE = 0.05

request = st.tuples(
    st.integers(0, 3),  # soldier (3 = never created)
    st.integers(1, 5),  # appearance
    st.integers(0, 2),  # weapon
    st.sampled_from([0.0, 0.0, 0.5, 1.4, 2.9, 3.1, 6.0]),  # speed
    st.floats(0, 360),  # heading
    st.booleans(),  # backward
    st.integers(0, 9),  # immediate when 0
    st.floats(0.0, 1.2),  # time until the next request
)


@pytest.mark.fuzz
@settings(deadline=None)
@given(st.lists(request, min_size=1, max_size=8), st.sampled_from([20.0, 30.0, 60.0]))
def test_states_stay_consistent(reqs, hz: float) -> None:
    m = SoldierManager(LIB, throttle=THROTTLE, tick_period=1 / hz, record_clips=True)
    for _ in range(3):
        m.create_soldier()
    last_sent = np.full(4, -np.inf)
    now = 0.0
    tick = 0
    for idx, app, wpn, speed, heading, back, imm, wait in reqs:
        h = np.radians(heading)
        s = -speed if back else speed
        rows = make_entity_requests(
            idx, app, wpn, (s * np.sin(h), s * np.cos(h), 0.0), heading, (0, 0, 0), imm == 0
        )
        assert m.apply_requests(rows, now).tolist() == [0 if idx < 3 else 1]
        a = m.answer(now, max(now, tick / hz))  # between ticks: the next tick's update, early
        assert np.isfinite(a.joints).all() and np.isfinite(a.figures).all()
        end = now + wait
        while tick / hz <= end:
            now = tick / hz
            u = m.tick(now)
            assert np.isfinite(u.joints).all() and np.isfinite(u.figures).all()
            np.testing.assert_allclose(np.linalg.norm(u.figures[..., 3:], axis=-1), 1.0, atol=1e-4)
            assert (now - last_sent[u.indices] >= THROTTLE - 0.5 / hz - 1e-9).all()  # rate cap on the grid
            last_sent[u.indices] = now
            tick += 1
        now = end
        tb = m.table
        for i in range(3):
            mode = Mode(int(tb.mode[i]))
            posture = LIB.postures[int(tb.node[i])]
            if mode == Mode.LOCO:
                assert posture == STAND_STOWED
            elif mode == Mode.CRAWL:
                assert posture == CRAWL_NODE
            assert (mode == Mode.TRANSITION) == (i in m._paths)
            if mode != Mode.IDLE:
                assert tb.end[i] > tb.clock[i] - 1e-9  # every ended clip was handled
    for i in range(3):
        times = [c.time for c in m.clips_of(i)]
        assert times == sorted(times)
