"""Posture graph files (seed 002, 3.4.2, Figure 7) and shortest paths in time.

A ``.graph`` file has three sections, each ended by a line starting with ``#``; ``//`` starts a comment
anywhere and blank lines are ignored::

    8                        // number of postures, then "token NAME" lines, tokens 0,1,2,... in order
    0 STAND_STOWED
    ...
    #
    17                       // number of channelset files, then "token filename" lines
    0 ststow2stfire_low.chset.env
    ...
    #
    STAND_STOWED STAND_FIRE 0 forward 0.8   // start end channelset-token forward|backward time-in-seconds
    ...
    #                        // optional at end of file

Arc times are seconds (> 0), or -1 for the channelset's stored duration. Nodes are static postures; an arc
plays a channelset forwards or backwards (reverse transitions reuse the forward recording). Every malformed
file raises :class:`PostureGraphError` naming the file and line.

**Variant nodes.** A node ``NAME@variant`` (e.g. ``DEAD@ststow``: dead the way a standing soldier falls) is
a variant of posture ``NAME`` (:func:`posture_of`): asked for posture ``NAME``, a path goes to the variant it
reaches first (:meth:`PostureGraph.nearest`), and a soldier already in one stays.
"""

from __future__ import annotations

import heapq
import math
import re
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

from server.motion.errors import PostureGraphError

_INT = re.compile(r"[+-]?[0-9]+", re.ASCII)
_FLOAT = re.compile(r"[+-]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][+-]?[0-9]+)?", re.ASCII)
_DIRECTIONS = {"forward": True, "forwards": True, "backward": False, "backwards": False}


def posture_of(node: str) -> str:
    """The posture a node shows: ``DEAD@ststow`` -> ``DEAD``; a plain node is its own posture."""
    return node.partition("@")[0]


@dataclass(frozen=True)
class Arc:
    """A directed transition: play channelset ``channelset`` (a file token) forwards or backwards."""

    start: str
    end: str
    channelset: int
    forward: bool
    time: float  # seconds; -1 = the channelset's stored duration
    line: int | None = field(default=None, compare=False)

    @property
    def direction(self) -> str:
        return "forward" if self.forward else "backward"


@dataclass
class PostureGraph:
    """Postures (index = token), channelset files (index = token) and arcs, as read from a ``.graph`` file."""

    postures: list[str]
    files: list[str]
    arcs: list[Arc]
    filename: str = "<string>"
    file_lines: list[int | None] = field(default_factory=list, compare=False)

    def __post_init__(self) -> None:
        if not self.file_lines:
            self.file_lines = [None] * len(self.files)
        self._tokens = {p: i for i, p in enumerate(self.postures)}

    def variants(self, posture: str) -> list[str]:
        """The nodes that show ``posture`` (the node itself, or its ``posture@...`` variants)."""
        return [p for p in self.postures if posture_of(p) == posture_of(posture)]

    def nearest(self, start: str, posture: str, durations: Sequence[float] | None = None) -> str:
        """The node of ``posture`` (any variant) to head for from ``start``: ``start`` itself when it is one;
        else the quickest variant one arc away (a kneeling soldier dies his kneeling death, even when
        standing up first and dying standing would end sooner); else the variant reached quickest. An exact
        node name is returned as it is."""
        self.token(start)
        if posture in self._tokens:
            return posture
        if posture_of(start) == posture:
            return start
        options = self.variants(posture)
        if not options:
            raise PostureGraphError(f"unknown posture {posture!r}", self.filename)
        direct = [(self.arc_time(a, durations), self._tokens[a.end], a.end) for a in self.arcs_from(start)]
        direct = [d for d in direct if d[2] in options]
        if direct:
            return min(direct)[2]
        best, _ = self._dijkstra(start, durations)
        reached = [p for p in options if p in best]
        if not reached:
            raise PostureGraphError(f"posture {posture!r} cannot be reached from {start!r}", self.filename)
        return min(reached, key=lambda p: (best[p], self._tokens[p]))

    def token(self, posture: str) -> int:
        try:
            return self._tokens[posture]
        except KeyError:
            raise PostureGraphError(f"unknown posture {posture!r}", self.filename) from None

    def arcs_from(self, posture: str) -> list[Arc]:
        return [a for a in self.arcs if a.start == posture]

    def arc_time(self, arc: Arc, durations: Sequence[float] | None = None) -> float:
        """Seconds the arc takes; ``-1`` resolves through ``durations`` (stored time per channelset token)."""
        if arc.time > 0:
            return arc.time
        if durations is None:
            raise PostureGraphError(
                f"arc {arc.start} -> {arc.end} uses the stored time (-1): load the channelsets first",
                self.filename,
                arc.line,
            )
        return float(durations[arc.channelset])

    def shortest_path(self, start: str, goal: str, durations: Sequence[float] | None = None) -> list[Arc]:
        """The arcs of the quickest route from ``start`` to ``goal`` (Dijkstra over arc times; [] if same).
        A ``goal`` that names a posture with variant nodes goes to the nearest variant."""
        self.token(start)
        if goal not in self._tokens and self.variants(goal):
            goal = self.nearest(start, goal, durations)
        self.token(goal)
        if start == goal:
            return []
        _, via = self._dijkstra(start, durations, goal)
        if goal not in via:
            raise PostureGraphError(f"posture {goal!r} cannot be reached from {start!r}", self.filename)
        path: list[Arc] = []
        node = goal
        while node != start:
            arc = via[node]
            path.append(arc)
            node = arc.start
        path.reverse()
        return path

    def _dijkstra(
        self, start: str, durations: Sequence[float] | None, goal: str | None = None
    ) -> tuple[dict[str, float], dict[str, Arc]]:
        """Quickest times from ``start`` (to every node, or until ``goal`` is settled), the arc into each."""
        adjacency: dict[str, list[tuple[float, Arc]]] = {p: [] for p in self.postures}
        for arc in self.arcs:
            adjacency[arc.start].append((self.arc_time(arc, durations), arc))
        best: dict[str, float] = {start: 0.0}
        via: dict[str, Arc] = {}
        heap: list[tuple[float, int, str]] = [(0.0, 0, start)]
        counter = 1
        done: set[str] = set()
        while heap:
            dist, _, node = heapq.heappop(heap)
            if node in done:
                continue
            done.add(node)
            if node == goal:
                break
            for t, arc in adjacency[node]:
                nd = dist + t
                if arc.end not in done and nd < best.get(arc.end, math.inf):
                    best[arc.end] = nd
                    via[arc.end] = arc
                    heapq.heappush(heap, (nd, counter, arc.end))
                    counter += 1
        return {p: d for p, d in best.items() if p in done}, {p: a for p, a in via.items() if p in done}

    def path_time(self, path: Sequence[Arc], durations: Sequence[float] | None = None) -> float:
        return float(sum(self.arc_time(a, durations) for a in path))


# --- reading -----------------------------------------------------------------------------------------------


def _decode(data: str | bytes, filename: str) -> str:
    if isinstance(data, str):
        return data
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = data.count(b"\n", 0, exc.start) + 1
        raise PostureGraphError("not UTF-8 text", filename, line) from None


def parse_posture_graph(data: str | bytes, filename: str = "<string>") -> PostureGraph:
    """Parse ``.graph`` text (see the module docstring)."""
    text = _decode(data, filename)

    def fail(msg: str, line: int) -> PostureGraphError:
        return PostureGraphError(msg, filename, line)

    postures: list[str] = []
    files: list[str] = []
    file_lines: list[int | None] = []
    arcs: list[Arc] = []
    names: dict[str, int] = {}
    section = 0  # 0: postures, 1: files, 2: arcs, 3: after the arcs
    counts: list[int] = []
    last_line = 1
    for lineno, raw in enumerate(text.split("\n"), 1):
        line = raw.split("//", 1)[0].strip()
        if not line:
            continue
        last_line = lineno
        if line.startswith("#"):
            if section < 2:
                entries = postures if section == 0 else files
                what = "postures" if section == 0 else "channelset files"
                if not counts or len(counts) <= section:
                    raise fail(f"'#' before the number of {what}", lineno)
                if len(entries) != counts[section]:
                    raise fail(f"declared {counts[section]} {what}, found {len(entries)}", lineno)
            section += 1
            continue
        fields = line.split()
        if section == 3:
            raise fail("text after the end of the arcs section", lineno)
        if section < 2:
            what = "postures" if section == 0 else "channelset files"
            if len(counts) <= section:
                if len(fields) != 1 or not _INT.fullmatch(fields[0]) or int(fields[0]) < 0:
                    raise fail(f"expected the number of {what}", lineno)
                counts.append(int(fields[0]))
                continue
            entries = postures if section == 0 else files
            if len(fields) != 2 or not _INT.fullmatch(fields[0]):
                raise fail(f"expected 'token name' in the {what} section", lineno)
            token = int(fields[0])
            if token != len(entries):
                raise fail(f"token {token} out of order: tokens start at 0 and are consecutive", lineno)
            if token >= counts[section]:
                raise fail(f"more {what} than the declared {counts[section]}", lineno)
            if section == 0:
                if fields[1] in names:
                    raise fail(f"duplicate posture {fields[1]!r}", lineno)
                names[fields[1]] = token
                postures.append(fields[1])
            else:
                files.append(fields[1])
                file_lines.append(lineno)
            continue
        # arcs
        if len(fields) != 5:
            raise fail("expected 'start end channelset forward|backward time'", lineno)
        start, end, tok, direction, time_text = fields
        for p in (start, end):
            if p not in names:
                raise fail(f"unknown posture {p!r}", lineno)
        if not _INT.fullmatch(tok) or not 0 <= int(tok) < len(files):
            raise fail(f"channelset token {tok!r} is not one of 0..{len(files) - 1}", lineno)
        if direction.lower() not in _DIRECTIONS:
            raise fail(f"direction must be forward or backward, not {direction!r}", lineno)
        if not _FLOAT.fullmatch(time_text):
            raise fail(f"bad time {time_text!r}", lineno)
        t = float(time_text)
        if not (math.isfinite(t) and (t > 0 or t == -1)):
            raise fail(f"time must be > 0 seconds (or -1 for the stored time), not {time_text}", lineno)
        arcs.append(Arc(start, end, int(tok), _DIRECTIONS[direction.lower()], t, lineno))
    if section < 2:
        what = "postures" if section == 0 else "channelset files"
        raise fail(f"missing '#' ending the {what} section", last_line)
    return PostureGraph(postures, files, arcs, filename, file_lines)


def read_posture_graph(path: str | Path) -> PostureGraph:
    path = Path(path)
    return parse_posture_graph(path.read_bytes(), str(path))


# --- writing -----------------------------------------------------------------------------------------------


def _time_text(t: float) -> str:
    return "-1" if t == -1 else repr(float(t))


def format_posture_graph(graph: PostureGraph) -> str:
    """``.graph`` text that parses back to an equal graph."""
    width = max([len(p) for p in graph.postures] + [5])
    out = [
        "// posture names and tokens (they start at 0 and are consecutively numbered)",
        f"{len(graph.postures)} // number of posture states",
        *(f"{i} {p}" for i, p in enumerate(graph.postures)),
        "# marks end-of-postures",
        "//",
        "// posture transition tokens and channelset filenames (from 0, consecutive)",
        f"{len(graph.files)} // number of transition files",
        *(f"{i} {f}" for i, f in enumerate(graph.files)),
        "# marks end-of-posture-transitions",
        "// the transitions (arcs of the graph)",
        f"// {'start':<{width - 3}} {'end':<{width}} channelset playback time",
    ]
    for a in graph.arcs:
        out.append(
            f"{a.start:<{width}} {a.end:<{width}} {a.channelset:<10} {a.direction:<8} {_time_text(a.time)}"
        )
    out.append("# marks end-of-arcs")
    return "\n".join(out) + "\n"


def write_posture_graph(graph: PostureGraph, path: str | Path) -> None:
    Path(path).write_text(format_posture_graph(graph), encoding="utf-8")
