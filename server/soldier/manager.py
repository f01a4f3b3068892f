"""The soldier manager (seed 002, Figure 12) over a struct-of-arrays soldier table.

Figure 12 runs "every iteration, for each soldier". Here the per-soldier Python runs only on *events* — a
request that changes what a soldier does, or a clip that ends a posture-change arc or the locomotion — and
:meth:`SoldierManager.tick` is vectorised: it advances every soldier's clock, handles the clip ends (the
Figure 5 table for all walking/crawling soldiers at once, Python only for finished posture-change arcs), then
samples every soldier that is due for an update in one :meth:`ClipLibrary.sample` call per figure set.

Figure 12, and where each line lives:

=============================================  ============================================================
new packet: copy, convert TTES → Jack          ``requests``: :meth:`apply_requests` (vectorised)
compute velocity / heading                     ``requests``: :meth:`apply_requests` (speed, direction)
transitioning: grab heading, continue          requests only stored; the path's arcs chain in ``tick``;
                                               a changed posture is taken up when the path ends
posture or weapon different: cancel the step,  ``events``: :meth:`_start_changes`, step cancelled (faded),
start a posture change                         quickest path to the goal posture (:meth:`MotionLibrary.path`)
moving and PRONE: continue crawling            ``Mode.CRAWL``: ``stepping``, :mod:`.locomotion`
moving and STANDING: walk or run               ``Mode.LOCO``: ``stepping``, :mod:`.locomotion`
only the heading changed: resend last update   ``ticking``: ``TickUpdate.heading_only``
=============================================  ============================================================

The class is assembled from mixins, one module of ``server/soldier/`` each, so every path reads on its own:
``core`` (table, settings, lookups, starting a clip or a rest), ``stepping`` (Figure 5's pacing), ``turning``
(turns in place), ``events`` (the per-soldier event path and clip ends), ``ticking`` (tick, the between-tick
answer, snapshots, poses), ``requests`` (entity requests, reactions and the JCL debugging commands),
``reactions`` (the reaction path: play now or when the soldier comes to rest).

Times: every method takes ``now`` (seconds, non-decreasing) — the manager reads no clock. Clip changes chain
at the exact end time of the previous clip, not at the tick that notices it, so nothing drifts with the tick
rate. Settings are one frozen :class:`~server.soldier.settings.SoldierSettings`, replaced whole by
:meth:`SoldierManager.configure`; ``every_frame`` (``set_channelset_parameters("yes")``) replaces real time by
one stored frame per tick.
"""

from __future__ import annotations

from typing import Any

from protocol.entity import Appearance, WeaponState
from server.soldier import report
from server.soldier.core import (
    MAX_RATE,
    MIN_RATE,
    REQUEST_BAD_VALUE,
    REQUEST_OK,
    REQUEST_UNKNOWN_SOLDIER,
    WALK_MAX_RATE,
    ClipStart,
    TickUpdate,
)
from server.soldier.library import PathStep
from server.soldier.requests import Requests

__all__ = [
    "MAX_RATE",
    "MIN_RATE",
    "REQUEST_BAD_VALUE",
    "REQUEST_OK",
    "REQUEST_UNKNOWN_SOLDIER",
    "WALK_MAX_RATE",
    "ClipStart",
    "SoldierManager",
    "TickUpdate",
]


class SoldierManager(Requests):
    """All soldier states of one server: requests in, vectorised ticks out."""

    def create_soldier(
        self,
        name: str | None = None,
        figure: str = "DI.fig",
        weapon: str = "AK_47.fig",
        index: int | None = None,
        now: float = 0.0,
    ) -> int:
        """A new soldier state resting in STAND_STOWED; returns its index. ValueError if impossible."""
        if name is not None and name in self._by_name:
            raise ValueError(f"soldier name {name!r} is in use")
        try:
            fset = self.library.set_index(figure, weapon)
        except KeyError as exc:
            raise ValueError(str(exc.args[0])) from None
        i = self.table.allocate(index)
        t = self.table
        t.fset[i] = fset
        t.clock[i] = now
        t.created[i] = now
        t.appearance[i] = Appearance.UPRIGHT
        t.weapon[i] = WeaponState.DEPLOYED
        t.foot[i] = 1
        t.root_t[i] = now
        self._rest(i, self._home, float(now))
        nm = name if name is not None else f"s{i}"
        if nm in self._by_name:  # a generated name clashing with a user's: make it unique
            nm = f"{nm}#{i}"
        self.names[i] = nm
        self._by_name[nm] = i
        return i

    def remove_soldier(self, index: int) -> None:
        """Forget a soldier (KeyError if there is none); its index is reused by later creates."""
        self.table.free(index)
        self._paths.pop(index, None)
        self._pending.pop(index, None)
        nm = self.names.pop(index, None)
        if nm is not None:
            self._by_name.pop(nm, None)

    def index_of(self, name: str) -> int:
        return self._by_name[name]

    @property
    def count(self) -> int:
        return self.table.count

    def clips_of(self, index: int) -> list[ClipStart]:
        """The recorded clip starts of one soldier (``record_clips=True``), oldest first."""
        return [c for c in self.clip_log if c.index == index]

    def path_steps(self, index: int) -> tuple[PathStep, ...]:
        """The posture-change path a soldier is playing (empty unless in TRANSITION)."""
        entry = self._paths.get(index)
        return tuple(entry[0]) if entry is not None else ()

    def goal_node(self, index: int) -> int:
        """The posture node the soldier's last request asks for (-1: none in this graph)."""
        return self._desired(index)

    def soldier_info(self, index: int) -> dict[str, Any]:
        """One soldier's state, for status reports and tests (:func:`server.soldier.report.soldier_info`)."""
        return report.soldier_info(self, index)

    def status(self) -> dict[str, Any]:
        """The periodic status report (:func:`server.soldier.report.status`)."""
        return report.status(self)
