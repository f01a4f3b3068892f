"""A soldier asked for another posture while a posture change's path plays goes on from the posture it reaches
(issue 16): asked to crawl while he went down from standing to prone (through CRAWL: ``ststow2crawl`` then
``crawl2prstow``), he lay down and came up again before he crawled, 3.2 s; now he crawls from CRAWL."""

from __future__ import annotations

import math

import numpy as np
import pytest
import trio

from protocol.entity import Appearance, WeaponState, make_entity_requests
from server.soldier.manager import REQUEST_OK, SoldierManager
from tests.test_gait_selection import shipped_library
from tests.test_prone_turn import served

HZ = 60.0


@pytest.fixture(scope="module")
def lib():
    return shipped_library()


def shown(lib, script: list[tuple[float, Appearance, float]], until: float) -> list[tuple[float, str]]:
    """Play ``(time, posture, speed m/s along 40°)`` requests to a standing DI soldier; the clips shown, each
    with the time it began."""
    m = SoldierManager(lib, throttle=0.0, record_clips=True)
    i = m.create_soldier(figure="DI.fig", weapon="AK_47.fig", now=0.0)
    out: list[tuple[float, str]] = []
    pos, vel, last = np.zeros(2), np.zeros(2), 0.0
    pending = list(script)
    for k in range(int(until * HZ) + 1):
        now = k / HZ
        pos, last = pos + vel * (now - last), now
        while pending and pending[0][0] <= now + 1e-9:
            _, app, v = pending.pop(0)
            vel = v * np.array([math.sin(math.radians(40.0)), math.cos(math.radians(40.0))])
            rows = make_entity_requests(i, app, WeaponState.DEPLOYED, (*vel, 0.0), 40.0, (*pos, 0.0))
            assert m.apply_requests(rows, now).tolist() == [REQUEST_OK]
        m.tick(now)
        clip = lib.clip_names[int(m.snapshot([i]).clips[0])].split("/")[-1]
        if not out or out[-1][1] != clip:
            out.append((now, clip))
    return out


def test_asked_to_crawl_on_his_way_down_to_prone_he_crawls_from_crawl(lib) -> None:
    """PRONE at 0.5 s, CRAWL at 0.3 m/s at 1 s (``ststow2crawl`` plays until 2.47 s): he crawls once he is
    on forearms and knees, without lying down first (before: ``crawl2prstow`` down and up, crawling at 5.67
    s)."""
    clips = shown(
        lib, [(0.0, Appearance.UPRIGHT, 0.0), (0.5, Appearance.PRONE, 0.0), (1.0, Appearance.CRAWL, 0.3)], 6.0
    )
    names = [c for _, c in clips]
    assert "crawl2prstow_low" not in names, clips
    start = next(t for t, c in clips if c == "crawl_start_low")
    down = next(t for t, c in clips if c == "ststow2crawl_low")
    assert start - down < 2.1, clips  # ststow2crawl's own 1.97 s


async def test_over_the_wire_asked_to_crawl_on_his_way_down_he_crawls_from_crawl(
    autojump_clock: trio.abc.Clock,
) -> None:
    """The same through a served world (real TCP, trio's autojump clock)."""
    ahead = 0.3 * np.array([math.sin(math.radians(40.0)), math.cos(math.radians(40.0)), 0.0])
    async with served() as (_, world, c):
        await c.requests(index=0, appearance=Appearance.PRONE, heading=40.0)
        await c.drain(0.5)
        await c.requests(index=0, appearance=Appearance.CRAWL, heading=40.0, velocity=tuple(ahead))
        await c.drain(3.0)
        log = [s.clip.split("/")[-1] for s in world.manager.clip_log if s.index == 0]
        assert "crawl2prstow_low" not in log and "crawl_cycle_low" in log, log
