"""The motion library a soldier manager plays from: the posture graphs bound into one ClipLibrary per set.

Seed 002, 3.4.2 and 3.6: Jack loads ``soldier_low.graph`` (static posture transitions), ``soldier_loco.graph``
(walking and running) and ``soldier_crawl.graph`` (crawling); the last two are only containers of channelsets.
Issue 11 added two more containers, loaded when present: ``soldier_turn.graph`` (turns in place and
side-steps, clips that move the soldier: ``end_offset``) and ``soldier_react.graph`` (recoil and flinch).
:class:`MotionLibrary` puts every channelset of the five into one
:class:`~server.motion.sampling.ClipLibrary` per *figure set* (soldier figure + weapon, e.g. ``DI.fig`` +
``AK_47.fig``), always in the same order so a clip id means the same clip in every set, and precomputes what
the manager needs per clip: which graph it came from (for the heading offsets), its stored duration, its
ground speed; per posture node the pose a resting soldier shows; per Figure-5 state and foot the locomotion
clip; and quickest paths between postures (cached).

Locomotion clips are found by name in the loco / crawl graphs: the file stem (``walk_start_l.chset.env`` →
``walk_start_l``; a ``_low``/``_high`` suffix is ignored) or the channelset name. Missing families degrade:
no ``run_*`` clips → no running; no ``bwalk_*`` → backward walking plays the forward walk backwards; no
``walk_*`` → standing soldiers do not walk; no crawl clips → prone soldiers do not crawl. A footless
``walk_cycle`` serves both feet.

**Local motion.** Updates carry motion relative to the soldier's feet; heading and position are the client's
(seed 3.7). A locomotion clip recorded travelling forwards would jump back at every cycle, so each loco/crawl
clip has the horizontal travel of its figure channels removed (a linear ramp from the first to the last frame,
only where the root site never changes) — every step then starts and ends over the same spot.

**Weapon variants** (issue 16): a weapon whose figure the graphs do not drive (``M16.fig`` beside graphs
made for ``AK_47.fig``) is played from its own graphs (``soldier_low_m16.graph`` …), which must have
the same postures, arcs and channelset files in the same order (the file names may differ by the weapon's
suffix, the frame counts must not): clip ids, durations, ground speeds and paths stay shared, only the
channels each set samples differ. ``weapon_graphs`` maps the weapon type to its graphs.

**Ground speed** (playback rate = speed / ground speed): the channelset's ``ground_speed`` field (cm/s) if
present, else ``stride_length`` (cm) / duration, else the travel measured above / duration, else
:data:`DEFAULT_GROUND_SPEED` for the clip's family (m/s).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from peabody.fk import FigureKinematics
from peabody.model import Figure
from server.motion.binding import protofiletype
from server.motion.channelset import Channelset
from server.motion.errors import PostureGraphError
from server.motion.posture_change import LoadedPostureGraph
from server.motion.posture_graph import posture_of
from server.motion.sampling import ClipLibrary
from server.soldier.locomotion import CLIP_OF, NSTATES
from server.soldier.root_motion import (
    TravelTable,
    feet_points,
    has_feet,
    linear_travel,
    side_turns,
    single_support_share,
    stance_contact,
    stance_count,
    stance_travel,
    step_turns,
)
from server.soldier.state import CRAWL_NODE, PRONE_NODES, STAND_STOWED, LocoState

GRAPH_STATIC, GRAPH_LOCO, GRAPH_CRAWL, GRAPH_TURN, GRAPH_REACT = 0, 1, 2, 3, 4
GRAPH_NAMES = ("static", "loco", "crawl", "turn", "react")
ARC_PREFIX = "crawlarc_"  # turn clips that carry the figure forward (a crawler turns on the move)

# m/s per clip family, used when a locomotion clip has no stride/ground-speed data and no measurable travel
DEFAULT_GROUND_SPEED: dict[str, float] = {
    "walk": 1.4,
    "bwalk": 0.9,
    "run": 4.0,
    "walk2run": 2.8,
    "run2walk": 2.8,
    "crawl": 0.4,
}
MIN_TRAVEL_CM = 1.0
_SUFFIXES = (".chset.env", ".env", ".chset")
_QUALITY = ("_low", "_high", "_hi", "_lo")


def clip_stem(filename: str) -> str:
    """``"walk_start_l_low.chset.env"`` → ``"walk_start_l_low"`` (the path and channelset suffix removed)."""
    name = filename.replace("\\", "/").rsplit("/", 1)[-1]
    for suf in _SUFFIXES:
        if name.endswith(suf):
            return name[: -len(suf)]
    return name


def _lookup_keys(stem: str) -> list[str]:
    keys = [stem]
    for q in _QUALITY:
        if stem.endswith(q):
            keys.append(stem[: -len(q)])
    return keys


def _family(base: str) -> str:
    if base.startswith("walk2run") or base.startswith("run2walk"):
        return base[:8]
    return base.split("_", 1)[0]


@dataclass(frozen=True)
class PathStep:
    """One arc of a posture change: play ``clip`` forwards or backwards over ``duration`` s into ``end``."""

    clip: int
    forward: bool
    duration: float
    start: int  # posture node index
    end: int


@dataclass(frozen=True)
class ClipInfo:
    name: str
    graph: int  # GRAPH_STATIC / GRAPH_LOCO / GRAPH_CRAWL
    duration: float  # stored seconds
    nframes: int
    fps: float
    ground_speed: float  # m/s (0 for static clips)
    travel_cm: float  # horizontal travel removed from the clip (0 if none)


class MotionLibrary:
    """The posture graphs bound to one or more figure sets as ClipLibraries with shared clip ids."""

    def __init__(
        self,
        static: LoadedPostureGraph,
        figure_sets: Sequence[Sequence[Figure]],
        loco: LoadedPostureGraph | None = None,
        crawl: LoadedPostureGraph | None = None,
        *,
        turn: LoadedPostureGraph | None = None,
        react: LoadedPostureGraph | None = None,
        in_place: bool = True,
        weapon_graphs: Mapping[str, GraphSet] | None = None,
    ) -> None:
        if not figure_sets:
            raise ValueError("a motion library needs at least one figure set")
        self.static, self.loco, self.crawl, self.turn, self.react = static, loco, crawl, turn, react
        self.postures: list[str] = list(static.graph.postures)  # node names (``DEAD@ststow``: a variant)
        self.posture_names: list[str] = [posture_of(p) for p in self.postures]  # what each node shows
        self._node = {p: i for i, p in enumerate(self.postures)}
        for i, p in enumerate(self.posture_names):  # a posture known only by variants: its first one
            self._node.setdefault(p, i)
        entries = _entries((static, loco, crawl, turn, react))
        infos: list[ClipInfo] = []
        prepared: list[Channelset] = []
        ref_type = protofiletype(figure_sets[0][0])
        for name, gi, cs, stem in entries:
            travel, gs = 0.0, 0.0
            if gi not in (GRAPH_STATIC, GRAPH_REACT):
                gs_travel = _travel(cs, ref_type)
                gs = _ground_speed(cs, gs_travel, _family(_lookup_keys(stem)[-1]))
                cs, travel = _strip_travel(cs, ref_type) if in_place and _strips(gi, cs) else (cs, 0.0)
            infos.append(ClipInfo(name, gi, cs.duration, cs.nframes, cs.fps, gs, travel))
            prepared.append(dataclasses.replace(cs, name=name))
        self.clips = infos
        self.sources: list[Channelset] = [cs for _, _, cs, _ in entries]  # as loaded, by clip id
        self.clip_names = [c.name for c in infos]
        self.sets: list[ClipLibrary] = []
        self.set_keys: list[tuple[str, str]] = []
        variants = {
            w: _variant_channelsets(entries, _entries(g), w, ref_type, in_place)
            for w, g in (weapon_graphs or {}).items()
        }
        for figs in figure_sets:
            lib = ClipLibrary(list(figs))
            weapon = protofiletype(figs[1]) if len(figs) > 1 else ""
            lib.extend(variants.get(weapon, prepared))
            if self.sets and (lib.ndof, lib.nfig) != (self.sets[0].ndof, self.sets[0].nfig):
                raise ValueError(
                    f"figure set {lib.name!r} has {lib.ndof} DOFs / {lib.nfig} figures, "
                    f"{self.sets[0].name!r} has {self.sets[0].ndof} / {self.sets[0].nfig}"
                )
            self.sets.append(lib)
            types = [protofiletype(f) for f in figs]
            self.set_keys.append((types[0], types[1] if len(types) > 1 else ""))
        first = self.sets[0]
        self.ndof, self.nfig = first.ndof, first.nfig
        self.clip_graph = np.array([c.graph for c in infos], np.int8)
        self.clip_duration = np.array([c.duration for c in infos], np.float64)
        self.clip_nframes = np.array([c.nframes for c in infos], np.int64)
        self.clip_last = np.maximum(self.clip_nframes - 1, 0)  # each clip's last frame (root_motion.frame_at)
        self.clip_ground_speed = np.array([c.ground_speed for c in infos], np.float64)
        self.clip_frame_time = self.clip_duration / np.maximum(self.clip_nframes - 1, 1)
        # end_offset (x cm, z cm, yaw degrees) of clips that move the soldier (turns, side-steps), else 0
        self.clip_end_offset = np.array(
            [tuple(cs.end_offset) if cs.end_offset is not None else (0.0, 0.0, 0.0) for cs in self.sources],
            np.float64,
        ).reshape(-1, 3)
        # turns in place per posture node (STAND_STOWED; CRAWL, on forearms and knees): (clip id, compass
        # degrees it turns, clockwise positive)
        self.node_turns: dict[int, list[tuple[int, float]]] = {}
        # ... and those that carry the figure forward as they turn (ARC_PREFIX: a crawler's, on the move)
        self.node_arcs: dict[int, list[tuple[int, float]]] = {}
        if turn is not None:
            base = next(k for k, e in enumerate(entries) if e[1] == GRAPH_TURN)
            for arc in turn.graph.arcs:
                cid = base + arc.channelset
                if arc.start == arc.end and arc.start in self._node and self.clip_end_offset[cid, 2] != 0.0:
                    moving = clip_stem(turn.graph.files[arc.channelset]).startswith(ARC_PREFIX)
                    into = self.node_arcs if moving else self.node_turns
                    into.setdefault(self._node[arc.start], []).append(
                        (cid, -float(self.clip_end_offset[cid, 2]))
                    )
        # ... standing (the pivots of walking soldiers too)
        self.turn_clips: list[tuple[int, float]] = self.node_turns.get(self._node.get(STAND_STOWED, -1), [])
        # a prone soldier turns on forearms and knees: up to CRAWL, the turn there, down again
        crawl_node = self._node.get(CRAWL_NODE, -1)
        self.turn_via: dict[int, int] = {
            self._node[p]: crawl_node
            for p in PRONE_NODES
            if p in self._node and crawl_node in self.node_turns
        }
        # the nodes whose figure keeps its orientation in the world when its entity turns (turns in place)
        self.faces_world = np.zeros(len(self.postures), bool)
        self.faces_world[[*self.node_turns, *self.turn_via]] = True
        self.static_clip = list(range(len(static.graph.files)))  # static clips come first, by token
        self._loco_table(entries)
        # reactions without a posture change: (posture, "recoil" | "flinch") -> clip id (soldier_react.graph)
        self.reaction: dict[tuple[str, str], int] = {}
        if react is not None:
            base = next(k for k, e in enumerate(entries) if e[1] == GRAPH_REACT)
            for arc in react.graph.arcs:
                stem = _lookup_keys(clip_stem(react.graph.files[arc.channelset]))[-1]
                self.reaction.setdefault(
                    (posture_of(arc.start), stem.rsplit("_", 1)[-1]), base + arc.channelset
                )
        self.travel = self._travel_table(figure_sets[0][0])
        self._rest_poses()
        self._paths: dict[tuple[int, int], tuple[PathStep, ...] | None] = {}
        self._variant_goals()

    # -- construction helpers ----------------------------------------------------------------------------
    def _loco_table(self, entries: list[tuple[str, int, Channelset, str]]) -> None:
        by_key: dict[tuple[int, str], int] = {}
        for cid, (_, gi, _, stem) in enumerate(entries):
            if gi in (GRAPH_STATIC, GRAPH_REACT):
                continue
            for k in _lookup_keys(stem):
                by_key.setdefault((gi, k), cid)
        self.loco_clip = np.full((NSTATES, 2), -1, np.int32)
        self.loco_dir = np.ones(NSTATES, np.int8)
        for state, (base, footed, direction) in CLIP_OF.items():
            gi = (
                GRAPH_CRAWL
                if base.startswith("crawl")
                else GRAPH_TURN
                if base.startswith("side")
                else GRAPH_LOCO
            )
            for foot, suffix in ((0, "_l"), (1, "_r")):
                clip = by_key.get((gi, base + suffix)) if footed else None
                if clip is None:
                    clip = by_key.get((gi, base))
                if clip is None and footed:  # only one foot recorded: use it for both
                    clip = by_key.get((gi, base + ("_r" if foot == 0 else "_l")))
                if clip is not None:
                    self.loco_clip[state, foot] = clip
            self.loco_dir[state] = direction
        s = LocoState
        # a gait transition recorded once (no _l/_r variants) swings the right foot: see locomotion.GAIT_STAY
        self.transition_foot = np.full(NSTATES, -1, np.int8)
        for state in (s.WALK2RUN, s.RUN2WALK):
            base = CLIP_OF[state][0]
            if (GRAPH_LOCO, base + "_l") not in by_key and (GRAPH_LOCO, base + "_r") not in by_key:
                self.transition_foot[state] = 1
        have = np.asarray((self.loco_clip >= 0).all(axis=1))
        self.can_walk = bool(have[[s.WALK_START, s.WALK_CYCLE, s.WALK_END]].all()) and (
            STAND_STOWED in self._node
        )
        self.can_run = self.can_walk and bool(
            have[[s.RUN_START, s.RUN_CYCLE, s.RUN_END, s.WALK2RUN, s.RUN2WALK]].all()
        )
        if self.can_walk and not have[[s.BWALK_START, s.BWALK_CYCLE, s.BWALK_END]].all():
            # no backward recordings: a backward step is the forward step played backwards, the start step
            # reversed being the end step (and vice versa)
            for b, f in (
                (s.BWALK_START, s.WALK_END),
                (s.BWALK_CYCLE, s.WALK_CYCLE),
                (s.BWALK_END, s.WALK_START),
            ):
                self.loco_clip[b] = self.loco_clip[f]
                self.loco_dir[b] = -1
        self.can_side = self.can_walk and bool(have[[s.SIDESTEP_L, s.SIDESTEP_R]].all())
        self.can_crawl = bool(have[[s.CRAWL_START, s.CRAWL_CYCLE, s.CRAWL_END]].all()) and (
            CRAWL_NODE in self._node
        )

    def _travel_table(self, figure: Figure) -> TravelTable:
        """Each clip's own travel (:mod:`~server.soldier.root_motion`): measured from the planted feet for
        walking, running and side-steps, the stride spread evenly for crawling (hands and knees carry it) or
        a figure without sole sites, none for posture changes, turns (their yaw is the entity's) and
        reactions. Turns in place keep where their weight is (``TravelTable.contact``), for a reversal's pivot
        (:func:`~server.soldier.root_motion.pivot`)."""
        kin = FigureKinematics(figure)
        feet = has_feet(kin)
        first = self.sets[0]
        sl = first.figure_slice(protofiletype(figure))
        stepping = {int(c) for c in self.loco_clip.ravel() if c >= 0}
        sides = self.loco_clip[[LocoState.SIDESTEP_L, LocoState.SIDESTEP_R]].ravel()
        side = {int(c) for c in sides if c >= 0}  # they turn in their single-support stances
        curves: list[np.ndarray] = []
        contacts: list[np.ndarray] = []
        shares: list[np.ndarray] = []
        stances = [1] * len(self.clips)
        turns: list[np.ndarray | None] = [None] * len(self.clips)
        for cid, info in enumerate(self.clips):
            n = info.nframes
            contacts.append(np.zeros((n, 2)))
            shares.append(np.linspace(0.0, 1.0, n) if n > 1 else np.zeros(n))
            if cid not in stepping or n < 2:
                curves.append(np.zeros((n, 2)))
                if feet and n >= 2 and info.graph == GRAPH_TURN and self.clip_end_offset[cid, 2] != 0.0:
                    points = self._feet(kin, cid, sl)
                    contacts[-1] = stance_contact(points)
                    shares[-1] = single_support_share(points)
                    stances[cid] = stance_count(points)
                continue
            if info.graph == GRAPH_CRAWL or not feet:
                curves.append(linear_travel(n, self._travel_vector(cid)))
                continue
            points = self._feet(kin, cid, sl)
            curves.append(stance_travel(points, self.sources[cid].stride_length))
            turns[cid], contacts[-1] = (side_turns if cid in side else step_turns)(points)
        return TravelTable(curves, contacts, shares, stances, turns)

    def _feet(self, kin: FigureKinematics, cid: int, sl: slice) -> np.ndarray:
        """The sole points of clip ``cid``'s every stored frame (``root_motion.feet_points``)."""
        n = self.clips[cid].nframes
        t = np.arange(n) * self.clip_frame_time[cid]
        s = self.sets[0].sample(
            np.full(n, cid),
            np.zeros(n),
            np.ones(n),
            np.full(n, self.clips[cid].duration),
            t,
            interpolate=False,
        )
        return feet_points(kin, s.joints[:, sl], s.figures[:, 0])

    def _travel_vector(self, cid: int) -> np.ndarray:
        """(X, Z cm) a clip carries the soldier: its recorded root travel, else its ground speed times its
        duration along its family's direction (forwards -Z, backwards +Z, left -X, right +X)."""
        cs = self.sources[cid]
        d = (
            (cs.fig_pos[-1, 0] - cs.fig_pos[0, 0]).astype(np.float64)[[0, 2]]
            if cs.nframes > 1
            else np.zeros(2)
        )
        if math.hypot(*d) >= MIN_TRAVEL_CM:
            return d
        stem = self.clip_names[cid].rsplit("/", 1)[-1]
        direction = {"bwalk": (0.0, 1.0), "sidestep_l": (-1.0, 0.0), "sidestep_r": (1.0, 0.0)}
        key = next((k for k in direction if stem.startswith(k)), None)
        unit = np.array(direction[key] if key else (0.0, -1.0))
        return unit * self.clips[cid].ground_speed * 100.0 * self.clips[cid].duration

    def _rest_poses(self) -> None:
        """Per posture node a clip held at the frame that shows the posture (``rest_dir`` +1: last frame)."""
        n = len(self.postures)
        self.rest_clip = np.zeros(n, np.int32)
        self.rest_dir = np.ones(n, np.int8)
        g = self.static.graph
        for node, p in enumerate(self.postures):
            arc = next((a for a in g.arcs if a.end == p), None)
            if arc is not None:  # ends there: forwards → last frame, backwards → first frame
                self.rest_clip[node], self.rest_dir[node] = arc.channelset, 1 if arc.forward else -1
                continue
            arc = next((a for a in g.arcs if a.start == p), None)
            if arc is not None:  # starts there: forwards → first frame, backwards → last frame
                self.rest_clip[node], self.rest_dir[node] = arc.channelset, -1 if arc.forward else 1

    def _variant_goals(self) -> None:
        """``goal_node[current, goal]``: the node to head for when asked for ``goal``'s posture while resting
        in ``current`` — ``goal`` itself, except for a posture with variant nodes (``DEAD@...``): the variant
        reached quickest (``current`` itself when it is one). Precomputed, so a request costs one lookup."""
        n = len(self.postures)
        g = self.static.graph
        self.goal_node = np.tile(np.arange(n, dtype=np.int16), (n, 1))
        for goal, posture in enumerate(self.posture_names):
            if len(g.variants(posture)) < 2:
                continue
            for cur in range(n):
                try:
                    best = g.nearest(self.postures[cur], posture, self.static.durations)
                except PostureGraphError:
                    continue
                self.goal_node[cur, goal] = self._node[best]

    # -- queries -----------------------------------------------------------------------------------------
    @property
    def nclips(self) -> int:
        return len(self.clips)

    def node(self, posture: str) -> int:
        try:
            return self._node[posture]
        except KeyError:
            raise KeyError(f"posture graph {self.static.name!r} has no posture {posture!r}") from None

    def has_node(self, posture: str) -> bool:
        return posture in self._node

    def clip_id(self, name: str) -> int:
        """A clip id by full name (``"soldier_loco/walk_cycle_l"``) or by stem if that is unambiguous."""
        if name in self.clip_names:
            return self.clip_names.index(name)
        hits = [i for i, c in enumerate(self.clip_names) if name in _lookup_keys(c.rsplit("/", 1)[-1])]
        if len(hits) == 1:
            return hits[0]
        raise KeyError(f"no clip {name!r}" if not hits else f"clip name {name!r} is ambiguous")

    def clip_end_node(self, clip: int, forward: bool, node: int) -> int:
        """The posture node a soldier resting in ``node`` is in after playing ``clip``: a static arc's end
        (its start when played against the arc), any other clip leaves it where it was."""
        for arc in self.static.graph.arcs:
            if arc.channelset == clip and clip in self.static_clip:
                return self._node[arc.end if forward == arc.forward else arc.start]
        return node

    def clip_of(self, channelset: Channelset) -> int:
        """The clip id of a channelset the library was built from (the same loaded object); KeyError."""
        for cid, source in enumerate(self.sources):
            if source is channelset:
                return cid
        raise KeyError(f"channelset {channelset.name!r} is not a clip of the motion library")

    def set_index(self, figure: str, weapon: str) -> int:
        """The figure set of ``figure`` + ``weapon`` file names (base names compared)."""
        fig, wpn = figure.rsplit("/", 1)[-1], weapon.rsplit("/", 1)[-1]
        for i, (f, w) in enumerate(self.set_keys):
            if f == fig and wpn in ("", w):
                return i
        raise KeyError(f"no figure set for figure {figure!r} with weapon {weapon!r} (have {self.set_keys})")

    def path(self, start: int, goal: int) -> tuple[PathStep, ...] | None:
        """Quickest path in time between posture nodes (None if unreachable; () if the same)."""
        key = (start, goal)
        if key not in self._paths:
            try:
                arcs = self.static.shortest_path(self.postures[start], self.postures[goal])
            except PostureGraphError:
                self._paths[key] = None
            else:
                self._paths[key] = tuple(
                    PathStep(
                        self.static_clip[a.channelset],
                        a.forward,
                        float(self.static.arc_time(a)),
                        self._node[a.start],
                        self._node[a.end],
                    )
                    for a in arcs
                )
        return self._paths[key]

    @property
    def nbytes(self) -> int:
        return sum(s.nbytes for s in self.sets)


# (static, loco, crawl, turn, react): the static graph is required, the others are loaded when present
GraphSet = tuple[
    LoadedPostureGraph,
    LoadedPostureGraph | None,
    LoadedPostureGraph | None,
    LoadedPostureGraph | None,
    LoadedPostureGraph | None,
]


def _entries(graphs: GraphSet) -> list[tuple[str, int, Channelset, str]]:
    """(clip name, graph, channelset, file stem) of every channelset of the five graphs, in clip-id order."""
    out: list[tuple[str, int, Channelset, str]] = []
    order = (GRAPH_STATIC, GRAPH_LOCO, GRAPH_CRAWL, GRAPH_TURN, GRAPH_REACT)
    for gi, loaded in zip(order, graphs, strict=True):
        if loaded is None:
            continue
        for fname, cs in zip(loaded.graph.files, loaded.channelsets, strict=True):
            stem = clip_stem(fname)
            out.append((f"{loaded.name}/{stem}", gi, cs, stem))
    return out


def _variant_channelsets(
    base: list[tuple[str, int, Channelset, str]],
    variant: list[tuple[str, int, Channelset, str]],
    weapon: str,
    ref_type: str,
    in_place: bool,
) -> list[Channelset]:
    """A weapon variant's channelsets in the base clip order, named as the base clips (ValueError unless the
    graphs match clip for clip: same graph, same stem but for the weapon's suffix, same frames and rate)."""
    if len(variant) != len(base):
        raise ValueError(f"the {weapon} graphs have {len(variant)} channelsets, the base graphs {len(base)}")
    suffix = weapon_suffix(weapon)
    out: list[Channelset] = []
    for (name, gi, cs0, stem0), (_, gv, cs, stem) in zip(base, variant, strict=True):
        same_stem = stem.replace(suffix, "", 1) == stem0
        if gv != gi or not same_stem or (cs.nframes, cs.fps) != (cs0.nframes, cs0.fps):
            raise ValueError(f"the {weapon} clip {stem!r} does not match the base clip {stem0!r}")
        if in_place and _strips(gi, cs0):  # exactly as the base clip
            cs, _ = _strip_travel(cs, ref_type)
        out.append(dataclasses.replace(cs, name=name))
    return out


def weapon_suffix(weapon: str) -> str:
    """What a weapon's graph and channelset names carry: ``"M16.fig"`` → ``"_m16"``."""
    stem = weapon.replace("\\", "/").rsplit("/", 1)[-1].removesuffix(".fig")
    return "_" + "".join(c if c.isalnum() else "_" for c in stem.lower())


def _soldier_channel(cs: Channelset, ref_type: str) -> int:
    figs = cs.figure_channels()
    for c in figs:
        if c.protofiletype == ref_type:
            return c.column
    return figs[0].column if figs else -1


def _travel(cs: Channelset, ref_type: str) -> float:
    k = _soldier_channel(cs, ref_type)
    if k < 0 or cs.nframes < 2 or (cs.fig_root[:, k] != cs.fig_root[0, k]).any():
        return 0.0
    d = cs.fig_pos[-1, k].astype(np.float64) - cs.fig_pos[0, k]
    return float(math.hypot(d[0], d[2]))  # Jack: Y up, X/Z horizontal


def _strips(graph: int, cs: Channelset) -> bool:
    """Whether a clip loses its horizontal travel (local motion): locomotion and crawl clips do; static clips
    and reactions have none, and a turn's move (``end_offset``) is the entity's to make."""
    turns = cs.end_offset is not None and cs.end_offset[2] != 0.0
    return graph not in (GRAPH_STATIC, GRAPH_REACT) and not turns


def _strip_travel(cs: Channelset, ref_type: str) -> tuple[Channelset, float]:
    """The clip with its soldier's horizontal travel removed from all figure channels; the travel (cm)."""
    travel = _travel(cs, ref_type)
    if travel < MIN_TRAVEL_CM:
        return cs, 0.0
    k = _soldier_channel(cs, ref_type)
    d = cs.fig_pos[-1, k].astype(np.float64) - cs.fig_pos[0, k]
    d[1] = 0.0
    ramp = np.linspace(0.0, 1.0, cs.nframes)[:, None, None] * d[None, None, :]
    pos = (cs.fig_pos.astype(np.float64) - ramp).astype(np.float32)
    return dataclasses.replace(cs, fig_pos=pos), travel


def _ground_speed(cs: Channelset, travel_cm: float, family: str) -> float:
    gs = cs.ground_speed
    if gs:  # recorded (0 or absent: derive it)
        return gs / 100.0
    stride = cs.stride_length or None
    if stride is None and travel_cm >= MIN_TRAVEL_CM:
        stride = travel_cm
    if stride is not None and cs.duration > 0:
        return stride / 100.0 / cs.duration
    return DEFAULT_GROUND_SPEED.get(family, DEFAULT_GROUND_SPEED["walk"])
