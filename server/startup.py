"""Start-up: the seed's JCL commands (section 3.6) wired to the soldier manager and the motion library.

:class:`ServerWorld` owns what ``jack-ttes-soldier_low.jcl`` builds: the environment (figures read from
``.env`` files), the loaded channelsets and posture graphs, the :class:`~server.soldier.MotionLibrary` (built,
as in 1994, by the first ``create_soldier_state``), the :class:`~server.soldier.SoldierManager`, one update
table per figure set, and the "ready" flag ``start_ttes_socket_simulation()`` raises. The trio layer
(:mod:`server.app`) subscribes to its events (ready, soldier created/removed, status requests).

JCL arrives from the start-up script and from clients, so everything goes through the whitelist interpreter
of :mod:`server.jcl`; :class:`SearchPathInterpreter` adds the search path (the data dir, then ``figures/``,
``channelsets/``, ``posture_graphs/``) without leaving the data directory. Re-running the start-up script
(a 1994 client always sends ``read_file("jack-ttes-soldier_low.jcl")``) is harmless: an environment file is
read once and ``create_soldier_state`` of an existing soldier with the same figures does nothing.
"""

from __future__ import annotations

import io
import itertools
import json
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from peabody.model import Environment, Figure
from protocol.events import DEFAULT_MAX_SOLDIERS
from protocol.update_table import UpdateTable
from server.jcl import JclError, JclInterpreter
from server.logging import get_logger
from server.motion.binding import bind_channelset, protofiletype
from server.motion.cache import load_channelset
from server.motion.channelset import Channelset
from server.motion.errors import BindingError, ChannelsetError, PostureGraphError
from server.motion.posture_change import (
    BoundPostureGraph,
    LoadedPostureGraph,
    bind_posture_graph,
    load_posture_graph,
)
from server.soldier.library import MotionLibrary
from server.soldier.manager import SoldierManager
from server.soldier.wire import WireConverter, update_table_for

SEARCH_SUBDIRS = ("figures", "channelsets", "posture_graphs")
GRAPH_FILES = ("soldier_low.graph", "soldier_loco.graph", "soldier_crawl.graph")  # static, loco, crawl
DEFAULT_REPORT_INTERVAL = 30.0
log = get_logger("startup")


@dataclass
class WorldEvents:
    """Callbacks the trio layer installs (all optional; called synchronously)."""

    ready: Callable[[object | None], None] = lambda caller: None
    soldier_created: Callable[[int], None] = lambda index: None
    soldier_removed: Callable[[int], None] = lambda index: None
    report: Callable[[object | None, str], None] = lambda caller, text: None


@dataclass
class FigureSet:
    """One (soldier figure type, weapon type) pair the library plays, with its wire table and converter."""

    index: int
    figure: str
    weapon: str
    table: UpdateTable
    converter: WireConverter


@dataclass
class _Settings:
    throttle: float | None = None
    heading_offsets: tuple[float, float, float] | None = None
    every_frame: bool | None = None
    walk_run_threshold: float | None = None
    blend_time: float | None = None
    record_clips: bool = False


class ServerWorld:
    """The server's one simulation: JCL state, motion library, soldier manager, readiness."""

    def __init__(
        self,
        data_dir: str | Path,
        *,
        max_soldiers: int = DEFAULT_MAX_SOLDIERS,
        clock: Callable[[], float] = lambda: 0.0,
        record_clips: bool = False,
        library: MotionLibrary | None = None,
    ) -> None:
        self.data_dir = Path(data_dir).resolve()
        self.max_soldiers = max_soldiers
        self.clock = clock
        self.events = WorldEvents()
        self.jcl = JclInterpreter(self.data_dir, SEARCH_SUBDIRS)
        self.environment = Environment()
        self.env_files: set[Path] = set()
        self.channelsets: dict[str, Channelset] = {}
        self.bound_channelsets: dict[str, object] = {}
        self.graphs: dict[str, LoadedPostureGraph] = {}
        self._graph_paths: dict[str, Path] = {}
        self.bound_graphs: dict[str, BoundPostureGraph | str] = {}
        self.library: MotionLibrary | None = None
        self.manager: SoldierManager | None = None
        self.sets: list[FigureSet] = []
        self.ready = False
        self.graphics = True
        self.report_interval = DEFAULT_REPORT_INTERVAL
        self._settings = _Settings(record_clips=record_clips)
        self._caller: object | None = None
        self._register()
        if library is not None:
            self._adopt_library(library)

    # -- running JCL -------------------------------------------------------------------------------------
    def run_jcl(self, text: str, caller: object | None = None, filename: str = "<jcl>") -> None:
        """Run JCL text on behalf of ``caller`` (a session, or None for the server itself); JclError."""
        prev, self._caller = self._caller, caller
        try:
            self.jcl.run_text(text, filename)
        finally:
            self._caller = prev

    def run_startup(self, script: str) -> None:
        """``read_file(script)``: the start-up sequence of seed 3.6."""
        path = self.jcl.resolve_path(script)
        if not path.is_file():
            raise JclError(f"start-up script {script!r} not found in {self.data_dir} (or its search path)")
        self.run_jcl(f"read_file({json.dumps(script)});", None, "<startup>")

    def _register(self) -> None:
        r = self.jcl.register
        self.jcl.register_file_handler(".env", self._read_env)
        self.jcl.register_file_handler(".graph", lambda p: self._load_graph(p, None))
        self.jcl.register_file_handler(".chset", self._load_chset_file)
        r("load_channelset", self._cmd_load_channelset, (str, str), optional=1)
        r("bind_channelset", self._cmd_bind_channelset, (str, str), optional=1, variadic=str)
        r("load_posture_graph", self._cmd_load_posture_graph, (str, str), optional=1)
        r("bind_posture_graph", self._cmd_bind_posture_graph, (str, str), optional=1, variadic=str)
        r("print_channelset_info", self._cmd_print_channelset_info, (str, float), optional=2)
        r("create_soldier_state", self._cmd_create_soldier_state, (str, str, str), optional=1)
        r("remove_soldier_state", self._cmd_remove_soldier_state, (str,))
        r("set_channelset_parameters", self._cmd_set_channelset_parameters, (str,))
        r("set_ttes_report_interval", self._cmd_set_report_interval, (float,))
        r("set_ttes_heading_offset", self._cmd_set_heading_offset, (float, float, float))
        r("set_ttes_soldier_throttle", self._cmd_set_throttle, (float,))
        r("set_ttes_walk_run_threshold", self._cmd_set_walk_run_threshold, (float,))
        r("set_ttes_blend_time", self._cmd_set_blend_time, (float,))
        r("set_ttes_clip_recording", self._cmd_set_clip_recording, (str,))
        r("start_ttes_socket_simulation", self._cmd_start, ())
        r("disable_graphics", self._cmd_disable_graphics, ())
        r("enable_graphics", self._cmd_enable_graphics, ())
        r("report_ttes_status", self._cmd_report_status, (), variadic=str)
        r("report_ttes_clips", self._cmd_report_clips, (str,))

    # -- files -------------------------------------------------------------------------------------------
    def _read_env(self, path: Path) -> object:
        if path.name.endswith(".chset.env"):
            return self._load_chset_file(path)
        if path in self.env_files:  # the start-up script run again: the figures are there already
            log.debug("env_already_read", file=str(path))
            return None
        from peabody.language import PeabodyError
        from peabody.loader import read_environment

        try:
            read_environment(path, self.environment, load_psurfs=False, search_path=self.jcl.search_dirs)
        except PeabodyError as exc:
            raise JclError(f"read_file: {exc}") from None
        self.env_files.add(path)
        log.info("environment_read", file=path.name, figures=len(self.environment.figures))
        return None

    def _load_chset_file(self, path: Path, name: str | None = None) -> Channelset:
        try:
            cs = load_channelset(path)
        except (ChannelsetError, OSError) as exc:
            raise JclError(f"load_channelset: {exc}") from None
        self.channelsets[name or cs.name] = cs
        return cs

    def _load_graph(self, path: Path, name: str | None) -> LoadedPostureGraph:
        key = name or path.stem
        if key in self.graphs and self._graph_paths.get(key) == path:
            return self.graphs[key]  # the start-up script run again
        try:
            loaded = load_posture_graph(path, key)
        except (PostureGraphError, ChannelsetError, OSError) as exc:
            raise JclError(f"load_posture_graph: {exc}") from None
        self.graphs[key] = loaded
        self._graph_paths[key] = path
        log.info(
            "posture_graph_loaded",
            graph=key,
            postures=len(loaded.graph.postures),
            channelsets=len(loaded.channelsets),
        )
        return loaded

    # -- channelset and posture graph commands (earlier issues) --------------------------------------------
    def _cmd_load_channelset(self, file: str, name: str = "") -> None:
        self._load_chset_file(self.jcl.resolve_path(file), name or None)

    def _figures(self, names: Sequence[str]) -> list[Figure]:
        missing = [n for n in names if n not in self.environment.figures]
        if missing:
            raise JclError(f"no figure(s) {missing} in the environment")
        return [self.environment.figures[n] for n in names]

    def _cmd_bind_channelset(self, chset: str, name: str = "", *figures: str) -> None:
        cs = self.channelsets.get(chset)
        if cs is None:
            raise JclError(f"bind_channelset: no channelset {chset!r} loaded")
        figs = self._figures(figures) if figures else list(self.environment.figures.values())
        try:
            self.bound_channelsets[name or f"{chset}/bound"] = bind_channelset(cs, figs, name or None)
        except BindingError as exc:
            raise JclError(f"bind_channelset: {exc}") from None

    def _cmd_load_posture_graph(self, file: str, name: str = "") -> None:
        self._load_graph(self.jcl.resolve_path(file), name or None)

    def _cmd_bind_posture_graph(self, graph: str, name: str = "", *figures: str) -> None:
        loaded = self.graphs.get(graph)
        if loaded is None:
            raise JclError(f"bind_posture_graph: no posture graph {graph!r} loaded")
        new = name or f"bound/{graph}"
        if not figures:  # bound per figure set when the library is built (the first create_soldier_state)
            self.bound_graphs[new] = graph
            return
        try:
            self.bound_graphs[new] = bind_posture_graph(loaded, self._figures(figures), new)
        except BindingError as exc:
            raise JclError(f"bind_posture_graph: {exc}") from None

    def _cmd_print_channelset_info(self, name: str = "", verbosity: float = 0.0) -> None:
        from server.motion.info import print_channelset_info

        names = [name] if name else sorted(self.channelsets)
        if name and name not in self.channelsets:
            raise JclError(f"print_channelset_info: no channelset {name!r} loaded")
        out = io.StringIO()
        for n in names:
            print_channelset_info(self.channelsets[n], verbosity=int(verbosity), file=out)
        text = out.getvalue()
        log.info("channelset_info", text=text.rstrip())
        self.events.report(self._caller, text)

    # -- soldiers ----------------------------------------------------------------------------------------
    def _graph(self, key: str, filename: str, required: bool) -> LoadedPostureGraph | None:
        if key in self.graphs:
            return self.graphs[key]
        path = self.jcl.resolve_path(filename)
        if not path.is_file():
            if required:
                raise JclError(
                    f"posture graph {filename!r} not found in {self.data_dir} (or its search path)"
                )
            return None
        return self._load_graph(path, key)

    def ensure_library(self, wanted: tuple[Figure, Figure | None] | None = None) -> MotionLibrary:
        """Load the three posture graphs and bind them to every figure set of the environment (seed 3.6:
        "the first soldier state create triggers the loading of all the posture graph files")."""
        if self.library is not None:
            return self.library
        static = self._graph("soldier_low", GRAPH_FILES[0], True)
        loco = self._graph("soldier_loco", GRAPH_FILES[1], False)
        crawl = self._graph("soldier_crawl", GRAPH_FILES[2], False)
        assert static is not None
        types = set(static.protofiletypes)
        for g in (loco, crawl):
            if g is not None:
                types.update(g.protofiletypes)
        soldiers: dict[str, Figure] = {}
        weapons: dict[str, Figure] = {}
        for fig in self.environment.figures.values():
            t = protofiletype(fig)
            if t not in types:
                continue
            (soldiers if fig.dof_count > 0 else weapons).setdefault(t, fig)
        if wanted is not None:
            soldiers.setdefault(protofiletype(wanted[0]), wanted[0])
            if wanted[1] is not None:
                weapons.setdefault(protofiletype(wanted[1]), wanted[1])
        if not soldiers:
            raise JclError(
                f"no soldier figure of a type the posture graphs drive ({sorted(types)}) is loaded"
            )
        figure_sets: list[list[Figure]] = [
            [s, w] for s, w in itertools.product(soldiers.values(), weapons.values())
        ] or [[s] for s in soldiers.values()]
        try:
            library = MotionLibrary(static, figure_sets, loco, crawl)
        except (BindingError, PostureGraphError, ValueError) as exc:
            raise JclError(f"binding the posture graphs: {exc}") from None
        self._adopt_library(library)
        return library

    def _adopt_library(self, library: MotionLibrary) -> None:
        self.library = library
        self.sets = []
        for k, (fig, wpn) in enumerate(library.set_keys):
            table = update_table_for(library, k + 1, k)
            self.sets.append(FigureSet(k, fig, wpn, table, WireConverter(library, table, k)))
        s = self._settings
        self.manager = SoldierManager(
            library,
            max_soldiers=self.max_soldiers,
            record_clips=s.record_clips,
            **({"throttle": s.throttle} if s.throttle is not None else {}),
            **({"heading_offsets": s.heading_offsets} if s.heading_offsets is not None else {}),
            **({"every_frame": s.every_frame} if s.every_frame is not None else {}),
            **({"walk_run_threshold": s.walk_run_threshold} if s.walk_run_threshold is not None else {}),
            **({"blend_time": s.blend_time} if s.blend_time is not None else {}),
        )
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

    def create_soldier(
        self, figure: str, weapon: str, index: int | None = None, name: str | None = None
    ) -> int:
        """A new soldier of figure/weapon *types* (``"DI.fig"``, ``"AK_47.fig"``); ValueError/KeyError."""
        if self.manager is None:
            self.ensure_library()
        assert self.manager is not None
        i = self.manager.create_soldier(name, figure, weapon, index, now=self.clock())
        self.events.soldier_created(i)
        return i

    def remove_soldier(self, index: int) -> None:
        if self.manager is None or not self.manager.table.is_live(index):
            raise KeyError(f"no soldier {index}")
        self.manager.remove_soldier(index)
        self.events.soldier_removed(index)

    def _cmd_create_soldier_state(self, name: str, figure: str, weapon: str = "") -> None:
        fig, *rest = self._figures([figure] + ([weapon] if weapon else []))
        gun = rest[0] if rest else None
        ftype, wtype = protofiletype(fig), protofiletype(gun) if gun is not None else ""
        if self.manager is not None and name in self.manager.names.values():
            i = self.manager.index_of(name)
            have = self.manager.library.set_keys[int(self.manager.table.fset[i])]
            if have[0] == ftype and wtype in ("", have[1]):
                return  # the start-up script run again
            raise JclError(f"create_soldier_state: soldier {name!r} exists with figures {have}")
        self.ensure_library((fig, gun))
        try:
            i = self.create_soldier(ftype, wtype, None, name)
        except (ValueError, KeyError) as exc:
            raise JclError(f"create_soldier_state: {exc}") from None
        log.info("soldier_state_created", soldier=name, index=i, figure=figure, weapon=weapon)

    def _cmd_remove_soldier_state(self, name: str) -> None:
        if self.manager is None or name not in self.manager.names.values():
            raise JclError(f"remove_soldier_state: no soldier {name!r}")
        self.remove_soldier(self.manager.index_of(name))

    # -- settings ----------------------------------------------------------------------------------------
    def _cmd_set_channelset_parameters(self, every_frame: str) -> None:
        v = every_frame.strip().lower()
        if v not in ("yes", "no"):
            raise JclError(f'set_channelset_parameters: expected "yes" or "no", not {every_frame!r}')
        self.set_every_frame(v == "yes")

    def set_every_frame(self, on: bool) -> None:
        self._settings.every_frame = on
        if self.manager is not None:
            self.manager.set_every_frame(on)

    def _cmd_set_report_interval(self, seconds: float) -> None:
        if not (math.isfinite(seconds) and seconds > 0):
            raise JclError(f"set_ttes_report_interval: {seconds} is not a positive number of seconds")
        self.report_interval = float(seconds)

    def set_report_interval(self, seconds: float) -> None:
        self._cmd_set_report_interval(seconds)

    def _cmd_set_heading_offset(self, static: float, loco: float, crawl: float) -> None:
        offsets = (float(static), float(loco), float(crawl))
        if self.manager is not None:
            self.manager.set_heading_offsets(*offsets)  # ValueError → JclError
        self._settings.heading_offsets = offsets

    def set_throttle(self, seconds: float) -> None:
        if self.manager is not None:
            self.manager.set_throttle(seconds)
        elif not (math.isfinite(seconds) and seconds >= 0):
            raise ValueError(f"throttle must be >= 0 seconds, not {seconds}")
        self._settings.throttle = float(seconds)

    def _cmd_set_throttle(self, seconds: float) -> None:
        self.set_throttle(seconds)

    def _cmd_set_walk_run_threshold(self, mps: float) -> None:
        if self.manager is not None:
            self.manager.set_walk_run_threshold(mps)
        elif not (math.isfinite(mps) and mps > 0):
            raise ValueError("walk/run threshold must be > 0 m/s")
        self._settings.walk_run_threshold = float(mps)

    def _cmd_set_blend_time(self, seconds: float) -> None:
        if self.manager is not None:
            self.manager.set_blend_time(seconds)
        elif not (math.isfinite(seconds) and seconds >= 0):
            raise ValueError("blend time must be >= 0 seconds")
        self._settings.blend_time = float(seconds)

    def _cmd_set_clip_recording(self, on: str) -> None:
        v = on.strip().lower()
        if v not in ("yes", "no"):
            raise JclError(f'set_ttes_clip_recording: expected "yes" or "no", not {on!r}')
        self._settings.record_clips = v == "yes"
        if self.manager is not None:
            self.manager.record_clips = v == "yes"

    def _cmd_start(self) -> None:
        """``start_ttes_socket_simulation()``: the "I'm ready!" message (READY) — the library must exist."""
        self.ensure_library()
        first = not self.ready
        self.ready = True
        if first:
            log.info("simulation_ready", soldiers=self.manager.count if self.manager else 0)
        self.events.ready(self._caller)

    def _cmd_disable_graphics(self) -> None:
        self.graphics = False  # there are no graphics to disable: accepted for the 1994 script

    def _cmd_enable_graphics(self) -> None:
        self.graphics = True

    # -- reports (debugging over the wire: a STATUS message whose text is JSON) ---------------------------
    def soldier_report(self, names: Sequence[str] = ()) -> dict[str, Any]:
        m = self.manager
        if m is None:
            return {"ready": self.ready, "soldiers": []}
        if names:
            missing = [n for n in names if n not in m.names.values()]
            if missing:
                raise JclError(f"no soldier(s) {missing}")
            idx = [m.index_of(n) for n in names]
        else:
            idx = [int(i) for i in m.table.live[:100]]
        return {"ready": self.ready, "time": self.clock(), "soldiers": [m.soldier_info(i) for i in idx]}

    def _cmd_report_status(self, *names: str) -> None:
        self.events.report(self._caller, json.dumps(self.soldier_report(names)))

    def _cmd_report_clips(self, name: str) -> None:
        m = self.manager
        if m is None or name not in m.names.values():
            raise JclError(f"report_ttes_clips: no soldier {name!r}")
        clips = [
            {
                "time": c.time,
                "clip": c.clip,
                "forward": c.forward,
                "duration": c.duration,
                "mode": c.mode,
                "state": c.state,
            }
            for c in m.clips_of(m.index_of(name))
        ]
        self.events.report(self._caller, json.dumps({"soldier": name, "clips": clips}))


# -- a synthetic data directory: tests, benches and `ttes server --synthetic` until the real library ships --
@dataclass
class SyntheticDataDir:
    path: Path
    startup_script: str
    soldiers: list[str] = field(default_factory=list)


def write_synthetic_data_dir(
    directory: str | Path, *, soldiers: int = 10, ndof: int = 50, amplitude: float = 0.2, seed: int = 7
) -> SyntheticDataDir:
    """A data dir laid out like the real one, with :mod:`server.soldier.synthetic`'s motion library:
    ``figures/DI.fig`` (a chain soldier) and ``figures/AK_47.fig``, ``posture_graphs/*.graph`` with their
    channelsets, ``jack-ttes-soldier_low.env`` (``soldiers`` soldier/gun pairs) and the seed's start-up script
    ``jack-ttes-soldier_low.jcl``."""
    from peabody.writer import write_figure
    from server.soldier.synthetic import synthetic_figures, write_synthetic_library

    out = Path(directory)
    (out / "figures").mkdir(parents=True, exist_ok=True)
    figs = synthetic_figures(ndof)
    for fig in figs:
        write_figure(fig, out / "figures" / (fig.filename or f"{fig.name}.fig"))
    write_synthetic_library(out / "posture_graphs", figs, amplitude=amplitude, seed=seed)
    names = [f"s{i}" for i in range(soldiers)]
    env = [
        f'figure Di2_{i} {{ file = "DI.fig"; }}\nfigure AK_47_{i} {{ file = "AK_47.fig"; }}\n'
        for i in range(soldiers)
    ]
    (out / "jack-ttes-soldier_low.env").write_text("".join(env) or "\n", encoding="utf-8")
    script = ['read_file("jack-ttes-soldier_low.env");']
    script += [f'create_soldier_state("s{i}","Di2_{i}","AK_47_{i}");' for i in range(soldiers)]
    script += [
        'set_channelset_parameters("no");',
        "set_ttes_report_interval(10.00);",
        "set_ttes_heading_offset(0.00,0.00,0.00);",
        "set_ttes_soldier_throttle(0.04);",
        "set_ttes_report_interval(30.00);",
        "start_ttes_socket_simulation();",
        "disable_graphics();",
    ]
    (out / "jack-ttes-soldier_low.jcl").write_text("\n".join(script) + "\n", encoding="utf-8")
    return SyntheticDataDir(out, "jack-ttes-soldier_low.jcl", names)
