"""Posture graph files, shortest paths in time, bound posture graphs and posture changes (seed 002, 3.4.2)."""

from __future__ import annotations

import itertools
import json
import math
import shutil
from pathlib import Path

import pytest

from server.motion.cache import cache_path
from server.motion.errors import BindingError, PostureGraphError
from server.motion.posture_change import bind_posture_graph, load_posture_graph
from server.motion.posture_graph import (
    Arc,
    PostureGraph,
    format_posture_graph,
    parse_posture_graph,
    read_posture_graph,
)
from server.motion.synthetic import toy_rifle, toy_soldier
from ttes.cli import main

DATA = Path(__file__).resolve().parent / "data" / "motion"
GRAPH = DATA / "soldier_low.graph"

SMALL = """// a tiny graph
3 // postures
0 A
1 B
2 C
#
2 // files
0 a2b.chset.env
1 b2c.chset.env
#
// start end channelset playback time
A B 0 forward 1.0
B A 0 backward 1.0
B C 1 forward -1
# end
"""


@pytest.fixture
def seed_dir(tmp_path: Path) -> Path:
    """A private copy of the seed graph and its channelsets (so caches land in tmp, not in the repo)."""
    for f in DATA.glob("*.graph"):
        shutil.copy(f, tmp_path / f.name)
    for f in DATA.glob("*.chset.env"):
        shutil.copy(f, tmp_path / f.name)
    return tmp_path


# --- the file format ---------------------------------------------------------------------------------------


def test_seed_graph_reads() -> None:
    g = read_posture_graph(GRAPH)
    stand, kneel, prone = (
        ["STAND_STOWED", "STAND_FIRE"],
        ["KNEEL_STOWED", "KNEEL_FIRE"],
        ["PRONE_STOWED", "PRONE_FIRE"],
    )
    assert g.postures == [*stand, *kneel, *prone, "CRAWL", "DEAD"]
    assert len(g.files) == 17 and g.files[0] == "ststow2stfire_low.chset.env"
    assert g.files[16] == "stfire2kstow_low.chset.env"
    assert g.arcs[0] == Arc("STAND_STOWED", "STAND_FIRE", 0, True, 0.8)
    assert g.arcs[-1] == Arc("DEAD", "STAND_STOWED", 4, False, 10.0)
    assert (
        g.arcs[0].line
        == GRAPH.read_text().splitlines().index("STAND_STOWED STAND_FIRE   0          forward  0.8") + 1
    )
    assert not any({a.start, a.end} == {"PRONE_FIRE", "KNEEL_FIRE"} for a in g.arcs)  # no direct transition


def test_graph_text_round_trip() -> None:
    g = read_posture_graph(GRAPH)
    back = parse_posture_graph(format_posture_graph(g), "x.graph")
    assert (back.postures, back.files, back.arcs) == (g.postures, g.files, g.arcs)
    small = parse_posture_graph(SMALL)
    assert small.arcs[2].time == -1
    again = parse_posture_graph(format_posture_graph(small))
    assert again.arcs == small.arcs


def test_comments_blank_lines_and_tolerated_spellings() -> None:
    text = SMALL.replace("A B 0 forward 1.0", "  A   B 0 Forwards 1.  // comment").replace("# end\n", "")
    g = parse_posture_graph(text)
    assert g.arcs[0] == Arc("A", "B", 0, True, 1.0)


def located_error(text: str) -> PostureGraphError:
    with pytest.raises(PostureGraphError) as info:
        parse_posture_graph(text, "bad.graph")
    assert info.value.file == "bad.graph"
    return info.value


def line_of(text: str, needle: str) -> int:
    return text[: text.index(needle)].count("\n") + 1


@pytest.mark.parametrize(
    ("old", "new", "marker"),
    [
        ("1 B\n", "2 B\n", "2 B"),  # tokens not consecutive
        ("0 A\n", "1 A\n", "1 A"),  # not starting at 0
        ("3 // postures", "4 // postures", "#\n2 // files"),  # count does not match
        ("2 // files", "1 // files", "1 b2c"),  # more entries than declared
        ("A B 0 forward 1.0", "A B 2 forward 1.0", "A B 2"),  # missing channelset token
        ("A B 0 forward 1.0", "A Q 0 forward 1.0", "A Q 0"),  # unknown posture
        ("A B 0 forward 1.0", "A B 0 sideways 1.0", "A B 0 sideways"),  # bad direction
        ("A B 0 forward 1.0", "A B 0 forward 0", "A B 0 forward 0"),  # zero time
        ("A B 0 forward 1.0", "A B 0 forward nan", "A B 0 forward nan"),  # not a number
        ("A B 0 forward 1.0", "A B 0 forward", "A B 0 forward\n"),  # missing field
        ("2 C\n", "2 A\n", "2 A"),  # duplicate posture
        ("3 // postures", "three // postures", "three"),  # bad count
    ],
)
def test_bad_graphs_give_located_errors(old: str, new: str, marker: str) -> None:
    text = SMALL.replace(old, new, 1)
    assert text != SMALL
    err = located_error(text)
    assert err.line == line_of(text, marker), str(err)


def test_truncated_and_binary_graphs_are_located_errors() -> None:
    after = located_error(SMALL + "A B 0 forward 1.0\n")
    assert after.line == SMALL.count("\n") + 1 and "after the end" in after.message
    assert located_error("3\n0 A\n").line == 2
    assert located_error("").line == 1
    with pytest.raises(PostureGraphError) as info:
        parse_posture_graph(b"3\n0 A\n\xff\xfe", "bin.graph")
    assert info.value.line == 3


# --- shortest paths ----------------------------------------------------------------------------------------


def test_shortest_path_to_prone_fire_goes_through_crawl() -> None:
    g = read_posture_graph(GRAPH)
    path = g.shortest_path("STAND_STOWED", "PRONE_FIRE")
    assert [a.start for a in path] + [path[-1].end] == ["STAND_STOWED", "CRAWL", "PRONE_STOWED", "PRONE_FIRE"]
    assert g.path_time(path) == pytest.approx(3.6)
    assert g.shortest_path("CRAWL", "CRAWL") == []


def floyd_warshall(g: PostureGraph) -> dict[tuple[str, str], float]:
    d = {(a, b): (0.0 if a == b else math.inf) for a in g.postures for b in g.postures}
    for arc in g.arcs:
        d[arc.start, arc.end] = min(d[arc.start, arc.end], arc.time)
    for k, i, j in itertools.product(g.postures, repeat=3):
        d[i, j] = min(d[i, j], d[i, k] + d[k, j])
    return d


def test_dijkstra_agrees_with_floyd_warshall_on_every_pair() -> None:
    g = read_posture_graph(GRAPH)
    best = floyd_warshall(g)
    for a, b in itertools.product(g.postures, repeat=2):
        path = g.shortest_path(a, b)
        assert g.path_time(path) == pytest.approx(best[a, b])
        assert all(x.end == y.start for x, y in itertools.pairwise(path))
        if path:
            assert path[0].start == a and path[-1].end == b
    dead = g.shortest_path("DEAD", "PRONE_FIRE")
    assert dead[0] == Arc("DEAD", "STAND_STOWED", 4, False, 10.0)


def test_unreachable_and_unknown_postures_are_clear_errors() -> None:
    g = parse_posture_graph(SMALL.replace("B C 1 forward -1", "B C 1 forward 2"), "small.graph")
    with pytest.raises(PostureGraphError, match="cannot be reached"):
        g.shortest_path("C", "A")
    with pytest.raises(PostureGraphError, match="unknown posture"):
        g.shortest_path("A", "Z")


def test_stored_time_arcs_need_the_channelsets() -> None:
    g = parse_posture_graph(SMALL, "small.graph")
    with pytest.raises(PostureGraphError, match="stored time"):
        g.shortest_path("A", "C")
    durations = [1.0, 0.25]
    assert g.path_time(g.shortest_path("A", "C", durations), durations) == pytest.approx(1.25)


# --- loading, binding and executing ------------------------------------------------------------------------


def test_missing_channelset_file_names_the_graph_line(seed_dir: Path) -> None:
    (seed_dir / "crawl2dead_low.chset.env").unlink()
    with pytest.raises(PostureGraphError) as info:
        load_posture_graph(seed_dir / "soldier_low.graph")
    text = (seed_dir / "soldier_low.graph").read_text()
    assert info.value.line == line_of(text, "13 crawl2dead_low.chset.env")
    assert info.value.file == str(seed_dir / "soldier_low.graph")


def test_load_and_bind_the_seed_graph(seed_dir: Path) -> None:
    loaded = load_posture_graph(seed_dir / "soldier_low.graph", "ptrans")
    assert len(loaded.channelsets) == 17 and cache_path(seed_dir / "crawl2dead_low.chset.env").is_file()
    assert loaded.protofiletypes == ["toy_rifle.fig", "toy_soldier.fig"]
    assert loaded.durations[2] == pytest.approx(2.0)
    with pytest.raises(BindingError, match=r"toy_rifle\.fig"):
        bind_posture_graph(loaded, [toy_soldier("soldier3")])
    bound = bind_posture_graph(loaded, [toy_soldier("soldier3"), toy_rifle("gun3")], "soldier3/ptrans")
    assert bound.current == "STAND_STOWED"
    assert bound.bound[2].name == "soldier3/ptrans/ststow2crawl_low.chset"
    assert bound.bound[2].channelset is loaded.channelsets[2]
    assert 0 < bound.nbytes < sum(c.nbytes for c in loaded.channelsets)
    again = load_posture_graph(seed_dir / "soldier_low.graph")  # from the caches now
    assert [c.nframes for c in again.channelsets] == [c.nframes for c in loaded.channelsets]


def test_a_bound_graph_plans_the_quickest_path_from_where_it_rests(seed_dir: Path) -> None:
    """Executing the path is the soldier manager's (test_soldier_manager.py, test_jcl_commands.py)."""
    loaded = load_posture_graph(seed_dir / "soldier_low.graph")
    bound = bind_posture_graph(loaded, [toy_soldier(), toy_rifle()])
    path = bound.shortest_path("PRONE_FIRE")
    assert [(a.end, loaded.arc_time(a)) for a in path] == [
        ("CRAWL", 2.0),
        ("PRONE_STOWED", 0.8),
        ("PRONE_FIRE", pytest.approx(0.8)),
    ]
    dead = bind_posture_graph(loaded, [toy_soldier(), toy_rifle()], initial="DEAD")
    back = dead.shortest_path("STAND_STOWED")
    assert not back[0].forward and loaded.arc_time(back[0]) == 10.0  # backwards, stretched to 10 s
    assert bound.shortest_path("STAND_STOWED") == []  # already there


# --- the CLI -----------------------------------------------------------------------------------------------


def test_cli_graph_path_json(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["graph", "path", str(GRAPH), "STAND_STOWED", "PRONE_FIRE", "--json"]) == 0
    obj = json.loads(capsys.readouterr().out)
    assert obj["path"] == ["STAND_STOWED", "CRAWL", "PRONE_STOWED", "PRONE_FIRE"]
    assert obj["arcs"][0] == {
        "from": "STAND_STOWED",
        "to": "CRAWL",
        "channelset": "ststow2crawl_low.chset.env",
        "direction": "forward",
        "time": 2.0,
    }
    assert obj["time_s"] == pytest.approx(3.6)
    assert main(["graph", "path", str(GRAPH), "STAND_STOWED", "FLYING"]) == 2
    assert "unknown posture" in capsys.readouterr().err


def test_cli_graph_info_json(capsys: pytest.CaptureFixture[str], seed_dir: Path) -> None:
    assert main(["graph", "info", str(seed_dir / "soldier_low.graph"), "--load", "--json"]) == 0
    obj = json.loads(capsys.readouterr().out)
    assert len(obj["postures"]) == 8 and len(obj["channelsets"]) == 17 and len(obj["arcs"]) == 28
    assert obj["channelset_durations_s"][11] == pytest.approx(0.8)
