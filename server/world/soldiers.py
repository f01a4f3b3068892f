"""The soldiers of one server: the motion library, the soldier manager, its settings, one wire table per set.

Settings are one frozen :class:`~server.soldier.settings.SoldierSettings`. Before the library exists (a
script may set the throttle before the first ``create_soldier_state``) they wait here; from then on the
manager owns them. Either way :meth:`Soldiers.configure` replaces the whole value with a validated copy, in
this one place.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import msgpack

from peabody.language import PeabodyError
from peabody.loader import read_figure
from protocol.events import FigureMsg
from protocol.figure import figure_from_wire, figure_to_wire
from protocol.update_table import FigureEntry, UpdateTable
from server.logging import get_logger
from server.soldier.library import MotionLibrary
from server.soldier.manager import SoldierManager
from server.soldier.settings import SoldierSettings
from server.soldier.wire import WireConverter, update_table_for

log = get_logger("soldiers")


@dataclass
class FigureSet:
    """One (soldier figure type, weapon type) pair the library plays, with its wire table and converter."""

    index: int
    figure: str
    weapon: str
    table: UpdateTable
    converter: WireConverter


class Soldiers:
    """Soldier states over the motion library; figure names per soldier for the JCL debugging commands."""

    def __init__(self, max_soldiers: int, settings: SoldierSettings | None = None) -> None:
        self.max_soldiers = max_soldiers
        self.library: MotionLibrary | None = None
        self.manager: SoldierManager | None = None
        self.sets: list[FigureSet] = []
        self.figures_of: dict[str, tuple[str, ...]] = {}  # soldier name -> environment figure names
        self._figure_msgs: dict[tuple[int, bool], FigureMsg] = {}  # (table id, meshes) -> FIGURE, built once
        self._pending = settings or SoldierSettings()
        self.resolve: Callable[[str], Path] = Path  # a figure file name -> its path (the world's search path)

    # -- settings ----------------------------------------------------------------------------------------
    @property
    def settings(self) -> SoldierSettings:
        return self.manager.settings if self.manager is not None else self._pending

    def configure(self, **changes: Any) -> SoldierSettings:
        """Replace the settings with a validated copy (ValueError names the setting; nothing changes)."""
        if self.manager is not None:
            return self.manager.configure(**changes)
        self._pending = self._pending.replace(**changes)
        return self._pending

    # -- the library -------------------------------------------------------------------------------------
    def adopt(self, library: MotionLibrary) -> None:
        self.library = library
        self.sets = []
        self._figure_msgs = {}
        for k, (fig, wpn) in enumerate(library.set_keys):
            table = update_table_for(library, k + 1, k)
            self.sets.append(FigureSet(k, fig, wpn, table, WireConverter(library, table, k)))
        self.manager = SoldierManager(library, self._pending, max_soldiers=self.max_soldiers)
        log.info(
            "motion_library_bound",
            clips=library.nclips,
            figure_sets=[list(k) for k in library.set_keys],
            walk=library.can_walk,
            run=library.can_run,
            crawl=library.can_crawl,
        )

    @property
    def tables(self) -> list[UpdateTable]:
        return [s.table for s in self.sets]

    def table_of(self, index: int) -> int:
        """The update table id of a live soldier."""
        assert self.manager is not None
        return self.sets[int(self.manager.table.fset[index])].table.table_id

    def figure_message(self, table_id: int, meshes: bool) -> FigureMsg | None:
        """The FIGURE answering REQUEST_FIGURE for ``table_id`` (None: no such table), built once."""
        key = (table_id, meshes)
        if key not in self._figure_msgs:
            fset = next((s for s in self.sets if s.table.table_id == table_id), None)
            if fset is None or self.library is None:
                return None
            names = [e.name for e in fset.table.entries if isinstance(e, FigureEntry)]
            figures = self.library.sets[fset.index].prototypes
            if meshes:
                figures = [_with_surfaces(f, self.resolve) for f in figures]
            body = figure_to_wire(fset.table, figures, names, meshes=meshes)
            # decoded from its own f32 bytes, so the event holds what a client will hold
            raw = msgpack.unpackb(msgpack.packb(body, use_single_float=True))
            self._figure_msgs[key] = FigureMsg(table_id, figure_from_wire(raw)[1], body)
        return self._figure_msgs[key]

    # -- soldier states ----------------------------------------------------------------------------------
    def create(self, figure: str, weapon: str, index: int | None, name: str | None, now: float) -> int:
        """A new soldier of figure/weapon *types* (``"DI.fig"``); ValueError/KeyError."""
        assert self.manager is not None, "adopt a library first"
        return self.manager.create_soldier(name, figure, weapon, index, now=now)

    def remove(self, index: int) -> None:
        if self.manager is None or not self.manager.table.is_live(index):
            raise KeyError(f"no soldier {index}")
        self.figures_of.pop(self.manager.names.get(index, ""), None)
        self.manager.remove_soldier(index)

    def index_of(self, name: str) -> int:
        if self.manager is None or name not in self.manager.names.values():
            raise KeyError(f"no soldier {name!r}")
        return self.manager.index_of(name)

    def soldier_with(self, figures: Sequence[str]) -> int:
        """The soldier created from one of ``figures`` (``create_soldier_state``): who a bound channelset
        or bound posture graph drives here."""
        for name, figs in self.figures_of.items():
            if set(figs) & set(figures):
                return self.index_of(name)
        raise KeyError(f"no soldier state uses figure(s) {sorted(figures)}; create_soldier_state first")

    def report(
        self, clock: Callable[[], float], ready: bool, indices: Sequence[int] | None = None
    ) -> dict[str, Any]:
        """The states of these soldiers (None: the first 100 live ones)."""
        m = self.manager
        if m is None:
            return {"ready": ready, "soldiers": []}
        idx = [int(i) for i in m.table.live[:100]] if indices is None else list(indices)
        return {"ready": ready, "time": clock(), "soldiers": [m.soldier_info(i) for i in idx]}


def _with_surfaces(figure: Any, resolve: Callable[[str], Path]) -> Any:
    """The figure with its psurfs: the server loads figures without them (it never draws), so a FIGURE with
    meshes (docs/PROTOCOL.md §7.2, asked for by a drawing client such as ``ttes web``) reads the figure's file
    again, once per table; a figure whose file cannot be read again goes without surfaces."""
    if not figure.filename:
        return figure
    try:
        return read_figure(resolve(figure.filename), figure.name, load_psurfs=True)
    except (PeabodyError, OSError) as exc:
        log.warning("figure_surfaces_unreadable", figure=figure.name, error=str(exc))
        return figure
