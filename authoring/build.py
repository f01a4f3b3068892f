"""``ttes author build``: record the whole motion library (seed 002, 3.4: record, organise, slave, re-record).

1. Solve the key postures (:mod:`~authoring.postures`) on ``soldier.fig`` with the ``AK_47.fig`` rifle.
2. Record every clip on soldier.fig at 60 fps — the 17 static transitions
   (:mod:`~authoring.transitions`), walking / backward walking / running
   (:mod:`~authoring.gait`)
   and crawling (:mod:`~authoring.crawl`), turns in place and side-steps
   (:mod:`~authoring.turns`), and the reactions without a posture change (firing recoil, flinch:
   :mod:`~authoring.reactions`) — into ``channelsets/NAME.chset.env``.
3. Slave a ``DI.fig`` to a soldier.fig master (:mod:`~authoring.slaving`), put it on its kneeling
   knees where the master kneels (:mod:`~authoring.slave_contacts`) and re-record each clip into
   ``channelsets/NAME_low.chset.env``; slave it again with ``M16.fig`` in the hands instead of the AK
   (:mod:`~authoring.rifle_swap`, the M16 library) into ``channelsets/NAME_m16_low.chset.env``.
4. Write the posture graph files of both figure types and the TTES start-up script and environment into
   ``posture_graphs/``.

Everything is deterministic (no randomness, fixed iteration counts), so a rebuild gives the same bytes.
``only`` (a shell pattern on clip names) limits steps 2-3; ``figure`` picks the figure sets written
(``"DI"`` / ``"M16"`` re-slave the committed soldier.fig channelsets for DI.fig with the AK / the M16
without recording them again).
"""

from __future__ import annotations

import fnmatch
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from functools import partial
from pathlib import Path

import numpy as np

from authoring import crawl, crawl_prone, crawl_turn, deaths, gait, postures, reactions, transitions, turns
from authoring.death_specs import spec_of
from authoring.grounded import ground_channelset
from authoring.motion import KeyPosture
from authoring.passive_range import passive_figure, past_live_limits
from authoring.quality_frames import FigureSet, play
from authoring.slave_arms import pin_slave_arms
from authoring.slave_arms_down import keep_slave_arms_down
from authoring.slave_arms_late import lag_slave_arms
from authoring.slave_arms_lift import lift_slave_arms
from authoring.slave_belly import lift_slave_belly
from authoring.slave_belly_held import hold_slave_belly
from authoring.slave_contacts import pin_end, rest_slave_forearms, rest_slave_knees, tilt_onto_knees
from authoring.slave_feet import plant_slave_feet
from authoring.slave_feet_down import lower_slave_feet
from authoring.slave_forearm_lift import lift_slave_forearms, steps_forearm
from authoring.slave_ground import clear_rifle, rest_limbs
from authoring.slave_lying import lay_slave_forearms
from authoring.slave_reactions import follow_master
from authoring.slave_rest import rest_slave_trunk
from authoring.slave_slack import slack_slave_feet
from authoring.slave_spine import lay_slave_spine
from authoring.slave_start import ease_slave_start
from authoring.slave_wrists import ease_slave_wrists
from authoring.slaving import MasterSlavePair
from authoring.transitions import ClipFrames, clip_to_channelset
from peabody.fk import FigureKinematics
from peabody.loader import read_figure
from peabody.model import Figure
from server.motion.binding import bind_channelset, protofiletype
from server.motion.cache import load_channelset
from server.motion.channelset import Channelset
from server.motion.channelset_file import format_channelset, parse_channelsets, save_channelset
from server.motion.posture_graph import Arc, PostureGraph, format_posture_graph
from server.world import synthetic

FIGURE_SETS = ("soldier", "DI", "M16", "all")
SUFFIXES = {"soldier": "", "DI": "_low", "M16": "_m16_low"}  # channelset file name suffix per figure set
HOLDS = {"soldier": "soldier.fig + AK_47.fig", "DI": "DI.fig + AK_47.fig", "M16": "DI.fig + M16.fig"}
SLAVE_PARAMETERS = ("yes", "yes", "yes", "yes", 0.50, "yes", 0.50, "yes", "yes")  # seed 002, 3.4.4
SOLDIERS = 10  # soldier/rifle pairs in the start-up environment (seed 002, 3.6)


@dataclass
class BuildContext:
    """The figures and the (lazily solved) key postures every clip generator needs."""

    soldier: Figure
    rifle: Figure
    di: Figure
    m16: Figure
    _keys: dict[str, KeyPosture] = field(default_factory=dict)
    _figure_set: FigureSet | None = None
    _passive: BuildContext | None = field(default=None, repr=False, compare=False)

    @classmethod
    def load(cls, figures_dir: Path) -> BuildContext:
        return cls(
            read_figure(figures_dir / "soldier.fig"),
            read_figure(figures_dir / "AK_47.fig"),
            read_figure(figures_dir / "DI.fig"),
            read_figure(figures_dir / "M16.fig"),
        )

    @property
    def figure_set(self) -> FigureSet:
        """Every figure of the build by file type, with cached kinematics (for playing clips back)."""
        if self._figure_set is None:
            figs = (self.soldier, self.di, self.rifle, self.m16)
            self._figure_set = FigureSet({protofiletype(f): f for f in figs})
        return self._figure_set

    @property
    def keys(self) -> dict[str, KeyPosture]:
        if not self._keys:
            self._keys.update(postures.build_postures(self.soldier, self.rifle))
        return self._keys

    def passive(self) -> BuildContext:
        """This context with soldier.fig and DI.fig widened to their legs' passive range
        (:func:`passive_figure`; made once): the figures a death's slave is solved on (issue 14)."""
        if self._passive is None:
            soldier, di = passive_figure(self.soldier), passive_figure(self.di)
            self._passive = BuildContext(soldier, self.rifle, di, self.m16, self._keys)
        return self._passive


@dataclass(frozen=True)
class Clip:
    """A recorded clip: its frames and, for locomotion, stride length (cm) and ground speed (cm/s); for a
    clip that moves the soldier (turns, side-steps) its ``end_offset`` (x cm, z cm, yaw deg)."""

    frames: ClipFrames
    stride_length: float | None = None
    ground_speed: float | None = None
    end_offset: tuple[float, float, float] | None = None
    release_frame: int | None = None  # deaths: the frame the hands let go of the rifle


@dataclass(frozen=True)
class ClipJob:
    """One channelset of the library: file stem, the graph that lists it, and how to record it."""

    name: str
    graph: str  # "static", "loco", "crawl", "turn" or "react"
    make: Callable[[BuildContext], Clip]


def clip_jobs() -> list[ClipJob]:
    """Every clip of the library, in build order."""
    dying = deaths.death_specs()
    jobs = [ClipJob(t.name, "static", _record_of(t, dying)) for t in transitions.TRANSITIONS]
    jobs += [ClipJob(name, "loco", _gait_maker(make)) for name, make in gait.locomotion_clips().items()]
    jobs += [ClipJob(name, "crawl", _gait_maker(make)) for name, make in crawl.crawl_clips().items()]
    jobs += [ClipJob(name, "turn", _moved_maker(make)) for name, make in turns.turn_clips().items()]
    jobs += [
        ClipJob(name, "turn", _moved_maker(make)) for name, make in crawl_turn.crawl_turn_clips().items()
    ]
    jobs += [ClipJob(name, "react", _gait_maker(make)) for name, make in reactions.reaction_clips().items()]
    return jobs


# One closure per clip (a lambda in a loop would late-bind the loop variable).
_Record = Callable[[BuildContext], Clip]


def _record_of(spec: transitions.TransitionSpec, dying: Mapping[str, deaths.DeathSpec]) -> _Record:
    """How a static transition is recorded: simulated (a death), planned limb by limb (crawl -> prone), or
    keyframed (the rest)."""
    if spec.name in dying:
        return _death_maker(dying[spec.name])
    if spec.name == crawl_prone.NAME:
        return lambda ctx: Clip(crawl_prone.record_crawl_to_prone(ctx.keys, (ctx.soldier, ctx.rifle)))
    return _transition_maker(spec)


def _transition_maker(spec: transitions.TransitionSpec) -> _Record:
    return lambda ctx: Clip(transitions.record_transition(spec, ctx.keys, (ctx.soldier, ctx.rifle)))


def _death_maker(spec: deaths.DeathSpec) -> _Record:
    return lambda ctx: _death(spec, ctx)


def _gait_maker(make: Callable[[BuildContext], tuple[ClipFrames, float | None, float | None]]) -> _Record:
    """(frames, stride length, ground speed) recorders: locomotion, crawl and reactions (no stride)."""
    return lambda ctx: Clip(*make(ctx))


def _moved_maker(make: Callable[[BuildContext], tuple[ClipFrames, tuple[float, float, float]]]) -> _Record:
    return lambda ctx: _moved(*make(ctx))


def _moved(frames: ClipFrames, end_offset: tuple[float, float, float]) -> Clip:
    return Clip(frames, end_offset=end_offset)


def _death(spec: deaths.DeathSpec, ctx: BuildContext) -> Clip:
    """A simulated death; one that rolls its legs into their passive range
    (:attr:`deaths.DeathSpec.legs_roll`) is recorded on soldier.fig with its legs' passive range
    (:mod:`authoring.passive_range`)."""
    body = ctx.soldier if spec.legs_roll is None else passive_figure(ctx.soldier)
    clip = deaths.simulate(spec, ctx.keys, (body, ctx.rifle))
    return Clip(clip.frames, release_frame=clip.release_frame)


def record(job: ClipJob, ctx: BuildContext) -> Channelset:
    """The soldier.fig channelset of one clip."""
    clip = job.make(ctx)
    chset = clip_to_channelset(f"{job.name}.chset", clip.frames, ctx.soldier, ctx.rifle)
    if clip.stride_length is not None or clip.ground_speed is not None:
        chset = replace(
            chset,
            stride_length=None if clip.stride_length is None else round(clip.stride_length, 2),
            ground_speed=None if clip.ground_speed is None else round(clip.ground_speed, 2),
        )
    if clip.end_offset is not None:
        x, z, yaw = clip.end_offset
        chset = replace(chset, end_offset=(round(x, 4), round(z, 4), round(yaw, 4)))
    if clip.release_frame is not None:
        chset = replace(chset, release_frame=clip.release_frame)
    return chset


LIFT_SIGMA_FRAMES = 3.0  # a death's lift off the ground is smoothed over the clip (at or above the need)


def lift_off_ground(chset: Channelset, body: Figure) -> None:
    """Raise every figure channel (soldier and rifle) in frames where the body's mesh would sink below the
    ground (the slave's torso is shaped differently from the master's, so a lying DI can dip where the
    soldier did not). In place."""
    from authoring.postures import lowest_point
    from authoring.signal_shaping import smooth_above
    from server.motion.binding import bind_channelset

    bound = bind_channelset(chset, [body])
    bf = bound.figures[0]
    poses = np.tile(bf.neutral.astype(np.float64), (chset.nframes, 1))
    poses[:, bf.dst] = chset.joint_data[:, bf.src]
    chan = next(c for c in chset.figure_channels() if c.column == bf.figure_channel)
    lift = np.maximum(0.0, -lowest_point(FigureKinematics(body), poses, chset.transforms(chan)))
    if chset.release_frame is not None:  # a death: lifted frame by frame, the prone body hopped 1.2 cm up
        lift = smooth_above(lift, LIFT_SIGMA_FRAMES)
    if lift.any():
        held = np.ones(chset.nframes, bool)  # the rifle rises with the hands only while they hold it
        if chset.release_frame is not None:
            held[chset.release_frame :] = False
        lifted = np.where(held[:, None], lift[:, None], 0.0).repeat(chset.fig_pos.shape[1], axis=1)
        lifted[:, chan.column] = lift
        chset.fig_pos[:, :, 1] += lifted.astype(np.float32)


def slave_one(
    chset: Channelset, pair: MasterSlavePair, ctx: BuildContext, figure: str, name: str
) -> Channelset:
    """One soldier.fig channelset re-recorded for DI.fig holding the AK (``figure="DI"``) or the M16."""
    from authoring.rifle_swap import reslave_holding
    from authoring.slaving import reslave_channelset

    if figure == "M16":
        out = reslave_holding(chset, pair, ctx.m16, name)
    else:
        out = reslave_channelset(chset, pair, name)
    # DI's kneecaps sit higher than the master's and its prone forearms float: put them down where his are;
    # its feet held where his are planted (the body no longer moves under them); last, a dead DI's trunk
    # turned so its pelvis and chest both rest on the ground (its torso is shaped differently), holding a
    # foot it hovers over the ground (DeathSpec.slave_feet_held), sliding its resting parts as far as the
    # death asks (slave_rest_slide_cm) or holding an arm lying there at the end (slave_arms_held); then,
    # where it asks (slave_arms_pinned), its hands and forearms on the ground held still where they rest
    spec = spec_of(chset.name)
    trunk: Callable[[Channelset, Channelset, FigureSet], object] = partial(
        rest_slave_trunk,
        feet_held=bool(spec and spec.slave_feet_held),
        slide_cm=spec.slave_rest_slide_cm if spec else None,
        arms_held=bool(spec and spec.slave_arms_held),
        heels_cm=spec.slave_heels_cm if spec else None,
    )
    rests: tuple[Callable[[Channelset, Channelset, FigureSet], object], ...] = (
        *((lay_slave_spine,) if spec and spec.slave_spine_laid else ()),  # first: its belly out by the spine
        rest_slave_knees,
        rest_slave_forearms,
        tilt_onto_knees,
        rest_limbs,
        plant_slave_feet,
        trunk,
        keep_slave_arms_down,  # where a death asks (slave_arms_down): no arm rising once the body is down
    )
    if spec and spec.slave_arms_pinned:
        rests += (pin_slave_arms,)
    if spec and spec.slave_belly_held:  # its root back by a share of its belly's slide (slave_belly_held)
        rests += (hold_slave_belly,)
    if spec and spec.slave_forearms_lying:  # then its forearms lie still where his do (slave_forearms_lying)
        rests += (lay_slave_forearms,)
    if spec and spec.slave_feet_slack:  # last: the feet go slack as his, from where the slave's lay
        rests += (slack_slave_feet,)
    if crawl_turn.eases_slave_wrists(chset.name.removesuffix(".chset")):  # a wrist flicking at its limits
        rests += (ease_slave_wrists,)
    if chset.name.removesuffix(".chset") == crawl_prone.NAME:  # last: its belly clear while he turns on it
        rests += (partial(lift_slave_belly, until_s=crawl_prone.TURN[1], fade_s=crawl_prone.BELLY_DOWN_S),)
        rests += (partial(lower_slave_feet, window=crawl_prone.SLAVE_FEET_DOWN),)  # ... its feet down as his
    stepped = steps_forearm(chset.name.removesuffix(".chset"))
    if figure == "DI" and (crawl.lifts_slave_forearms(chset.name.removesuffix(".chset")) or stepped):
        rests += (lift_slave_forearms,)  # last: its forearms down no longer than the master's (or stepped)
    laid = bool(spec and spec.slave_spine_laid)  # its trunk laid by its spine: nothing to lift it for ...
    for rest in rests:
        rest(chset, out, ctx.figure_set)
        if laid:  # ... nor its arms, out of the ground by the arm (slave_arms_lift)
            lift_slave_arms(out, ctx.figure_set)
        lift_off_ground(out, ctx.di)
    if spec and (spec.grounded or spec.slave_grounded):  # lowered where it hovers (authoring.grounded)
        ground_channelset(out, ctx.di, spec.grounded_until_down, spec.slave_grounded_leave)
    clear_rifle(out, ctx.figure_set)  # a dropped rifle: out of the body and the ground it now lies on
    return out


def slaving_context(ctx: BuildContext, name: str, master: Channelset) -> BuildContext:
    """The figures clip ``name``'s slaves are solved on: those of :meth:`BuildContext.passive` (a passive
    master and a passive slave) for a death (it ends in DEAD) whose ``master`` clip takes a leg past the
    live limits (:attr:`deaths.DeathSpec.legs_roll`: with its ankles and hips clamped to the active range
    the DI's heels stayed 15.2 cm up where the master's lie 11.4): the slave follows the master's legs into
    the passive range. Every other clip keeps the live figures (a kneeling death's slave solved on the
    passive ones: its knee jumped 20 degrees in a frame, its foot skated 3.8 cm)."""
    if name not in deaths.death_specs():
        return ctx
    body = protofiletype(ctx.soldier)
    poses = play(master, ctx.figure_set).poses[body]
    return ctx.passive() if past_live_limits(ctx.figure_set.kin[body], poses) else ctx


def slave_pair(ctx: BuildContext) -> MasterSlavePair:
    pair = MasterSlavePair(ctx.soldier, ctx.di, ctx.rifle)
    pair.slave_parameters(*SLAVE_PARAMETERS)
    return pair


# --- graphs and start-up files ------------------------------------------------------------------------------


def _end_node(t: transitions.TransitionSpec) -> str:
    """The graph node a transition ends in: a death's own DEAD variant (``DEAD@ststow``), else its posture."""
    return deaths.dead_node(t.name) if t.name in deaths.death_specs() else t.end


def static_graph(suffix: str) -> PostureGraph:
    """Figure 7: the postures, the 17 transition files and their arcs (reverse arcs play backwards).

    Each simulated death ends in its own DEAD variant node (``DEAD@<start>``, :mod:`authoring.deaths`)
    and plays at its recorded length (``-1``); getting up from it replays that death backwards, slowly
    (:data:`authoring.deaths.GET_UP_SECONDS`)."""
    files = [f"../channelsets/{t.name}{suffix}.chset.env" for t in transitions.TRANSITIONS]
    arcs: list[Arc] = []
    dying = deaths.death_specs()
    for i, t in enumerate(transitions.TRANSITIONS):
        if t.name in dying:
            arcs.append(Arc(t.start, _end_node(t), i, True, -1.0))
            arcs.append(Arc(_end_node(t), t.start, i, False, deaths.GET_UP_SECONDS))
            continue
        arcs.append(Arc(t.start, t.end, i, True, t.duration))
        arcs.append(Arc(t.end, t.start, i, False, t.duration))
    nodes = [p for p in postures.POSTURES if p != deaths.DEAD]
    nodes += [deaths.dead_node(d.name) for d in deaths.DEATHS]
    return PostureGraph(nodes, files, arcs)


def _container_graph(
    nodes: Sequence[str], arcs: Iterable[tuple[str, str, str, bool]], suffix: str
) -> PostureGraph:
    files: list[str] = []
    out: list[Arc] = []
    for a, b, clip, forward in arcs:
        path = f"../channelsets/{clip}{suffix}.chset.env"
        if path not in files:
            files.append(path)
        out.append(Arc(a, b, files.index(path), forward, -1.0))
    return PostureGraph(list(nodes), files, out)


def loco_graph(suffix: str) -> PostureGraph:
    return _container_graph(gait.LOCO_NODES, gait.loco_arcs(), suffix)


def crawl_graph(suffix: str) -> PostureGraph:
    return _container_graph(crawl.CRAWL_NODES, crawl.crawl_arcs(), suffix)


def turn_graph(suffix: str) -> PostureGraph:
    return _container_graph(turn_nodes(), turn_arcs(), suffix)


def turn_nodes() -> tuple[str, ...]:
    """The nodes of the turn graph: standing (STAND_STOWED) and on forearms and knees (CRAWL)."""
    return (*turns.TURN_NODES, crawl_turn.BASE)


def turn_arcs() -> list[tuple[str, str, str, bool]]:
    """The turn graph's self-loops: the standing turns and side-steps, then the turns on the ground."""
    return turns.turn_arcs() + crawl_turn.crawl_turn_arcs()


def react_graph(suffix: str) -> PostureGraph:
    return _container_graph(reactions.REACT_NODES, reactions.react_arcs(), suffix)


GRAPH_FILES: dict[str, dict[str, str]] = {
    "DI": {
        "static": "soldier_low.graph",
        "loco": "soldier_loco.graph",
        "crawl": "soldier_crawl.graph",
        "turn": "soldier_turn.graph",
        "react": "soldier_react.graph",
    },
    "soldier": {
        "static": "soldier_hi.graph",
        "loco": "soldier_loco_hi.graph",
        "crawl": "soldier_crawl_hi.graph",
        "turn": "soldier_turn_hi.graph",
        "react": "soldier_react_hi.graph",
    },
}
# the M16 library's graphs: the DI.fig ones with "_m16" before ".graph" (soldier_low_m16.graph, ...)
GRAPH_FILES["M16"] = {kind: name.replace(".graph", "_m16.graph") for kind, name in GRAPH_FILES["DI"].items()}
_GRAPH_HEADERS = {
    "static": "static posture transitions (seed 002, Figures 3 and 7)",
    "loco": "walking, backward walking and running (seed 002, 3.3 and Figure 5): a container of channelsets",
    "crawl": "crawling (seed 002, 3.3): a container of channelsets; crawl_start backwards ends a crawl",
    "turn": "turns in place and side-steps: a container of channelsets, each moving the soldier (end_offset)",
    "react": "reactions without a posture change (firing recoil, flinch): a self-loop per clip",
}


def graph_text(kind: str, figure_set: str) -> str:
    make = {
        "static": static_graph,
        "loco": loco_graph,
        "crawl": crawl_graph,
        "turn": turn_graph,
        "react": react_graph,
    }[kind]
    graph = make(SUFFIXES[figure_set])
    head = f"// {_GRAPH_HEADERS[kind]}; {HOLDS[figure_set]}. Generated by `ttes author build`.\n"
    return head + format_posture_graph(graph)


def environment_text() -> str:
    """``jack-ttes-soldier_low.env``: the soldier/rifle pairs ``Di2_i`` / ``AK_47_i``, two metres apart."""
    lines = [
        "// TTES start-up environment (seed 002, 3.6): 10 DI.fig soldiers with AK-47s, read by",
        "// jack-ttes-soldier_low.jcl. Generated by `ttes author build`.",
    ]
    for i in range(SOLDIERS):
        x = 200 * i
        lines.append(
            f'figure Di2_{i} {{ file = "../figures/DI.fig"; root = lower_torso.proximal; '
            f"location = trans({x}cm, 103.58cm, 0cm); }}"
        )
        lines.append(
            f'figure AK_47_{i} {{ file = "../figures/AK_47.fig"; root = rifle.proximal; '
            f"location = trans({x + 26}cm, 89cm, -2cm); }}"
        )
    return "\n".join(lines) + "\n"


def startup_jcl() -> str:
    """``jack-ttes-soldier_low.jcl`` for the shipped environment's soldiers (the server writes the same script
    for its synthetic data dir: one definition, :func:`server.world.synthetic.startup_jcl`)."""
    return synthetic.startup_jcl(SOLDIERS)


def write_graphs(root: Path, figure: str = "all") -> list[Path]:
    out_dir = root / "posture_graphs"
    out_dir.mkdir(parents=True, exist_ok=True)
    written: list[Path] = []
    sets = ("soldier", "DI", "M16") if figure == "all" else (figure,)
    for fs in sets:
        for kind, fname in GRAPH_FILES[fs].items():
            p = out_dir / fname
            p.write_text(graph_text(kind, fs), encoding="utf-8")
            written.append(p)
    if "DI" in sets:
        for fname, text in (
            ("jack-ttes-soldier_low.env", environment_text()),
            ("jack-ttes-soldier_low.jcl", startup_jcl()),
        ):
            p = out_dir / fname
            p.write_text(text, encoding="utf-8")
            written.append(p)
    return written


# --- the build ----------------------------------------------------------------------------------------------


def select(jobs: Sequence[ClipJob], only: str | None) -> list[ClipJob]:
    if not only:
        return list(jobs)
    return [j for j in jobs if fnmatch.fnmatchcase(j.name, only)]


def _graph_endpoints(kind: str) -> dict[str, list[tuple[str, int]]]:
    """Per posture node of a graph kind: the (clip, frame) where its arcs arrive or leave (-1 = last)."""
    if kind == "static":
        arcs = [(t.start, _end_node(t), t.name, True) for t in transitions.TRANSITIONS]
    elif kind == "loco":
        arcs = gait.loco_arcs()
    elif kind == "turn":
        arcs = turn_arcs()
    elif kind == "react":
        arcs = reactions.react_arcs()
    else:
        arcs = crawl.crawl_arcs()
    out: dict[str, list[tuple[str, int]]] = {}
    for a, b, clip, forward in arcs:
        out.setdefault(a, []).append((clip, 0 if forward else -1))
        out.setdefault(b, []).append((clip, -1 if forward else 0))
    return out


def snap_endpoints(
    chsets: dict[str, Channelset], committed: Callable[[str], Channelset | None] | None = None
) -> None:
    """Make the clips meeting at a posture node agree exactly there (joint channels, in place).

    Recorded soldier clips already meet exactly; re-slaved DI clips can differ by the slave solver's
    tolerance, so the first clip's pose at each node is copied to the others' endpoints (faded into them).
    When that clip is not among ``chsets`` (a partial build), ``committed(name)`` gives its file's version as
    the reference."""
    nodes: dict[str, list[tuple[str, int]]] = {}
    for kind in GRAPH_FILES["DI"]:  # a node of several graphs (STAND_STOWED, CRAWL) is one pose
        for node, ends in _graph_endpoints(kind).items():
            nodes.setdefault(node, []).extend(ends)
    for ends in nodes.values():
        have = [(c, f) for c, f in ends if c in chsets]
        if not have:
            continue
        first = chsets.get(ends[0][0])
        if first is None and committed is not None:
            first = committed(ends[0][0])
        ref_clip, ref_frame = (first, ends[0][1]) if first is not None else (chsets[have[0][0]], have[0][1])
        ref = ref_clip.joint_data[ref_frame].copy()
        for c, f in have:
            cols, frames = _head_held(chsets[c], c, f)
            solved = chsets[c].joint_data[:, cols].astype(np.float64)
            _snap_end(chsets[c].joint_data, f, ref)
            if frames:
                held = hold_in(solved, ref[cols], frames)
                chsets[c].joint_data[:, cols] = held.astype(chsets[c].joint_data.dtype)
            _snap_rifle(chsets[c], f, ref_clip, ref_frame)


def _head_held(cs: Channelset, clip: str, frame: int) -> tuple[list[int], int]:
    """The joint columns of ``cs``'s neck and head and over how many frames they blend from their start
    pose into ``clip`` (:attr:`authoring.deaths.DeathSpec.slave_head_held`; 0: not held)."""
    spec = deaths.death_specs().get(clip)
    if frame != 0 or spec is None or not spec.slave_head_held:
        return [], 0
    cols = [c.column + k for c in cs.joint_channels() if c.name in deaths.HEAD for k in range(c.width)]
    return cols, spec.slave_head_held


def hold_in(solved: np.ndarray, start: np.ndarray, frames: int) -> np.ndarray:
    """``solved`` ``(n, k)`` starting still at ``start``: blended from it into ``solved`` over ``frames``
    (smoothstep), so the first frames barely move whatever ``solved`` does there."""
    t = np.clip(np.arange(len(solved)) / frames, 0.0, 1.0)[:, None]
    s = t * t * (3.0 - 2.0 * t)
    return (1.0 - s) * start[None, :] + s * solved


def clamp_to_limits(chset: Channelset, body: Figure) -> None:
    """Keep ``body``'s joint channels of ``chset`` within the figure's joint limits (in place)."""
    bf = bind_channelset(chset, [body]).figures[0]
    kin = FigureKinematics(body)
    q = np.clip(chset.joint_data[:, bf.src], kin.lower[bf.dst], kin.upper[bf.dst])
    chset.joint_data[:, bf.src] = q.astype(chset.joint_data.dtype)


def _held_rifles(cs: Channelset, frame: int) -> tuple[np.ndarray, dict[str, tuple[int, np.ndarray]]]:
    """The body's root site frame at ``frame`` (0 or -1) and, by figure type, each rifle's (a figure channel
    without joints) column and position relative to it (none without a body channel)."""
    bodies = {c.protofiletype for c in cs.joint_channels()}
    figs = cs.figure_channels()
    body = next((c for c in figs if c.protofiletype in bodies), None)
    if body is None:
        return np.eye(4), {}
    root = cs.transforms(body)[frame]
    inv = np.linalg.inv(root)
    rifles = {
        c.protofiletype: (c.column, inv[:3, :3] @ cs.fig_pos[frame, c.column] + inv[:3, 3])
        for c in figs
        if c.protofiletype not in bodies
    }
    return root, rifles


def _snap_rifle(cs: Channelset, frame: int, ref: Channelset, ref_frame: int) -> None:
    """Where a slid rifle (:mod:`authoring.slave_rifle`: slid by each clip's own solve of the prone forearms)
    lies elsewhere at a clip's end than in ``ref`` at the same posture node, by more than ``SNAP_RIFLE_CM``
    relative to the body, put it where ``ref`` has it, the change faded into the clip like the joints' (the
    palms, snapped with the joints, stay on it). Below that the clips agree as recorded."""
    (root, mine), (_, theirs) = _held_rifles(cs, frame), _held_rifles(ref, ref_frame)
    for ptype, (col, at) in mine.items():
        if ptype in theirs and np.linalg.norm(theirs[ptype][1] - at) > SNAP_RIFLE_CM:
            pos = cs.fig_pos[:, col].astype(np.float64)
            pin_end(pos, frame, pos[frame] + root[:3, :3] @ (theirs[ptype][1] - at), SNAP_FADE_FRAMES)
            cs.fig_pos[:, col] = pos.astype(cs.fig_pos.dtype)


SNAP_RIFLE_CM = 0.5  # more than any two recorded clips differ by at a node (0.46 cm, KNEEL_STOWED)
SNAP_FADE_FRAMES = 12  # a snapped endpoint's change fades out over this many frames (0.2 s at 60 fps)


def _snap_end(data: np.ndarray, frame: int, ref: np.ndarray) -> None:
    """Set ``data[frame]`` (0 or -1) to ``ref`` and carry the change into the clip, fading out smoothly, so
    an endpoint that the slave solve put a little elsewhere in this clip does not jump at its first or last
    frame."""
    pin_end(data, frame, ref, SNAP_FADE_FRAMES)


def build(
    root: Path,
    figures_dir: Path,
    only: str | None = None,
    figure: str = "all",
    progress: bool = True,
) -> list[Path]:
    """Record the library under ``root`` (``channelsets/``, ``posture_graphs/``); returns files written."""
    if figure not in FIGURE_SETS:
        raise ValueError(f"figure must be one of {', '.join(FIGURE_SETS)}, not {figure!r}")
    ctx = BuildContext.load(figures_dir)
    jobs = select(clip_jobs(), only)
    if only and not jobs:
        raise ValueError(f"no clip matches {only!r}")
    chdir = root / "channelsets"
    chdir.mkdir(parents=True, exist_ok=True)
    hi: dict[str, Channelset] = {}
    slaved: dict[str, dict[str, Channelset]] = {fs: {} for fs in ("DI", "M16") if figure in (fs, "all")}
    pairs: dict[int, MasterSlavePair] = {}  # per figures slaved on (slaving_context)
    slaved_on: dict[str, BuildContext] = {}
    bar = _progress(jobs, progress)
    for job in bar:
        if hasattr(bar, "set_postfix_str"):
            bar.set_postfix_str(job.name)
        if figure in slaved and figure != "all":
            hi[job.name] = load_channelset(chdir / f"{job.name}.chset.env", use_cache=False)
        else:  # slave what the file will hold, so a DI-only rebuild from the files gives the same bytes
            hi[job.name] = parse_channelsets(
                format_channelset(record(job, ctx)), str(chdir / f"{job.name}.chset.env")
            )[0]
        if slaved:
            on = slaved_on[job.name] = slaving_context(ctx, job.name, hi[job.name])
            if id(on) not in pairs:
                pairs[id(on)] = slave_pair(on)
            pair = pairs[id(on)]
            for fs, out in slaved.items():
                out[job.name] = slave_one(hi[job.name], pair, on, fs, f"{job.name}{SUFFIXES[fs]}.chset")
    for fs, out in slaved.items():

        def committed(name: str, fs: str = fs) -> Channelset | None:
            path = chdir / f"{name}{SUFFIXES[fs]}.chset.env"
            return load_channelset(path, use_cache=False) if path.is_file() else None

        snap_endpoints(out, committed)
        for name, chset in out.items():  # a snapped end faded into a joint at its limit can pass it by a hair
            _settle(chset, name, hi[name], slaved_on[name], pairs[id(slaved_on[name])])
    written: list[Path] = []
    for name in (j.name for j in jobs):
        if figure in ("soldier", "all"):
            save_channelset(hi[name], chdir / f"{name}.chset.env")
            written.append(chdir / f"{name}.chset.env")
        for fs, out in slaved.items():
            path = chdir / f"{name}{SUFFIXES[fs]}.chset.env"
            save_channelset(out[name], path)
            written.append(path)
    written += write_graphs(root, figure)
    return written


def _settle(
    chset: Channelset, name: str, master: Channelset, on: BuildContext, pair: MasterSlavePair
) -> None:
    """A slave after the snap: a following reaction from its snapped posture as its master moves
    (:mod:`authoring.slave_reactions`), a death leaving its snapped start from rest and its arms leaving it
    late where it asks, every joint within its limits."""
    if name in reactions.FOLLOWING:
        follow_master(
            master,
            chset,
            pair,
            on.figure_set,
            name in reactions.RIFLE_TURNS,
            name in reactions.SHOULDERS_KEPT,
        )
    _ease_start(chset, name)
    _arms_late(chset, name, on.figure_set)
    clamp_to_limits(chset, on.di)


def _ease_start(chset: Channelset, name: str) -> None:
    """A slave of death ``name`` retimed to leave its start from rest (:mod:`authoring.slave_start`), where
    the death asks (:attr:`deaths.DeathSpec.slave_start_ease`): after the snap, its first frame kept."""
    spec = deaths.death_specs().get(name)
    if spec and spec.slave_start_ease:
        ease_slave_start(chset, spec.slave_start_ease)


def _arms_late(chset: Channelset, name: str, figures: FigureSet) -> None:
    """A slave of death ``name`` whose arms leave its snapped start late (:mod:`authoring.slave_arms_late`),
    where the death asks (:attr:`deaths.DeathSpec.slave_arms_late`)."""
    spec = deaths.death_specs().get(name)
    if spec and any(spec.slave_arms_late):
        lag_slave_arms(chset, figures, *spec.slave_arms_late)


def _progress(jobs: Sequence[ClipJob], enabled: bool) -> Iterable[ClipJob]:
    if not enabled:
        return jobs
    from tqdm import tqdm

    return tqdm(jobs, desc="ttes author build", unit="clip")
