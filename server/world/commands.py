"""JCL as a thin typed adapter over the server core: every command of seed 002, sections 3.4-3.6 (and the
appendix's ``spit``), each saying what it does *here*.

:data:`COMMANDS` is the one table: name, argument types, the seed section and a plain sentence of what the
command does in this server, or why it is refused. It registers the commands with the whitelist interpreter
(:mod:`server.jcl`), answers ``help()`` and is the table in ``docs/JCL.md`` (a test keeps them equal). A
command's handler is the method ``cmd_<name>`` of :class:`JclCommands`; it converts the JCL arguments and
calls one part of the core (:class:`~server.world.store.MotionStore`,
:class:`~server.world.soldiers.Soldiers`, the soldier manager). A refused command has no handler: it answers
every call with its reason (``JCL_ERROR`` over the wire).
"""

from __future__ import annotations

import copy
import io
import json
import math
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from server.jcl import JclError, JclInterpreter, parse_jcl
from server.logging import get_logger
from server.world.access import caller_of, check_access

if TYPE_CHECKING:
    from server.startup import ServerWorld

log = get_logger("jcl")
# commands that only read files and fill the store: they run where the JCL runs (a worker thread under the
# trio app); every other command runs on the trio loop (ServerWorld.in_loop), between ticks
OFF_LOOP = frozenset(
    {"load_channelset", "load_posture_graph", "write_channelset", "reroot_figure_channel", "spit"}
)
_ANY = object  # argument type of a refused command: whatever it is given


def needs_worker(text: str, already_run: Callable[[str], bool] = lambda name: False) -> bool:
    """Whether a JCL frame may load files: an OFF_LOOP command, or ``read_file`` of anything but a script
    ``already_run`` says is done (a 1994 client's start-up script, answered as done). Only such frames go to a
    worker thread; the rest run at once on the loop, so a frame of cheap commands neither waits for a thread
    nor lets (autojump's virtual) time run on while it does. A frame that does not parse fails at once: the
    loop runs it."""
    try:
        calls = parse_jcl(text)
    except JclError:
        return False
    return any(
        c.name in OFF_LOOP or (c.name == "read_file" and not (c.args and already_run(str(c.args[0]))))
        for c in calls
    )


@dataclass(frozen=True)
class Command:
    """One JCL command: its signature, where the seed defines it, what it does here."""

    name: str
    args: str  # shown in help() and the docs
    seed: str  # section of seed 002 ("" = this server's own)
    here: str  # what it does in this server (or why it is refused)
    types: tuple[type, ...] = ()
    optional: int = 0
    variadic: type | None = None
    refused: bool = False
    access: str = "operator"  # who may run it (server.world.access): operator, soldier, connection, read


_SLAVING = (
    "refused: slaving is off-line authoring (`authoring/slaving.py`, run by `ttes author build`), and the "
    "server never imports authoring; it plays the slaved `*_low` channelsets that build wrote"
)
S, F = str, float
COMMANDS: tuple[Command, ...] = (
    # -- 3.4.1 channelsets
    Command(
        "write_channelset",
        "file, name, begin, end, fps, stride, bound_channelset",
        "3.4.1",
        "writes stored frames begin..end (every stride) of a bound channelset as a new channelset at fps "
        "to a new `.chset.env` file inside the data directory and loads it as `name` (the server's only "
        "channels are bound channelsets: it has no motions to interpolate)",
        (S, S, F, F, F, F, S),
        access="operator",
    ),
    Command(
        "load_channelset",
        "file [, name]",
        "3.4.1",
        "reads a `.chset.env` channelset (also `read_file`) under its own name or `name`, in a worker "
        "thread beside the tick; the same unchanged file again shares the loaded one (at most 4096 names)",
        (S, S),
        1,
        access="operator",
    ),
    Command(
        "bind_channelset",
        "channelset [, name [, figure ...]]",
        "3.4.1",
        "binds a loaded channelset to figures of the environment (all when none are named) as `name` "
        "(default `<channelset>/bound`); play, step and write use it",
        (S, S),
        1,
        S,
        access="operator",
    ),
    Command(
        "play_bound_channelset",
        "bound_channelset, direction, time",
        "3.4.1",
        "the soldier created from the bound figures plays the clip once (`forwards`/`backwards`, over "
        "`time` s, -1 = stored time), then takes up its last request again; the channelset must be a clip "
        "of the motion library (loaded through its posture graphs)",
        (S, S, F),
        access="soldier",
    ),
    Command(
        "step_bound_channelset",
        "bound_channelset [, frames]",
        "3.4.1",
        "moves the bound channelset's debugging cursor `frames` stored frames (default 1, negative goes "
        "back, clamped) and reports that frame's poses and root placements to the caller (JSON STATUS); "
        "soldiers are not moved",
        (S, F),
        1,
        access="operator",
    ),
    Command(
        "set_channelset_parameters",
        '"yes" or "no"',
        "3.4.1",
        "the soldier manager setting every_frame: one stored frame per tick (yes) or real time (no)",
        (S,),
        access="operator",
    ),
    Command(
        "print_channelset_info",
        "[channelset [, verbosity]]",
        "3.4.1",
        "reports frames, channels and memory of one or every loaded channelset to the caller",
        (S, F),
        2,
        access="read",
    ),
    Command(
        "reroot_figure_channel",
        "channelset, figure, site",
        "3.4.1",
        "replaces the loaded channelset by one whose figure channel for `figure` gives every frame "
        "relative to root `site` (batched FK); bind it again to use it (the motion library keeps the clips "
        "it was built from)",
        (S, S, S),
        access="operator",
    ),
    # -- 3.4.2 posture graphs
    Command(
        "load_posture_graph",
        "file [, name]",
        "3.4.2",
        "reads a `.graph` file and its channelsets (registered by name too) as `name` (default: the file "
        "stem), in a worker thread beside the tick; the same unchanged file again shares the loaded graph "
        "(at most 256 names); `soldier_low`, `soldier_loco`, `soldier_crawl` are the library's graphs",
        (S, S),
        1,
        access="operator",
    ),
    Command(
        "bind_posture_graph",
        "graph [, name [, figure ...]]",
        "3.4.2",
        "binds a loaded graph to figures (default: the first of each type it drives) as `name`; the "
        "motion library, built at the first create_soldier_state, is bound to the figure sets of the "
        "graphs bound from `soldier_low` (all environment types when none is); posture_change uses it",
        (S, S),
        1,
        S,
        access="operator",
    ),
    Command(
        "posture_change",
        "bound_graph, posture",
        "3.4.2",
        "the soldier created from the bound graph's figures goes to `posture` along the quickest path, as "
        "a standing-still request for it would (a DEAD variant is picked as for a request; a soldier in a "
        "transition finishes it first); reports the goal and the path playing to the caller",
        (S, S),
        access="soldier",
    ),
    # -- 3.4.4 slaving
    Command("create_master_slave_pair", "...", "3.4.4", _SLAVING, (), 0, _ANY, True, access="operator"),
    Command("slave_parameters", "...", "3.4.4", _SLAVING, (), 0, _ANY, True, access="operator"),
    Command("turn_slave_on", "...", "3.4.4", _SLAVING, (), 0, _ANY, True, access="operator"),
    Command("turn_slave_off", "...", "3.4.4", _SLAVING, (), 0, _ANY, True, access="operator"),
    Command("turn_behavior_constr_off", "...", "3.4.4", _SLAVING, (), 0, _ANY, True, access="operator"),
    Command("create_channelset_motion", "...", "3.4.4", _SLAVING, (), 0, _ANY, True, access="operator"),
    # -- 3.6 start-up
    Command(
        "open_ttes_sockets",
        "host",
        "3.6",
        "accepted and ignored: the server listens on `ttes server --host/--port` before any script runs",
        (S,),
        access="read",
    ),
    Command(
        "change_directory",
        "directory",
        "3.6",
        "refused: the data directory is fixed by `ttes server --data-dir`, and scripts from clients may "
        "not leave it",
        (),
        0,
        _ANY,
        True,
        access="operator",
    ),
    Command(
        "read_file",
        "file",
        "3.6",
        "runs a `.jcl` script or reads an `.env` / `.chset.env` / `.graph` file (inside the data "
        "directory, then its figures/, channelsets/, posture_graphs/)",
        (S,),
        access="operator",
    ),
    Command(
        "create_soldier_state",
        "name, figure [, weapon]",
        "3.6",
        "creates soldier `name` from environment figures; the first one builds the motion library",
        (S, S, S),
        1,
        access="soldier",
    ),
    Command(
        "set_ttes_report_interval", "seconds", "3.6", "the STATUS period (> 0 s)", (F,), access="connection"
    ),
    Command(
        "set_ttes_heading_offset",
        "static, loco, crawl",
        "3.6",
        "the soldier manager setting heading_offsets (compass degrees per graph)",
        (F, F, F),
        access="operator",
    ),
    Command(
        "set_ttes_soldier_throttle",
        "seconds",
        "3.6",
        "the soldier manager setting throttle: a rate cap, at most one update per soldier per `seconds` (due"
        " at a tick when its last update is at least `seconds` − ½ tick old: 0.04 at 30 Hz is every tick)",
        (F,),
        access="connection",
    ),
    Command(
        "start_ttes_socket_simulation",
        "",
        "3.6",
        'builds the library if needed and sends READY (the "I\'m ready!" message)',
        access="operator",
    ),
    Command("disable_graphics", "", "3.6", "accepted: there are no graphics", access="operator"),
    Command("enable_graphics", "", "3.6", "accepted: there are no graphics", access="operator"),
    # -- appendix: TIPS
    Command(
        "spit",
        "file",
        "A",
        "writes the environment's figures as TIPS to a new `.tips` file inside the data directory "
        "(without geometry: the server reads no psurfs; `ttes figure spit` writes it all)",
        (S,),
        access="operator",
    ),
    # -- this server's own
    Command(
        "remove_soldier_state",
        "name",
        "",
        "removes a soldier (REMOVE_SOLDIER over the wire)",
        (S,),
        access="soldier",
    ),
    Command(
        "react_soldier_state",
        'name, "recoil" or "flinch"',
        "",
        "a resting soldier plays its posture's recoil (a Fire PDU) or flinch (a near detonation) once; "
        "reports the clip, or null when it cannot react now (one changing posture or turning reacts when "
        "that ends; REACT over the wire does the same)",
        (S, S),
        access="soldier",
    ),
    Command(
        "set_ttes_walk_run_threshold",
        "m_per_s",
        "",
        "the soldier manager setting walk_run_threshold (> 0 m/s)",
        (F,),
        access="operator",
    ),
    Command(
        "set_ttes_blend_time",
        "seconds",
        "",
        "the soldier manager setting blend_time (>= 0 s)",
        (F,),
        access="operator",
    ),
    Command(
        "set_ttes_clip_recording",
        '"yes" or "no"',
        "",
        "the soldier manager setting record_clips (for report_ttes_clips)",
        (S,),
        access="operator",
    ),
    Command(
        "report_ttes_status",
        "[soldier ...]",
        "",
        "reports soldier states to the caller (JSON)",
        (),
        0,
        S,
        access="soldier",
    ),
    Command(
        "report_ttes_clips",
        "soldier",
        "",
        "reports a soldier's recorded clip starts (JSON)",
        (S,),
        access="soldier",
    ),
    Command("help", "", "", "reports this table to the caller", access="connection"),
)
del S, F


def help_table() -> str:
    """The command table as Markdown: ``help()`` answers it and ``docs/JCL.md`` holds it."""
    rows = ["| command | seed | access | what it does here |", "| --- | --- | --- | --- |"]
    for c in sorted(COMMANDS, key=lambda c: (c.seed or "~", c.name)):
        rows.append(f"| `{c.name}({c.args})` | {c.seed or 'server'} | {c.access} | {c.here} |")
    return "\n".join(rows) + "\n"


def _yes_no(command: str, value: str) -> bool:
    v = value.strip().lower()
    if v not in ("yes", "no"):
        raise JclError(f'{command}: expected "yes" or "no", not {value!r}')
    return v == "yes"


def _count(name: str, value: float, lo: int = 0) -> int:
    if not (math.isfinite(value) and value == int(value) and value >= lo):
        raise JclError(f"{name} must be a whole number >= {lo}, not {value}")
    return int(value)


class JclCommands:
    """The handlers: each converts its JCL arguments and calls one part of the world."""

    def __init__(self, world: ServerWorld) -> None:
        self.world = world
        self.store = world.store
        self.soldiers = world.soldiers
        self.cursors: dict[str, int] = {}  # step_bound_channelset: bound channelset -> frame shown

    def register(self, jcl: JclInterpreter) -> None:
        for c in COMMANDS:
            if c.name == "read_file":  # the interpreter's own (it dispatches on the file suffix)
                func = self._read_file_guard(jcl.command("read_file"))
            else:
                func = self._refuse(c) if c.refused else self._guard(c, getattr(self, f"cmd_{c.name}"))
                if c.name not in OFF_LOOP:
                    func = self._in_loop(func)
            jcl.register(c.name, func, c.types, optional=c.optional, variadic=c.variadic)
        jcl.register_file_handler(".env", lambda p: self.store.read_env(p, jcl.search_dirs))
        jcl.register_file_handler(".graph", self.store.load_graph)
        jcl.register_file_handler(".chset", self.store.load_channelset)

    def _in_loop(self, func: Any) -> Any:
        def run(*args: object) -> object:
            return self.world.in_loop(lambda: func(*args))

        return run

    def _guard(self, command: Command, func: Any) -> Any:
        """The handler, run only when the caller's role may run the command (``server.world.access``)."""

        def guarded(*args: Any) -> object:
            check_access(command.name, command.access, self.world.caller)
            return func(*args)

        return guarded

    def _read_file_guard(self, read_file: Any) -> Any:
        """``read_file`` is the operator's, but a 1994 client (a controller) always sends the start-up
        script first: once the server has run it, that request is answered as done (nothing runs)."""

        def guarded(name: str) -> object:
            if caller_of(self.world.caller) is not None and self.world.is_startup_script(name):
                log.info("startup_script_rerun_skipped", file=name)
                return None
            check_access("read_file", "operator", self.world.caller)
            return read_file(name)

        return guarded

    def _own(self, index: int, name: str = "", *, remove: bool = False) -> int:
        """``index``, when the caller may drive (or ``remove``) that soldier; else JclError."""
        who, owners = caller_of(self.world.caller), self.world.owners
        if who is None:
            return index
        if remove and not owners.may_remove(index, who.client_id, who.role):
            raise JclError(f"soldier {name or index!r} (index {index}) is not this client's to remove")
        if not owners.may_drive(index, who.client_id, who.role):
            raise JclError(f"soldier {name or index!r} (index {index}) belongs to another client")
        return index

    @staticmethod
    def _refuse(command: Command) -> Any:
        def refuse(*_args: object) -> None:
            raise JclError(f"{command.name}: {command.here}")

        return refuse

    def _report(self, text: str) -> None:
        caller = self.world.caller
        self.world.in_loop(lambda: self.world.events.report(caller, text))

    def _new_file(self, name: str, suffix: str) -> Path:
        """A file a command writes: new, inside the data directory, with the expected suffix."""
        if not name.endswith(suffix):
            raise JclError(f"the file name must end in {suffix!r}, not {name!r}")
        path = self.world.jcl.resolve_path(name)
        if path.exists():
            raise JclError(f"{name!r} exists; the server never overwrites a file")
        path.parent.mkdir(parents=True, exist_ok=True)
        return path

    # -- 3.4.1 channelsets -------------------------------------------------------------------------------
    def cmd_write_channelset(
        self, file: str, name: str, begin: float, end: float, fps: float, stride: float, bound: str
    ) -> None:
        from server.motion.channelset_file import save_channelset
        from server.motion.recording import Recording, write_channelset

        b = self.store.bound_channelset(bound)
        figs = [copy.deepcopy(f) for f in self.store.figures([bf.figure for bf in b.figures])]
        by_name = {f.name: f for f in figs}
        rec = Recording(figs)
        for k in range(b.channelset.nframes):  # the "channels": the bound channelset played frame by frame
            b.apply(float(k), by_name, interpolate=False)
            rec.capture()
        frames = (_count("begin", begin), _count("end", end), fps, _count("stride", stride, 1))
        cs = write_channelset(None, name, rec, *frames)  # checked before anything is written
        path = self._new_file(file, ".chset.env")
        save_channelset(cs, path)
        self.store.channelsets[name] = cs
        log.info("channelset_written", file=str(path), frames=cs.nframes)

    def cmd_load_channelset(self, file: str, name: str = "") -> None:
        self.store.load_channelset(self.world.jcl.resolve_path(file), name or None)

    def cmd_bind_channelset(self, chset: str, name: str = "", *figures: str) -> None:
        bound = self.store.bind_channelset(chset, name, figures)
        self.cursors.pop(bound.name, None)

    def cmd_play_bound_channelset(self, bound: str, direction: str, time: float) -> None:
        d = direction.strip().lower()
        if d not in ("forwards", "forward", "backwards", "backward"):
            raise JclError(
                f'play_bound_channelset: direction must be "forwards" or "backwards", not {direction!r}'
            )
        b = self.store.bound_channelset(bound)
        lib, m = self.world.ensure_library(), self.soldiers.manager
        assert m is not None
        i = self._own(self.soldiers.soldier_with([bf.figure for bf in b.figures]))
        clip = lib.clip_of(b.channelset)  # the same clip id in every figure set
        m.play_clip(i, clip, d.startswith("forward"), time, self.world.clock())

    def cmd_step_bound_channelset(self, bound: str, frames: float = 1.0) -> None:
        b = self.store.bound_channelset(bound)
        last = b.channelset.nframes - 1
        if not math.isfinite(frames):
            raise JclError(f"step_bound_channelset: {frames} is not a number of frames")
        k = min(max(self.cursors.get(bound, 0) + round(frames), 0), last)
        self.cursors[bound] = k
        s = b.sample(float(k), interpolate=False)
        self._report(
            json.dumps(
                {
                    "bound_channelset": bound,
                    "frame": k,
                    "nframes": last + 1,
                    "poses": {n: [round(float(v), 6) for v in p] for n, p in s.poses.items()},
                    "placements": {
                        n: None
                        if pl is None
                        else {
                            "root": pl.root,
                            "position": pl.position.tolist(),
                            "quaternion": pl.quaternion.tolist(),
                        }
                        for n, pl in s.placements.items()
                    },
                }
            )
        )

    def cmd_set_channelset_parameters(self, every_frame: str) -> None:
        self.soldiers.configure(every_frame=_yes_no("set_channelset_parameters", every_frame))

    def cmd_print_channelset_info(self, name: str = "", verbosity: float = 0.0) -> None:
        from server.motion.info import print_channelset_info

        names = [name] if name else sorted(self.store.channelsets)
        level = _count("verbosity", verbosity)
        out = io.StringIO()
        for n in names:
            print_channelset_info(self.store.channelset(n), verbosity=level, file=out)
        text = out.getvalue()
        log.info("channelset_info", text=text.rstrip())
        self._report(text)

    def cmd_reroot_figure_channel(self, chset: str, figure: str, site: str) -> None:
        from peabody.fk import FigureKinematics
        from server.motion.recording import reroot_figure_channel

        cs = self.store.channelset(chset)
        (fig,) = self.store.figures([figure])
        self.store.channelsets[chset] = reroot_figure_channel(cs, fig, site, FigureKinematics(fig))

    # -- 3.4.2 posture graphs ----------------------------------------------------------------------------
    def cmd_load_posture_graph(self, file: str, name: str = "") -> None:
        self.store.load_graph(self.world.jcl.resolve_path(file), name or None)

    def cmd_bind_posture_graph(self, graph: str, name: str = "", *figures: str) -> None:
        self.store.bind_posture_graph(graph, name, figures)

    def cmd_posture_change(self, bound: str, posture: str) -> None:
        g = self.store.bound_graph(bound)
        self.world.ensure_library()
        m = self.soldiers.manager
        assert m is not None
        i = self._own(self.soldiers.soldier_with([bf.figure for bf in g.bound[0].figures] if g.bound else []))
        if not any(posture in (p, p.partition("@")[0]) for p in g.graph.postures):
            raise JclError(f"posture_change: posture graph {bound!r} has no posture {posture!r}")
        path = m.posture_change(i, posture, self.world.clock())
        goal = m.soldier_info(i)["goal"]
        self._report(json.dumps({"soldier": m.names[i], "posture": posture, "goal": goal, "path": path}))

    # -- 3.6 start-up ------------------------------------------------------------------------------------
    def cmd_open_ttes_sockets(self, host: str) -> None:
        log.info("open_ttes_sockets_ignored", host=host)

    def cmd_create_soldier_state(self, name: str, figure: str, weapon: str = "") -> None:
        self.world.create_soldier_state(name, figure, weapon)

    def cmd_set_ttes_report_interval(self, seconds: float) -> None:
        who = caller_of(self.world.caller)
        if who is None:
            self.world.set_report_interval(seconds)
        else:
            who.set_report_interval(seconds)

    def cmd_set_ttes_heading_offset(self, static: float, loco: float, crawl: float) -> None:
        self.soldiers.configure(heading_offsets=(static, loco, crawl))

    def cmd_set_ttes_soldier_throttle(self, seconds: float) -> None:
        who = caller_of(self.world.caller)
        if who is None:
            self.soldiers.configure(throttle=seconds)
        else:
            who.set_throttle(seconds)

    def cmd_start_ttes_socket_simulation(self) -> None:
        self.world.start()

    def cmd_disable_graphics(self) -> None:
        self.world.graphics = False

    def cmd_enable_graphics(self) -> None:
        self.world.graphics = True

    def cmd_spit(self, file: str) -> None:
        from peabody.tips import format_tips

        path = self._new_file(file, ".tips")
        path.write_text(format_tips(self.store.environment), encoding="utf-8")
        log.info("tips_written", file=str(path), figures=len(self.store.environment.figures))

    # -- this server's own -------------------------------------------------------------------------------
    def cmd_remove_soldier_state(self, name: str) -> None:
        self.world.remove_soldier(
            self._own(self.soldiers.index_of(name), name, remove=True), "removed by JCL"
        )

    def cmd_react_soldier_state(self, name: str, kind: str) -> None:
        k = kind.strip().lower()
        if k not in ("recoil", "flinch"):
            raise JclError(f'react_soldier_state: the reaction must be "recoil" or "flinch", not {kind!r}')
        m = self.soldiers.manager
        if m is None:
            raise JclError("react_soldier_state: no soldiers yet")
        clip = m.react(self._own(self.soldiers.index_of(name), name), k, self.world.clock())
        self._report(json.dumps({"soldier": name, "reaction": k, "clip": clip}))

    def cmd_set_ttes_walk_run_threshold(self, mps: float) -> None:
        self.soldiers.configure(walk_run_threshold=mps)

    def cmd_set_ttes_blend_time(self, seconds: float) -> None:
        self.soldiers.configure(blend_time=seconds)

    def cmd_set_ttes_clip_recording(self, on: str) -> None:
        self.soldiers.configure(record_clips=_yes_no("set_ttes_clip_recording", on))

    def cmd_report_ttes_status(self, *names: str) -> None:
        indices = [self._own(self.soldiers.index_of(n), n) for n in names]
        who, m = caller_of(self.world.caller), self.soldiers.manager
        if not names and who is not None and m is not None:  # every soldier the caller may drive
            live = m.table.live
            indices = live[self.world.owners.drivable(live, who.client_id, who.role)][:100].tolist()
        report = self.soldiers.report(self.world.clock, self.world.ready, indices if who or names else None)
        self._report(json.dumps(report))

    def cmd_report_ttes_clips(self, name: str) -> None:
        m = self.soldiers.manager
        i = self._own(self.soldiers.index_of(name), name)
        assert m is not None
        clips = [
            {
                "time": c.time,
                "clip": c.clip,
                "forward": c.forward,
                "duration": c.duration,
                "skipped": c.skipped,
                "mode": c.mode,
                "state": c.state,
            }
            for c in m.clips_of(i)
        ]
        self._report(json.dumps({"soldier": name, "clips": clips}))

    def cmd_help(self) -> None:
        self._report(help_table())
