"""Start-up: one server's simulation, composed from its parts (seed 002, 3.6).

:class:`ServerWorld` composes what ``jack-ttes-soldier_low.jcl`` builds, one part per concern:

* :class:`~server.world.store.MotionStore` — the environment, channelsets, posture graphs and what is bound;
* :mod:`server.world.library` — the motion library, built (as in 1994) by the first ``create_soldier_state``;
* :class:`~server.world.soldiers.Soldiers` — the soldier manager, its one settings value, the wire tables;
* :class:`~server.world.commands.JclCommands` — the JCL commands, registered with the whitelist interpreter;

plus the "ready" flag ``start_ttes_socket_simulation()`` raises. The trio layer (:mod:`server.app`)
subscribes to its events (ready, soldier created/removed, reports to the client that asked).

JCL arrives from the start-up script and from clients, so everything goes through :mod:`server.jcl`, whose
search path (the data dir, then ``figures/``, ``channelsets/``, ``posture_graphs/``) never leaves the data
directory. Re-running the start-up script (a 1994 client always sends
``read_file("jack-ttes-soldier_low.jcl")``) is harmless: a file is read once and ``create_soldier_state`` of
an existing soldier with the same figures does nothing.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from peabody.model import Environment, Figure
from protocol.events import DEFAULT_MAX_SOLDIERS
from protocol.update_table import UpdateTable
from server.data_root import SEARCH_SUBDIRS
from server.jcl import JclError, JclInterpreter
from server.logging import get_logger
from server.motion.binding import protofiletype
from server.motion.channelset import Channelset
from server.motion.posture_change import LoadedPostureGraph
from server.soldier.library import MotionLibrary
from server.soldier.manager import REQUEST_OK, SoldierManager
from server.soldier.settings import SoldierSettings
from server.world.access import caller_of
from server.world.commands import JclCommands
from server.world.library import build_library
from server.world.owners import Owners
from server.world.soldiers import FigureSet, Soldiers
from server.world.store import MotionStore
from server.world.synthetic import SyntheticDataDir, write_synthetic_data_dir

__all__ = ["FigureSet", "ServerWorld", "SyntheticDataDir", "WorldEvents", "write_synthetic_data_dir"]

DEFAULT_REPORT_INTERVAL = 30.0
log = get_logger("startup")


@dataclass
class WorldEvents:
    """Callbacks the trio layer installs (all optional; called synchronously)."""

    ready: Callable[[object | None], None] = lambda caller: None
    soldier_created: Callable[[int], None] = lambda index: None
    soldier_removed: Callable[[int, str], None] = lambda index, reason: None
    report: Callable[[object | None, str], None] = lambda caller, text: None


class Relay(Protocol):
    """Where a front-end (``ttes front``, :mod:`server.fabric`) sends what its clients ask of soldiers that
    shards animate. The front's own manager keeps the books (which soldiers live, their tables and owners,
    the requests' checks); it is never ticked."""

    def allot(self, index: int | None) -> int | None:
        """The index a new soldier takes (None: the table's lowest free one): with several front-ends each
        allots from its own share of the index space; ValueError for an index another front-end allots."""
        ...

    def created(self, index: int, figure: str, weapon: str, owner: str | None) -> None: ...

    def removed(self, index: int) -> None: ...

    def requests(self, rows: np.ndarray) -> None: ...

    def react(self, index: int, kind: str) -> None: ...

    def orphans(self, indices: list[int]) -> list[int]:
        """Of a gone client id's soldiers, those this front-end removes (of several, each removes those of
        its share, and tells the others: two removing one soldier could remove a soldier created again)."""
        ...


class ServerWorld:
    """The server's one simulation: its parts, readiness, and the JCL that drives them."""

    def __init__(
        self,
        data_dir: str | Path,
        *,
        max_soldiers: int = DEFAULT_MAX_SOLDIERS,
        max_soldiers_per_client: int = 4096,
        clock: Callable[[], float] = lambda: 0.0,
        record_clips: bool = False,
        library: MotionLibrary | None = None,
        cache_dir: str | Path | None = None,
    ) -> None:
        self.data_dir = Path(data_dir).resolve()
        self.clock = clock
        self.events = WorldEvents()
        self.jcl = JclInterpreter(self.data_dir, SEARCH_SUBDIRS)
        self.store = MotionStore(cache_dir=Path(cache_dir) if cache_dir is not None else None)
        self.soldiers = Soldiers(max_soldiers, SoldierSettings(record_clips=record_clips))
        self.soldiers.resolve = self.jcl.resolve_path  # FIGURE with meshes reads the figure's surfaces
        self.owners = Owners(max_soldiers, max_soldiers_per_client)
        self.startup_script: Path | None = None  # the script run_startup ran
        self.commands = JclCommands(self)
        self.commands.register(self.jcl)
        self.ready = False
        self.graphics = True
        self.report_interval = DEFAULT_REPORT_INTERVAL
        self.caller: object | None = None  # who runs the JCL now (a session; None: the server itself)
        # how a JCL command that touches soldiers, settings or clients runs: directly, or (JCL run by the trio
        # app in a worker thread) on the trio loop, so that only file loads run beside the tick
        self.in_loop: Callable[[Callable[[], object]], object] = lambda func: func()
        self.relay: Relay | None = None  # a front-end's: soldiers live in shards (server.fabric)
        if library is not None:
            self.soldiers.adopt(library)

    # -- running JCL -------------------------------------------------------------------------------------
    def run_jcl(self, text: str, caller: object | None = None, filename: str = "<jcl>") -> None:
        """Run JCL text on behalf of ``caller`` (a session, or None for the server itself); JclError."""
        prev, self.caller = self.caller, caller
        try:
            self.jcl.run_text(text, filename)
        finally:
            self.caller = prev

    def run_startup(self, script: str) -> None:
        """``read_file(script)``: the start-up sequence of seed 3.6."""
        path = self.jcl.resolve_path(script)
        if not path.is_file():
            raise JclError(f"start-up script {script!r} not found in {self.data_dir} (or its search path)")
        self.run_jcl(f"read_file({json.dumps(script)});", None, "<startup>")
        self.startup_script = path

    def is_startup_script(self, name: str) -> bool:
        """Whether ``name`` is the start-up script the server has already run."""
        return self.startup_script is not None and self.jcl.resolve_path(name) == self.startup_script

    # -- the core operations the JCL commands and the sessions share --------------------------------------
    def ensure_library(self, wanted: tuple[Figure, Figure | None] | None = None) -> MotionLibrary:
        """The motion library, built from the loaded and bound posture graphs the first time (seed 3.6)."""
        if self.soldiers.library is None:
            self.soldiers.adopt(build_library(self.store, self.jcl.resolve_path, wanted))
        assert self.soldiers.library is not None
        return self.soldiers.library

    def create_soldier(
        self,
        figure: str,
        weapon: str,
        index: int | None = None,
        name: str | None = None,
        owner: str | None = None,
        *,
        relay: bool = True,
    ) -> int:
        """A new soldier of figure/weapon *types* (``"DI.fig"``, ``"AK_47.fig"``) owned by client ``owner``
        (None: shared); ValueError (the owner's cap, no free index)/KeyError. ``relay=False``: a front-end
        keeps in its books a soldier that a shard or another front-end already has (not relayed)."""
        self.owners.check_cap(owner)
        self.ensure_library()
        relayed = self.relay if relay else None
        if relayed is not None:
            index = relayed.allot(index)
        i = self.soldiers.create(figure, weapon, index, name, self.clock())
        self.owners.add(i, owner)
        if relayed is not None:
            relayed.created(i, figure, weapon, owner)
        self.events.soldier_created(i)
        return i

    def create_soldier_state(self, name: str, figure: str, weapon: str = "") -> None:
        """``create_soldier_state(name, figure[, weapon])`` from environment figures; idempotent."""
        fig, *rest = self.store.figures([figure] + ([weapon] if weapon else []))
        gun = rest[0] if rest else None
        ftype, wtype = protofiletype(fig), protofiletype(gun) if gun is not None else ""
        m = self.soldiers.manager
        if m is not None and name in m.names.values():
            have = m.library.set_keys[int(m.table.fset[m.index_of(name)])]
            if have[0] == ftype and wtype in ("", have[1]):
                return  # the start-up script run again
            raise JclError(f"create_soldier_state: soldier {name!r} exists with figures {have}")
        self.ensure_library((fig, gun))
        who = caller_of(
            self.caller
        )  # an operator's are shared, as the start-up script's; a controller's its own
        owner = who.client_id if who is not None and who.role != "operator" else None
        i = self.create_soldier(ftype, wtype, None, name, owner)
        self.soldiers.figures_of[name] = (figure, weapon) if weapon else (figure,)
        log.info("soldier_state_created", soldier=name, index=i, figure=figure, weapon=weapon)

    def remove_soldier(self, index: int, reason: str = "removed", *, relay: bool = True) -> None:
        self.soldiers.remove(index)
        self.events.soldier_removed(index, reason)  # before the owner is forgotten: who could see it
        self.owners.discard(index)
        if relay and self.relay is not None:
            self.relay.removed(index)

    def apply_requests(self, rows: np.ndarray) -> np.ndarray:
        """Entity requests (``SoldierManager.apply_requests``: its per-row status). A front-end only checks
        them (``check_requests``) and sends the rows taken to the shards, which animate the soldiers."""
        m = self.manager
        assert m is not None
        if self.relay is None:
            return m.apply_requests(rows, self.clock())
        status = m.check_requests(rows)
        ok = status == REQUEST_OK
        self.relay.requests(rows if ok.all() else rows[ok])
        return status

    def react(self, index: int, kind: str) -> None:
        """A reaction (``SoldierManager.react``); a front-end only sends it to the shard that animates the
        soldier (KeyError for an unknown one, as the manager's)."""
        m = self.manager
        assert m is not None
        if self.relay is None:
            m.react(index, kind, self.clock())
            return
        if not m.table.is_live(index):
            raise KeyError(f"no soldier {index}")
        self.relay.react(index, kind)

    def start(self) -> None:
        """``start_ttes_socket_simulation()``: the "I'm ready!" message (READY) — the library must exist."""
        self.ensure_library()
        if not self.ready:
            self.ready = True
            log.info("simulation_ready", soldiers=self.manager.count if self.manager else 0)
        self.events.ready(self.caller)

    def set_throttle(self, seconds: float) -> None:
        self.soldiers.configure(throttle=seconds)

    def set_report_interval(self, seconds: float) -> None:
        """``set_ttes_report_interval``: the STATUS period."""
        if not (math.isfinite(seconds) and seconds > 0):
            raise ValueError(f"{seconds} is not a positive number of seconds")
        self.report_interval = float(seconds)

    def soldier_report(self, names: Sequence[str] = ()) -> dict[str, Any]:
        return self.soldiers.report(
            self.clock, self.ready, [self.soldiers.index_of(n) for n in names] or None
        )

    # -- views of the parts (what the trio layer and the tests read) -------------------------------------
    @property
    def manager(self) -> SoldierManager | None:
        return self.soldiers.manager

    @property
    def library(self) -> MotionLibrary | None:
        return self.soldiers.library

    @property
    def settings(self) -> SoldierSettings:
        return self.soldiers.settings

    @property
    def sets(self) -> list[FigureSet]:
        return self.soldiers.sets

    @property
    def tables(self) -> list[UpdateTable]:
        return self.soldiers.tables

    def table_of(self, index: int) -> int:
        return self.soldiers.table_of(index)

    @property
    def environment(self) -> Environment:
        return self.store.environment

    @property
    def channelsets(self) -> dict[str, Channelset]:
        return self.store.channelsets

    @property
    def graphs(self) -> dict[str, LoadedPostureGraph]:
        return self.store.graphs
