"""Loaded and bound posture graphs (seed 002, 3.4.2).

``load_posture_graph`` reads a ``.graph`` file and every channelset it lists (relative to the graph file,
through the ``.npz`` cache); ``bind_posture_graph`` binds each channelset to one soldier's figures (one figure
per protofiletype), naming the bound channelsets ``"<bound graph>/<channelset>"``. Executing a posture change
is the soldier manager's (:meth:`~server.soldier.manager.SoldierManager.posture_change`): it plays the
quickest path for thousands of soldiers at once.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

from peabody.model import Figure
from server.motion.binding import BoundChannelset, bind_channelset, protofiletype
from server.motion.channelset import Channelset
from server.motion.errors import BindingError, PostureGraphError
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
    path: str | Path,
    name: str | None = None,
    *,
    use_cache: bool = True,
    cache_dir: str | Path | None = None,
    loader: Callable[[Path], Channelset] | None = None,
) -> LoadedPostureGraph:
    """Read a ``.graph`` and its channelsets (through ``loader`` when given: the server's store shares files
    has loaded); a missing channelset file is a located PostureGraphError."""
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
        if loader is not None:
            chsets.append(loader(cpath))
        else:
            chsets.append(load_channelset(cpath, use_cache=use_cache, directory=cache_dir))
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

    def shortest_path(self, goal: str) -> list[Arc]:
        """The quickest path (in time) from the posture this bound graph rests in to ``goal``."""
        return self.loaded.shortest_path(self.current, goal)

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
