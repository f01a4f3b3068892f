"""One DI soldier of a SoldierManager driven by a script of DIS-like requests at a fixed update rate, with
``now`` passed in (no clock): the scenario tests of re-planning and pivots share it."""

from __future__ import annotations

import math
from collections.abc import Iterator

import numpy as np

from protocol.entity import Appearance, WeaponState, make_entity_requests
from server.soldier.manager import REQUEST_OK, SoldierManager

Script = list[tuple[float, Appearance, float, float]]  # (time, posture, speed m/s, compass heading)


Tick = tuple[float, SoldierManager, int, np.ndarray, float]


def driven(lib, script: Script, until: float, hz: float) -> Iterator[Tick]:
    """Play ``script`` to a standing DI soldier (index ``i``), his entity moving at the asked velocity, and
    tick the manager ``hz`` times a second up to ``until``: yields ``(now, manager, i, entity position (2,),
    entity heading)`` after each tick."""
    m = SoldierManager(lib, throttle=0.0, record_clips=True)
    i = m.create_soldier(figure="DI.fig", weapon="AK_47.fig", now=0.0)
    pos, vel, hd, pending = np.zeros(2), np.zeros(2), 0.0, sorted(script, key=lambda s: s[0])
    for k in range(int(until * hz) + 1):
        now = k / hz
        pos = pos + vel / hz if k else pos
        while pending and pending[0][0] <= now + 1e-9:
            _, app, v, hd = pending.pop(0)
            vel = v * np.array([math.sin(math.radians(hd)), math.cos(math.radians(hd))])
            rows = make_entity_requests(i, app, WeaponState.DEPLOYED, (*vel, 0.0), hd, (*pos, 0.0))
            assert m.apply_requests(rows, now).tolist() == [REQUEST_OK]
        m.tick(now)
        yield now, m, i, pos.copy(), hd
