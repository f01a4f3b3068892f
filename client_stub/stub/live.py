"""The stub's own soldiers (seed 002, 4.1–4.2): SimSoldier behaviours and the keys move them; with a server
each is bound to a server soldier (Figures 9 and 10) and its changed requests go out once a frame.

Binding: a slot takes a free soldier of those the start-up JCL made (READY), else one CREATE_SOLDIER made
for it (an AK-47 soldier when the server has no motion for the slot's rifle). The joint updates of bound
slots pose them (:meth:`StubApp.frame`); slots without a server soldier are posed offline.

A lost server (:meth:`StubApp.lose_server`, seen within one frame) is tried again with ``reconnect`` after
backoff delays counted in stub time (0.5, 1, 2, 4, 8 s, then every 8 s); once it answers, every slot is bound
again. After ``give_up_after`` seconds without one, ``app.gave_up`` says so (``ttes stub`` exits 3).
"""

from __future__ import annotations

import contextlib
import logging
from collections.abc import Callable, Sequence

import numpy as np

from client_stub.link.client import LinkError
from client_stub.link.retry import BACKOFF, RetrySchedule
from client_stub.stub.app import DEFAULT_FIGURE, WEAPONS, StubApp
from client_stub.stub.jack import JackProc, JackSoldier
from client_stub.stub.simsoldier import Behaviour, Force
from protocol.entity import Appearance, WeaponState

log = logging.getLogger("ttes.stub")


class LiveSoldiers:
    """A :class:`~client_stub.stub.app.SoldierSource`: SimSoldiers and keys, optionally on a server."""

    def __init__(
        self,
        reconnect: Callable[[], JackProc] | None = None,
        *,
        give_up_after: float = 120.0,
        ready_timeout: float = 30.0,
        backoff: Sequence[float] = BACKOFF,
    ) -> None:
        self.jack: JackProc | None = None
        self.reconnect = reconnect  # a new connected JackProc (LinkError when no server answers)
        self.ready_timeout = ready_timeout
        self.retry = RetrySchedule(backoff, give_up_after)  # in stub time

    @property
    def give_up_after(self) -> float:
        return self.retry.give_up_after

    @give_up_after.setter
    def give_up_after(self, seconds: float) -> None:
        self.retry.give_up_after = seconds

    @property
    def link(self) -> JackProc | None:
        return self.jack

    def connect(
        self, app: StubApp, jack: JackProc, ready_timeout: float = 30.0, soldierprefix: str = "soldier_low"
    ) -> bool:
        """Start Jack (the start-up JCL), wait for READY, bind every slot to a server soldier, subscribe."""
        self.jack = jack
        jack.start(soldierprefix)
        if not jack.wait_ready(ready_timeout):
            log.warning(
                "server not ready after %.0f s: soldiers stay offline (%s)", ready_timeout, jack.failure
            )
            return False
        for slot in range(app.soldiers.count):
            self._bind(app, slot)
        return True

    def added(self, app: StubApp, slot: int) -> None:
        if self.jack is not None and self.jack.jackready:
            self._bind(app, slot)

    def _bind(self, app: StubApp, slot: int) -> None:
        """Give ``slot`` a server soldier: a free one from READY, else CREATE_SOLDIER."""
        jack = self.jack
        if jack is None or app.server_of[slot] >= 0:
            return
        weapon = WEAPONS[Force(int(app.soldiers.force[slot]))]
        free = sorted(set(jack.ready_soldiers) - set(app.slot_of_server))
        try:
            js = self._soldier(jack, free, weapon)
        except LinkError as exc:
            log.warning("soldier %d stays offline: %s", slot, exc)
            return
        wire = jack.tables.get(js.updatetable)
        if wire is None:
            log.warning("soldier %d: update table %d unknown; offline", slot, js.updatetable)
            return
        kind = app.kind(wire.figure, wire.weapon)
        app.binding(kind, wire)
        app.set_kind(slot, kind)
        app.map_server(slot, js.soldiernum)
        app.soldiers.dirty[slot] = True
        jack.subscribe([js.soldiernum])

    @staticmethod
    def _soldier(jack: JackProc, free: list[int], weapon: str) -> JackSoldier:
        if free:
            return jack.soldier(free[0], jack.ready_soldiers[free[0]])
        try:
            return jack.new_soldier(DEFAULT_FIGURE, weapon, timeout=5.0)
        except LinkError:
            return jack.new_soldier(DEFAULT_FIGURE, "AK_47.fig", timeout=5.0)

    def step(self, app: StubApp, dt: float) -> None:
        """Behaviours and dead reckoning; the changed requests of bound slots go to the server."""
        s = app.soldiers
        s.step(dt)
        app.grow()
        requests = s.requests()
        jack = self.jack
        if jack is not None and jack.connected:
            out = requests[app.server_of[requests["index"]] >= 0]
            out["index"] = app.server_of[out["index"]]
            jack.send_requests(out)
        elif jack is None and app.server_lost and self.reconnect is not None and not app.gave_up:
            self._try_again(app)

    def _try_again(self, app: StubApp) -> None:
        """One reconnection attempt when the backoff says so; give up after ``give_up_after``."""
        assert self.reconnect is not None
        jack = self.retry.attempt(app.time, self.reconnect, app.server_lost)
        app.gave_up = self.retry.gave_up
        if jack is None:
            return
        if self.connect(app, jack, self.ready_timeout):
            self.retry.reset()
            app.regain_server()
        else:
            self.lose_server()

    def refuse_key(self, key: str) -> str | None:
        return None

    def camera_pose(self, app: StubApp) -> np.ndarray | None:
        return None

    def lose_server(self) -> None:
        if self.jack is not None:
            with contextlib.suppress(LinkError):
                self.jack.quit()
        self.jack = None

    def close(self) -> None:
        if self.jack is not None:
            self.jack.quit()
            self.jack = None


def populate_demo(app: StubApp) -> None:
    """The seed's start (4.1): soldier 0 standing in the middle of the village, soldier 1 walking a square,
    soldier 2 a circle; then friendly soldiers kneeling and prone, and an opposing group (Figure 8)."""
    t = app.terrain
    centre = t.landmark("centre")
    square = t.landmarks["square"]
    circle = t.landmarks["circle"]
    groups = t.landmarks["groups"]
    fr, op = np.asarray(groups["friendly"]), np.asarray(groups["opposing"])
    app.add_soldier(centre, 0.0)
    app.add_soldier(square["centre"], 0.0, speed=1.3, behaviour=Behaviour.SQUARE, size=square["side"])
    app.add_soldier(circle["centre"], 90.0, speed=1.2, behaviour=Behaviour.CIRCLE, size=circle["radius"])
    app.add_soldier(fr + np.array([-3.0, 0.0]), 20.0, appearance=Appearance.KNEEL, weapon=WeaponState.FIRING)
    app.add_soldier(fr + np.array([3.0, -2.0]), 10.0, appearance=Appearance.PRONE, weapon=WeaponState.FIRING)
    opposing = dict(force=Force.OPPOSING)
    app.add_soldier(op + np.array([-4.0, 0.0]), 200.0, weapon=WeaponState.FIRING, **opposing)
    app.add_soldier(op + np.array([0.0, 2.0]), 180.0, appearance=Appearance.KNEEL, **opposing)
    app.add_soldier(op + np.array([4.0, 0.0]), 170.0, appearance=Appearance.PRONE, **opposing)
    app.add_soldier(
        op + np.array([0.0, -8.0]), 180.0, speed=3.6, behaviour=Behaviour.SQUARE, size=12.0, **opposing
    )
    app.add_soldier(op + np.array([7.0, -3.0]), 0.0, appearance=Appearance.DEAD, **opposing)
