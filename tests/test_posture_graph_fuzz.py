"""Fuzzed posture graph files: located PostureGraphErrors, never another exception and never a hang."""

from __future__ import annotations

import itertools
import math
from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st

from server.motion.errors import PostureGraphError
from server.motion.posture_graph import Arc, PostureGraph, format_posture_graph, parse_posture_graph

SEED = (Path(__file__).resolve().parent / "data" / "motion" / "soldier_low.graph").read_text()
SEED_LINES = SEED.splitlines(keepends=True)
WORDS = [
    "#",
    "//",
    "-1",
    "0",
    "17",
    "8",
    "forward",
    "backward",
    "DEAD",
    "CRAWL",
    "nan",
    "1e999",
    "\t",
    " ",
    "\n",
]


def check(data: str | bytes) -> PostureGraph | None:
    try:
        g = parse_posture_graph(data, "fuzz.graph")
    except PostureGraphError as exc:
        assert exc.file == "fuzz.graph" and isinstance(exc.line, int) and exc.line >= 1
        return None
    # whatever parses must round-trip and answer path queries with results or PostureGraphErrors
    back = parse_posture_graph(format_posture_graph(g), "again.graph")
    assert (back.postures, back.files, back.arcs) == (g.postures, g.files, g.arcs)
    for a, b in itertools.islice(itertools.product(g.postures, repeat=2), 20):
        try:
            path = g.shortest_path(a, b, durations=[1.0] * len(g.files))
        except PostureGraphError:
            continue
        assert not path or (path[0].start == a and path[-1].end == b)
    return g


@pytest.mark.fuzz
@given(st.binary(max_size=400))
def test_random_bytes(data: bytes) -> None:
    check(data)


@st.composite
def mutated_seed(draw: st.DrawFn) -> str:
    lines = list(SEED_LINES)
    for _ in range(draw(st.integers(1, 4))):
        i = draw(st.integers(0, len(lines) - 1))
        op = draw(st.sampled_from(["delete", "duplicate", "swap", "replace_word", "insert", "truncate"]))
        if op == "delete":
            del lines[i]
        elif op == "duplicate":
            lines.insert(i, lines[i])
        elif op == "swap":
            j = draw(st.integers(0, len(lines) - 1))
            lines[i], lines[j] = lines[j], lines[i]
        elif op == "replace_word":
            words = lines[i].split(" ")
            k = draw(st.integers(0, len(words) - 1))
            words[k] = draw(st.sampled_from(WORDS) | st.text(max_size=6))
            lines[i] = " ".join(words)
        elif op == "insert":
            pos = draw(st.integers(0, len(lines[i])))
            lines[i] = lines[i][:pos] + draw(st.text(max_size=5)) + lines[i][pos:]
        else:
            lines[i] = lines[i][: draw(st.integers(0, len(lines[i])))]
        if not lines:
            break
    return "".join(lines)


@pytest.mark.fuzz
@given(mutated_seed())
def test_mutated_seed_graph(text: str) -> None:
    check(text)


@st.composite
def graphs(draw: st.DrawFn) -> PostureGraph:
    names = draw(
        st.lists(st.from_regex(r"[A-Z][A-Z_0-9]{0,8}", fullmatch=True), min_size=1, max_size=7, unique=True)
    )
    files = draw(
        st.lists(st.from_regex(r"[a-z0-9_]{1,10}\.chset\.env", fullmatch=True), min_size=1, max_size=5)
    )
    arc = st.builds(
        Arc,
        st.sampled_from(names),
        st.sampled_from(names),
        st.integers(0, len(files) - 1),
        st.booleans(),
        st.floats(0.01, 20.0) | st.just(-1.0),
    )
    return PostureGraph(names, files, draw(st.lists(arc, max_size=20)))


def floyd(g: PostureGraph, durations: list[float]) -> dict[tuple[str, str], float]:
    d = {(a, b): (0.0 if a == b else math.inf) for a in g.postures for b in g.postures}
    for arc in g.arcs:
        d[arc.start, arc.end] = min(d[arc.start, arc.end], g.arc_time(arc, durations))
    for k, i, j in itertools.product(g.postures, repeat=3):
        d[i, j] = min(d[i, j], d[i, k] + d[k, j])
    return d


@given(graphs(), st.lists(st.floats(0.01, 5.0), min_size=5, max_size=5))
def test_generated_graphs_round_trip_and_paths_are_shortest(g: PostureGraph, durations: list[float]) -> None:
    back = parse_posture_graph(format_posture_graph(g), "gen.graph")
    assert (back.postures, back.files, back.arcs) == (g.postures, g.files, g.arcs)
    best = floyd(g, durations)
    for a, b in itertools.product(g.postures, repeat=2):
        if math.isinf(best[a, b]):
            with pytest.raises(PostureGraphError, match="cannot be reached"):
                g.shortest_path(a, b, durations)
            continue
        path = g.shortest_path(a, b, durations)
        assert g.path_time(path, durations) == pytest.approx(best[a, b])
