"""Loaded and bound posture graphs and executing a posture change (seed 002, 3.4.2).

``load_posture_graph`` reads a ``.graph`` file and every channelset it lists (relative to the graph file,
through the ``.npz`` cache); ``bind_posture_graph`` binds each channelset to one soldier's figures (one figure
per protofiletype), naming the bound channelsets ``"<bound graph>/<channelset>"``. A :class:`PostureChange`
walks the quickest path to a goal posture: given the clock it says which bound channelset plays now, in which
direction and over what time, and moves on to the next arc exactly when one ends (the next arc starts at the
previous arc's end time, not at the tick that noticed it, so long paths do not drift).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from peabody.model import Figure
from server.motion.binding import BoundChannelset, BoundSample, bind_channelset, protofiletype
from server.motion.channelset import Channelset
from server.motion.errors import BindingError, PostureGraphError
from server.motion.playback import frame_position, nearest_frame
from server.motion.posture_graph import Arc, PostureGraph, read_posture_graph


@dataclass
class LoadedPostureGraph:
    """A posture graph with its channelsets loaded (``channelsets[token]``)."""

    name: str
    graph: PostureGraph
    channelsets: list[Channelset]

    @property
    def durations(self) -> list[float]:
        return [c.duration for c in self.channelsets]

    def arc_time(self, arc: Arc) -> float:
        return self.graph.arc_time(arc, self.durations)

    def shortest_path(self, start: str, goal: str) -> list[Arc]:
        return self.graph.shortest_path(start, goal, self.durations)

    @property
    def protofiletypes(self) -> list[str]:
        """Every figure file type the channelsets drive (each bound soldier needs one figure of each)."""
        return sorted({c.protofiletype for cs in self.channelsets for c in cs.channels})


def load_posture_graph(
    path: str | Path, name: str | None = None, *, use_cache: bool = True
) -> LoadedPostureGraph:
    """Read a ``.graph`` and its channelsets; a missing channelset file is a located PostureGraphError."""
    from server.motion.cache import load_channelset

    path = Path(path)
    graph = read_posture_graph(path)
    chsets: list[Channelset] = []
    for fname, line in zip(graph.files, graph.file_lines, strict=True):
        cpath = path.parent / fname
        if not cpath.is_file():
            raise PostureGraphError(
                f"channelset file {fname!r} not found (looked in {path.parent})", str(path), line
            )
        chsets.append(load_channelset(cpath, use_cache=use_cache))
    return LoadedPostureGraph(name or path.stem, graph, chsets)


@dataclass
class BoundPostureGraph:
    """A loaded posture graph bound to one soldier's figures; ``current`` is the posture it rests in."""

    name: str
    loaded: LoadedPostureGraph
    bound: list[BoundChannelset]  # by channelset token
    current: str

    @property
    def graph(self) -> PostureGraph:
        return self.loaded.graph

    def posture_change(self, goal: str, now: float) -> PostureChange:
        """Start moving from the current posture to ``goal`` along the quickest path."""
        return PostureChange(self, goal, now)

    @property
    def nbytes(self) -> int:
        return sum(b.nbytes for b in self.bound)


def bind_posture_graph(
    loaded: LoadedPostureGraph, figures: Sequence[Figure], name: str | None = None, initial: str | None = None
) -> BoundPostureGraph:
    """Bind every channelset of ``loaded`` to ``figures`` (which must include one figure of each type)."""
    have = {protofiletype(f) for f in figures}
    missing = [t for t in loaded.protofiletypes if t not in have]
    if missing:
        raise BindingError(f"posture graph {loaded.name!r} needs figures of type {', '.join(missing)}")
    gname = name or f"{figures[0].name}/{loaded.name}"
    bound = [bind_channelset(cs, figures, f"{gname}/{cs.name}") for cs in loaded.channelsets]
    start = initial if initial is not None else loaded.graph.postures[0]
    loaded.graph.token(start)
    return BoundPostureGraph(gname, loaded, bound, start)


@dataclass(frozen=True)
class Transition:
    """What plays now: one arc of a posture change."""

    arc: Arc
    bound: BoundChannelset
    forward: bool
    duration: float
    start_time: float

    @property
    def end_time(self) -> float:
        return self.start_time + self.duration

    def position(self, now: float, interpolate: bool = True) -> float:
        cs = self.bound.channelset
        pos, _ = frame_position(cs.nframes, cs.fps, self.forward, self.duration, now - self.start_time)
        return pos if interpolate else float(nearest_frame(pos, cs.nframes))


class PostureChange:
    """Executes the quickest path from the bound graph's current posture to ``goal`` in real time."""

    def __init__(self, graph: BoundPostureGraph, goal: str, now: float) -> None:
        self.graph = graph
        self.goal = goal
        self.path = graph.loaded.shortest_path(graph.current, goal)
        self.index = 0
        self._transition = self._make(0, float(now)) if self.path else None

    def _make(self, i: int, start: float) -> Transition:
        arc = self.path[i]
        return Transition(
            arc, self.graph.bound[arc.channelset], arc.forward, self.graph.loaded.arc_time(arc), start
        )

    @property
    def done(self) -> bool:
        return self.index >= len(self.path)

    @property
    def total_time(self) -> float:
        return float(sum(self.graph.loaded.arc_time(a) for a in self.path))

    def update(self, now: float) -> Transition | None:
        """The transition playing at ``now`` (the last one, held at its end, once done; None if no path).

        Arcs whose end time has passed complete, moving the bound graph's ``current`` posture along.
        """
        t = self._transition
        while t is not None and not self.done and now >= t.end_time:
            self.graph.current = t.arc.end
            self.index += 1
            if not self.done:
                t = self._transition = self._make(self.index, t.end_time)
        return t

    def sample(self, now: float, interpolate: bool = True) -> BoundSample | None:
        """Poses and placements at ``now`` (None for an empty path)."""
        t = self.update(now)
        if t is None:
            return None
        return t.bound.sample(t.position(now, interpolate), interpolate)
